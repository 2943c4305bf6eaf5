"""A fleet's bag: one report per robot (found by namespace) and the distance between the robots over time.

A bag of several robots (nav2_bringup's multi-robot naming: `/robot1/odom`, `/robot2/scan`, one
`/clock`) is read once per robot, each pass reading that robot's topics as a one-robot bag's
(`collect(namespace=...)`), so every robot gets the metrics, mission and plots a one-robot report
has. The robots' positions then give the smallest distance between any two of them over time:
from the simulator's ground truth when every robot has it, else from AMCL's estimates, which all
robots give in the one map frame (their odometry is each in its own odom frame, so it cannot).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin import __version__
from twin.analysis import plots
from twin.analysis.collect import ContactEvent, PoseTrack, collect, robot_namespaces
from twin.analysis.metrics import RunMetrics, compute_metrics, metric_data
from twin.analysis.report import Report, bag_line, bag_summary, build_report, markdown_html, robot_markdown
from twin.bag import BagInfo, open_bag
from twin.bag.raw import require_readable
from twin.core.errors import ConfigError

__all__ = [
    "FleetReport",
    "RobotDistance",
    "analyze_fleet",
    "bag_robots",
    "check_namespace",
    "fleet_metrics",
    "fleet_summary_lines",
    "pair_contacts",
    "robot_distance",
    "write_fleet_report",
]

F64 = NDArray[np.float64]

#: The position sources for the distance between robots, in order of trust: (topic, what it is).
_DISTANCE_SOURCES = (
    ("/ground_truth/odom", "ground truth"),
    ("/amcl_pose", "AMCL estimates in the map frame"),
)


def bag_robots(path: str | os.PathLike[str]) -> tuple[BagInfo, list[str]]:
    """The bag's metadata and its robots' namespaces (empty for a one-robot bag).

    Raises:
        BagError: If it is not a readable bag (a truncated one: run `twin bag recover`).
    """
    bag = Path(path)
    require_readable(bag)  # as `collect` does: a truncated file is one error line
    info = open_bag(bag)
    return info, robot_namespaces(info)


def check_namespace(info: BagInfo, namespace: str, *, flag: str = "--namespace") -> str:
    """The namespace without slashes, if the bag holds a robot under it.

    Raises:
        ConfigError: If it does not, naming the robots the bag has.
    """
    ns = namespace.strip("/")
    have = robot_namespaces(info)
    if ns not in have:
        robots = ", ".join(have) if have else "no namespaced robot (a one-robot bag: leave it out)"
        msg = f"{info.path}: {flag} {namespace!r} is not a robot of this bag; it has {robots}"
        raise ConfigError(msg)
    return ns


def _plot_prefix(ns: str) -> str:
    return ns.replace("/", "_") + "_"


@dataclass(frozen=True, kw_only=True, slots=True)
class RobotDistance:
    """The distance between the robots of a fleet over time, from one kind of position."""

    source: str  # what the positions are: "ground truth" or AMCL's estimates
    topics: tuple[str, ...]  # the bag's topics they come from
    t_s: F64  # s from the bag's start (the positions' header stamps)
    pairs: dict[tuple[str, str], F64]  # (robot, robot) -> distance between them at t_s, m

    @property
    def distance_m(self) -> F64:
        """The smallest distance between any two robots at each time, m."""
        out: F64 = np.min(np.stack(list(self.pairs.values())), axis=0)
        return out

    def pair_minimum(self, pair: tuple[str, str]) -> tuple[float, float]:
        """(smallest distance m, time s) of one pair."""
        d = self.pairs[pair]
        i = int(np.argmin(d))
        return float(d[i]), float(self.t_s[i])

    def minimum(self) -> tuple[float, float, tuple[str, str]]:
        """(smallest distance m, time s, the pair) over every pair and time."""
        pair = min(self.pairs, key=lambda p: self.pair_minimum(p)[0])
        d, t = self.pair_minimum(pair)
        return d, t, pair

    def to_dict(self) -> dict[str, Any]:
        """The minimum, each pair's, and a 1 s series of the smallest distance (JSON-ready)."""
        d, t, pair = self.minimum()
        overall = self.distance_m
        marks = np.arange(float(self.t_s[0]), float(self.t_s[-1]) + 1e-9, 1.0)
        return {
            "source": self.source,
            "topics": list(self.topics),
            "samples": len(self.t_s),
            "min_m": d,
            "min_t_s": t,
            "min_pair": list(pair),
            "pairs": [
                {"robots": list(p), "min_m": self.pair_minimum(p)[0], "min_t_s": self.pair_minimum(p)[1]}
                for p in self.pairs
            ],
            "each_s": [{"t_s": float(m), "min_m": float(np.interp(m, self.t_s, overall))} for m in marks],
        }


def robot_distance(tracks: Mapping[str, PoseTrack], start_ns: int, source: str = "") -> RobotDistance | None:
    """The distance between every two robots, at every stamp of any robot's track where all have poses.

    Each robot's position is interpolated linearly on its header stamps at the union of the
    stamps; only the span every track covers counts.

    Args:
        tracks: Each robot's positions (one frame for all), by namespace; two or more.
        start_ns: The bag's start: times are given from it.
        source: What the positions are, for the report.

    Returns:
        None if there are fewer than two robots with two poses each, or their spans do not overlap.
    """
    usable = {ns: tr for ns, tr in tracks.items() if len(tr) >= 2}
    if len(usable) < 2 or len(usable) != len(tracks):
        return None
    ordered: dict[str, tuple[NDArray[np.int64], F64]] = {}
    for ns, tr in usable.items():
        order = np.argsort(tr.stamp_ns, kind="stable")
        ordered[ns] = (tr.stamp_ns[order], tr.values[order, :2])
    lo = max(int(st[0]) for st, _ in ordered.values())
    hi = min(int(st[-1]) for st, _ in ordered.values())
    stamps = np.unique(np.concatenate([st for st, _ in ordered.values()]))
    stamps = stamps[(stamps >= lo) & (stamps <= hi)]
    if not len(stamps):
        return None
    at = stamps.astype(np.float64)
    xy = {
        ns: np.stack((np.interp(at, st.astype(np.float64), v[:, 0]), np.interp(at, st.astype(np.float64), v[:, 1])), 1)
        for ns, (st, v) in ordered.items()
    }
    pairs = {(a, b): np.hypot(*(xy[a] - xy[b]).T) for a, b in itertools.combinations(sorted(xy), 2)}
    return RobotDistance(
        source=source,
        topics=tuple(usable[ns].topic for ns in sorted(usable)),
        t_s=(stamps - start_ns).astype(np.float64) * 1e-9,
        pairs=pairs,
    )


#: How far apart two robots' reports of one touch may lie when their episodes do not overlap, s: each
#: robot finds the touch at a step of its own drive (a Burger and a Waffle head on: 4.725 and 4.730 s).
_SAME_TOUCH_S = 0.1


def _names_robot(event: ContactEvent, ns: str) -> bool:
    """Whether a contact's other party is robot `ns` (the twin names it `<namespace>::<model>::<link>`)."""
    return event.what.split("::", 1)[0].strip("/") == ns


def _episodes(events: Iterable[ContactEvent], other: str) -> list[tuple[float, float]]:
    """A robot's contact episodes with robot `other`: (begin s, end s), the end inf while it lasts."""
    out: list[tuple[float, float]] = []
    open_at: list[int] = []  # indices into out, oldest first
    for e in events:
        if not _names_robot(e, other):
            continue
        if e.begin:
            open_at.append(len(out))
            out.append((e.t_s, math.inf))
        elif open_at:
            k = open_at.pop(0)
            out[k] = (out[k][0], e.t_s)
    return out


def _touches(own: list[tuple[float, float]], theirs: list[tuple[float, float]]) -> int:
    """A robot's touches with another: its own episodes, and the other's that meet none of them.

    Two episodes meet when they overlap or lie within `_SAME_TOUCH_S` of each other.
    """
    near = _SAME_TOUCH_S
    alone = [(b0, b1) for b0, b1 in theirs if not any(a0 <= b1 + near and b0 <= a1 + near for a0, a1 in own)]
    return len(own) + len(alone)


def robot_contacts(contacts: Mapping[str, list[ContactEvent] | None]) -> dict[str, dict[str, int]]:
    """Contacts between robots: for each robot, how many contacts it had with each other robot.

    A robot's contacts with another are its own contact episodes naming that robot (BEGIN to END on
    its `/<ns>/contacts`), and the other robot's episodes naming it that none of its own meets: a
    touch both report, each at a step of its own drive some ms apart, counts once; one only the
    other reports (a robot standing still does not report being driven into) counts too. So a
    robot that reports its touches has no more contacts with robots than contacts, and a robot
    whose one episode spans two of the other's (it stayed blocked while the other backed off and
    came again) counts one where the other counts two.

    Args:
        contacts: Each robot's own contact events, in time order (None: it has no contacts topic).
    """
    out: dict[str, dict[str, int]] = {ns: {} for ns in contacts}
    for a, b in itertools.permutations(contacts, 2):
        n = _touches(_episodes(contacts[a] or (), b), _episodes(contacts[b] or (), a))
        if n:
            out[a][b] = n
    return out


def pair_contacts(with_robots: Mapping[str, Mapping[str, int]]) -> int:
    """The touches between robots, each once: for every pair, as many as the robot counting more counts.

    Args:
        with_robots: Each robot's contacts with each other robot, as `robot_contacts` gives them.
    """
    return sum(
        max(with_robots[a].get(b, 0), with_robots[b].get(a, 0)) for a, b in itertools.combinations(with_robots, 2)
    )


def fleet_metrics(path: str | os.PathLike[str]) -> dict[str, tuple[RunMetrics, dict[str, int]]]:
    """Each robot's run metrics and its contacts with each other robot, by namespace ({} for a one-robot bag).

    The metrics are those `run_metrics` gives a one-robot bag, each from the robot's own topics;
    the contacts with other robots are counted as `robot_contacts` counts them.

    Raises:
        BagError: If it is not a readable bag.
    """
    bag = Path(path)
    namespaces = robot_namespaces(open_bag(bag))
    metrics: dict[str, RunMetrics] = {}
    contacts: dict[str, list[ContactEvent] | None] = {}
    for ns in namespaces:
        data = metric_data(bag, namespace=ns)
        metrics[ns] = compute_metrics(data)
        contacts[ns] = data.contacts
    with_robots = robot_contacts(contacts)
    return {ns: (metrics[ns], with_robots[ns]) for ns in namespaces}


@dataclass(kw_only=True, slots=True)
class FleetReport:
    """Everything `twin analyze` computes for a fleet's bag."""

    bag: Path
    summary: dict[str, Any]
    robots: dict[str, Report]  # by namespace
    robot_contacts: dict[str, dict[str, int]]
    distance: RobotDistance | None
    distance_needs: str = ""
    pngs: dict[str, bytes] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready values (plots by file name)."""
        return {
            "twin_version": __version__,
            "bag": str(self.bag),
            "summary": self.summary,
            "namespaces": list(self.robots),
            "inter_robot_distance": None if self.distance is None else self.distance.to_dict(),
            "inter_robot_distance_needs": self.distance_needs or None,
            "robot_contacts": self.robot_contacts,
            "robots": {ns: r.to_dict() for ns, r in self.robots.items()},
        }


def analyze_fleet(
    path: str | os.PathLike[str],
    *,
    walls: F64 | None = None,
    world_name: str = "",
    plots_enabled: bool = True,
    progress: Callable[[float], None] | None = None,
) -> FleetReport:
    """Read a fleet's bag once per robot and compute each robot's report and the distance between them.

    Args:
        path: The bag folder.
        walls: The world's wall segments for the maps (see `twin.analysis.report.analyze`).
        world_name: Named on the maps when `walls` are given.
        plots_enabled: Render the PNGs.
        progress: Called with the fraction of the work done.

    Raises:
        BagError: If it is not a readable bag.
        ConfigError: If it holds no namespaced robot.
    """
    bag = Path(path)
    info = open_bag(bag)
    namespaces = robot_namespaces(info)
    if not namespaces:
        msg = f"{bag}: no robot under a namespace (no /<ns>/odom or /<ns>/ground_truth/odom); analyze it as one robot"
        raise ConfigError(msg)
    robots: dict[str, Report] = {}
    contacts: dict[str, list[ContactEvent] | None] = {}
    positions: dict[str, dict[str, PoseTrack]] = {topic: {} for topic, _ in _DISTANCE_SOURCES}
    for k, ns in enumerate(namespaces):
        step = None if progress is None else _part(progress, k, len(namespaces))
        data = collect(bag, scan_points=walls is None, progress=step, series=True, namespace=ns)
        robot = build_report(bag, data, walls=walls, world_name=world_name, plots_enabled=plots_enabled, namespace=ns)
        robots[ns] = _prefixed(robot, _plot_prefix(ns))
        contacts[ns] = data.contacts
        for topic, _ in _DISTANCE_SOURCES:
            track = data.poses.get(topic)
            if track is not None and len(track):
                positions[topic][ns] = track
    summary = bag_summary(info)
    distance = None
    needs = ""
    if len(namespaces) < 2:
        needs = "two robots or more"
    else:
        for topic, source in _DISTANCE_SOURCES:
            if len(positions[topic]) == len(namespaces):
                distance = robot_distance(positions[topic], info.start_ns, source)
                if distance is not None:
                    break
        if distance is None:
            needs = (
                "every robot's /<ns>/ground_truth/odom or /<ns>/amcl_pose, over a common span "
                "(odometry is each robot's own odom frame)"
            )
    report = FleetReport(
        bag=bag,
        summary=summary,
        robots=robots,
        robot_contacts=robot_contacts(contacts),
        distance=distance,
        distance_needs=needs,
    )
    if distance is not None and plots_enabled:
        labels = {f"{a} – {b}": v for (a, b), v in distance.pairs.items()}
        report.pngs["inter_robot_distance.png"] = plots.distance_plot(
            distance.t_s, labels, f"{bag.name}: distance between robots ({distance.source})", "distance (m)"
        )
    return report


def _part(progress: Callable[[float], None], k: int, n: int) -> Callable[[float], None]:
    return lambda f: progress((k + f) / n)


def _prefixed(report: Report, prefix: str) -> Report:
    """The report with its plots' files named for its robot (`robot1_map.png`)."""
    report.pngs = {prefix + name: png for name, png in report.pngs.items()}
    report.sections = [
        dataclasses.replace(s, plot=None if s.plot is None else prefix + s.plot) for s in report.sections
    ]
    return report


def _fmt(value: Any, unit: str = "", digits: int = 3) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}f}{' ' + unit if unit else ''}"
    return f"{value}{' ' + unit if unit else ''}"


def _distance_line(report: FleetReport) -> str:
    dist = report.distance
    if dist is None:
        return f"Inter-robot distance: not computed, needs {report.distance_needs}."
    d, t, (a, b) = dist.minimum()
    return (
        f"Inter-robot minimum distance {d:.3f} m at {t:.2f} s ({a} – {b}), from {dist.source} "
        f"({', '.join(dist.topics)}), {len(dist.t_s)} samples."
    )


def _contacts_with(report: FleetReport, ns: str) -> str:
    hits = report.robot_contacts.get(ns, {})
    return ", ".join(f"{other} ×{n}" for other, n in sorted(hits.items())) or "none"


def fleet_summary_lines(report: FleetReport) -> list[str]:
    """The terminal summary: one line per robot, then the distance between them."""
    s = report.summary
    lines = [
        f"{report.bag}: {s['storage']}, {s['duration_s']:.1f} s, {s['messages']} messages on {s['topics']} topics, "
        f"{len(report.robots)} robots: {', '.join(report.robots)}",
    ]
    for ns, r in report.robots.items():
        m = r.metrics
        goals = "n/a" if m.goals_succeeded is None else f"{m.goals_succeeded}/{len(m.goals)}"
        lines.append(
            f"  /{ns}: {m.outcome}, goals {goals}, path {_fmt(m.path_length_m, 'm')}, "
            f"mean speed {_fmt(m.mean_speed_mps, 'm/s')}, contacts {_fmt(m.contacts)} "
            f"(with robots: {_contacts_with(report, ns)}), "
            f"loc. error median {_fmt(m.localization_error_median_m, 'm', 4)}"
        )
        for note in m.notes:
            lines.append(f"    note: {note}")
    lines.append("  " + _distance_line(report))
    return lines


def _markdown(report: FleetReport) -> str:
    out = [
        f"# Fleet bag report: {report.bag.name}",
        "",
        bag_line(next(iter(report.robots.values()))),
        "",
        f"Robots, by namespace: {', '.join('/' + ns for ns in report.robots)}. Each robot's section reads its own "
        "topics; the bag's topics outside every namespace (`/clock`, `/rosout`) are in each.",
        "",
        "## Robots",
        "",
        "| robot | outcome | goals succeeded | path length (m) | mean speed (m/s) | max speed (m/s) | contacts "
        "| contacts with robots | loc. error median (m) | min lidar range (m) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for ns, r in report.robots.items():
        m = r.metrics
        goals = "n/a" if m.goals_succeeded is None else f"{m.goals_succeeded} of {len(m.goals)}"
        out.append(
            f"| /{ns} | {m.outcome} | {goals} | {_fmt(m.path_length_m)} | {_fmt(m.mean_speed_mps)} | "
            f"{_fmt(m.max_speed_mps)} | {_fmt(m.contacts)} | {_contacts_with(report, ns)} | "
            f"{_fmt(m.localization_error_median_m, '', 4)} | {_fmt(m.min_lidar_range_m)} |"
        )
    out += ["", "## Inter-robot distance", "", _distance_line(report), ""]
    if report.distance is not None:
        out += ["| robots | min distance (m) | at (s) |", "|---|---|---|"]
        for a, b in report.distance.pairs:
            d, t = report.distance.pair_minimum((a, b))
            out.append(f"| {a} – {b} | {d:.3f} | {t:.2f} |")
        out.append("")
        if "inter_robot_distance.png" in report.pngs:
            out += ["![inter_robot_distance](inter_robot_distance.png)", ""]
    for ns, r in report.robots.items():
        out += [f"## Robot /{ns}", "", *robot_markdown(r, 3), ""]
    out += [f"_Written by twin {__version__} `twin analyze`._", ""]
    return "\n".join(out)


def write_fleet_report(report: FleetReport, out_dir: Path) -> list[Path]:
    """Write report.json, report.md, report.html and every PNG into `out_dir`; return the files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    pngs = dict(report.pngs)
    for r in report.robots.values():
        pngs.update(r.pngs)
    written = []
    for name, png in pngs.items():
        (out_dir / name).write_bytes(png)
        written.append(out_dir / name)
    md = _markdown(report)
    (out_dir / "report.json").write_text(json.dumps(report.to_dict(), indent=2) + "\n")
    (out_dir / "report.md").write_text(md)
    (out_dir / "report.html").write_text(markdown_html(md, pngs, f"Fleet bag report: {report.bag.name}"))
    written += [out_dir / "report.json", out_dir / "report.md", out_dir / "report.html"]
    return written
