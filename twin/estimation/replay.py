"""Offline replay: run the odometry EKF over recorded wheel joint states and gyro, and compare it with a reference.

Everything here is pure: arrays in, arrays out. `collect_inputs` turns decoded messages (any objects with
the ROS field names, such as rosbags' dataclasses) into arrays; `replay` runs the filter; `compare`
measures it against a reference trajectory (a bag's own `/odom`). Bag I/O lives in the CLI.

Joint-state velocity units: Gazebo publishes wheel speeds in rad/s, the real TurtleBot3 the wheel's
rim speed in m/s (TB3_FACTS.md §3.2). `infer_velocity_units` tells them apart by comparing the
velocities with the joint positions' rate of change. The filter uses the positions whenever a bag has
them (the unit then does not matter) and the velocities only when it does not.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import EstimationError
from twin.estimation.config import EstimationSection
from twin.estimation.ekf import OdometryEstimate, OdometryFilter

__all__ = [
    "Comparison",
    "PoseSeries",
    "ReplayInputs",
    "ReplayResult",
    "UnitsDecision",
    "collect_inputs",
    "compare",
    "infer_velocity_units",
    "replay",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
VelocityUnits = Literal["rad/s", "m/s"]

# Velocity/position-rate ratios within this factor of 1 (rad/s) or of the wheel radius (m/s) decide the unit.
_UNIT_TOLERANCE = 1.2
# Wheels must turn at least this fast (rad/s) for a sample to count in the unit check.
_MOVING_RADPS = 0.5


@dataclass(frozen=True, kw_only=True, slots=True)
class PoseSeries:
    """A planar trajectory: time, position and heading."""

    t_ns: IntArray
    x_m: FloatArray
    y_m: FloatArray
    yaw_rad: FloatArray


@dataclass(frozen=True, kw_only=True, slots=True)
class ReplayInputs:
    """What a replay needs from a recording, time-ordered by measurement time.

    Joint positions or velocities may be absent (None) when the recording has none.
    """

    joint_t_ns: IntArray
    position_left_rad: FloatArray | None
    position_right_rad: FloatArray | None
    velocity_left: FloatArray | None
    velocity_right: FloatArray | None
    gyro_t_ns: IntArray
    gyro_z_radps: FloatArray
    reference: PoseSeries | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class UnitsDecision:
    """Which unit the joint velocities are taken to be in, and why."""

    units: VelocityUnits
    how: Literal["given", "inferred", "assumed"]
    ratio: float | None  # median of velocity / position rate over moving samples

    def describe(self, wheel_radius_m: float) -> str:
        """One line for the user."""
        if self.how == "given":
            return f"{self.units} (given)"
        if self.how == "inferred":
            return f"{self.units} (inferred: velocity / position rate = {self.ratio:.4f}; r = {wheel_radius_m:g} m)"
        why = "no joint positions to compare with" if self.ratio is None else f"ratio {self.ratio:.4g} fits neither"
        return f"{self.units} (assumed: {why})"


@dataclass(frozen=True, kw_only=True, slots=True)
class ReplayResult:
    """The fused odometry at every joint-state time, and how it was obtained.

    Covariances are (N, 36): row-major 6x6 in ROS order (x, y, z, rot X, rot Y, rot Z).
    """

    t_ns: IntArray
    x_m: FloatArray
    y_m: FloatArray
    yaw_rad: FloatArray
    v_mps: FloatArray
    yaw_rate_radps: FloatArray
    gyro_bias_radps: FloatArray
    pose_covariance: FloatArray
    twist_covariance: FloatArray
    wheel_source: Literal["positions", "velocities"]
    gyro_samples: int
    slip_detections: int


@dataclass(frozen=True, kw_only=True, slots=True)
class Comparison:
    """Errors of a fused trajectory against a reference, over the time both cover."""

    samples: int
    duration_s: float
    distance_m: float
    position_error_mean_m: float
    position_error_rms_m: float
    position_error_max_m: float
    position_error_final_m: float
    yaw_error_mean_rad: float  # mean of the absolute error
    yaw_error_rms_rad: float
    yaw_error_max_rad: float
    yaw_error_final_rad: float
    position_error_m: FloatArray  # per compared sample
    yaw_error_rad: FloatArray  # signed, wrapped
    reference_x_m: FloatArray
    reference_y_m: FloatArray
    reference_yaw_rad: FloatArray
    compared: NDArray[np.bool_]  # which result samples fall inside the reference's time span

    @property
    def final_error_percent_of_distance(self) -> float:
        """Final position error as a percentage of the reference's path length (nan if it did not move)."""
        return 100.0 * self.position_error_final_m / self.distance_m if self.distance_m > 0.0 else math.nan


def _stamp_ns(msg: Any, fallback_ns: int) -> int:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return fallback_ns
    t_ns = int(stamp.sec) * 1_000_000_000 + int(getattr(stamp, "nanosec", getattr(stamp, "nsec", 0)))
    return t_ns if t_ns > 0 else fallback_ns


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def collect_inputs(
    messages: Iterable[tuple[str, str, int, Any]],
    *,
    imu_topic: str = "/imu",
    joint_topic: str = "/joint_states",
    reference_topic: str | None = "/odom",
    left_joint: str = "wheel_left_joint",
    right_joint: str = "wheel_right_joint",
) -> ReplayInputs:
    """Gather the gyro, the two wheels' joint states and the reference poses from decoded messages.

    Times are the messages' header stamps (the measurement times), or the bag time when a stamp is zero.
    Messages are sorted by that time; repeated stamps keep the first message.

    Args:
        messages: `(topic, msgtype, bag_t_ns, msg)` tuples; other topics are ignored.
        imu_topic: `sensor_msgs/Imu` topic; `angular_velocity.z` is the yaw rate (a level IMU).
        joint_topic: `sensor_msgs/JointState` topic.
        reference_topic: `nav_msgs/Odometry` topic to compare with, or None.
        left_joint: Name of the left wheel's joint.
        right_joint: Name of the right wheel's joint.

    Raises:
        EstimationError: If the joint states never name both wheels.
    """
    gyro: list[tuple[int, float]] = []
    joints: list[tuple[int, float, float, float, float]] = []
    reference: list[tuple[int, float, float, float]] = []
    names_seen: set[str] = set()
    nan = math.nan
    for topic, _, bag_t_ns, msg in messages:
        if topic == imu_topic:
            gyro.append((_stamp_ns(msg, bag_t_ns), float(msg.angular_velocity.z)))
        elif topic == joint_topic:
            names = list(msg.name)
            names_seen.update(names)
            if left_joint not in names or right_joint not in names:
                continue
            il, ir = names.index(left_joint), names.index(right_joint)
            pos, vel = msg.position, msg.velocity
            has_pos = len(pos) == len(names)
            has_vel = len(vel) == len(names)
            joints.append(
                (
                    _stamp_ns(msg, bag_t_ns),
                    float(pos[il]) if has_pos else nan,
                    float(pos[ir]) if has_pos else nan,
                    float(vel[il]) if has_vel else nan,
                    float(vel[ir]) if has_vel else nan,
                )
            )
        elif reference_topic is not None and topic == reference_topic:
            pose = msg.pose.pose
            reference.append(
                (_stamp_ns(msg, bag_t_ns), float(pose.position.x), float(pose.position.y), _yaw(pose.orientation))
            )
    if not joints and names_seen:
        msg_text = (
            f"{joint_topic} names joints {', '.join(sorted(names_seen))}, not both {left_joint} and {right_joint}; "
            "pass the wheel joint names with --left-joint NAME --right-joint NAME"
        )
        raise EstimationError(msg_text)
    jt, j = _sorted_unique(joints, 4)
    gt, g = _sorted_unique(gyro, 1)
    rt, r = _sorted_unique(reference, 3)
    pos_ok = bool(len(j)) and bool(np.isfinite(j[:, 0:2]).all())
    vel_ok = bool(len(j)) and bool(np.isfinite(j[:, 2:4]).all())
    return ReplayInputs(
        joint_t_ns=jt,
        position_left_rad=j[:, 0].copy() if pos_ok else None,
        position_right_rad=j[:, 1].copy() if pos_ok else None,
        velocity_left=j[:, 2].copy() if vel_ok else None,
        velocity_right=j[:, 3].copy() if vel_ok else None,
        gyro_t_ns=gt,
        gyro_z_radps=g[:, 0].copy(),
        reference=PoseSeries(t_ns=rt, x_m=r[:, 0].copy(), y_m=r[:, 1].copy(), yaw_rad=r[:, 2].copy())
        if len(r)
        else None,
    )


def _sorted_unique(rows: list[Any], width: int) -> tuple[IntArray, FloatArray]:
    """Times and values of rows `(t_ns, v1, ..., v_width)`, sorted by time, repeated times dropped."""
    rows = sorted(rows, key=lambda row: row[0])
    unique = [row for k, row in enumerate(rows) if k == 0 or row[0] != rows[k - 1][0]]
    t_ns = np.array([row[0] for row in unique], dtype=np.int64)
    values = np.array([row[1:] for row in unique], dtype=float).reshape(len(unique), width)
    return t_ns, values


def infer_velocity_units(inputs: ReplayInputs, wheel_radius_m: float) -> UnitsDecision:
    """Decide whether the joint velocities are rad/s or rim m/s by comparing them with the position rate.

    Returns an `assumed` rad/s decision when there are no positions, no velocities, no motion, or the
    ratio fits neither unit.
    """
    pl, pr, vl, vr = inputs.position_left_rad, inputs.position_right_rad, inputs.velocity_left, inputs.velocity_right
    if pl is None or pr is None or vl is None or vr is None or len(inputs.joint_t_ns) < 2:
        return UnitsDecision(units="rad/s", how="assumed", ratio=None)
    dt = np.diff(inputs.joint_t_ns).astype(float) * 1e-9
    rate = np.concatenate((np.diff(pl) / dt, np.diff(pr) / dt))
    # Velocities at both ends of each interval, averaged: the best match to the interval's mean rate.
    vel = np.concatenate((0.5 * (vl[1:] + vl[:-1]), 0.5 * (vr[1:] + vr[:-1])))
    moving = np.abs(rate) > _MOVING_RADPS
    if moving.sum() < 3:
        return UnitsDecision(units="rad/s", how="assumed", ratio=None)
    ratio = float(np.median(vel[moving] / rate[moving]))
    if 1.0 / _UNIT_TOLERANCE < ratio < _UNIT_TOLERANCE:
        return UnitsDecision(units="rad/s", how="inferred", ratio=ratio)
    if wheel_radius_m / _UNIT_TOLERANCE < ratio < wheel_radius_m * _UNIT_TOLERANCE:
        return UnitsDecision(units="m/s", how="inferred", ratio=ratio)
    return UnitsDecision(units="rad/s", how="assumed", ratio=ratio)


def _initial_pose(reference: PoseSeries | None, t_ns: int) -> tuple[float, float, float]:
    if reference is None or not len(reference.t_ns):
        return (0.0, 0.0, 0.0)
    i = int(np.clip(np.searchsorted(reference.t_ns, t_ns), 0, len(reference.t_ns) - 1))
    if i > 0 and abs(int(reference.t_ns[i - 1]) - t_ns) < abs(int(reference.t_ns[i]) - t_ns):
        i -= 1
    return (float(reference.x_m[i]), float(reference.y_m[i]), float(reference.yaw_rad[i]))


def replay(
    inputs: ReplayInputs,
    config: EstimationSection,
    *,
    wheel_radius_m: float,
    wheel_separation_m: float,
    velocity_units: VelocityUnits = "rad/s",
    wheel_source: Literal["auto", "positions", "velocities"] = "auto",
    start_at_reference: bool = True,
) -> ReplayResult:
    """Run the odometry filter over a recording, one step per joint state.

    Gyro samples are fed in time order before the joint state that follows them.

    Args:
        inputs: The recording's arrays.
        config: The filter's noise settings.
        wheel_radius_m: Wheel radius.
        wheel_separation_m: Distance between the wheels.
        velocity_units: Unit of the joint velocities (used only when the filter runs on them).
        wheel_source: `positions`, `velocities`, or `auto` (positions when present).
        start_at_reference: Start at the reference's pose at the first joint state (so the result
            overlays it); otherwise at the origin of a fresh `odom` frame.

    Raises:
        EstimationError: If there are fewer than two joint states, or the chosen source is missing.
    """
    n = len(inputs.joint_t_ns)
    if n < 2:
        msg = f"need at least 2 joint states with both wheels to replay, got {n}"
        raise EstimationError(msg)
    has_positions = inputs.position_left_rad is not None and inputs.position_right_rad is not None
    has_velocities = inputs.velocity_left is not None and inputs.velocity_right is not None
    auto: Literal["positions", "velocities"] = "positions" if has_positions else "velocities"
    source = auto if wheel_source == "auto" else wheel_source
    if (source == "positions" and not has_positions) or (source == "velocities" and not has_velocities):
        msg = f"the joint states carry no wheel {source}; use the other wheel source"
        raise EstimationError(msg)
    t0 = int(inputs.joint_t_ns[0])
    initial = _initial_pose(inputs.reference, t0) if start_at_reference else (0.0, 0.0, 0.0)
    odom = OdometryFilter(
        config, wheel_radius_m=wheel_radius_m, wheel_separation_m=wheel_separation_m, initial_pose=initial
    )
    step: Callable[[int, float, float], OdometryEstimate]
    if source == "positions":
        assert inputs.position_left_rad is not None and inputs.position_right_rad is not None
        a, b = inputs.position_left_rad.tolist(), inputs.position_right_rad.tolist()
        step = odom.add_wheel_positions
    else:
        assert inputs.velocity_left is not None and inputs.velocity_right is not None
        scale = 1.0 / wheel_radius_m if velocity_units == "m/s" else 1.0
        # The filter wants each interval's mean speed: average the speeds at its two ends.
        vl, vr = inputs.velocity_left * scale, inputs.velocity_right * scale
        a = np.concatenate(([vl[0]], 0.5 * (vl[1:] + vl[:-1]))).tolist()
        b = np.concatenate(([vr[0]], 0.5 * (vr[1:] + vr[:-1]))).tolist()
        step = odom.add_wheel_speeds
    gyro_t, gyro_z = inputs.gyro_t_ns.tolist(), inputs.gyro_z_radps.tolist()
    rows: list[tuple[float, ...]] = []
    pose_cov = np.empty((n, 36))
    twist_cov = np.empty((n, 36))
    g, used = 0, 0
    for i, t_ns in enumerate(inputs.joint_t_ns.tolist()):
        while g < len(gyro_t) and gyro_t[g] <= t_ns:
            odom.add_gyro(gyro_t[g], gyro_z[g])
            g += 1
            used += 1
        est = step(t_ns, a[i], b[i])
        rows.append((est.x_m, est.y_m, est.yaw_rad, est.v_mps, est.yaw_rate_radps, est.gyro_bias_radps))
        pose_cov[i] = est.pose_covariance
        twist_cov[i] = est.twist_covariance
    out = np.array(rows)
    return ReplayResult(
        t_ns=inputs.joint_t_ns.copy(),
        x_m=out[:, 0],
        y_m=out[:, 1],
        yaw_rad=out[:, 2],
        v_mps=out[:, 3],
        yaw_rate_radps=out[:, 4],
        gyro_bias_radps=out[:, 5],
        pose_covariance=pose_cov,
        twist_covariance=twist_cov,
        wheel_source=source,
        gyro_samples=used,
        slip_detections=odom.slip_detections,
    )


def compare(result: ReplayResult, reference: PoseSeries) -> Comparison:
    """Measure the fused trajectory against a reference, interpolated to the result's times.

    Only result samples inside the reference's time span count; the reference's yaw is unwrapped before
    interpolation.

    Raises:
        EstimationError: If the two do not overlap in time.
    """
    rt = reference.t_ns.astype(float)
    t = result.t_ns.astype(float)
    inside = (t >= rt[0]) & (t <= rt[-1])
    if inside.sum() < 1 or len(rt) < 2:
        msg = "the reference trajectory does not overlap the replay in time"
        raise EstimationError(msg)
    ref_x = np.interp(t, rt, reference.x_m)
    ref_y = np.interp(t, rt, reference.y_m)
    ref_yaw = np.interp(t, rt, np.unwrap(reference.yaw_rad))
    ref_yaw = (ref_yaw + math.pi) % (2.0 * math.pi) - math.pi
    pos_err = np.hypot(result.x_m - ref_x, result.y_m - ref_y)
    yaw_err = (result.yaw_rad - ref_yaw + math.pi) % (2.0 * math.pi) - math.pi
    pe, ye = pos_err[inside], yaw_err[inside]
    first, last = t[inside][0], t[inside][-1]
    # The reference's path between the first and the last compared time, its ends interpolated.
    path_t = np.concatenate(([first], rt[(rt > first) & (rt < last)], [last]))
    path_x, path_y = np.interp(path_t, rt, reference.x_m), np.interp(path_t, rt, reference.y_m)
    distance = float(np.sum(np.hypot(np.diff(path_x), np.diff(path_y))))
    return Comparison(
        samples=int(inside.sum()),
        duration_s=float(last - first) * 1e-9,
        distance_m=distance,
        position_error_mean_m=float(pe.mean()),
        position_error_rms_m=float(np.sqrt(np.mean(pe * pe))),
        position_error_max_m=float(pe.max()),
        position_error_final_m=float(pe[-1]),
        yaw_error_mean_rad=float(np.abs(ye).mean()),
        yaw_error_rms_rad=float(np.sqrt(np.mean(ye * ye))),
        yaw_error_max_rad=float(np.abs(ye).max()),
        yaw_error_final_rad=float(ye[-1]),
        position_error_m=pos_err,
        yaw_error_rad=yaw_err,
        reference_x_m=ref_x,
        reference_y_m=ref_y,
        reference_yaw_rad=ref_yaw,
        compared=inside,
    )
