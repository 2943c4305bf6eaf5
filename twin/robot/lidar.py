"""The planar lidar: LaserScan ranges as Gazebo Classic's ray sensor and gazebo_ros_ray_sensor give them.

What Gazebo does, and so what this does (gazebo-classic `RaySensor`/`MultiRayShape`, gazebo_ros
`Convert<LaserScan>`):

- Rays: `samples` rays at `angle_min + i * (angle_max - angle_min) / (samples - 1)` in the sensor
  frame. Each ray starts `range_min` from the sensor, so nearer surfaces are not seen; the raw range
  is `range_min` plus the distance to the first surface crossed (a ray starting inside a shape
  reports where it leaves), or `range_max` when nothing is crossed.
- Ranges: `samples x resolution` of them; when that differs from `samples`, each is linearly
  interpolated between the two nearest rays (before masking and noise).
- Published `angle_increment` is Gazebo's `angle_step`, `(angle_max - angle_min) / (count - 1)`:
  6.28 / 359 = 0.017493 rad for the LDS-01, not 2*pi/360. `time_increment` and `scan_time` are 0.
- Masking (REP 117): a raw range >= `range_max` becomes `+inf`, one <= `range_min` becomes `-inf`.
- Noise only on ranges in between: Gaussian (mean, stddev) added, then clamped to
  [`range_min`, `range_max`]. `<range><resolution>` is not applied to the values (Gazebo keeps it
  as metadata).

The caller passes a `numpy.random.Generator` for the noise (one seeded stream per noise source);
every scan draws exactly `count` samples, so the stream does not depend on what is hit.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.world.obstacles import ObstacleCaster
from twin.world.robot_model import LidarSpec, RobotModelSpec
from twin.world.scene import RayCaster, Scene, mask_ranges

__all__ = ["Lidar", "ScanGeometry"]


class ScanGeometry(NamedTuple):
    """The LaserScan fields that do not change from scan to scan."""

    angle_min_rad: float
    angle_max_rad: float
    angle_increment_rad: float
    time_increment_s: float
    scan_time_s: float
    range_min_m: float
    range_max_m: float
    num_ranges: int


class ObstacleSource(Protocol):
    """What moves in the world besides its fixed geometry, as a lidar sees it (an `ObstacleField`, other robots)."""

    def caster(self, height_m: float) -> ObstacleCaster | None:
        """A ray caster over what stands at `height_m` now (None: nothing reaches it)."""
        ...


class Lidar:
    """Produces scans for a robot pose from a `LidarSpec` and the scene's ray caster.

    Args:
        spec: The lidar (rates, angles, ranges, noise, mount pose in the robot's base frame).
        caster: The scene's ray caster at the lidar's height above the floor.
        rng: Source of the Gaussian noise; required when the spec has noise.
        obstacles: Obstacles that come and go (`ObstacleField`), seen at the caster's height along
            with the world; None (the default) costs nothing.
    """

    def __init__(
        self,
        spec: LidarSpec,
        caster: RayCaster,
        rng: np.random.Generator | None = None,
        *,
        obstacles: ObstacleSource | None = None,
    ) -> None:
        if spec.samples < 1 or spec.count < 1:
            msg = f"lidar {spec.name!r}: samples and samples x resolution must be at least 1"
            raise ValueError(msg)
        if not 0.0 <= spec.range_min_m < spec.range_max_m:
            msg = (
                f"lidar {spec.name!r}: need 0 <= range_min_m < range_max_m, got {spec.range_min_m}, {spec.range_max_m}"
            )
            raise ValueError(msg)
        self.spec = spec
        self._caster = caster
        self._obstacles = obstacles
        self._noisy = spec.noise_std_m > 0.0 or spec.noise_mean_m != 0.0
        if self._noisy and rng is None:
            msg = f"lidar {spec.name!r} has noise; pass a numpy.random.Generator"
            raise ValueError(msg)
        self._rng = rng
        mount = spec.mount
        # A sensor mounted upside down (roll or pitch of pi) sweeps the other way round.
        self._sweep = 1.0 if math.cos(mount.roll_rad) * math.cos(mount.pitch_rad) >= 0.0 else -1.0
        self._mx, self._my, self._myaw = mount.x_m, mount.y_m, mount.yaw_rad
        self._ray_step = (spec.angle_max_rad - spec.angle_min_rad) / (spec.samples - 1) if spec.samples > 1 else 0.0
        self._start = spec.angle_min_rad if spec.samples > 1 else 0.0
        count = spec.count
        if count != spec.samples:
            position = np.arange(count) * (spec.samples - 1) / (count - 1) if count > 1 else np.zeros(1)
            self._lo = np.floor(position).astype(np.intp)
            self._hi = np.minimum(self._lo + 1, spec.samples - 1)
            self._frac = position - self._lo
        self.geometry = ScanGeometry(
            angle_min_rad=spec.angle_min_rad,
            angle_max_rad=spec.angle_max_rad,
            angle_increment_rad=spec.angle_increment_rad,
            time_increment_s=0.0,
            scan_time_s=0.0,
            range_min_m=spec.range_min_m,
            range_max_m=spec.range_max_m,
            num_ranges=count,
        )

    @classmethod
    def from_robot(
        cls,
        robot: RobotModelSpec,
        scene: Scene,
        rng: np.random.Generator | None = None,
        *,
        spec: LidarSpec | None = None,
        obstacles: ObstacleSource | None = None,
    ) -> Lidar:
        """Return the robot's lidar in a scene, seeing `obstacles` too (`spec` overrides the robot's).

        Raises:
            ValueError: If the robot has no lidar and none is given.
        """
        spec = spec or robot.lidar
        if spec is None:
            msg = f"robot {robot.name!r} has no lidar (<sensor type='ray|gpu_ray|lidar|gpu_lidar'>)"
            raise ValueError(msg)
        return cls(spec, scene.ray_caster(robot.base_height_m + spec.mount.z_m), rng, obstacles=obstacles)

    def scan(self, x_m: float, y_m: float, yaw_rad: float) -> NDArray[np.float32]:
        """Return one scan's ranges (float32, as LaserScan carries them) for the base at (x, y, yaw).

        The pose is the robot base frame's on the floor plane, in the world frame.
        """
        spec = self.spec
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        ox = x_m + c * self._mx - s * self._my
        oy = y_m + s * self._mx + c * self._my
        heading = yaw_rad + self._myaw
        noise = None
        if self._noisy:
            assert self._rng is not None
            noise = self._rng.normal(spec.noise_mean_m, spec.noise_std_m, spec.count)
        if self._sweep > 0.0:
            first = heading + self._start
        else:  # mirrored: beam i points at heading - (start + i * step); cast in increasing order
            first = heading - self._start - self._ray_step * (spec.samples - 1)
        dynamic = self._obstacles.caster(self._caster.height_m) if self._obstacles is not None else None
        if spec.count == spec.samples and self._sweep > 0.0 and (dynamic is None or self._caster.native):
            return self._caster.cast_scan(
                (ox, oy),
                first,
                self._ray_step,
                spec.samples,
                range_min_m=spec.range_min_m,
                range_max_m=spec.range_max_m,
                noise_m=noise,
                also=None if dynamic is None else dynamic.shapes,
            )
        ranges = self._caster.cast_fan(
            (ox, oy), first, self._ray_step, spec.samples, spec.range_max_m, min_range_m=spec.range_min_m
        )
        if dynamic is not None:  # the nearer of the world and the obstacles, beam by beam
            np.minimum(
                ranges,
                dynamic.cast_fan(
                    (ox, oy), first, self._ray_step, spec.samples, spec.range_max_m, min_range_m=spec.range_min_m
                ),
                out=ranges,
            )
        if self._sweep < 0.0:
            ranges = ranges[::-1].copy()
        if spec.count != spec.samples:
            raw = np.minimum(ranges, spec.range_max_m)
            ranges = (1.0 - self._frac) * raw[self._lo] + self._frac * raw[self._hi]
        return mask_ranges(ranges, spec.range_min_m, spec.range_max_m, noise)
