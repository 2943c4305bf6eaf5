"""Layer 2: the robot: drivetrain, sensors (lidar, IMU, encoders, ground truth), description.

Import the modules directly, e.g. `twin.robot.lidar`.
"""

__all__: list[str] = []
