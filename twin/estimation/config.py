"""The scenario's `estimation:` section: process noise, measurement noise and initial uncertainty of the EKF.

Every number has a unit in its name. The defaults describe the default twin exactly (the scenario's
`disturbances:` defaults, `twin.robot.disturbances`): a TurtleBot3 gyro (2e-4 rad/s white noise at
200 Hz, TB3_FACTS.md §2.2) with a 5e-4 rad/s turn-on bias drifting by 1e-6 rad/s per square-root
second, 4096-tick encoders (§3.1) and wheel odometry noise of 0.005 rad per square-root radian, so the
filter's covariances are honest there. For a real robot's bag, raise what its floor and IMU need
(docs/estimation.md).

```yaml
estimation:
  fuse_gyro: true
  slip_gate_probability: 0.999
  process_noise:
    velocity_random_walk_mps_per_sqrt_s: 0.2
    yaw_rate_random_walk_radps_per_sqrt_s: 1.0
    gyro_bias_random_walk_radps_per_sqrt_s: 1.0e-6
    wheel_travel_std_per_sqrt_rad: 0.005
  measurement_noise:
    encoder_ticks_per_rev: 4096
    wheel_speed_std_radps: 0.01
    gyro_std_radps: 2.0e-4
    standstill_speed_std_mps: 1.0e-4
    standstill_yaw_rate_std_radps: 1.0e-5
  initial_std:
    position_m: 1.0e-6
    yaw_rad: 1.0e-6
    velocity_mps: 1.0e-3
    yaw_rate_radps: 1.0e-3
    gyro_bias_radps: 5.0e-4
```
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

__all__ = ["EstimationSection", "InitialStd", "MeasurementNoise", "ProcessNoise"]


def _check_nonnegative(obj: object) -> None:
    for f in fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if not (value >= 0.0 and math.isfinite(value)):
            msg = f"{f.name} must be a finite number >= 0, got {value}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class ProcessNoise:
    """How fast the unmeasured truth may change, as random walks (variance grows with time).

    Attributes:
        velocity_random_walk_mps_per_sqrt_s: Forward speed; 0.2 covers the TurtleBot3's 1 m/s² wheel
            acceleration limit between two 30 Hz updates.
        yaw_rate_random_walk_radps_per_sqrt_s: Yaw rate; 1.0 covers spin-ups at the same limit.
        gyro_bias_random_walk_radps_per_sqrt_s: Slow drift of the gyro bias.
        wheel_travel_std_per_sqrt_rad: Odometry noise: a wheel's reading wanders from the travel the
            chassis motion explains by this many radians per square-root radian the wheel turns
            (variance grows with travel, as odometry error does; nothing at standstill).
    """

    velocity_random_walk_mps_per_sqrt_s: float = 0.2
    yaw_rate_random_walk_radps_per_sqrt_s: float = 1.0
    gyro_bias_random_walk_radps_per_sqrt_s: float = 1.0e-6
    wheel_travel_std_per_sqrt_rad: float = 0.005

    def __post_init__(self) -> None:
        _check_nonnegative(self)


@dataclass(frozen=True, kw_only=True, slots=True)
class MeasurementNoise:
    """Noise of the encoders and the gyro as the filter models it.

    Attributes:
        encoder_ticks_per_rev: Encoder resolution: each wheel-angle reading is rounded to a tick, an
            error of variance `tick**2 / 12` that does not accumulate.
        wheel_speed_std_radps: Noise of a wheel speed when only speeds are available (a joint state
            without positions); unused when the wheel angles are.
        gyro_std_radps: White noise of one gyro sample; the filter averages the samples between two
            encoder readings, so the average has `gyro_std_radps**2 / n` variance.
        standstill_speed_std_mps: When neither wheel has moved a tick for two readings, the robot
            stands still: speed 0 with this deviation (a zero-velocity update).
        standstill_yaw_rate_std_radps: Yaw rate 0 with this deviation at standstill; this is where
            the gyro bias is learned.
    """

    encoder_ticks_per_rev: int = 4096
    wheel_speed_std_radps: float = 0.01
    gyro_std_radps: float = 2.0e-4
    standstill_speed_std_mps: float = 1.0e-4
    standstill_yaw_rate_std_radps: float = 1.0e-5

    def __post_init__(self) -> None:
        _check_nonnegative(self)
        if self.encoder_ticks_per_rev < 1:
            msg = f"encoder_ticks_per_rev must be at least 1, got {self.encoder_ticks_per_rev}"
            raise ValueError(msg)
        for name in ("gyro_std_radps", "standstill_speed_std_mps", "standstill_yaw_rate_std_radps"):
            if getattr(self, name) <= 0.0:
                msg = f"{name} must be positive, got {getattr(self, name)}"
                raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class InitialStd:
    """Standard deviations of the initial state (the filter starts at the given pose, at rest, bias 0).

    The `odom` frame is where the robot starts, so the pose is known there; the small defaults only keep
    the covariance positive definite. The bias prior is what an IMU's turn-on bias may be.
    """

    position_m: float = 1.0e-6
    yaw_rad: float = 1.0e-6
    velocity_mps: float = 1.0e-3
    yaw_rate_radps: float = 1.0e-3
    gyro_bias_radps: float = 5.0e-4

    def __post_init__(self) -> None:
        _check_nonnegative(self)


@dataclass(frozen=True, kw_only=True, slots=True)
class EstimationSection:
    """The EKF that fuses wheel encoders and the gyro into `/odom`.

    Attributes:
        fuse_gyro: Fuse the gyro's yaw rate (false gives wheel odometry alone, for comparison).
        slip_gate_probability: When an update's normalised innovation squared exceeds this chi-square
            quantile, the wheels and the gyro disagree beyond their noise (at standstill: the robot
            turns while its wheels do not): the wheels' say on the yaw is dropped for that step.
            null disables the gate.
        process_noise: Random-walk rates of speed, yaw rate and gyro bias.
        measurement_noise: Encoder and gyro noise.
        initial_std: Initial uncertainty.
    """

    fuse_gyro: bool = True
    slip_gate_probability: float | None = 0.999
    process_noise: ProcessNoise = field(default_factory=ProcessNoise)
    measurement_noise: MeasurementNoise = field(default_factory=MeasurementNoise)
    initial_std: InitialStd = field(default_factory=InitialStd)

    def __post_init__(self) -> None:
        p = self.slip_gate_probability
        if p is not None and not 0.0 < p < 1.0:
            msg = f"slip_gate_probability must be between 0 and 1 (exclusive) or null, got {p}"
            raise ValueError(msg)
