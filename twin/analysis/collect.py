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
import struct
from array import array
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from twin.analysis import _cdr
from twin.analysis.series import TopicSeries, series_kind
from twin.bag import BagInfo, TopicInfo, open_bag, read_raw
from twin.bag.raw import require_readable
from twin.bag.reader import robot_namespaces, undecodable
from twin.bag.typesys import message_type_name
from twin.core.errors import ConfigError

__all__ = [
    "CMD_TOPIC",
    "POSE_TOPICS",
    "BagData",
    "ContactEvent",
    "PoseTrack",
    "TopicHealth",
    "best_pose",
    "collect",
    "namespace_view",
    "robot_namespaces",
    "scan_points",
]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

#: Pose sources in order of trust: the simulator's truth, the localization, the odometry.
POSE_TOPICS: tuple[str, ...] = ("/ground_truth/odom", "/amcl_pose", "/odom")
CMD_TOPIC = "/cmd_vel"
SCAN_TOPIC = "/scan"
_DECODED_TOPICS = (
    "/behavior_tree_log",
    "/mission/behavior_tree_log",
    "/plan",
    "/goal_pose",
    "/contacts",
    "/map",
    "/robot_description",
)

#: Rates the twin publishes at with its TurtleBot3 models (Gazebo's defaults), Hz. A twin bag's topics
#: are judged against the rates its own run had (`twin_rates`: its recorded scenario and robot
#: model); another bag's against their own steady rate.
EXPECTED_RATE_HZ: dict[str, float] = {
    "/imu": 200.0,
    "/odom": 30.0,
    "/joint_states": 30.0,
    "/ground_truth/odom": 30.0,
    "/scan": 5.0,
}

_SCAN_CELL_M = 0.05
_SCAN_BEAM_STRIDE = 4
_SCAN_MOVE_M = 0.05
_SCAN_TURN_RAD = 0.1
_PLAN_POINTS = 200
_BLOCK = 8192


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


def _steady(intervals: NDArray[np.float64]) -> bool:
    """Whether intervals (s) look like a periodic topic's: positive on average and not spread wide."""
    mean = float(intervals.mean()) if len(intervals) else 0.0
    return len(intervals) >= 3 and mean > 0.0 and float(intervals.std()) < 0.5 * mean


@dataclass(kw_only=True, slots=True)
class TopicHealth:
    """Running statistics of one topic's message times, updated a block of messages at a time.

    `add` only appends the record time and the stamp's 8 raw bytes; every `_BLOCK` messages the
    block is reduced with numpy into sums, extremes and counts, so memory stays bounded.
    """

    topic: str
    msgtype: str
    decodable: bool
    expected_rate_hz: float | None
    stamp_kind: int = 0  # 0: no stamp, 1: a leading header/Time, 2: TFMessage's first transform
    little_endian: bool = True
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
    periodic: bool = True
    _period_s: float | None = None
    _steady_s: float | None = None  # the median interval of the first block, s
    _last_stamp: int = 0
    t_buf: array[int] = field(default_factory=lambda: array("q"))
    stamp_buf: bytearray = field(default_factory=bytearray)
    # TFMessage: each message's first transform (frame, child) as a small id; its stamps run on their own
    tf_ids: array[int] = field(default_factory=lambda: array("i"))
    _tf_pairs: dict[bytes, int] = field(default_factory=dict)
    _tf_last: dict[int, int] = field(default_factory=dict)

    def add(self, t_ns: int, buf: bytes) -> None:
        """Count one message recorded at `t_ns` (its serialized bytes `buf` give the stamp)."""
        if not self.t_buf and self.count == 0:
            self.little_endian = len(buf) > 1 and bool(buf[1] & 1)
        self.t_buf.append(t_ns)
        kind = self.stamp_kind
        if kind == 1:
            # a message too short to hold a stamp (a damaged record) counts as one without a stamp
            self.stamp_buf += buf[4:12] if len(buf) >= 12 else bytes(8)
        elif kind == 2:
            self.add_tf_stamp(buf)
        if len(self.t_buf) >= _BLOCK:
            self.flush()

    def add_tf_stamp(self, buf: bytes) -> None:
        """Buffer the stamp of a TFMessage's first transform (zeros when it has none) and its frame pair.

        One /tf topic carries several transform streams (odometry, joints, AMCL's map -> odom stamped
        ahead by its transform tolerance), each on its own stamps: whether stamps go backwards is
        judged per (frame, child) pair of the message's first transform.
        """
        pair = b""
        if len(buf) >= 16 and buf[4:8] != b"\0\0\0\0":
            self.stamp_buf += buf[8:16]
            order: Literal["little", "big"] = "little" if self.little_endian else "big"
            n1 = int.from_bytes(buf[16:20], order)
            end1 = 20 + n1
            at = end1 + (-(end1 - 4) % 4)  # CDR aligns the child's length to 4 from the body's start
            n2 = int.from_bytes(buf[at : at + 4], order)
            pair = bytes(buf[16 : at + 4 + n2])
        else:
            self.stamp_buf += bytes(8)
        pairs = self._tf_pairs
        ident = pairs.get(pair)
        if ident is None:
            ident = pairs[pair] = len(pairs)
        self.tf_ids.append(ident)

    def flush(self) -> None:
        """Reduce the buffered block into the statistics."""
        if not self.t_buf:
            return
        t = np.frombuffer(self.t_buf, dtype=np.int64).copy()  # the buffer is cleared below
        if self.count:
            dt = np.diff(t, prepend=self.last_ns) * 1e-9
        else:
            self.first_ns = int(t[0])
            dt = np.diff(t) * 1e-9
        if len(dt):
            if self._period_s is None:
                self._settle(dt, np.diff(self._stamps()[0]) * 1e-9 if self.stamp_kind == 1 else None)
            assert self._period_s is not None
            self.sum_dt += float(dt.sum())
            self.sum_dt2 += float(np.dot(dt, dt))
            self.max_gap_s = max(self.max_gap_s, float(dt.max()))
            self.gaps += int(np.count_nonzero(dt > 3.0 * self._period_s))
        self.count += len(t)
        self.last_ns = int(t[-1])
        if self.stamp_kind:
            st, has = self._stamps()
            if len(st):
                if self.stamp_kind == 2:
                    self._count_backwards_per_pair(st, np.frombuffer(self.tf_ids, dtype=np.int32)[has])
                else:
                    prev = np.concatenate(([self._last_stamp], st[:-1])) if self._last_stamp else st[:-1]
                    cur = st if self._last_stamp else st[1:]
                    self.non_monotonic += int(np.count_nonzero(cur < prev))
                    self._last_stamp = int(st[-1])
                skew = (t[has] - st) * 1e-9
                self.skew_count += len(skew)
                self.skew_sum_s += float(skew.sum())
                self.skew_min_s = min(self.skew_min_s, float(skew.min()))
                self.skew_max_s = max(self.skew_max_s, float(skew.max()))
        del self.t_buf[:]
        del self.stamp_buf[:]
        del self.tf_ids[:]

    def _stamps(self) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """The buffered block's header stamps that are set, ns, and which messages carry one."""
        raw = np.frombuffer(bytes(self.stamp_buf), dtype=np.dtype([("s", "<i4"), ("n", "<u4")]))
        if not self.little_endian:
            raw = raw.byteswap()
        stamps = raw["s"].astype(np.int64) * 1_000_000_000 + raw["n"].astype(np.int64)
        has = stamps > 0
        return stamps[has], has

    def _count_backwards_per_pair(self, stamps: NDArray[np.int64], ids: NDArray[np.int32]) -> None:
        last = self._tf_last
        for ident in np.unique(ids).tolist():
            st = stamps[ids == ident]
            prev = last.get(ident)
            seq = np.concatenate(([prev], st)) if prev is not None else st
            self.non_monotonic += int(np.count_nonzero(np.diff(seq) < 0))
            last[ident] = int(st[-1])

    def _settle(self, warm: NDArray[np.float64], warm_stamps: NDArray[np.float64] | None = None) -> None:
        """Judge the topic's steady period from its first block of record intervals.

        A driver that writes its records in bunches (two `/odom` within a millisecond, stamped 50 ms
        apart) looks aperiodic by record times; its header stamps (`warm_stamps`, their intervals)
        then tell the steady period.
        """
        median = float(np.median(warm))
        self._steady_s = median if median > 0.0 else None
        if self.expected_rate_hz:
            self._period_s = 1.0 / self.expected_rate_hz
            return
        # Only a periodic topic has gaps: events (logs, parameters) come when they come.
        self.periodic = _steady(warm)
        if not self.periodic and warm_stamps is not None and _steady(warm_stamps):
            self.periodic = True
            median = float(np.median(warm_stamps))
            self._steady_s = median
        self._period_s = median if self.periodic else math.inf

    def finish(self) -> None:
        """Reduce what is still buffered."""
        self.flush()
        if self._period_s is None:
            self.periodic = False

    @property
    def rate_hz(self) -> float | None:
        """Mean rate, Hz (None below two messages, and for a burst: an aperiodic topic whose messages span under 1 s).

        (A latched /rosout's start-up lines, 19 in 5 ms, made a "rate" of 1940 Hz.)
        """
        n = self.count - 1
        if n <= 0 or self.sum_dt <= 0 or (not self.periodic and self.sum_dt < _BURST_S):
            return None
        return n / self.sum_dt

    @property
    def steady_rate_hz(self) -> float | None:
        """The topic's own steady rate (1 / the median interval of its first messages), Hz; None if not periodic."""
        if not self.periodic or self._steady_s is None:
            return None
        return 1.0 / self._steady_s

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
            "steady_rate_hz": self.steady_rate_hz,
            "jitter_ms": None if self.jitter_s is None else self.jitter_s * 1e3,
            "max_interval_s": self.max_gap_s if self.count > 1 else None,
            "gaps_over_3_periods": self.gaps if self.periodic else None,
            "non_monotonic_stamps": self.non_monotonic,
            "stamp_offset_mean_s": self.skew_sum_s / self.skew_count if skew else None,
            "stamp_skew_spread_ms": (self.skew_max_s - self.skew_min_s) * 1e3 if skew else None,
        }


_BURST_S = 1.0
"""An aperiodic topic whose messages all come within this span has no rate to speak of, s."""


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
    twin_bag: bool = False  # recorded by the twin (it has the twin's provenance)
    poses: dict[str, PoseTrack] = field(default_factory=dict)
    cmd: tuple[array[float], array[float], array[float]] | None = None  # t s, v, ω
    cmd_stamped: bool = False
    scan_min: tuple[array[float], array[float]] | None = None  # t s, min valid range m
    scan_topic: str | None = None  # where scan_min comes from: /scan, else the bag's one LaserScan topic
    scan_choices: tuple[str, ...] = ()  # without /scan, the bag's several LaserScan topics (none taken)
    scan_cells: dict[int, int] = field(default_factory=dict)  # cell (x << 32 | y) -> scans that hit it
    scan_from: tuple[float, float, float] | None = None  # pose of the last scan placed
    health: dict[str, TopicHealth] = field(default_factory=dict)
    clock: tuple[array[int], array[int]] | None = None  # record ns, clock ns
    bt_events: list[tuple[float, str, str, str]] = field(default_factory=list)  # /behavior_tree_log
    # the mission's own tree when Nav2's bt_navigator has /behavior_tree_log (a twin bag)
    mission_events: list[tuple[float, str, str, str]] = field(default_factory=list)
    plans: list[tuple[float, F64]] = field(default_factory=list)
    goals: list[tuple[float, float, float, float]] = field(default_factory=list)  # t s, x, y, yaw
    contacts: list[ContactEvent] | None = None
    occupancy: tuple[F64, float, float, float] | None = None  # grid (rows=y), resolution, origin x, y
    robot_description: str | None = None
    series: dict[str, TopicSeries] = field(default_factory=dict)  # standard types the fixed sections leave out

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
        rec = np.frombuffer(self.clock[0], dtype=np.int64).astype(np.float64)
        sim = np.frombuffer(self.clock[1], dtype=np.int64).astype(np.float64)
        t = t_ns.astype(np.float64)
        out = np.interp(t, rec, sim)
        # Before the first and after the last /clock message (10 Hz from Gazebo and the twin, so up to 0.1 s
        # of commands), go on at the pace of the nearest ten intervals rather than holding the end value.
        k = min(10, len(rec) - 1)
        before, after = t < rec[0], t > rec[-1]
        if before.any() and rec[k] > rec[0]:
            pace = (sim[k] - sim[0]) / (rec[k] - rec[0])
            out[before] = sim[0] + (t[before] - rec[0]) * pace
        if after.any() and rec[-1] > rec[-1 - k]:
            pace = (sim[-1] - sim[-1 - k]) / (rec[-1] - rec[-1 - k])
            out[after] = sim[-1] + (t[after] - rec[-1]) * pace
        return np.round(out).astype(np.int64)


def _best_pose(data: BagData) -> PoseTrack | None:
    for track in data.poses.values():  # most trusted first (see _pose_topics)
        if len(track):
            return track
    return None


def _pose_topics(types: dict[str, str], extra: Iterable[str]) -> list[str]:
    """The topics to read poses from, most trusted first.

    POSE_TOPICS where present, then `extra` (topics a caller names). A bag with none of POSE_TOPICS
    (a real robot's `/odometry/filtered`, `/wheel/odom`, `/pose`) gives every topic of a pose type,
    Odometry first, by name.
    """
    out: list[str] = []
    for t in (*POSE_TOPICS, *extra):
        if t in types and t not in out and _cdr.pose_reader(types[t]) is not None:
            out.append(t)
    if not any(t in POSE_TOPICS for t in out):
        others = [t for t, ty in types.items() if t not in out and _cdr.pose_reader(ty) is not None]
        out += sorted(others, key=lambda t: (types[t] != "nav_msgs/msg/Odometry", t))
    return out


def namespace_view(info: BagInfo, namespace: str | None) -> dict[str, TopicInfo]:
    """The bag's topics as one robot's pass reads them: `{name read as: topic}`.

    With no namespace, every topic under its own name. With one, the robot's topics under
    `/<namespace>/` stand for their names without it (`/robot1/odom` as `/odom`), and the topics
    outside every robot's namespace (`/clock`, `/rosout`) are kept as they are; other robots'
    topics are left out.
    """
    if not namespace:
        return {t.name: t for t in info.topics}
    ns = namespace.strip("/")
    prefix = f"/{ns}/"
    others = tuple(f"/{o}/" for o in robot_namespaces(info) if o != ns)
    view = {"/" + t.name[len(prefix) :]: t for t in info.topics if t.name.startswith(prefix)}
    for t in info.topics:
        if not t.name.startswith(prefix) and not t.name.startswith(others) and t.name not in view:
            view[t.name] = t
    return view


def twin_rates(bag: Path, namespace: str | None = None) -> dict[str, float] | None:
    """The rates the twin run that recorded `bag` published at, Hz, by topic (without the namespace).

    Read from the scenario the bag records (written whole, every default filled in) and the robot
    model it names (its lidar's and IMU's update rates, its joint-state plugin's, the scenario's
    overrides); None when the bag records no scenario or its robot model is not found here (its
    topics are then judged by their steady rate).
    """
    import yaml

    from twin.bag import read_provenance
    from twin.core.errors import TwinError
    from twin.world.robot_model import load_robot

    try:
        provenance = read_provenance(bag)
        if provenance is None or "scenario_yaml" not in provenance:
            return None
        scenario = yaml.safe_load(provenance["scenario_yaml"])
        entries = scenario.get("robots") or []
        if entries:  # a fleet's: the robot of this namespace (or the only one), its own sections
            chosen = [e for e in entries if (e.get("namespace") or e.get("name")) == namespace] or (
                entries if len(entries) == 1 else []
            )
            if not chosen:
                return None
            robot, sensors = chosen[0]["robot"], chosen[0]["sensors"]
        else:
            robot, sensors = scenario["robot"], scenario["sensors"]
        model_path = scenario.get("world", {}).get("model_path") or []
        sdf_log = logging.getLogger("twin.world.sdf")  # the run warned of its model's missing meshes already
        level = sdf_log.level
        sdf_log.setLevel(logging.ERROR)
        try:
            spec = load_robot(str(robot["model"]), model_path=[str(p) for p in model_path])
        finally:
            sdf_log.setLevel(level)
        lidar_hz = (sensors.get("lidar") or {}).get("rate_hz")
        ground_truth_hz = float((sensors.get("ground_truth") or {}).get("rate_hz", 30.0))
        imu_on = bool((sensors.get("imu") or {}).get("enabled", True))
    except (TwinError, OSError, ValueError, KeyError, TypeError, AttributeError, yaml.YAMLError):
        return None
    encoders = spec.joint_states.rate_hz if spec.joint_states is not None else 30.0  # as the run's JointStateNode
    rates = {"/joint_states": encoders, "/odom": encoders, "/ground_truth/odom": ground_truth_hz}
    if spec.lidar is not None:
        rates["/scan"] = float(lidar_hz) if lidar_hz else spec.lidar.rate_hz
    if spec.imu is not None and imu_on:
        rates["/imu"] = spec.imu.rate_hz
    return rates


def _is_twin_bag(bag: Path) -> bool:
    from twin.bag import read_provenance
    from twin.core.errors import BagError

    try:
        return read_provenance(bag) is not None
    except BagError:
        return False


def collect(
    path: str | os.PathLike[str],
    *,
    topics: Iterable[str] | None = None,
    health: bool = True,
    scan_points: bool = False,
    decoded: bool = True,
    progress: Callable[[float], None] | None = None,
    pose_topics: Iterable[str] = (),
    series: bool = False,
    namespace: str | None = None,
    scan_topic: str | None = None,
) -> BagData:
    """Read the bag once (twice with `decoded`) and keep the series analysis uses.

    Args:
        path: The bag folder.
        topics: Only these topics (None: all; health then covers every topic).
        health: Accumulate each topic's timing statistics.
        scan_points: Accumulate scan endpoints (placed with the best pose known at the scan).
        decoded: Also decode the rare structured topics (BT log, plans, goals, contacts, map).
        progress: Called with the fraction of the bag's time read, now and then.
        pose_topics: Topics to read poses from besides POSE_TOPICS (a bag without any of those reads
            every topic of a pose type); `data.poses` holds them most trusted first.
        series: Also keep samples of every topic of a standard type the other series leave out
            (IMU, joint states, battery, GNSS, other Twist and LaserScan topics) in `data.series`.
        namespace: Read one robot of a fleet's bag: its topics under `/<namespace>/` stand for the
            usual names (`/robot1/odom` is read as `/odom`: `data.poses`, `data.health` and the
            other fields are keyed by those), plus the bag's topics outside every robot's namespace
            (`/clock`); tracks and topic health keep the bag's own names. `topics` and
            `pose_topics` are then given without the namespace.
        scan_topic: The LaserScan topic clearance comes from (None: `/scan`, else the bag's only one).

    Raises:
        BagError: If the folder is not a readable bag; a truncated storage file says to run
            `twin bag recover`.
    """
    bag = Path(path)
    # Opening the storage first turns a truncated file into one error line, not a warning and an error.
    require_readable(bag)
    info = open_bag(bag)
    data = BagData(info=info, start_ns=info.start_ns, twin_bag=_is_twin_bag(bag))
    nominal = (twin_rates(bag, namespace) or {}) if data.twin_bag else {}
    # the topics as this pass names them: a robot's own without its namespace (see namespace_view)
    by_name = namespace_view(info, namespace)
    names = set(by_name)
    by_real = {ti.name: ti for ti in by_name.values()}
    types = {n: message_type_name(t.msgtype) for n, t in by_name.items()}  # full names, as the fast readers know them
    pose_list = _pose_topics(types, pose_topics)
    scan_topic = _scan_topic(types) if scan_topic is None else _chosen_scan(bag, types, scan_topic)
    wanted = None
    if topics is not None:
        asked = list(topics)
        wanted = [t for t in asked if t in names]
        if pose_topics or any(t in asked for t in POSE_TOPICS):
            # a caller asking for the usual pose topics gets whatever the bag carries poses on
            wanted += [t for t in pose_list if t not in wanted]
        if SCAN_TOPIC in asked and scan_topic is not None and scan_topic not in wanted:
            wanted.append(scan_topic)  # ... and for /scan, its one LaserScan topic
    for name, ti in by_name.items():
        if wanted is None or name in wanted:
            data.health[name] = TopicHealth(
                topic=ti.name,
                msgtype=ti.msgtype,
                decodable=ti.decodable,
                expected_rate_hz=nominal.get(name),
            )
    pose_fns = {t: fn for t in pose_list if (fn := _cdr.pose_reader(types[t])) is not None}
    for t in pose_fns:
        data.poses[t] = PoseTrack(by_name[t].name, types[t])
    twist_fn = _cdr.twist_reader(types[CMD_TOPIC]) if CMD_TOPIC in by_name else None
    if twist_fn is not None:
        data.cmd = (array("d"), array("d"), array("d"))
        data.cmd_stamped = types[CMD_TOPIC].endswith("Stamped")
    if scan_topic is not None:
        data.scan_min = (array("d"), array("d"))
        data.scan_topic = scan_topic
    else:
        data.scan_choices = tuple(sorted(n for n, t in types.items() if t == "sensor_msgs/msg/LaserScan"))
    clock_ok = "/clock" in by_name and types["/clock"] == "rosgraph_msgs/msg/Clock"
    if clock_ok:
        data.clock = (array("q"), array("q"))
    for name, h in data.health.items():
        h.stamp_kind = _cdr.stamp_kind(types[name])

    read_topics = None if wanted is None else [by_name[t].name for t in wanted]
    if read_topics is None and namespace:
        read_topics = [ti.name for ti in by_name.values()]
    if read_topics is not None and not read_topics:
        return data
    span = max(info.duration_ns, 1)
    next_report = 0
    pose_rank = {t: i for i, t in enumerate(pose_list)}
    best_rank = min((pose_rank[t] for t in pose_fns), default=99)
    handlers: dict[str, Callable[[int, bytes], None]] = {}
    state = {"pose": None}
    for topic, fn in pose_fns.items():
        handlers[topic] = _pose_handler(data, topic, fn, state if pose_rank[topic] == best_rank else None)
    if twist_fn is not None and data.cmd is not None:
        handlers[CMD_TOPIC] = _cmd_handler(data, twist_fn)
    if data.scan_min is not None and scan_topic is not None:
        handlers[scan_topic] = lambda t_ns, buf: _add_scan(data, t_ns, buf, state["pose"] if scan_points else None)
    if data.clock is not None:
        handlers["/clock"] = _clock_handler(data.clock)
    if decoded:
        if "/contacts" in by_name and (wanted is None or "/contacts" in wanted):
            data.contacts = []
        for name in _DECODED_TOPICS:
            if name in by_name and (wanted is None or name in wanted) and by_name[name].decodable:
                rare = _rare_handler(data, name, types[name])
                if rare is not None:
                    handlers[name] = rare
    if series:
        _add_series(data, handlers, by_name, types, wanted)
    health_of = data.health if health else {}
    # keyed by the bag's own topic names, as the reader yields them
    route: dict[str, tuple[TopicHealth | None, Callable[[int, bytes], None] | None]] = {
        by_name[name].name: (health_of.get(name), handlers.get(name)) for name in set(health_of) | set(handlers)
    }
    if namespace:
        robots = robot_namespaces(info)
        _keep_only(route, by_name, types, "tf2_msgs/msg/TFMessage", _own_transforms(namespace, robots))
        _keep_only(route, by_name, types, "rcl_interfaces/msg/Log", _own_log_lines(namespace, robots))
    block = _BLOCK
    for topic, t_ns, raw in read_raw(bag, read_topics):
        r = route.get(topic)
        if r is None:
            continue
        buf: Any = raw  # bytes or a memoryview into the chunk
        th, handler = r
        if th is not None:  # TopicHealth.add, inlined: this runs for every message of the bag
            tb = th.t_buf
            if not tb and th.count == 0:  # a topic's first message: is it CDR at all?
                if len(buf) < 4 or buf[0] != 0:
                    err = ValueError(f"no CDR header: starts with {bytes(buf[:4]).hex(' ')}")
                    raise undecodable(bag, buf, err, topic=topic, t_ns=t_ns, msgtype=th.msgtype)
                th.little_endian = bool(buf[1] & 1)
            tb.append(t_ns)
            kind = th.stamp_kind
            if kind == 1:
                th.stamp_buf += buf[4:12] if len(buf) >= 12 else bytes(8)  # too short: a damaged record
            elif kind == 2:
                th.add_tf_stamp(buf)
            if len(tb) >= block:
                th.flush()
        if handler is not None:
            try:
                handler(t_ns, buf)
            except (IndexError, ValueError, TypeError, struct.error) as err:
                raise undecodable(bag, buf, err, topic=topic, t_ns=t_ns, msgtype=by_real[topic].msgtype) from None
        if progress is not None and t_ns >= next_report:
            progress((t_ns - info.start_ns) / span)
            next_report = t_ns + span // 50
    for h in data.health.values():
        h.finish()
    return data


def _robot_of_frame(frame: str, robots: list[str]) -> str | None:
    """The robot whose frame this is with `frame_prefix` (`robot1/odom`: robot1), or None (`map`)."""
    name = frame.lstrip("/")
    under = [ns for ns in robots if name.startswith(f"{ns}/")]
    return max(under, key=len) if under else None  # a nested namespace's own robot, not its parent's


def _own_transforms(namespace: str, robots: list[str]) -> Callable[[bytes], bool]:
    """Whether a message of a fleet's shared TF topics (`tf: {mode: frame_prefix}`: one `/tf`) is this robot's.

    Every robot's transforms are then on the one `/tf`, their frames named `<ns>/odom`...: a
    message whose first transform's child frame (else its parent frame) is another robot's is left
    out of this robot's pass, so the topic's health (its rate) is the robot's own. Transforms of no
    robot's frames (the world's) are every robot's, as `/clock` is.
    """
    ns = namespace.strip("/")
    kept: dict[tuple[str, str], bool] = {}

    def own(buf: bytes) -> bool:
        frames = _cdr.tf_frames(buf)
        if frames is None:
            return True
        keep = kept.get(frames)
        if keep is None:
            parent, child = frames
            robot = _robot_of_frame(child, robots) or _robot_of_frame(parent, robots)
            keep = kept[frames] = robot is None or robot == ns
        return keep

    return own


def _own_log_lines(namespace: str, robots: list[str]) -> Callable[[bytes], bool]:
    """Whether a line of the shared `/rosout` is this robot's or the world's (not another robot's).

    A namespaced node logs under the name rcl gives it, `robot1.amcl` for `/robot1/amcl`: a line of
    another robot's nodes is left out of this robot's pass, so its rate and count are the robot's.
    """
    ns = namespace.strip("/")
    prefixes = sorted(((r.strip("/").replace("/", ".") + ".", r.strip("/")) for r in robots), reverse=True)
    kept: dict[str, bool] = {}

    def own(buf: bytes) -> bool:
        try:
            name = _cdr.log_name(buf)
        except (struct.error, IndexError):
            return True  # a damaged line: its health says so, whoever's it was
        keep = kept.get(name)
        if keep is None:
            robot = next((r for p, r in prefixes if name.startswith(p)), None)  # (longest prefix first)
            keep = kept[name] = robot is None or robot == ns
        return keep

    return own


def _keep_only(
    route: dict[str, tuple[TopicHealth | None, Callable[[int, bytes], None] | None]],
    by_name: dict[str, TopicInfo],
    types: dict[str, str],
    msgtype: str,
    own: Callable[[bytes], bool],
) -> None:
    """Read the topics of `msgtype` outside every namespace (a robot's view keeps their names) with `own`'s messages."""
    for name, ti in by_name.items():
        if ti.name == name and types[name] == msgtype and name in route:
            health, handler = route[name]
            route[name] = (None, _kept_handler(own, health, handler))


def _kept_handler(
    keep: Callable[[bytes], bool], health: TopicHealth | None, handler: Callable[[int, bytes], None] | None
) -> Callable[[int, bytes], None]:
    def handle(t_ns: int, buf: bytes) -> None:
        if not keep(buf):
            return
        if health is not None:
            health.add(t_ns, buf)
        if handler is not None:
            handler(t_ns, buf)

    return handle


def _chosen_scan(bag: Path, types: Mapping[str, str], topic: str) -> str:
    """The LaserScan topic a user named, checked.

    Raises:
        ConfigError: If the bag has no LaserScan topic of that name, naming those it has.
    """
    if types.get(topic) != "sensor_msgs/msg/LaserScan":
        scans = [name for name, msgtype in types.items() if msgtype == "sensor_msgs/msg/LaserScan"]
        msg = f"--scan-topic {topic}: {bag} has no LaserScan topic of that name (it has: {', '.join(scans) or 'none'})"
        raise ConfigError(msg)
    return topic


def _scan_topic(types: Mapping[str, str]) -> str | None:
    """The lidar's topic: `/scan`, else the bag's one LaserScan topic (`/front/scan`); None: none, or several."""
    laser = "sensor_msgs/msg/LaserScan"
    if types.get(SCAN_TOPIC) == laser:
        return SCAN_TOPIC
    scans = [name for name, msgtype in types.items() if msgtype == laser]
    return scans[0] if len(scans) == 1 else None


def _add_series(
    data: BagData,
    handlers: dict[str, Callable[[int, bytes], None]],
    by_name: dict[str, TopicInfo],
    types: dict[str, str],
    wanted: list[str] | None,
) -> None:
    store = _cdr.type_store()
    for name, ti in by_name.items():
        kind = series_kind(types[name])
        if kind is None or name in handlers or not ti.decodable or (wanted is not None and name not in wanted):
            continue
        if types[name] not in store.fielddefs:
            continue
        ts = data.series[name] = TopicSeries.for_topic(ti.name, kind, ti.message_count)  # its title: the bag's name
        handlers[name] = _series_handler(ts, store, types[name])


def _series_handler(ts: TopicSeries, store: Any, msgtype: str) -> Callable[[int, bytes], None]:
    skipped = 0

    def handle(t_ns: int, buf: bytes) -> None:
        nonlocal skipped
        if not ts.wants():
            return
        try:
            msg = store.deserialize_cdr(bytes(buf), msgtype)
        except Exception as err:  # rosbags raises several kinds; a damaged message is skipped, not fatal
            skipped += 1
            if skipped == 1:  # once per topic: a damaged bag may hold thousands
                _log.warning(
                    "%s at %d ns does not decode as %s (%s); skipped, and so are any more", ts.topic, t_ns, msgtype, err
                )
            return
        ts.add(t_ns, msg)

    return handle


def _pose_handler(
    data: BagData, topic: str, fn: Callable[[bytes], _cdr.PoseSample], state: dict[str, Any] | None
) -> Callable[[int, bytes], None]:
    track = data.poses[topic]

    def handle(t_ns: int, buf: bytes) -> None:
        sample = fn(buf)
        track.add(t_ns, sample)
        if state is not None:
            state["pose"] = (sample[1], sample[2], sample[3])

    return handle


def _clock_handler(clock: tuple[array[int], array[int]]) -> Callable[[int, bytes], None]:
    rec, sim = clock

    def handle(t_ns: int, buf: bytes) -> None:
        rec.append(t_ns)
        sim.append(_cdr.clock_ns(buf))

    return handle


def _cmd_handler(data: BagData, fn: Callable[[bytes], tuple[int | None, float, float]]) -> Callable[[int, bytes], None]:
    assert data.cmd is not None
    t_arr, v_arr, w_arr = data.cmd
    t_s = data.t_s

    def handle(t_ns: int, buf: bytes) -> None:
        _stamp, v, w = fn(buf)
        t_arr.append(t_s(t_ns))
        v_arr.append(v)
        w_arr.append(w)

    return handle


def _add_scan(data: BagData, t_ns: int, buf: bytes, pose: tuple[float, float, float] | None) -> None:
    assert data.scan_min is not None
    _stamp, a_min, a_inc, r_min, r_max, _u, ranges = _cdr.scan_ranges(buf)
    valid = (ranges >= r_min) & (ranges <= r_max)
    data.scan_min[0].append(data.t_s(t_ns))
    data.scan_min[1].append(float(ranges[valid].min()) if valid.any() else math.nan)
    if pose is None:
        return
    # Endpoints only from scans taken after the robot moved or turned: a standing robot adds nothing new.
    last = data.scan_from
    x, y, yaw = pose
    if last is not None and math.hypot(x - last[0], y - last[1]) < _SCAN_MOVE_M and abs(yaw - last[2]) < _SCAN_TURN_RAD:
        return
    data.scan_from = pose
    idx = np.flatnonzero(valid[::_SCAN_BEAM_STRIDE]) * _SCAN_BEAM_STRIDE
    if not len(idx):
        return
    ang = yaw + a_min + a_inc * idx
    r = ranges[idx].astype(np.float64)
    cx = np.floor((x + r * np.cos(ang)) / _SCAN_CELL_M).astype(np.int64)
    cy = np.floor((y + r * np.sin(ang)) / _SCAN_CELL_M).astype(np.int64)
    keys = np.unique((cx << 32) + (cy & 0xFFFFFFFF))
    cells = data.scan_cells
    for key in keys.tolist():
        cells[key] = cells.get(key, 0) + 1


def scan_points(data: BagData, min_hits: int = 2) -> F64:
    """Centres of the scan-endpoint cells hit at least `min_hits` times, shape (N, 2)."""
    keys = np.array([k for k, n in data.scan_cells.items() if n >= min_hits], dtype=np.int64)
    if not len(keys):
        return np.zeros((0, 2))
    cx = keys >> 32
    cy = (keys & 0xFFFFFFFF).astype(np.int64)
    cy = np.where(cy >= 2**31, cy - 2**32, cy)
    return (np.stack((cx, cy), axis=1).astype(np.float64) + 0.5) * _SCAN_CELL_M


def _rare_handler(data: BagData, topic: str, msgtype: str) -> Callable[[int, bytes], None] | None:
    """A handler decoding a rare structured topic in the main pass (standard definitions), or None."""
    store = _cdr.type_store()
    if msgtype not in store.fielddefs:
        return None

    def handle(t_ns: int, buf: bytes) -> None:
        try:
            msg = store.deserialize_cdr(bytes(buf), msgtype)
        except Exception as err:  # rosbags raises several kinds; one bad message is skipped, not fatal
            _log.warning("%s at %d ns does not decode as %s (%s); skipped", topic, t_ns, msgtype, err)
            return
        _take_rare(data, topic, data.t_s(t_ns), msg)

    return handle


def _take_rare(data: BagData, topic: str, t_s: float, msg: Any) -> None:
    if topic in ("/behavior_tree_log", "/mission/behavior_tree_log") and hasattr(msg, "event_log"):
        events = data.bt_events if topic == "/behavior_tree_log" else data.mission_events
        for e in msg.event_log:
            events.append((t_s, str(e.node_name), str(e.previous_status), str(e.current_status)))
    elif topic == "/plan" and hasattr(msg, "poses"):
        xy = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=np.float64)
        if len(xy) > _PLAN_POINTS:
            xy = xy[np.linspace(0, len(xy) - 1, _PLAN_POINTS).astype(np.int64)]
        data.plans.append((t_s, xy.reshape(-1, 2)))
    elif topic == "/goal_pose" and hasattr(msg, "pose"):
        p = msg.pose
        q = p.orientation
        data.goals.append((t_s, p.position.x, p.position.y, _cdr.yaw_of(q.x, q.y, q.z, q.w)))
    elif topic == "/contacts" and data.contacts is not None and hasattr(msg, "event"):
        data.contacts.append(
            ContactEvent(
                t_s=t_s,
                begin=int(msg.event) == 1,
                x_m=float(msg.position.x),
                y_m=float(msg.position.y),
                what=str(msg.world_collision),
            )
        )
    elif topic == "/map" and hasattr(msg, "info"):
        w, h = int(msg.info.width), int(msg.info.height)
        grid = np.asarray(msg.data, dtype=np.float64).reshape(h, w) if w * h else np.zeros((0, 0))
        o = msg.info.origin.position
        data.occupancy = (grid, float(msg.info.resolution), float(o.x), float(o.y))
    elif topic == "/robot_description" and hasattr(msg, "data"):
        data.robot_description = str(msg.data)


def best_pose(data: BagData) -> PoseTrack | None:
    """The most trusted pose source present (ground truth, then localization, then odometry)."""
    return _best_pose(data)
