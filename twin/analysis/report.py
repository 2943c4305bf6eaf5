"""`twin analyze`: a bag's report as JSON, Markdown, one self-contained HTML page and PNG plots.

`analyze(bag)` reads the bag once (streaming) and computes everything; `write_report(report, out)`
writes the files. A section whose topics the bag lacks says what it would need; the rest runs.
"""

from __future__ import annotations

import base64
import datetime as dt
import functools
import html
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin import __version__
from twin.analysis import plots
from twin.analysis.collect import POSE_TOPICS, BagData, collect, scan_points
from twin.analysis.metrics import RunMetrics, bag_timeline, compute_metrics, localization_error
from twin.bag import BagInfo

__all__ = ["Report", "analyze", "world_walls", "write_report"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True, slots=True)
class Section:
    """One part of the report: present, or what it would need."""

    name: str
    available: bool
    needs: str = ""
    plot: str | None = None  # file name of its PNG


@dataclass(kw_only=True, slots=True)
class Report:
    """Everything `twin analyze` computes for one bag."""

    bag: Path
    summary: dict[str, Any]
    metrics: RunMetrics
    timeline: dict[str, Any] | None
    health: list[dict[str, Any]]
    sections: list[Section]
    pngs: dict[str, bytes] = field(default_factory=dict)
    namespace: str | None = None  # the robot of a fleet's bag this report is about (None: the bag's one robot)

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready values (plots by file name)."""
        robot = {} if self.namespace is None else {"namespace": self.namespace}
        return {
            "twin_version": __version__,
            "bag": str(self.bag),
            **robot,
            "summary": self.summary,
            "metrics": self.metrics.to_dict(),
            "mission": self.timeline,
            "topic_health": self.health,
            "sections": [
                {"name": s.name, "available": s.available, "needs": s.needs or None, "plot": s.plot}
                for s in self.sections
            ],
        }


def world_walls(sdf: Path, model_path: Sequence[Path] = (), height_m: float = 0.17) -> F64:
    """The walls of an SDF world cut at `height_m` (a TB3 lidar's height), shape (M, 4): x0, y0, x1, y1.

    Robots in the world (models named `turtlebot3_*` other than the world models) are left out.

    Raises:
        WorldError: If the world does not load.
    """
    from twin.world import build_scene, load_world

    world = load_world(sdf, model_path=tuple(model_path))
    robots = [
        m.name
        for m in world.models
        if m.name.startswith("turtlebot3_") and not m.name.endswith(("_world", "_house")) and "dqn" not in m.name
    ]
    scene = build_scene(world, exclude_models=robots)
    caster = scene.ray_caster(height_m)
    segments = np.asarray(caster.segments, dtype=np.float64).reshape(-1, 4)
    circles = np.asarray(caster.circles, dtype=np.float64).reshape(-1, 3)
    if len(circles):  # round obstacles (cylinders) as 24-gons
        ang = np.linspace(0.0, 2.0 * math.pi, 25)
        cx, cy, r = circles[:, :1], circles[:, 1:2], circles[:, 2:3]
        px, py = cx + r * np.cos(ang), cy + r * np.sin(ang)
        polys = np.stack((px[:, :-1], py[:, :-1], px[:, 1:], py[:, 1:]), axis=2).reshape(-1, 4)
        segments = np.concatenate((segments, polys))
    return segments


def analyze(
    path: str | os.PathLike[str],
    *,
    walls: F64 | None = None,
    world_name: str = "",
    plots_enabled: bool = True,
    progress: Callable[[float], None] | None = None,
    namespace: str | None = None,
    scan_topic: str | None = None,
) -> Report:
    """Read the bag and compute its report (metrics, mission timeline, topic health, plots).

    Args:
        path: The bag folder.
        walls: The world's wall segments (from `world_walls`) for the map; None uses the bag's
            /map, else the scan endpoints.
        world_name: Named on the map when `walls` are given.
        plots_enabled: Render the PNGs (the slow part on long bags).
        progress: Called with the fraction of the bag read.
        namespace: Report on this robot of a fleet's bag (its topics under `/<namespace>/`).
        scan_topic: The LaserScan topic clearance comes from (None: `/scan`, else the bag's only one).

    Raises:
        BagError: If it is not a readable bag.
        ConfigError: If `scan_topic` is not a LaserScan topic of the bag.
    """
    bag = Path(path)
    data = collect(
        bag, scan_points=walls is None, progress=progress, series=True, namespace=namespace, scan_topic=scan_topic
    )
    return build_report(bag, data, walls=walls, world_name=world_name, plots_enabled=plots_enabled, namespace=namespace)


def bag_summary(info: BagInfo) -> dict[str, Any]:
    """The report's `bag` entry: storage, metadata version, distro, start, duration, counts and size."""
    return {
        "storage": info.storage,
        "metadata_version": info.version,
        "ros_distro": info.ros_distro or None,
        "start_utc": dt.datetime.fromtimestamp(info.start_ns / 1e9, tz=dt.UTC).isoformat(),
        "duration_s": info.duration_ns * 1e-9,
        "messages": info.message_count,
        "topics": len(info.topics),
        "size_bytes": info.size_bytes,
    }


def build_report(
    bag: Path,
    data: BagData,
    *,
    walls: F64 | None = None,
    world_name: str = "",
    plots_enabled: bool = True,
    namespace: str | None = None,
) -> Report:
    """The report of what `collect` kept of `bag` (see `analyze`; `namespace` as `data` was read)."""
    metrics = compute_metrics(data)
    info = data.info
    timeline = bag_timeline(data)
    summary = bag_summary(info)
    health = [h.to_dict() for h in sorted(data.health.values(), key=lambda h: h.topic)]
    report = Report(
        bag=bag,
        summary=summary,
        metrics=metrics,
        timeline=None if timeline is None else _timeline_dict(timeline),
        health=health,
        sections=[],
        namespace=namespace.strip("/") if namespace else None,
    )
    _sections(report, data, walls, world_name, plots_enabled)
    return report


def _timeline_dict(tl: Any) -> dict[str, Any]:
    return {
        "root": tl.root,
        "outcome": tl.outcome,
        "start_s": tl.start_s,
        "end_s": tl.end_s,
        "goals": [
            {"name": g.name, "start_s": g.start_s, "end_s": g.end_s, "duration_s": g.duration_s, "result": g.result}
            for g in tl.goals
        ],
        "recoveries": [{"t_s": t, "name": n} for t, n in tl.recoveries],
    }


_POSE_TYPES = "Odometry, PoseStamped or PoseWithCovarianceStamped"


def _sections(report: Report, data: BagData, walls: F64 | None, world_name: str, render: bool) -> None:
    title = report.bag.name if report.namespace is None else f"{report.bag.name} /{report.namespace}"
    add = report.sections.append
    tracks = {t: track.values[:, :2] for t, track in data.poses.items() if len(track)}

    # Map.
    if walls is not None:
        background = f"walls of {world_name or 'the world'}"
        layers = plots.MapLayers(walls=walls, background=background)
    elif data.occupancy is not None:
        layers = plots.MapLayers(occupancy=data.occupancy, background="/map")
    elif data.scan_cells:
        layers = plots.MapLayers(
            scan_points=scan_points(data), background=f"{data.scan_topic} endpoints, placed on the best pose"
        )
    else:
        layers = plots.MapLayers(background="")
    layers.tracks = tracks
    layers.plans = [p for _, p in data.plans]
    goals = [(x, y) for _, x, y, _ in data.goals] or [(p[-1, 0], p[-1, 1]) for _, p in data.plans if len(p)]
    layers.goals = np.array(goals, dtype=np.float64).reshape(-1, 2) if goals else None
    if data.contacts:
        layers.contacts = np.array([(c.x_m, c.y_m) for c in data.contacts if c.begin], dtype=np.float64).reshape(-1, 2)
    if tracks:
        _plot(report, "map", render, lambda: plots.map_plot(layers, title))
    else:
        add(
            Section(
                name="map",
                available=False,
                needs=f"a pose topic ({_POSE_TYPES}): " + ", ".join(POSE_TOPICS),
            )
        )

    # Velocity: commanded vs actual.
    # the first Odometry track (most trusted first): the one pose type that carries velocities
    motion = next((tr for tr in data.poses.values() if len(tr) and tr.msgtype == "nav_msgs/msg/Odometry"), None)
    cmd = None
    if data.cmd is not None and len(data.cmd[0]):
        cmd = tuple(np.frombuffer(a, dtype=np.float64) for a in data.cmd)
    actual = None
    if motion is not None:
        vals = motion.values
        actual = (data_t_s(data, motion.t_ns), vals[:, 3], vals[:, 4])
    if cmd is None and actual is None:
        add(Section(name="velocity", available=False, needs="/cmd_vel and an Odometry topic (/odom)"))
    else:
        label = motion.topic if motion is not None else ""
        _plot(report, "velocity", render, lambda: plots.velocity_plot(cmd, actual, label, title))  # type: ignore[arg-type]

    # Localization error.
    reference = data.poses.get("/ground_truth/odom")
    estimate = next((data.poses[t] for t in ("/amcl_pose", "/odom") if t in data.poses and len(data.poses[t])), None)
    if reference is not None and len(reference) and estimate is not None:
        t_ns, pos, yaw = localization_error(estimate, reference)
        t_s = (t_ns - data.start_ns) * 1e-9
        ttl = f"{title}: {estimate.topic} vs {reference.topic}"
        _plot(report, "localization", render, lambda: plots.localization_plot(t_s, pos, yaw, ttl))
    else:
        add(
            Section(
                name="localization",
                available=False,
                needs="/ground_truth/odom (the truth) and /amcl_pose or /odom (the estimate)",
            )
        )

    # Clearance.
    if data.scan_min is not None and len(data.scan_min[0]):
        t = np.frombuffer(data.scan_min[0], dtype=np.float64)
        r = np.frombuffer(data.scan_min[1], dtype=np.float64)
        _plot(report, "clearance", render, lambda: plots.clearance_plot(t, r, f"{title}: minimum lidar range"))
    else:
        several = data.scan_choices if len(data.scan_choices) > 1 else ()
        needs = (
            f"/scan, or --scan-topic (one of {', '.join(several)})"
            if several
            else "/scan, or the bag's only LaserScan topic"
        )
        add(Section(name="clearance", available=False, needs=needs))

    # Mission timeline.
    tl = report.timeline
    if tl is not None:
        end_all = report.summary["duration_s"]
        bars = [
            (g["name"], g["start_s"], g["end_s"] if g["end_s"] is not None else end_all, g["result"])
            for g in tl["goals"]
        ]
        recs = [(r["t_s"], r["name"]) for r in tl["recoveries"]]
        ttl = f"{title}: mission {tl['outcome']}"
        _plot(report, "timeline", render, lambda: plots.timeline_plot(bars, recs, end_all, ttl))
    else:
        add(Section(name="timeline", available=False, needs="/behavior_tree_log (nav2_msgs/BehaviorTreeLog)"))

    # One plot per topic of a standard type the sections above leave out (IMU, joints, battery, ...).
    for topic, ts in data.series.items():
        rec_ns, values = ts.arrays()
        if not len(rec_ns) or not ts.panels:
            continue
        name = ts.kind.name + topic.replace("/", "_")
        t_s = data_t_s(data, rec_ns)
        make = functools.partial(plots.series_plot, t_s, values, ts.columns, ts.panels, f"{title}: {ts.topic}")
        _plot(report, name, render, make)
    # Camera (a bag with images only): the first frame, the frame at each goal's end, the last frame.
    _camera_section(report, data, render, title)


_IMAGE_TOPICS = ("/camera/image_raw", "/camera/image_raw/compressed")


def _camera_section(report: Report, data: BagData, render: bool, title: str) -> None:
    topic = next((t for t in _IMAGE_TOPICS if data.has(t)), None)
    if topic is None:  # most robots have no camera: no section rather than a missing one
        return
    health = data.health[topic]
    msgtype = health.msgtype
    bag_topic = health.topic  # the bag's own name (a fleet robot's is under its namespace)
    picks = [("first", health.first_ns)]
    tl = report.timeline
    if tl is not None:
        picks += [
            (f"goal {n} end: {g['name']} ({g['result']})", data.start_ns + round(g["end_s"] * 1e9))
            for n, g in enumerate(tl["goals"], start=1)
            if g["end_s"] is not None
        ]
    picks.append(("last", health.last_ns))

    def sheet() -> bytes:
        from twin.analysis.export_images import pick_frames

        return plots.frames_sheet(pick_frames(report.bag, bag_topic, msgtype, picks), f"{title}: {bag_topic}")

    _plot(report, "camera", render, sheet)


def data_t_s(data: BagData, t_ns: NDArray[np.int64]) -> F64:
    """Record times as seconds from the bag's start."""
    return (t_ns - data.start_ns).astype(np.float64) * 1e-9


def _plot(report: Report, name: str, render: bool, make: Callable[[], bytes]) -> None:
    if render:
        report.pngs[f"{name}.png"] = make()
    report.sections.append(Section(name=name, available=True, plot=f"{name}.png" if render else None))


# -- writing -------------------------------------------------------------------------------------


def _fmt(value: Any, unit: str = "", digits: int = 3) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "n/a"
        return f"{value:.{digits}f}{' ' + unit if unit else ''}"
    return f"{value}{' ' + unit if unit else ''}"


_METRIC_ROWS: tuple[tuple[str, str, str, int], ...] = (
    ("outcome", "outcome", "", 0),
    ("goals_succeeded", "goals succeeded", "", 0),
    ("recoveries", "recoveries", "", 0),
    ("duration_s", "bag duration", "s", 2),
    ("mission_duration_s", "mission duration", "s", 2),
    ("pose_source", "path from", "", 0),
    ("path_length_m", "path length", "m", 3),
    ("mean_speed_mps", "mean speed (moving)", "m/s", 3),
    ("max_speed_mps", "max speed", "m/s", 3),
    ("rms_jerk_mps3", "RMS jerk", "m/s³", 2),
    ("time_stopped_s", "time stopped", "s", 2),
    ("contacts", "contacts", "", 0),
    ("localization_source", "localization", "", 0),
    ("localization_error_median_m", "loc. error median", "m", 4),
    ("localization_error_p95_m", "loc. error p95", "m", 4),
    ("localization_error_max_m", "loc. error max", "m", 4),
    ("min_lidar_range_m", "min lidar range", "m", 3),
    ("min_lidar_range_t_s", "  at", "s", 2),
)


def summary_lines(report: Report) -> list[str]:
    """The terminal summary: metrics, goals, unhealthy topics, missing sections."""
    m = report.metrics.to_dict()
    s = report.summary
    lines = [
        f"{report.bag}: {s['storage']}, {s['duration_s']:.1f} s, {s['messages']} messages on {s['topics']} topics",
    ]
    for key, label, unit, digits in _METRIC_ROWS:
        lines.append(f"  {label:<22}{_fmt(m[key], unit, digits)}")
    if report.timeline is not None:
        for g in report.timeline["goals"]:
            lines.append(f"  goal {g['name']:<17}{g['result']:<8} {_fmt(g['duration_s'], 's', 1)}")
    for h in report.health:
        flags = _health_flags(h)
        if flags:
            lines.append(f"  topic {h['topic']}: {'; '.join(flags)}")
    for sec in report.sections:
        if not sec.available:
            lines.append(f"  no {sec.name} plot: needs {sec.needs}")
    for note in report.metrics.notes:
        lines.append(f"  note: {note}")
    return lines


def _health_flags(h: dict[str, Any]) -> list[str]:
    flags = []
    if not h["decodable"]:
        flags.append(f"type {h['type']} cannot be decoded")
    rate, expected, steady = h["rate_hz"], h["expected_rate_hz"], h.get("steady_rate_hz")
    if rate is not None and expected is not None and abs(rate - expected) > 0.1 * expected:
        flags.append(f"rate {rate:.1f} Hz, expected {expected:g} Hz")
    elif rate is not None and expected is None and steady is not None and abs(rate - steady) > 0.1 * steady:
        flags.append(f"rate {rate:.1f} Hz, its steady rate {steady:.1f} Hz")
    if h["gaps_over_3_periods"]:
        flags.append(f"{h['gaps_over_3_periods']} gaps > 3 periods (longest {h['max_interval_s']:.3f} s)")
    if h["non_monotonic_stamps"]:
        flags.append(f"{h['non_monotonic_stamps']} stamps going backwards")
    return flags


def _expected(h: dict[str, Any]) -> str:
    """The rate a topic is judged by: the twin's nominal one (its own bags), else the topic's own steady rate."""
    if h["expected_rate_hz"] is not None:
        return _fmt(h["expected_rate_hz"], "", 0)
    steady = h.get("steady_rate_hz")
    return "n/a" if steady is None else f"{steady:.1f} (steady)"


def bag_line(report: Report) -> str:
    """The report's first line under its title: the bag, its storage, start, length and size."""
    s = report.summary
    return (
        f"`{report.bag}`: {s['storage']}, metadata v{s['metadata_version']}, {s['ros_distro'] or 'distro unknown'}, "
        f"started {s['start_utc']}, {s['duration_s']:.2f} s, {s['messages']} messages on {s['topics']} topics."
    )


def _markdown(report: Report) -> str:
    title = f"# Bag report: {report.bag.name}"
    if report.namespace:
        title += f", robot /{report.namespace}"
    out = [title, "", bag_line(report), "", *robot_markdown(report, 2)]
    out += ["", f"_Written by twin {__version__} `twin analyze`._", ""]
    return "\n".join(out)


def robot_markdown(report: Report, level: int) -> list[str]:
    """One robot's part of a report as Markdown lines: metrics, mission, plots, topic health.

    Args:
        report: The robot's report.
        level: The heading level of its parts (2 in a one-robot report).
    """
    d = report.to_dict()
    m = d["metrics"]
    h2, h3 = "#" * level, "#" * (level + 1)
    out = [
        f"{h2} Metrics",
        "",
        "| metric | value |",
        "|---|---|",
    ]
    out += [f"| {label.strip()} | {_fmt(m[key], unit, digits)} |" for key, label, unit, digits in _METRIC_ROWS]
    if m["notes"]:
        out += ["", *[f"- {n}" for n in m["notes"]]]
    out += ["", f"{h2} Mission", ""]
    tl = d["mission"]
    if tl is None:
        out.append("No mission timeline: it needs `/behavior_tree_log` (nav2_msgs/BehaviorTreeLog).")
    else:
        out += [
            f"Root `{tl['root']}`: **{tl['outcome']}**.",
            "",
            "| goal | start (s) | duration (s) | result |",
            "|---|---|---|---|",
        ]
        out += [
            f"| {g['name']} | {g['start_s']:.2f} | {_fmt(g['duration_s'], '', 2)} | {g['result']} |"
            for g in tl["goals"]
        ]
        out += ["", f"Recoveries: {len(tl['recoveries'])}"]
        out += [f"- {r['t_s']:.2f} s: {r['name']}" for r in tl["recoveries"]]
    out += ["", f"{h2} Plots", ""]
    for sec in report.sections:
        if sec.available and sec.plot:
            out += [f"{h3} {sec.name}", "", f"![{sec.name}]({sec.plot})", ""]
        elif not sec.available:
            out += [f"{h3} {sec.name}", "", f"Not drawn: needs {sec.needs}.", ""]
    out += [
        f"{h2} Topic health",
        "",
        "| topic | type | count | rate (Hz) | expected | jitter (ms) | gaps > 3 periods | max interval (s) "
        "| stamps backwards | record − stamp (s) | skew spread (ms) | flags |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for h in d["topic_health"]:
        out.append(
            f"| {h['topic']} | {h['type']} | {h['count']} | {_fmt(h['rate_hz'], '', 2)} | "
            f"{_expected(h)} | {_fmt(h['jitter_ms'], '', 2)} | "
            f"{_fmt(h['gaps_over_3_periods']) if h['gaps_over_3_periods'] is not None else 'aperiodic'} | "
            f"{_fmt(h['max_interval_s'], '', 3)} | {h['non_monotonic_stamps']} | "
            f"{_fmt(h['stamp_offset_mean_s'], '', 3)} | "
            f"{_fmt(h['stamp_skew_spread_ms'], '', 2)} | {'; '.join(_health_flags(h))} |"
        )
    return out


def _html(report: Report, markdown: str) -> str:
    return markdown_html(markdown, report.pngs, f"Bag report: {report.bag.name}")


def markdown_html(markdown: str, pngs: dict[str, bytes], title: str) -> str:
    """A self-contained page: the Markdown's content as HTML, the plots (`pngs`) inline as base64 PNGs."""
    body: list[str] = []
    in_table = False
    for line in markdown.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if all(set(c) <= {"-"} for c in cells):
                continue
            if not in_table:
                body.append("<table>")
                in_table = True
                body.append("<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in cells) + "</tr>")
            else:
                body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
            continue
        if in_table:
            body.append("</table>")
            in_table = False
        if line.startswith("![") and "](" in line:
            name = line[line.index("](") + 2 : -1]
            png = pngs.get(name)
            if png is not None:
                b64 = base64.b64encode(png).decode("ascii")
                body.append(f'<img alt="{html.escape(name)}" src="data:image/png;base64,{b64}">')
            continue
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            body.append(f"<h{level}>{html.escape(line[level:].strip())}</h{level}>")
        elif line.startswith("- "):
            body.append(f"<li>{html.escape(line[2:])}</li>")
        elif line.strip():
            text = line.replace("**", "").replace("`", "").strip()
            if len(text) > 1 and text[0] == text[-1] == "_":  # a line in italics; names keep their underscores
                text = text[1:-1]
            body.append(f"<p>{html.escape(text)}</p>")
    if in_table:
        body.append("</table>")
    style = (
        "body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}th{background:#eee}img{max-width:100%}"
    )
    title = html.escape(title)
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f"<style>{style}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )


def write_report(report: Report, out_dir: Path) -> list[Path]:
    """Write report.json, report.md, report.html and the PNGs into `out_dir`; return the files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, png in report.pngs.items():
        (out_dir / name).write_bytes(png)
        written.append(out_dir / name)
    md = _markdown(report)
    (out_dir / "report.json").write_text(json.dumps(report.to_dict(), indent=2) + "\n")
    (out_dir / "report.md").write_text(md)
    (out_dir / "report.html").write_text(_html(report, md))
    written += [out_dir / "report.json", out_dir / "report.md", out_dir / "report.html"]
    return written
