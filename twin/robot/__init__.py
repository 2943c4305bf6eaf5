"""Layer 2: the robot: drivetrains (ideal and FMU), chassis and contact, sensors (lidar, IMU, encoders).

Import the modules directly: `twin.robot.drivetrain`, `twin.robot.fmu_drive`, `twin.robot.fmu_drivetrain`,
`twin.robot.step_response`, `twin.robot.chassis`, `twin.robot.kinematic`,
`twin.robot.lidar`, `twin.robot.imu`, `twin.robot.encoders`, `twin.robot.disturbances`,
`twin.robot.drive_control`, `twin.robot.trajectory`.
"""

__all__: list[str] = []
