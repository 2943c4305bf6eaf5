"""Ground-truth differential-drive trajectories for tests and benchmarks (pure numpy, no physics engine).

`generate_trajectory` turns a list of timed velocity commands (straights, arcs, spins) into what a
TurtleBot3 does with them at a fixed physics rate: each wheel's rim speed follows its setpoint under an
acceleration limit (as `gazebo_ros_diff_drive`'s `max_wheel_acceleration` does), the wheel angles are
the integral of the wheel speeds, and the chassis moves with the wheels' ground speeds, which are the
rim speeds reduced by any wheel slip. With slip, the encoders (wheel angles) say the robot went further
than it did. Every array is sampled at the physics rate, including t = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.clock import period_ns
from twin.robot.disturbances import WheelSlip

__all__ = ["DriveSegment", "Trajectory", "default_test_drive", "generate_trajectory"]

FloatArray = NDArray[np.float64]


class DriveSegment(NamedTuple):
    """Hold one velocity command (a straight, an arc, a spin or a stop) for a duration."""

    duration_s: float
    linear_mps: float = 0.0
    angular_radps: float = 0.0


@dataclass(frozen=True, kw_only=True, slots=True)
class Trajectory:
    """Ground truth at the physics rate; index i is time `t_ns[i]`.

    Accelerations are those of the chassis origin (`base_footprint`) in chassis axes; the lateral one is
    the centripetal `v * yaw_rate`.
    """

    t_ns: NDArray[np.int64]
    x_m: FloatArray
    y_m: FloatArray
    yaw_rad: FloatArray
    v_mps: FloatArray
    yaw_rate_radps: FloatArray
    accel_x_mps2: FloatArray
    accel_y_mps2: FloatArray
    yaw_accel_radps2: FloatArray
    wheel_left_rad: FloatArray
    wheel_right_rad: FloatArray
    wheel_left_radps: FloatArray
    wheel_right_radps: FloatArray
    step_ns: int

    @property
    def duration_s(self) -> float:
        """Length of the trajectory in seconds."""
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9

    @property
    def distance_m(self) -> float:
        """Path length travelled by the chassis origin."""
        return float(np.sum(np.hypot(np.diff(self.x_m), np.diff(self.y_m))))

    def indices_at_rate(self, rate_hz: float) -> NDArray[np.intp]:
        """Return the sample indices where a publisher at `rate_hz` fires.

        That is the first physics step at or after each multiple of its integer period, as a fixed-step
        scheduler fires it.
        """
        period = period_ns(rate_hz)
        last = int(self.t_ns[-1] - self.t_ns[0])
        due = np.arange(0, last + 1, period, dtype=np.int64)
        return np.unique(-(-due // self.step_ns)).astype(np.intp)


def default_test_drive() -> tuple[DriveSegment, ...]:
    """Return a 120 s TurtleBot3 Waffle drive: straights, arcs both ways, spins both ways and stops."""
    return (
        DriveSegment(15.0, 0.20, 0.0),
        DriveSegment(1.6, 0.0, 1.0),
        DriveSegment(10.0, 0.15, 0.3),
        DriveSegment(2.0),
        DriveSegment(12.0, 0.22, 0.0),
        DriveSegment(2.1, 0.0, -1.5),
        DriveSegment(8.0, 0.20, -0.4),
        DriveSegment(10.0, 0.10, 0.0),
        DriveSegment(4.0, 0.0, 0.8),
        DriveSegment(15.0, 0.18, 0.25),
        DriveSegment(15.0, 0.20, 0.0),
        DriveSegment(3.0),
        DriveSegment(10.0, 0.12, -0.5),
        DriveSegment(12.3, 0.20, 0.0),
    )


def _rate_limited(setpoints: FloatArray, counts: NDArray[np.intp], max_step: float) -> FloatArray:
    """Return speeds at every sample: each segment ramps from the previous speed to its setpoint."""
    out = np.empty(int(counts.sum()) + 1)
    out[0] = 0.0
    start, speed = 0, 0.0
    for target, n in zip(setpoints, counts, strict=True):
        k = np.arange(1, n + 1)
        gap = speed - target
        out[start + 1 : start + n + 1] = target + math.copysign(1.0, gap) * np.maximum(abs(gap) - max_step * k, 0.0)
        start += n
        speed = float(out[start])
    return out


def generate_trajectory(
    segments: tuple[DriveSegment, ...],
    *,
    wheel_radius_m: float = 0.033,
    wheel_separation_m: float = 0.287,
    physics_rate_hz: float = 1000.0,
    max_wheel_accel_mps2: float = 1.0,
    slip: WheelSlip | None = None,
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Trajectory:
    """Drive a differential-drive robot through timed velocity commands.

    Args:
        segments: Commands, held one after another from t = 0 (robot at rest).
        wheel_radius_m: Wheel radius.
        wheel_separation_m: Distance between the wheels' contact points.
        physics_rate_hz: Sample rate of the result.
        max_wheel_accel_mps2: Rim acceleration limit per wheel.
        slip: Wheel slip (none by default).
        initial_pose: Start (x_m, y_m, yaw_rad) in the world.

    Raises:
        ValueError: If a segment has a negative duration or the geometry is not positive.
    """
    if wheel_radius_m <= 0.0 or wheel_separation_m <= 0.0:
        msg = f"wheel radius and separation must be positive, got {wheel_radius_m} and {wheel_separation_m}"
        raise ValueError(msg)
    if any(s.duration_s < 0.0 for s in segments):
        msg = "segment durations must be zero or positive"
        raise ValueError(msg)
    step_ns = period_ns(physics_rate_hz)
    dt = step_ns * 1e-9
    counts = np.array([round(s.duration_s / dt) for s in segments], dtype=np.intp)
    half = 0.5 * wheel_separation_m
    rim_left = _rate_limited(
        np.array([s.linear_mps - s.angular_radps * half for s in segments]), counts, max_wheel_accel_mps2 * dt
    )
    rim_right = _rate_limited(
        np.array([s.linear_mps + s.angular_radps * half for s in segments]), counts, max_wheel_accel_mps2 * dt
    )
    n = len(rim_left)
    t_ns = np.arange(n, dtype=np.int64) * step_ns
    wl = rim_left / wheel_radius_m
    wr = rim_right / wheel_radius_m
    angle_left = _integral(wl, dt)
    angle_right = _integral(wr, dt)

    slip = slip or WheelSlip()
    x0, y0, yaw0 = initial_pose
    if slip.is_uniform:
        ground_left = rim_left * (1.0 - slip.left_fraction)
        ground_right = rim_right * (1.0 - slip.right_fraction)
        v = 0.5 * (ground_left + ground_right)
        w = (ground_right - ground_left) / wheel_separation_m
        yaw = yaw0 + _integral(w, dt)
        mid = 0.5 * (yaw[1:] + yaw[:-1])
        ds = 0.5 * (v[1:] + v[:-1]) * dt
        x = x0 + np.concatenate(([0.0], np.cumsum(ds * np.cos(mid))))
        y = y0 + np.concatenate(([0.0], np.cumsum(ds * np.sin(mid))))
    else:
        x, y, yaw, v, w = _integrate_with_regions(
            rim_left, rim_right=rim_right, slip=slip, separation=wheel_separation_m, dt=dt, initial_pose=initial_pose
        )

    accel_x = np.append(np.diff(v) / dt, 0.0)
    yaw_accel = np.append(np.diff(w) / dt, 0.0)
    return Trajectory(
        t_ns=t_ns,
        x_m=x,
        y_m=y,
        yaw_rad=yaw,
        v_mps=v,
        yaw_rate_radps=w,
        accel_x_mps2=accel_x,
        accel_y_mps2=v * w,
        yaw_accel_radps2=yaw_accel,
        wheel_left_rad=angle_left,
        wheel_right_rad=angle_right,
        wheel_left_radps=wl,
        wheel_right_radps=wr,
        step_ns=step_ns,
    )


def _integral(rate: FloatArray, dt: float) -> FloatArray:
    """Running integral of a sampled rate by the trapezoid rule (exact for piecewise-linear rates), from 0."""
    return np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)))


def _integrate_with_regions(
    rim_left: FloatArray,
    *,
    rim_right: FloatArray,
    slip: WheelSlip,
    separation: float,
    dt: float,
    initial_pose: tuple[float, float, float],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Integrate step by step: the slip at each step depends on where the robot is."""
    n = len(rim_left)
    x, y, yaw = np.empty(n), np.empty(n), np.empty(n)
    v, w = np.empty(n), np.empty(n)
    px, py, pyaw = initial_pose
    sl, sr = slip.fractions_at(px, py)
    pv = 0.5 * (rim_left[0] * (1 - sl) + rim_right[0] * (1 - sr))
    pw = (rim_right[0] * (1 - sr) - rim_left[0] * (1 - sl)) / separation
    left, right = rim_left.tolist(), rim_right.tolist()
    for i in range(n):
        if i:
            sl, sr = slip.fractions_at(px, py)
            gl, gr = left[i] * (1 - sl), right[i] * (1 - sr)
            nv, nw = 0.5 * (gl + gr), (gr - gl) / separation
            nyaw = pyaw + 0.5 * (pw + nw) * dt
            mid = 0.5 * (pyaw + nyaw)
            ds = 0.5 * (pv + nv) * dt
            px += ds * math.cos(mid)
            py += ds * math.sin(mid)
            pyaw, pv, pw = nyaw, nv, nw
        x[i], y[i], yaw[i], v[i], w[i] = px, py, pyaw, pv, pw
    return x, y, yaw, v, w
