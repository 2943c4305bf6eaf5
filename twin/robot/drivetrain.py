"""Drivetrains: what the simulation loop steps to move the robot.

`Drivetrain` is the Protocol the loop calls; the FMU drive (`twin.robot.fmu_drivetrain`) and an
ideal kinematic drive (`twin.robot.kinematic`) implement it. The loop sets the latest command with
`set_cmd_vel`, calls `advance(n)` to run `n` fixed physics steps between its events, and reads
`chassis_state()` and `wheel_state()` for sensors and recording.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

from twin.robot.chassis import ChassisState

__all__ = ["Drivetrain", "WheelState"]


class WheelState(NamedTuple):
    """Per-wheel signals, each a (left, right) pair; NaN where the FMU has no such output."""

    angle_rad: tuple[float, float]
    speed_radps: tuple[float, float]
    effort_nm: tuple[float, float]  # drive torque at the wheel
    voltage_v: tuple[float, float]
    current_a: tuple[float, float]


class Drivetrain(Protocol):
    """What the simulation loop steps. Time advances only through `advance`."""

    step_ns: int
    label: str  # what a run's summary calls the drive, e.g. `kinematic`

    def set_cmd_vel(self, v_mps: float, w_radps: float) -> None:
        """Take a new body velocity command (held until the next one)."""

    def advance(self, n_steps: int) -> None:
        """Run `n_steps` fixed physics steps."""

    def chassis_state(self) -> ChassisState:
        """Pose, rates and accelerations of the chassis now."""

    def wheel_state(self) -> WheelState:
        """Wheel angles, speeds, efforts, voltages and currents now."""

    def close(self) -> None:
        """Release resources (idempotent)."""
