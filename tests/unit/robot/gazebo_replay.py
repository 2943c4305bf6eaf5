"""A self-contained replay of a Gazebo bag's /cmd_vel into a drivetrain, compared with the bag's /odom.

Gazebo's diff drive publishes /odom from the world pose (its default odometry source), so /odom is
the robot's true path in the simulator. The commands are applied at their receive times, the drive
stepped at 1 ms from the first /odom sample's pose, and the drive's pose compared with /odom at
the sample nearest a time and at the last sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from twin.robot.drivetrain import Drivetrain

FIXTURES = Path("/work/shared/fixtures")
WAFFLE_BAG = FIXTURES / "bags" / "tb3_waffle_gazebo_humble"
STEP_NS = 1_000_000


@dataclass(frozen=True, kw_only=True, slots=True)
class GazeboRun:
    """What the replay needs from a bag: commands and the true path, times from the bag's start, s."""

    cmd_vel: tuple[tuple[float, float, float], ...]  # (t_s, linear_mps, angular_radps)
    odom: tuple[tuple[float, float, float, float], ...]  # (t_s, x_m, y_m, yaw_rad)


def read_gazebo_run(bag: Path) -> GazeboRun:
    """Read /cmd_vel and /odom of a ROS 2 bag."""
    cmds: list[tuple[float, float, float]] = []
    odom: list[tuple[float, float, float, float]] = []
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        t0 = reader.start_time
        wanted = [c for c in reader.connections if c.topic in ("/cmd_vel", "/odom")]
        for conn, t_ns, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, conn.msgtype)
            t_s = (t_ns - t0) * 1e-9
            if conn.topic == "/cmd_vel":
                cmds.append((t_s, float(msg.linear.x), float(msg.angular.z)))
            else:
                p, q = msg.pose.pose.position, msg.pose.pose.orientation
                yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                odom.append((t_s, float(p.x), float(p.y), yaw))
    return GazeboRun(cmd_vel=tuple(cmds), odom=tuple(odom))


@dataclass(frozen=True, kw_only=True, slots=True)
class ReplayError:
    """Position and yaw error of the drive against /odom at one time."""

    t_s: float
    position_m: float
    yaw_deg: float


def replay(run: GazeboRun, drive: Drivetrain, at_s: tuple[float, ...]) -> list[ReplayError]:
    """Feed `run`'s commands into `drive` (started at the first /odom pose) and compare at the /odom
    samples nearest each time in `at_s` (math.inf: the last sample)."""
    t0 = run.odom[0][0]
    times = [o[0] for o in run.odom]
    checks = sorted(
        {min(range(len(times)), key=lambda k: abs(times[k] - t)) if math.isfinite(t) else len(times) - 1 for t in at_s}
    )
    events: list[tuple[float, int, float, float]] = [(c[0], 1, c[1], c[2]) for c in run.cmd_vel if c[0] >= t0]
    events += [(run.odom[k][0], 0, 0.0, 0.0) for k in checks]
    events.sort()
    k_now = 0
    errors: list[ReplayError] = []
    check_iter = iter(checks)
    for t_s, kind, v, w in events:
        k_target = round((t_s - t0) * 1e9 / STEP_NS)
        if k_target > k_now:
            drive.advance(k_target - k_now)
            k_now = k_target
        if kind == 1:
            drive.set_cmd_vel(v, w)
            continue
        k = next(check_iter)
        _, x, y, yaw = run.odom[k]
        s = drive.chassis_state()
        dyaw = math.remainder(s.yaw_rad - yaw, math.tau)
        errors.append(
            ReplayError(t_s=t_s, position_m=math.hypot(s.x_m - x, s.y_m - y), yaw_deg=math.degrees(abs(dyaw)))
        )
    return errors
