"""The scenario's `disturbances:` section: wheel slip, encoder noise and IMU noise, all from seeded streams.

Slip is physical: the chassis (and the test trajectory generator) moves the robot with the wheels'
ground speeds, which a slip fraction `s` makes `(1 - s)` times their rim speeds, everywhere or inside
polygonal floor regions (world frame). The encoders still count the wheels' turns, so wheel odometry
overestimates the travel, and a left/right difference turns into a heading error that only the gyro
sees. Encoder and IMU noise enter the sensor models (`twin.robot.encoders`, `twin.robot.imu`).

```yaml
disturbances:
  wheel_slip:
    left_fraction: 0.0          # share of the rim travel lost everywhere, in [0, 1)
    right_fraction: 0.0
    regions:                    # the first region that holds the robot wins
      - polygon_xy_m: [[1.0, -4.5], [3.0, -4.5], [3.0, -2.0], [1.0, -2.0]]
        left_fraction: 0.3
        right_fraction: 0.1
  encoders:
    travel_std_per_sqrt_rad: 0.005
    tick_noise_std: 0.0
  imu:
    gyro:                       # null keeps the robot SDF's <noise>
      stddev: 2.0e-4
      bias_stddev: 5.0e-4
      dynamic_bias_stddev: 1.0e-6     # rad/s per sqrt(s): the bias drift's random walk
      dynamic_bias_correlation_time_s: 3600.0
    accel: null
```

The defaults are the TurtleBot3 SDF's gyro noise plus what a real robot adds: a gyro turn-on bias
(about 0.03 deg/s), its slow drift, and wheel odometry noise. The `estimation:` defaults assume exactly
these, so the EKF's covariances are honest in the default twin.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from twin.robot.encoders import EncoderNoise
from twin.robot.imu import GaussianNoise, ImuSpec, three_axes

__all__ = ["DEFAULT_GYRO_NOISE", "Disturbances", "ImuDisturbances", "SlipRegion", "WheelSlip"]

DEFAULT_GYRO_NOISE = GaussianNoise(
    stddev=2.0e-4, bias_stddev=5.0e-4, dynamic_bias_stddev=1.0e-6, dynamic_bias_correlation_time_s=3600.0
)
"""The TurtleBot3's gyro white noise (2e-4 rad/s) with a turn-on bias and a slow bias drift."""


@dataclass(frozen=True, kw_only=True, slots=True)
class SlipRegion:
    """A floor region where the wheels slip: a simple polygon in the world frame.

    Attributes:
        polygon_xy_m: At least three (x, y) vertices, in order; the polygon closes itself.
        left_fraction: Share of the left wheel's rim travel lost inside the region, in [0, 1).
        right_fraction: Same for the right wheel.
    """

    polygon_xy_m: tuple[tuple[float, float], ...]
    left_fraction: float = 0.0
    right_fraction: float = 0.0

    def __post_init__(self) -> None:
        if len(self.polygon_xy_m) < 3:
            msg = f"polygon_xy_m needs at least 3 vertices, got {len(self.polygon_xy_m)}"
            raise ValueError(msg)
        _check_fraction("left_fraction", self.left_fraction)
        _check_fraction("right_fraction", self.right_fraction)

    @classmethod
    def rectangle(
        cls,
        *,
        x_min_m: float,
        y_min_m: float,
        x_max_m: float,
        y_max_m: float,
        left_fraction: float,
        right_fraction: float,
    ) -> SlipRegion:
        """Return an axis-aligned rectangular region."""
        corners = ((x_min_m, y_min_m), (x_max_m, y_min_m), (x_max_m, y_max_m), (x_min_m, y_max_m))
        return cls(polygon_xy_m=corners, left_fraction=left_fraction, right_fraction=right_fraction)

    def contains(self, x_m: float, y_m: float) -> bool:
        """Return True if the point is inside the polygon (even-odd rule)."""
        inside = False
        pts = self.polygon_xy_m
        x0, y0 = pts[-1]
        for x1, y1 in pts:
            if (y1 > y_m) != (y0 > y_m) and x_m < x0 + (y_m - y0) * (x1 - x0) / (y1 - y0):
                inside = not inside
            x0, y0 = x1, y1
        return inside


@dataclass(frozen=True, kw_only=True, slots=True)
class WheelSlip:
    """Wheel slip: fractions everywhere, overridden inside regions (the first region that holds the point wins).

    Attributes:
        left_fraction: Share of the left wheel's rim travel lost, in [0, 1).
        right_fraction: Same for the right wheel.
        regions: Floor regions with their own fractions.
    """

    left_fraction: float = 0.0
    right_fraction: float = 0.0
    regions: tuple[SlipRegion, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        _check_fraction("left_fraction", self.left_fraction)
        _check_fraction("right_fraction", self.right_fraction)

    @property
    def is_uniform(self) -> bool:
        """True when slip does not depend on where the robot is."""
        return not self.regions

    def fractions_at(self, x_m: float, y_m: float) -> tuple[float, float]:
        """Return (left, right) slip fractions at a world position."""
        for region in self.regions:
            if region.contains(x_m, y_m):
                return region.left_fraction, region.right_fraction
        return self.left_fraction, self.right_fraction


def _check_fraction(name: str, value: float) -> None:
    if not 0.0 <= value < 1.0:
        msg = f"{name} must be in [0, 1), got {value}"
        raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class ImuDisturbances:
    """IMU noise for the three axes of each channel; null keeps what the robot's SDF says."""

    gyro: GaussianNoise | None = DEFAULT_GYRO_NOISE
    accel: GaussianNoise | None = None

    def apply(self, spec: ImuSpec) -> ImuSpec:
        """Return `spec` with the noise set here."""
        if self.gyro is not None:
            spec = dataclasses.replace(spec, angular_velocity_noise=three_axes(self.gyro))
        if self.accel is not None:
            spec = dataclasses.replace(spec, linear_acceleration_noise=three_axes(self.accel))
        return spec


@dataclass(frozen=True, kw_only=True, slots=True)
class Disturbances:
    """Everything that makes the twin's sensors disagree with the truth, beyond the SDF's sensor noise."""

    wheel_slip: WheelSlip = field(default_factory=WheelSlip)
    encoders: EncoderNoise = field(default_factory=EncoderNoise)
    imu: ImuDisturbances = field(default_factory=ImuDisturbances)
