"""The robot: drivetrain (FMU wheels, controller, chassis, contact), sensors and robot description.

Import from the modules: `twin.robot.drivetrain`, `twin.robot.chassis`, `twin.robot.drive_control`.
"""

__all__: list[str] = []
