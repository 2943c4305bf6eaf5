"""Layer 2: the robot: drivetrain, chassis, sensors (lidar, IMU, encoders, ground truth), description.

Import the modules directly, e.g. `twin.robot.imu`, `twin.robot.encoders`.
"""

__all__: list[str] = []
