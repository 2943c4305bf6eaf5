"""The numbers of a run: outcome, goals, duration, path, speed, contacts, localization error, clearance.

`run_metrics(bag)` reads a bag once (streaming; memory does not grow with the messages kept,
only with a few doubles per pose) and returns a frozen `RunMetrics`. Each metric says where it
came from; one a bag cannot give (no ground truth, no behaviour-tree log) is None and `notes`
says what it would need.

```python
from twin.analysis import run_metrics

m = run_metrics(Path("bags/run1"))
print(m.outcome, m.path_length_m, m.localization_error_p95_m)
json.dumps(m.to_dict())
```
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.analysis.collect import CMD_TOPIC, POSE_TOPICS, SCAN_TOPIC, BagData, PoseTrack, best_pose, collect

__all__ = [
    "GoalResult",
    "MissionTimeline",
    "RunMetrics",
    "bag_timeline",
    "compute_metrics",
    "mission_timeline",
    "run_metrics",
]

F64 = NDArray[np.float64]

#: Below these the robot counts as stopped.
STOPPED_SPEED_MPS = 0.01
STOPPED_YAW_RATE_RADPS = 0.01

_GOAL_NODE = re.compile(r"go_?to|gotopose|navigate_?to_?pose|navigatetopose|\bgoal", re.IGNORECASE)
_RECOVERY_NODE = re.compile(  # (Nav2's trees name their clearing `ClearLocalCostmap-Context` and the like)
    r"^(spin|back_?up|wait|drive_?on_?heading|assisted_?teleop|clear[\w-]*costmap[\w-]*)$", re.IGNORECASE
)
_TERMINAL = ("SUCCESS", "FAILURE")

_METRIC_TOPICS = (
    *POSE_TOPICS,
    CMD_TOPIC,
    SCAN_TOPIC,
    "/contacts",
    "/behavior_tree_log",
    "/mission/behavior_tree_log",
    "/clock",
)


@dataclass(frozen=True, kw_only=True, slots=True)
class GoalResult:
    """One goal of the mission: when it started and ended (s from the bag's start), and how."""

    name: str
    start_s: float
    end_s: float | None  # None: still running when the bag ended
    result: str  # SUCCESS, FAILURE, or running

    @property
    def duration_s(self) -> float | None:
        """How long the goal took (None while running)."""
        return None if self.end_s is None else self.end_s - self.start_s


@dataclass(frozen=True, kw_only=True, slots=True)
class MissionTimeline:
    """What the behaviour-tree log says: the root, its outcome, the goals and the recoveries."""

    root: str
    outcome: str  # SUCCESS, FAILURE, or running (the bag ended first)
    start_s: float
    end_s: float | None
    goals: tuple[GoalResult, ...]
    recoveries: tuple[tuple[float, str], ...]  # (t s, node name) each time a recovery started


def mission_timeline(events: list[tuple[float, str, str, str]]) -> MissionTimeline | None:
    """Read goals and recoveries from the status changes of a `/behavior_tree_log`.

    Goals are the nodes named like `GoToPose`/`go_to_*`/`NavigateToPose`; a tree without such
    nodes (Nav2's navigator tree, one run per goal) has one goal per run of its root.
    Recoveries are Nav2's behaviours (Spin, BackUp, Wait, DriveOnHeading, clearing costmaps).

    Args:
        events: (t s, node name, previous status, new status), in time order.

    Returns:
        None if there are no events.
    """
    if not events:
        return None
    root = events[0][1]
    names = {e[1] for e in events}
    goal_names = {n for n in names if _GOAL_NODE.search(n)} or {root}
    open_goals: dict[str, float] = {}
    goals: list[GoalResult] = []
    recoveries: list[tuple[float, str]] = []
    root_start: float | None = None
    root_end: float | None = None
    outcome = "running"
    for t_s, name, prev, new in events:
        if name == root:
            if new == "RUNNING" and prev != "RUNNING" and root_start is None:
                root_start = t_s
            if new == "RUNNING":
                outcome, root_end = "running", None
            elif new in _TERMINAL:
                outcome, root_end = new, t_s
        if name in goal_names:
            if new == "RUNNING" and name not in open_goals:
                open_goals[name] = t_s
            elif new in _TERMINAL and name in open_goals:
                goals.append(GoalResult(name=name, start_s=open_goals.pop(name), end_s=t_s, result=new))
        # a recovery starts (RUNNING), or runs whole within one tick (a costmap clearing: IDLE to SUCCESS)
        starts = (new == "RUNNING" and prev != "RUNNING") or (prev == "IDLE" and new in _TERMINAL)
        if starts and _RECOVERY_NODE.match(name):
            recoveries.append((t_s, name))
    goals.extend(GoalResult(name=n, start_s=t, end_s=None, result="running") for n, t in open_goals.items())
    goals.sort(key=lambda g: g.start_s)
    return MissionTimeline(
        root=root,
        outcome=outcome,
        start_s=events[0][0] if root_start is None else root_start,
        end_s=root_end,
        goals=tuple(goals),
        recoveries=tuple(recoveries),
    )


@dataclass(frozen=True, kw_only=True, slots=True)
class RunMetrics:
    """The metrics of one run (None where the bag lacks what a metric needs; `notes` says what)."""

    bag: str
    outcome: str  # SUCCESS, FAILURE, running (the bag ended first) or unknown (no behaviour-tree log)
    goals: tuple[GoalResult, ...]
    goals_succeeded: int | None  # None: the bag has no behaviour-tree log to tell (not zero)
    recoveries: int | None
    duration_s: float  # the bag: first to last message
    mission_duration_s: float | None  # the tree's root: start to end (to the bag's end while running)
    pose_source: str | None  # the topic path and speed come from
    path_length_m: float | None
    mean_speed_mps: float | None  # path length over the time moving (span minus time stopped)
    max_speed_mps: float | None
    rms_jerk_mps3: float | None  # of the pose source's forward speed, on its header stamps
    time_stopped_s: float | None
    contacts: int | None
    localization_source: str | None
    localization_reference: str | None
    localization_error_median_m: float | None
    localization_error_p95_m: float | None
    localization_error_max_m: float | None
    min_lidar_range_m: float | None
    min_lidar_range_t_s: float | None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The metrics as plain JSON-ready values (goals as objects with their duration)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "goals":
                value = [{**dataclasses.asdict(g), "duration_s": g.duration_s} for g in value]
            elif isinstance(value, tuple):
                value = list(value)
            elif isinstance(value, float) and not math.isfinite(value):
                value = None
            out[f.name] = value
        return out


def path_length(xy: F64) -> float:
    """Length of a polyline of shape (N, 2), m."""
    if len(xy) < 2:
        return 0.0
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())


def localization_error(estimate: PoseTrack, reference: PoseTrack) -> tuple[F64, F64, F64]:
    """Position and yaw error of `estimate` against `reference`, interpolated at the estimate's stamps.

    Returns:
        (t s of the estimate's record times, position error m, |yaw error| rad), only where the
        reference covers the estimate's stamp.
    """
    ref_t = reference.stamp_ns.astype(np.float64)
    est_t = estimate.stamp_ns.astype(np.float64)
    if len(ref_t) < 2 or not len(est_t):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    order = np.argsort(ref_t, kind="stable")
    ref_t = ref_t[order]
    ref = reference.values[order]
    inside = (est_t >= ref_t[0]) & (est_t <= ref_t[-1])
    est = estimate.values[inside]
    t = est_t[inside]
    rx = np.interp(t, ref_t, ref[:, 0])
    ry = np.interp(t, ref_t, ref[:, 1])
    ryaw = np.interp(t, ref_t, np.unwrap(ref[:, 2]))
    pos = np.hypot(est[:, 0] - rx, est[:, 1] - ry)
    yaw = np.abs(np.remainder(est[:, 2] - ryaw + math.pi, 2 * math.pi) - math.pi)
    return estimate.t_ns[inside].astype(np.float64), pos, yaw


def bag_timeline(data: BagData) -> MissionTimeline | None:
    """The mission's timeline in a bag: its own tree, with Nav2's recoveries.

    A twin bag run through Nav2 holds the mission's tree on `/mission/behavior_tree_log` and
    bt_navigator's on `/behavior_tree_log`: the goals and the outcome come from the first, the
    recoveries (Spin, BackUp, Wait, clearing costmaps) from both. A bag with `/behavior_tree_log`
    only (a real Nav2 run, or a twin run without Nav2) is read from that alone.
    """
    if not data.mission_events:
        return mission_timeline(data.bt_events)
    timeline = mission_timeline(data.mission_events)
    navigator = mission_timeline(data.bt_events)
    if timeline is None or navigator is None:
        return timeline
    recoveries = tuple(sorted(timeline.recoveries + navigator.recoveries))
    return dataclasses.replace(timeline, recoveries=recoveries)


def compute_metrics(data: BagData) -> RunMetrics:
    """The metrics of what `collect` kept of a bag."""
    notes: list[str] = []
    timeline = bag_timeline(data)
    duration_s = data.info.duration_ns * 1e-9
    if timeline is None:
        notes.append("outcome and goals need /behavior_tree_log")
        outcome, mission_s = "unknown", None
        recoveries: int | None = None
        goals: tuple[GoalResult, ...] = ()
    else:
        outcome, goals, recoveries = timeline.outcome, timeline.goals, len(timeline.recoveries)
        end = timeline.end_s if timeline.end_s is not None else duration_s
        mission_s = end - timeline.start_s

    motion_topics = ("/ground_truth/odom", "/odom")
    track = next((data.poses[t] for t in motion_topics if t in data.poses and len(data.poses[t])), None)
    if track is None:
        track = best_pose(data)
    path = mean_v = max_v = jerk = stopped = None
    if track is None:
        notes.append("path and speed need /ground_truth/odom, /odom or /amcl_pose")
    else:
        # Header stamps, where the messages carry them: a driver's records may bunch up (a real robot's
        # /odom written twice within a millisecond) while its stamps stay on its own clock.
        order = np.argsort(track.stamp_ns, kind="stable")
        vals = track.values[order]
        t = track.stamp_ns[order].astype(np.float64) * 1e-9
        path = path_length(vals[:, :2])
        span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
        moving = span
        v, w = vals[:, 3], vals[:, 4]
        if not np.all(np.isnan(v)):
            max_v = float(np.nanmax(np.abs(v)))
            jerk = _rms_jerk(t, v)
            still = (np.abs(v) < STOPPED_SPEED_MPS) & (np.abs(np.nan_to_num(w)) < STOPPED_YAW_RATE_RADPS)
            stopped = float(np.sum(np.diff(t)[still[:-1]])) if len(t) > 1 else 0.0
            moving = span - stopped
        mean_v = path / moving if moving > 0 else None
        if np.all(np.isnan(v)):
            notes.append(f"speed needs an Odometry pose source; {track.topic} carries no twist")

    contacts = None
    if data.contacts is None:
        notes.append("contacts need /contacts")
    else:
        contacts = sum(1 for c in data.contacts if c.begin)

    loc_src = loc_ref = med = p95 = mx = None
    reference = data.poses.get("/ground_truth/odom")
    estimate = next((data.poses[t] for t in ("/amcl_pose", "/odom") if t in data.poses and len(data.poses[t])), None)
    if reference is None or not len(reference) or estimate is None:
        notes.append("localization error needs /ground_truth/odom and /amcl_pose or /odom")
    else:
        _t, err, _yaw = localization_error(estimate, reference)
        if len(err):
            loc_src, loc_ref = estimate.topic, reference.topic
            med, p95, mx = (float(v) for v in (np.median(err), np.percentile(err, 95), err.max()))

    min_r = min_t = None
    if data.scan_min is None:
        notes.append(clearance_needs(data.scan_choices))
    else:
        if data.scan_topic != SCAN_TOPIC:
            notes.append(f"clearance from {data.scan_topic} (the bag has no /scan)")
        ranges = np.frombuffer(data.scan_min[1], dtype=np.float64)
        if len(ranges) and not np.all(np.isnan(ranges)):
            i = int(np.nanargmin(ranges))
            min_r, min_t = float(ranges[i]), float(data.scan_min[0][i])

    return RunMetrics(
        bag=str(data.info.path),
        outcome=outcome,
        goals=tuple(goals),
        goals_succeeded=None if timeline is None else sum(1 for g in goals if g.result == "SUCCESS"),
        recoveries=recoveries,
        duration_s=duration_s,
        mission_duration_s=mission_s,
        pose_source=None if track is None else track.topic,
        path_length_m=path,
        mean_speed_mps=mean_v,
        max_speed_mps=max_v,
        rms_jerk_mps3=jerk,
        time_stopped_s=stopped,
        contacts=contacts,
        localization_source=loc_src,
        localization_reference=loc_ref,
        localization_error_median_m=med,
        localization_error_p95_m=p95,
        localization_error_max_m=mx,
        min_lidar_range_m=min_r,
        min_lidar_range_t_s=min_t,
        notes=tuple(notes),
    )


def _rms_jerk(t: F64, v: F64) -> float | None:
    """RMS of d²v/dt² by finite differences over the samples (a noisy estimate; compare like with like)."""
    ok = ~np.isnan(v)
    t, v = t[ok], v[ok]
    if len(t) < 4:
        return None
    dt = np.diff(t)
    good = dt > 0
    if not good.all():
        t, v = t[np.r_[True, good]], v[np.r_[True, good]]
        dt = np.diff(t)
    a = np.diff(v) / dt
    ta = 0.5 * (t[1:] + t[:-1])
    dta = np.diff(ta)
    if not len(dta) or np.any(dta <= 0):
        return None
    j = np.diff(a) / dta
    return float(math.sqrt(float(np.mean(j * j))))


def run_metrics(bag_path: Path, *, namespace: str | None = None) -> RunMetrics:
    """Read the bag at `bag_path` once and return its metrics (one robot's of a fleet's bag with `namespace`).

    Raises:
        BagError: If it is not a readable bag (a truncated one: run `twin bag recover`).
    """
    return compute_metrics(metric_data(bag_path, namespace=namespace))


def metric_data(bag_path: Path, *, namespace: str | None = None) -> BagData:
    """What `run_metrics` reads of the bag: the topics its metrics need (one robot's with `namespace`).

    Raises:
        BagError: If it is not a readable bag.
    """
    return collect(bag_path, topics=_METRIC_TOPICS, health=False, namespace=namespace)


def clearance_needs(choices: tuple[str, ...]) -> str:
    """What clearance needs that the bag lacks: /scan, or one LaserScan topic chosen among several."""
    if len(choices) > 1:
        return f"clearance needs /scan or --scan-topic: the bag has several LaserScan topics ({', '.join(choices)})"
    return "clearance needs /scan (or a bag's only LaserScan topic)"
