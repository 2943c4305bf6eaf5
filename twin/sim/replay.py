"""The recorded commands of a replay mission: read from a bag, timed on its sim clock.

Sim time 0 of the replay is the bag's first pose on the pose topic (its header stamp). A command's
time is its header stamp when it has one (TwistStamped), else its record time mapped through the
bag's `/clock` (record time -> sim time, interpolated), else its record time. Commands recorded
before the first pose are not replayed: the first pose's velocity stands for them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag.typesys import message_type_name
from twin.core.errors import BagError
from twin.sim.scenario import InitialPose, ReplayMission, Scenario

__all__ = ["RecordedCommands", "check_bag", "first_pose", "load_commands", "start_moving", "with_replay_start"]

_log = logging.getLogger(__name__)

_POSE_TOPICS = ("/ground_truth/odom", "/odom")
# Types whose `pose` (or `pose.pose`) the replay reads its start pose from.
_POSE_TYPES = frozenset(
    {
        "nav_msgs/msg/Odometry",
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
    }
)
_TWIST_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


@dataclass(frozen=True, kw_only=True, slots=True)
class RecordedCommands:
    """Commands (v m/s, ω rad/s) from replay time `t_ns[i]` on, and where the bag's robot started."""

    t_ns: NDArray[np.int64]
    v_mps: NDArray[np.float64]
    w_radps: NDArray[np.float64]
    start_pose: tuple[float, float, float]
    start_velocity: tuple[float, float]  # (v m/s, ω rad/s) of the first pose, 0 if the topic carries none
    end_ns: int  # the bag's last pose, in replay time
    pose_topic: str
    time_source: str  # how command times were found: header stamps, /clock, or record times


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _pose_topic(spec: ReplayMission, topics: dict[str, str]) -> str:
    bag = spec.bag
    if spec.pose_topic is not None:
        if spec.pose_topic not in topics:
            msg = (
                f"{bag}: mission.pose_topic (twin replay --pose-topic) {spec.pose_topic!r} is not in the bag; it has "
                f"{', '.join(sorted(topics))}"
            )
            raise BagError(msg)
        kind = topics[spec.pose_topic]
        if message_type_name(kind) not in _POSE_TYPES:
            have = ", ".join(n for n, t in sorted(topics.items()) if message_type_name(t) in _POSE_TYPES) or "none"
            msg = (
                f"{bag}: mission.pose_topic (twin replay --pose-topic) {spec.pose_topic!r} is {kind}, which carries "
                "no pose; "
                f"give an Odometry or PoseStamped topic (the bag's: {have})"
            )
            raise BagError(msg)
        return spec.pose_topic
    for name in _POSE_TOPICS:
        if name in topics:
            return name
    msg = (
        f"{bag}: no {' or '.join(_POSE_TOPICS)} to start the replay from; set mission.pose_topic "
        "(twin replay --pose-topic) to its pose topic"
    )
    raise BagError(msg)


def _pose(msg: Any) -> tuple[float, float, float]:
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
    return (float(pose.position.x), float(pose.position.y), _yaw(pose.orientation))


def _first(spec: ReplayMission) -> tuple[str, int, tuple[float, float, float], tuple[float, float], int]:
    from twin.bag import open_bag, read_messages  # the bag readers load only for a replay

    info = open_bag(spec.bag)
    topics = {t.name: t.msgtype for t in info.topics}
    topic = _pose_topic(spec, topics)
    first: Any = None
    first_t = last_t = 0
    for m in read_messages(spec.bag, [topic]):
        if first is None:
            first, first_t = m.msg, _stamp_ns(m.msg) or m.t_ns
        last_t = _stamp_ns(m.msg) or m.t_ns
    if first is None:
        msg = f"{spec.bag}: {topic} has no messages to start the replay from; set mission.pose_topic (--pose-topic)"
        raise BagError(msg)
    twist = getattr(getattr(first, "twist", None), "twist", None)
    velocity = (float(twist.linear.x), float(twist.angular.z)) if twist is not None else (0.0, 0.0)
    return topic, first_t, _pose(first), velocity, last_t


def first_pose(spec: ReplayMission) -> tuple[float, float, float]:
    """The bag's first pose (x m, y m, yaw rad) on the mission's pose topic.

    Raises:
        BagError: If the bag is unreadable or has no such poses.
    """
    return _first(spec)[2]


def check_bag(spec: ReplayMission) -> dict[str, str]:
    """Check the bag has Twist commands on the mission's topic; return its topics and their types.

    Raises:
        BagError: If the bag is unreadable or lacks the command topic (or it is not a Twist).
    """
    from twin.bag import open_bag

    bag = spec.bag
    info = open_bag(bag)
    topics = {t.name: t.msgtype for t in info.topics}
    if spec.topic not in topics or info.topic(spec.topic).message_count == 0:
        have = ", ".join(n for n, t in sorted(topics.items()) if t in _TWIST_TYPES) or "no Twist topic"
        msg = (
            f"{bag}: no velocity commands on {spec.topic} to replay (Twist topics: {have}); "
            "record the robot's commands, or set mission.topic (twin replay --topic) to the topic carrying them"
        )
        raise BagError(msg)
    if topics[spec.topic] not in _TWIST_TYPES:
        msg = (
            f"{bag}: {spec.topic} is {topics[spec.topic]}, not a Twist; set mission.topic (twin replay --topic) "
            "to a Twist topic"
        )
        raise BagError(msg)
    return topics


def load_commands(spec: ReplayMission) -> RecordedCommands:
    """Read the mission's commands and start pose from its bag.

    Raises:
        BagError: If the bag is unreadable, lacks the command topic (or it is not a Twist), or
            has no poses to start from.
    """
    from twin.bag import read_messages

    bag: Path = spec.bag
    topics = check_bag(spec)
    pose_topic, t0_ns, pose, velocity, last_ns = _first(spec)
    clock_rec: list[int] = []
    clock_sim: list[int] = []
    if "/clock" in topics:
        for m in read_messages(bag, ["/clock"]):
            clock_rec.append(m.t_ns)
            clock_sim.append(int(m.msg.clock.sec) * 1_000_000_000 + int(m.msg.clock.nanosec))
    stamped = topics[spec.topic].endswith("Stamped")
    stamps: list[int] = []
    recorded: list[int] = []
    v: list[float] = []
    w: list[float] = []
    for m in read_messages(bag, [spec.topic]):
        twist = m.msg.twist if stamped else m.msg
        if stamped:
            stamps.append(_stamp_ns(m.msg))
        recorded.append(m.t_ns)
        v.append(float(twist.linear.x))
        w.append(float(twist.angular.z))
    # The commands' times on the poses' clock: their header stamps, else their record times mapped
    # through /clock, else their record times; the first of these that puts most commands within the
    # poses' span (a stamp of 0, or of the wall clock in a sim-time bag, does not).
    rec = np.asarray(recorded, dtype=np.int64)
    candidates: list[tuple[str, NDArray[np.int64]]] = []
    if stamped:
        candidates.append(("header stamps", np.asarray(stamps, dtype=np.int64)))
    if len(clock_rec) >= 2:
        mapped = np.interp(rec.astype(np.float64), np.asarray(clock_rec, np.float64), np.asarray(clock_sim, np.float64))
        candidates.append(("record times mapped through /clock", np.round(mapped).astype(np.int64)))
        candidates.append(("record times", rec))
    else:
        candidates.append(("record times (no /clock)", rec))
    margin = 1_000_000_000

    def within(times: NDArray[np.int64]) -> int:  # (a header stamp of 0 is one never set: never within)
        return int(np.count_nonzero((times >= t0_ns - margin) & (times <= last_ns + margin) & (times != 0)))

    source, t = next(((name, times) for name, times in candidates if 2 * within(times) >= len(times)), candidates[0])
    if within(t) == 0:
        source, t = max(candidates, key=lambda c: within(c[1]))
    if within(t) == 0:
        msg = (
            f"{bag}: no command on {spec.topic} falls within the poses on {pose_topic} "
            f"({_span(t0_ns, last_ns)}), by {' or '.join(name for name, _ in candidates)} "
            f"(the commands' {candidates[0][0]}: {_span(int(candidates[0][1].min()), int(candidates[0][1].max()))}): "
            "the bag's clocks disagree; record the commands and poses on one clock"
        )
        raise BagError(msg)
    if source != candidates[0][0]:
        first = candidates[0][1]
        _log.warning(
            "%s: the %s of %s are not on the clock of the poses on %s (%s against %s): replayed at their %s",
            bag,
            candidates[0][0],
            spec.topic,
            pose_topic,
            _span(int(first.min()), int(first.max())),
            _span(t0_ns, last_ns),
            source,
        )
    t = t - t0_ns
    # A command recorded before the bag's first pose reached no drive that published poses (Gazebo's
    # diff drive subscribes when it starts): the robot's state at the first pose already holds its effect.
    after = t >= 0
    if not after.all():
        _log.info(
            "%d command(s) on %s recorded before the first pose on %s are not replayed",
            int(np.count_nonzero(~after)),
            spec.topic,
            pose_topic,
        )
    return RecordedCommands(
        t_ns=t[after],
        v_mps=np.asarray(v, dtype=np.float64)[after],
        w_radps=np.asarray(w, dtype=np.float64)[after],
        start_pose=pose,
        start_velocity=velocity,
        end_ns=last_ns - t0_ns,
        pose_topic=pose_topic,
        time_source=source,
    )


def _span(first_ns: int, last_ns: int) -> str:
    """Two times of a bag, in seconds, for a message."""
    return f"{first_ns / 1e9:.3f} s to {last_ns / 1e9:.3f} s"


def start_moving(drive: object, v_mps: float, w_radps: float) -> bool:
    """Give `drive` the bag's first velocity if it can start moving (the kinematic drive can).

    Returns:
        Whether the velocity was applied; a drive that cannot starts at rest (logged).
    """
    if v_mps == 0.0 and w_radps == 0.0:
        return True
    setter = getattr(drive, "start_moving", None)
    if setter is None:
        _log.info(
            "the %s starts at rest; the bag's first velocity (%.4f m/s, %.4f rad/s) is not applied",
            type(drive).__name__,
            v_mps,
            w_radps,
        )
        return False
    setter(v_mps, w_radps)
    return True


def with_replay_start(scenario: Scenario) -> Scenario:
    """The scenario with `robot.initial_pose` at a replay mission's first recorded pose (else unchanged).

    Raises:
        BagError: If the bag is unreadable, has no commands on the mission's topic, or no poses.
    """
    mission = scenario.mission
    if not isinstance(mission, ReplayMission):
        return scenario
    check_bag(mission)
    if mission.initial_pose != "bag":
        return scenario
    x, y, yaw = first_pose(mission)
    pose = InitialPose(x_m=x, y_m=y, yaw_rad=yaw)
    return dataclasses.replace(scenario, robot=dataclasses.replace(scenario.robot, initial_pose=pose))
