"""One streaming pass over a bag, keeping only what analysis needs: series of a few numbers per message.

Poses, commands and scan minima are kept as compact arrays (a few doubles per message, the
messages themselves are dropped); topic health is accumulated as running sums; scan endpoints
go into a fixed-resolution occupancy count bounded by the area seen. Rare, structured topics
(the behaviour-tree log, plans, goals, contacts, the map, the robot description) are decoded
in a second pass over those topics alone.
"""

from __future__ import annotations

import logging
import math
import os
from array import array
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.analysis import _cdr
from twin.bag import BagInfo, open_bag, read_messages
from twin.core.errors import BagError

__all__ = [
    "CMD_TOPIC",
    "POSE_TOPICS",
    "BagData",
    "ContactEvent",
    "PoseTrack",
    "TopicHealth",
    "best_pose",
    "collect",
    "scan_points",
]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

#: Pose sources in order of trust: the simulator's truth, the localization, the odometry.
POSE_TOPICS: tuple[str, ...] = ("/ground_truth/odom", "/amcl_pose", "/odom")
CMD_TOPIC = "/cmd_vel"
SCAN_TOPIC = "/scan"
_DECODED_TOPICS = ("/behavior_tree_log", "/plan", "/goal_pose", "/contacts", "/map", "/robot_description")

#: Rates a TurtleBot3 system publishes at (the twin's and Gazebo's TB3 defaults), Hz.
EXPECTED_RATE_HZ: dict[str, float] = {
    "/imu": 200.0,
    "/odom": 30.0,
    "/joint_states": 30.0,
    "/ground_truth/odom": 30.0,
    "/scan": 5.0,
}

_SCAN_CELL_M = 0.05
_SCAN_BEAM_STRIDE = 4
_PLAN_POINTS = 200
_WARMUP = 50


class PoseTrack:
    """A pose topic as arrays: record time, header stamp, x, y, yaw, v and ω (nan where not carried)."""

    def __init__(self, topic: str, msgtype: str) -> None:
        self.topic = topic
        self.msgtype = msgtype
        self._t = array("q")
        self._stamp = array("q")
        self._vals = array("d")

    def add(self, t_ns: int, sample: _cdr.PoseSample) -> None:
        """Append one pose read at record time `t_ns`."""
        stamp, x, y, yaw, v, w = sample
        self._t.append(t_ns)
        self._stamp.append(stamp if stamp > 0 else t_ns)
        self._vals.extend((x, y, yaw, v, w))

    def __len__(self) -> int:
        return len(self._t)

    @property
    def t_ns(self) -> NDArray[np.int64]:
        """Record times, ns."""
        return np.frombuffer(self._t, dtype=np.int64) if self._t else np.zeros(0, np.int64)

    @property
    def stamp_ns(self) -> NDArray[np.int64]:
        """Header stamps, ns (the record time where the header carries none)."""
        return np.frombuffer(self._stamp, dtype=np.int64) if self._stamp else np.zeros(0, np.int64)

    @property
    def values(self) -> F64:
        """Shape (N, 5): x m, y m, yaw rad, v m/s, ω rad/s."""
        return np.frombuffer(self._vals, dtype=np.float64).reshape(-1, 5) if self._vals else np.zeros((0, 5))


@dataclass(kw_only=True, slots=True)
class TopicHealth:
    """Running statistics of one topic's message times."""

    topic: str
    msgtype: str
    decodable: bool
    expected_rate_hz: float | None
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    sum_dt: float = 0.0
    sum_dt2: float = 0.0
    max_gap_s: float = 0.0
    gaps: int = 0
    non_monotonic: int = 0
    skew_count: int = 0
    skew_min_s: float = math.inf
    skew_max_s: float = -math.inf
    skew_sum_s: float = 0.0
    _period_s: float | None = None
    _warmup: list[float] = field(default_factory=list)
    _last_stamp: int | None = None

    def add(self, t_ns: int, stamp_ns: int | None) -> None:
        """Count one message recorded at `t_ns` carrying header stamp `stamp_ns` (None: no stamp)."""
        if self.count:
            dt = (t_ns - self.last_ns) * 1e-9
            self.sum_dt += dt
            self.sum_dt2 += dt * dt
            self.max_gap_s = max(self.max_gap_s, dt)
            if self._period_s is None:
                self._warmup.append(dt)
                if len(self._warmup) >= _WARMUP:
                    self._settle()
            elif dt > 3.0 * self._period_s:
                self.gaps += 1
        else:
            self.first_ns = t_ns
        self.count += 1
        self.last_ns = t_ns
        if stamp_ns is not None and stamp_ns > 0:
            if self._last_stamp is not None and stamp_ns < self._last_stamp:
                self.non_monotonic += 1
            self._last_stamp = stamp_ns
            skew = (t_ns - stamp_ns) * 1e-9
            self.skew_count += 1
            self.skew_sum_s += skew
            self.skew_min_s = min(self.skew_min_s, skew)
            self.skew_max_s = max(self.skew_max_s, skew)

    def _settle(self) -> None:
        if self.expected_rate_hz:
            self._period_s = 1.0 / self.expected_rate_hz
        else:
            self._period_s = float(np.median(self._warmup)) if self._warmup else None
        if self._period_s is not None and self._period_s > 0.0:
            self.gaps += sum(1 for dt in self._warmup if dt > 3.0 * self._period_s)
        else:
            self._period_s = math.inf  # all at one time: no period to measure gaps against
        self._warmup = []

    def finish(self) -> None:
        """Count the gaps of a topic too short to leave its warm-up."""
        if self._period_s is None and self._warmup:
            self._settle()

    @property
    def rate_hz(self) -> float | None:
        """Mean rate, Hz (None below two messages)."""
        n = self.count - 1
        return n / self.sum_dt if n > 0 and self.sum_dt > 0 else None

    @property
    def jitter_s(self) -> float | None:
        """Standard deviation of the interval between messages, s."""
        n = self.count - 1
        if n < 2:
            return None
        mean = self.sum_dt / n
        return math.sqrt(max(self.sum_dt2 / n - mean * mean, 0.0))

    def to_dict(self) -> dict[str, Any]:
        """The topic's health as plain values (JSON-ready)."""
        skew = self.skew_count > 0
        return {
            "topic": self.topic,
            "type": self.msgtype,
            "decodable": self.decodable,
            "count": self.count,
            "rate_hz": self.rate_hz,
            "expected_rate_hz": self.expected_rate_hz,
            "jitter_ms": None if self.jitter_s is None else self.jitter_s * 1e3,
            "max_interval_s": self.max_gap_s if self.count > 1 else None,
            "gaps_over_3_periods": self.gaps,
            "non_monotonic_stamps": self.non_monotonic,
            "stamp_offset_mean_s": self.skew_sum_s / self.skew_count if skew else None,
            "stamp_skew_spread_ms": (self.skew_max_s - self.skew_min_s) * 1e3 if skew else None,
        }


@dataclass(frozen=True, kw_only=True, slots=True)
class ContactEvent:
    """A contact's beginning or end."""

    t_s: float
    begin: bool
    x_m: float
    y_m: float
    what: str


@dataclass(kw_only=True, slots=True)
class BagData:
    """What one pass over a bag keeps."""

    info: BagInfo
    start_ns: int
    poses: dict[str, PoseTrack] = field(default_factory=dict)
    cmd: tuple[array[float], array[float], array[float]] | None = None  # t s, v, ω
    cmd_stamped: bool = False
    scan_min: tuple[array[float], array[float]] | None = None  # t s, min valid range m
    scan_cells: dict[tuple[int, int], int] = field(default_factory=dict)
    health: dict[str, TopicHealth] = field(default_factory=dict)
    clock: tuple[array[int], array[int]] | None = None  # record ns, clock ns
    bt_events: list[tuple[float, str, str, str]] = field(default_factory=list)
    plans: list[tuple[float, F64]] = field(default_factory=list)
    goals: list[tuple[float, float, float, float]] = field(default_factory=list)  # t s, x, y, yaw
    contacts: list[ContactEvent] | None = None
    occupancy: tuple[F64, float, float, float] | None = None  # grid (rows=y), resolution, origin x, y
    robot_description: str | None = None

    def has(self, topic: str) -> bool:
        """Whether the bag has `topic` with at least one message."""
        h = self.health.get(topic)
        return h is not None and h.count > 0

    def t_s(self, t_ns: int) -> float:
        """Seconds from the bag's start."""
        return (t_ns - self.start_ns) * 1e-9

    def clock_at(self, t_ns: NDArray[np.int64]) -> NDArray[np.int64] | None:
        """The sim time (from /clock) at record times `t_ns`, or None without /clock."""
        if self.clock is None or len(self.clock[0]) < 2:
            return None
        rec = np.frombuffer(self.clock[0], dtype=np.int64)
        sim = np.frombuffer(self.clock[1], dtype=np.int64)
        return np.round(np.interp(t_ns.astype(np.float64), rec.astype(np.float64), sim.astype(np.float64))).astype(
            np.int64
        )


def _best_pose(data: BagData) -> PoseTrack | None:
    for topic in POSE_TOPICS:
        track = data.poses.get(topic)
        if track is not None and len(track):
            return track
    return None


def collect(
    path: str | os.PathLike[str],
    *,
    topics: Iterable[str] | None = None,
    health: bool = True,
    scan_points: bool = False,
    decoded: bool = True,
    progress: Callable[[float], None] | None = None,
) -> BagData:
    """Read the bag once (twice with `decoded`) and keep the series analysis uses.

    Args:
        path: The bag folder.
        topics: Only these topics (None: all; health then covers every topic).
        health: Accumulate each topic's timing statistics.
        scan_points: Accumulate scan endpoints (placed with the best pose known at the scan).
        decoded: Also decode the rare structured topics (BT log, plans, goals, contacts, map).
        progress: Called with the fraction of the bag's time read, now and then.

    Raises:
        BagError: If the folder is not a readable bag; a truncated storage file says to run
            `twin bag recover`.
    """
    bag = Path(path)
    info = open_bag(bag)
    data = BagData(info=info, start_ns=info.start_ns)
    names = {t.name for t in info.topics}
    wanted = None if topics is None else [t for t in topics if t in names]
    by_name = {t.name: t for t in info.topics}
    for ti in info.topics:
        if wanted is None or ti.name in wanted:
            data.health[ti.name] = TopicHealth(
                topic=ti.name,
                msgtype=ti.msgtype,
                decodable=ti.decodable,
                expected_rate_hz=EXPECTED_RATE_HZ.get(ti.name),
            )
    pose_fns = {t: fn for t in POSE_TOPICS if t in by_name and (fn := _cdr.pose_reader(by_name[t].msgtype)) is not None}
    for t in pose_fns:
        data.poses[t] = PoseTrack(t, by_name[t].msgtype)
    twist_fn = _cdr.twist_reader(by_name[CMD_TOPIC].msgtype) if CMD_TOPIC in by_name else None
    if twist_fn is not None:
        data.cmd = (array("d"), array("d"), array("d"))
        data.cmd_stamped = by_name[CMD_TOPIC].msgtype.endswith("Stamped")
    scan_ok = SCAN_TOPIC in by_name and by_name[SCAN_TOPIC].msgtype == "sensor_msgs/msg/LaserScan"
    if scan_ok:
        data.scan_min = (array("d"), array("d"))
    clock_ok = "/clock" in by_name and by_name["/clock"].msgtype == "rosgraph_msgs/msg/Clock"
    if clock_ok:
        data.clock = (array("q"), array("q"))
    stamp_fns = {ti.name: _cdr.stamp_reader(ti.msgtype) for ti in info.topics}

    read_topics = None if wanted is None else wanted
    if read_topics is not None and not read_topics:
        return data
    span = max(info.duration_ns, 1)
    next_report = 0
    last_pose: tuple[float, float, float] | None = None
    pose_rank = {t: i for i, t in enumerate(POSE_TOPICS)}
    best_rank = min((pose_rank[t] for t in pose_fns), default=99)
    try:
        for topic, _type, t_ns, raw in read_messages(bag, read_topics, decode=False):
            buf: bytes = raw
            try:
                if health:
                    h = data.health.get(topic)
                    if h is not None:
                        stamp_fn = stamp_fns.get(topic)
                        h.add(t_ns, stamp_fn(buf) if stamp_fn is not None else None)
                pose_fn = pose_fns.get(topic)
                if pose_fn is not None:
                    sample = pose_fn(buf)
                    data.poses[topic].add(t_ns, sample)
                    if pose_rank[topic] == best_rank:
                        last_pose = (sample[1], sample[2], sample[3])
                elif topic == CMD_TOPIC and twist_fn is not None and data.cmd is not None:
                    _stamp, v, w = twist_fn(buf)
                    data.cmd[0].append(data.t_s(t_ns))
                    data.cmd[1].append(v)
                    data.cmd[2].append(w)
                elif topic == SCAN_TOPIC and data.scan_min is not None:
                    _add_scan(data, t_ns, buf, last_pose if scan_points else None)
                elif topic == "/clock" and data.clock is not None:
                    data.clock[0].append(t_ns)
                    data.clock[1].append(_cdr.clock_ns(buf))
            except (IndexError, ValueError, TypeError) as err:  # struct.error is a ValueError
                _log.warning("%s: a message on %s at %d ns does not parse (%s); skipped", bag, topic, t_ns, err)
            if progress is not None and t_ns >= next_report:
                progress((t_ns - info.start_ns) / span)
                next_report = t_ns + span // 50
    except BagError as err:
        raise BagError(_truncation_hint(bag, err)) from None
    for h in data.health.values():
        h.finish()
    if decoded:
        _decode_rare(data, bag, names if wanted is None else set(wanted))
    return data


def _truncation_hint(bag: Path, err: BagError) -> str:
    text = str(err)
    if "recover" in text:
        return text
    return f"{text}; if its recording was killed, run `twin bag recover {bag}`"


def _add_scan(data: BagData, t_ns: int, buf: bytes, pose: tuple[float, float, float] | None) -> None:
    assert data.scan_min is not None
    _stamp, a_min, a_inc, r_min, r_max, _u, ranges = _cdr.scan_ranges(buf)
    valid = (ranges >= r_min) & (ranges <= r_max) & np.isfinite(ranges)
    data.scan_min[0].append(data.t_s(t_ns))
    data.scan_min[1].append(float(ranges[valid].min()) if valid.any() else math.nan)
    if pose is None:
        return
    idx = np.flatnonzero(valid[::_SCAN_BEAM_STRIDE]) * _SCAN_BEAM_STRIDE
    if not len(idx):
        return
    x, y, yaw = pose
    ang = yaw + a_min + a_inc * idx
    r = ranges[idx].astype(np.float64)
    cells = np.floor(np.stack((x + r * np.cos(ang), y + r * np.sin(ang)), axis=1) / _SCAN_CELL_M).astype(np.int64)
    cells_counts = data.scan_cells
    for cx, cy in np.unique(cells, axis=0).tolist():
        key = (cx, cy)
        cells_counts[key] = cells_counts.get(key, 0) + 1


def scan_points(data: BagData, min_hits: int = 2) -> F64:
    """Centres of the scan-endpoint cells hit at least `min_hits` times, shape (N, 2)."""
    pts = [k for k, n in data.scan_cells.items() if n >= min_hits]
    if not pts:
        return np.zeros((0, 2))
    return (np.asarray(pts, dtype=np.float64) + 0.5) * _SCAN_CELL_M


def _decode_rare(data: BagData, bag: Path, names: set[str]) -> None:
    rare = [t for t in _DECODED_TOPICS if t in names and data.info.topic(t).decodable]
    if "/contacts" in names:
        data.contacts = []
    if not rare:
        return
    try:
        for m in read_messages(bag, rare):
            t_s = data.t_s(m.t_ns)
            msg = m.msg
            if m.topic == "/behavior_tree_log" and hasattr(msg, "event_log"):
                for e in msg.event_log:
                    data.bt_events.append((t_s, str(e.node_name), str(e.previous_status), str(e.current_status)))
            elif m.topic == "/plan" and hasattr(msg, "poses"):
                xy = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=np.float64)
                if len(xy) > _PLAN_POINTS:
                    xy = xy[np.linspace(0, len(xy) - 1, _PLAN_POINTS).astype(np.int64)]
                data.plans.append((t_s, xy.reshape(-1, 2)))
            elif m.topic == "/goal_pose" and hasattr(msg, "pose"):
                p = msg.pose
                q = p.orientation
                data.goals.append((t_s, p.position.x, p.position.y, _cdr.yaw_of(q.x, q.y, q.z, q.w)))
            elif m.topic == "/contacts" and data.contacts is not None and hasattr(msg, "event"):
                data.contacts.append(
                    ContactEvent(
                        t_s=t_s,
                        begin=int(msg.event) == 1,
                        x_m=float(msg.position.x),
                        y_m=float(msg.position.y),
                        what=str(msg.world_collision),
                    )
                )
            elif m.topic == "/map" and hasattr(msg, "info"):
                w, h = int(msg.info.width), int(msg.info.height)
                grid = np.asarray(msg.data, dtype=np.float64).reshape(h, w) if w * h else np.zeros((0, 0))
                o = msg.info.origin.position
                data.occupancy = (grid, float(msg.info.resolution), float(o.x), float(o.y))
            elif m.topic == "/robot_description" and hasattr(msg, "data"):
                data.robot_description = str(msg.data)
    except BagError as err:
        _log.warning("%s", err)


def best_pose(data: BagData) -> PoseTrack | None:
    """The most trusted pose source present (ground truth, then localization, then odometry)."""
    return _best_pose(data)
