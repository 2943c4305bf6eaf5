"""Wheel encoders and `/joint_states`, and the wheel-slip disturbance that makes them lie.

**Encoders.** The TurtleBot3's Dynamixels report an absolute 12-bit position (4096 ticks per turn);
the twin reads each wheel's true angle (from the drive), adds optional Gaussian jitter in ticks, and
rounds to whole ticks. The published position is `ticks * 2*pi / ticks_per_rev` radians.

**Velocity.** The twin derives each wheel's velocity from the ticks, as odometry on the real robot
would: the tick change since the previous reading over the time between them (so its resolution is
one tick per period, 0.046 rad/s at 30 Hz). Gazebo's joint-state publisher reports the physics
engine's exact joint velocity instead, and the real TurtleBot3 reports the Dynamixel's own velocity
register converted to the wheel's rim speed in m/s (TB3_FACTS.md §3.2). `velocity_units` chooses
rad/s (Gazebo, the default) or m/s (the real robot's convention) for the published value.

**Odometry noise.** Tyres are compliant and slip a little on any floor, and gears have backlash, so a
reading drifts from the wheel's travel over the floor. `EncoderNoise.travel_std_per_sqrt_rad` makes
that drift a random walk whose variance grows with the angle the wheel turns (and not at all while it
stands still), the usual model of odometry error. Gross wheel slip is a disturbance of the chassis
(`twin.robot.disturbances.WheelSlip`), not of the encoders: there the wheels turn and the robot does
not follow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np

# Normals drawn per refill of the noise stream.
_BLOCK = 256

__all__ = ["EncoderModel", "EncoderNoise", "EncoderSpec", "JointStateReading"]


@dataclass(frozen=True, kw_only=True, slots=True)
class EncoderSpec:
    """The wheel encoders and the `/joint_states` they feed.

    Attributes:
        ticks_per_rev: Encoder resolution (4096 on the TurtleBot3's XL430/XM430).
        rate_hz: `/joint_states` rate (30 Hz in the TurtleBot3 Gazebo model).
        joint_names: Left and right wheel joint names, in that order.
        wheel_radius_m: Used only to publish rim speed when `velocity_units` is m/s.
        velocity_units: `rad/s` (Gazebo) or `m/s` of wheel rim (the real TurtleBot3).
    """

    ticks_per_rev: int = 4096
    rate_hz: float = 30.0
    joint_names: tuple[str, str] = ("wheel_left_joint", "wheel_right_joint")
    wheel_radius_m: float = 0.033
    velocity_units: Literal["rad/s", "m/s"] = "rad/s"

    def __post_init__(self) -> None:
        if self.ticks_per_rev < 1:
            msg = f"ticks_per_rev must be at least 1, got {self.ticks_per_rev}"
            raise ValueError(msg)
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            msg = f"rate_hz must be a positive number, got {self.rate_hz}"
            raise ValueError(msg)

    @property
    def tick_rad(self) -> float:
        """One tick in radians."""
        return 2.0 * math.pi / self.ticks_per_rev


@dataclass(frozen=True, kw_only=True, slots=True)
class EncoderNoise:
    """How the encoder readings depart from the wheels' travel over the floor.

    Attributes:
        travel_std_per_sqrt_rad: Odometry noise: each reading drifts from the wheel's ground travel
            as a random walk of this many radians per square-root radian turned (tyre compliance,
            micro-slip, gear backlash), so the error grows with distance, as odometry error does.
            The default, 0.005, lets a TurtleBot3 wheel's reading err by about 4 mm over 20 m of travel,
            and wheel odometry's heading by about 1 degree.
        tick_noise_std: Gaussian jitter on each reading, in ticks, before rounding.
    """

    travel_std_per_sqrt_rad: float = 0.005
    tick_noise_std: float = 0.0

    def __post_init__(self) -> None:
        for name in ("travel_std_per_sqrt_rad", "tick_noise_std"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                msg = f"{name} must be a finite number >= 0, got {value}"
                raise ValueError(msg)


class JointStateReading(NamedTuple):
    """One `/joint_states` worth of numbers for the two wheels (names from `EncoderSpec.joint_names`).

    Positions are radians; velocities are in `EncoderSpec.velocity_units`.
    """

    position_left_rad: float
    position_right_rad: float
    velocity_left: float
    velocity_right: float


class EncoderModel:
    """Quantised wheel encoders sampled by the caller at `spec.rate_hz`.

    Args:
        spec: Resolution, rate, names and velocity units.
        noise: Odometry noise and jitter.
        rng: The encoders' noise stream (drawn in blocks, four normals per reading).
    """

    def __init__(self, spec: EncoderSpec, noise: EncoderNoise, rng: np.random.Generator) -> None:
        self.spec = spec
        self.joint_names = spec.joint_names
        self._ticks_per_rad = spec.ticks_per_rev / (2.0 * math.pi)
        self._tick_rad = spec.tick_rad
        self._travel_std = noise.travel_std_per_sqrt_rad
        self._jitter = noise.tick_noise_std
        self._noisy = self._travel_std > 0.0 or self._jitter > 0.0
        self._rng = rng
        self._normals: list[list[float]] = []
        self._next = 0
        self._velocity_scale = spec.wheel_radius_m if spec.velocity_units == "m/s" else 1.0
        self._last: tuple[int, int, int] | None = None
        self._angles: tuple[float, float] | None = None
        self._drift_left = 0.0
        self._drift_right = 0.0

    @property
    def drift_rad(self) -> tuple[float, float]:
        """How far each reading has drifted from its wheel's true angle by odometry noise (ground truth)."""
        return self._drift_left, self._drift_right

    def ticks(self, left_angle_rad: float, right_angle_rad: float) -> tuple[int, int]:
        """Return the encoder counts for two true wheel angles (with drift and jitter, if any)."""
        left, right = left_angle_rad, right_angle_rad
        if self._noisy:
            if self._next == len(self._normals):
                self._normals = self._rng.standard_normal((_BLOCK, 4)).tolist()
                self._next = 0
            n = self._normals[self._next]
            self._next += 1
            last = self._angles or (left, right)
            std = self._travel_std
            self._drift_left += std * math.sqrt(abs(left - last[0])) * n[0]
            self._drift_right += std * math.sqrt(abs(right - last[1])) * n[1]
            self._angles = (left, right)
            tick_rad = self._tick_rad
            left += self._drift_left + self._jitter * n[2] * tick_rad
            right += self._drift_right + self._jitter * n[3] * tick_rad
        return round(left * self._ticks_per_rad), round(right * self._ticks_per_rad)

    def read(self, t_ns: int, left_angle_rad: float, right_angle_rad: float) -> JointStateReading:
        """Return the joint state at `t_ns` from the wheels' true angles.

        The first reading reports zero velocity (no previous count to difference against).
        """
        tl, tr = self.ticks(left_angle_rad, right_angle_rad)
        last = self._last
        if last is None or t_ns <= last[0]:
            vl = vr = 0.0
        else:
            scale = self._tick_rad * self._velocity_scale * 1e9 / (t_ns - last[0])
            vl = (tl - last[1]) * scale
            vr = (tr - last[2]) * scale
        self._last = (t_ns, tl, tr)
        return JointStateReading(tl * self._tick_rad, tr * self._tick_rad, vl, vr)
