"""A sweep's results: results.csv (and .parquet with pyarrow), summary.md and mission_time.png."""

from __future__ import annotations

import csv
import logging
import math
import re
import statistics
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from twin.sweep.engine import SweepResult
from twin.sweep.runner import FLEET_COLUMNS, METRIC_COLUMNS, ROBOT_COLUMNS, SUCCEEDED

__all__ = ["columns", "robot_namespaces", "wilson_interval", "write_reports"]

_log = logging.getLogger(__name__)

_Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson_interval(successes: int, runs: int, z: float = _Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % by default); (0, 1) for no runs."""
    if runs == 0:
        return 0.0, 1.0
    p = successes / runs
    z2 = z * z
    centre = (p + z2 / (2 * runs)) / (1 + z2 / runs)
    half = z * math.sqrt(p * (1 - p) / runs + z2 / (4 * runs * runs)) / (1 + z2 / runs)
    return max(0.0, centre - half), min(1.0, centre + half)


def robot_namespaces(rows: Sequence[dict[str, Any]]) -> list[str]:
    """A fleet sweep's robots, in their scenario's order (none for one robot)."""
    found: dict[str, None] = {}
    for row in rows:
        for ns in row.get("robots") or ():
            found.setdefault(str(ns), None)
    return list(found)


def columns(result: SweepResult) -> list[str]:
    """The table's columns: run id, seed, the varied keys, outcome, reason, metrics, wall time, bag.

    A fleet's table adds the contacts between robots and, for each robot, its own columns
    (`robot1.result`, `robot1.mission_time_s`... `ROBOT_COLUMNS`) after the fleet's.
    """
    varied = [k for k, _ in result.spec.vary] + [d.key for d in result.spec.random]
    robots = robot_namespaces(result.rows)
    fleet = [*FLEET_COLUMNS, *(f"{ns}.{c}" for ns in robots for c in ROBOT_COLUMNS)] if robots else []
    return ["run_id", "seed", *varied, "outcome", "reason", *METRIC_COLUMNS, *fleet, "wall_s", "bag_path"]


def write_reports(result: SweepResult) -> list[Path]:
    """Write the tables, the summary and the plot into the sweep's folder; return the files written."""
    out = result.out_dir
    names = columns(result)
    written = [_write_csv(out / "results.csv", names, result.rows)]
    parquet = _write_parquet(out / "results.parquet", names, result.rows)
    if parquet is not None:
        written.append(parquet)
    plot = _plot_mission_time(out / "mission_time.png", result)
    if plot is not None:
        written.append(plot)
    summary = out / "summary.md"
    summary.write_text(_summary(result, plot), encoding="utf-8")
    written.append(summary)
    return written


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, list | tuple | dict):
        return repr(value)
    return value


def _write_csv(path: Path, names: Sequence[str], rows: Sequence[dict[str, Any]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in rows:
            writer.writerow([_cell(row.get(n)) for n in names])
    return path


def _write_parquet(path: Path, names: Sequence[str], rows: Sequence[dict[str, Any]]) -> Path | None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        _log.warning(
            "%s not written: pyarrow is not installed (pip install 'twin[parquet]'); %s has the same table",
            path.name,
            path.with_suffix(".csv").name,
        )
        return None
    data: dict[str, list[Any]] = {}
    for name in names:
        values = [row.get(name) for row in rows]
        kinds = {type(v) for v in values if v is not None}
        if kinds - {int, float, bool} and kinds != {str}:
            values = [None if v is None else str(v) for v in values]  # mixed column: text
        elif kinds == {int, float}:
            values = [None if v is None else float(v) for v in values]
        data[name] = values
    pq.write_table(pa.table(data), path)
    return path


def _label(row: dict[str, Any], keys: Sequence[str]) -> str:
    return ", ".join(f"{k}={row.get(k)}" for k in keys) or "all runs"


def _plot_mission_time(path: Path, result: SweepResult) -> Path | None:
    keys = [k for k, _ in result.spec.vary]
    groups: dict[str, list[float]] = defaultdict(list)
    for row in result.rows:
        t = row.get("mission_time_s")
        if isinstance(t, int | float) and math.isfinite(t):
            groups[_label(row, keys)].append(float(t))
    if not groups:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=100)
    values = [v for vs in groups.values() for v in vs]
    bins = min(30, max(5, len(values) // 2))
    low, high = min(values), max(values)
    if high - low < 1e-9:
        low, high = low - 0.5, high + 0.5
    for label, times in sorted(groups.items()):
        ax.hist(times, bins=bins, range=(low, high), alpha=0.6, label=f"{label} ({len(times)})")
    ax.set_xlabel("mission time (s, simulated)")
    ax.set_ylabel("runs")
    ax.set_title(f"{result.spec.name}: mission time over {len(values)} runs")
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _reason_group(row: dict[str, Any], out_dir: Path) -> str:
    """The reason with run-specific paths taken out, so equal failures group together."""
    text = str(row.get("reason") or row.get("outcome"))
    text = text.replace(str(out_dir / "runs"), "<runs>")
    return re.sub(r"<runs>/r\d+", "<run>", text)


def _rate(successes: int, runs: int) -> str:
    if runs == 0:
        return "no runs"
    low, high = wilson_interval(successes, runs)
    return f"{successes} of {runs} ({100 * successes / runs:.1f} %, 95 % CI {100 * low:.1f} to {100 * high:.1f} %)"


def _robots_section(rows: Sequence[dict[str, Any]]) -> list[str]:
    """A fleet's table of robots: each robot's success, mission time and contacts over the runs (none for one robot)."""
    robots = robot_namespaces(rows)
    if not robots:
        return []
    lines = [
        "## Robots",
        "",
        "A run succeeds when every robot's mission does. Each robot's own results, over the runs that "
        "finished (contacts with robots: contacts between that robot and another):",
        "",
        "| robot | mission succeeded | mission time median (s) | max (s) | contacts | with robots "
        "| runs with a contact |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for ns in robots:
        finished = [r for r in rows if r.get(f"{ns}.result")]
        ok = sum(1 for r in finished if r.get(f"{ns}.result") in SUCCEEDED)
        times = sorted(
            float(r[f"{ns}.mission_time_s"])
            for r in finished
            if r.get(f"{ns}.result") in SUCCEEDED and isinstance(r.get(f"{ns}.mission_time_s"), int | float)
        )
        contacts = [r.get(f"{ns}.contacts") for r in finished]
        with_robots = [r.get(f"{ns}.robot_contacts") for r in finished]
        touched = sum(1 for c in contacts if isinstance(c, int) and c > 0)
        median = f"{statistics.median(times):.2f}" if times else "-"
        longest = f"{times[-1]:.2f}" if times else "-"
        lines.append(
            f"| {ns} | {_rate(ok, len(finished))} | {median} | {longest} "
            f"| {sum(c for c in contacts if isinstance(c, int))} | {sum(c for c in with_robots if isinstance(c, int))} "
            f"| {touched} |"
        )
    lines.append("")
    return lines


def _summary(result: SweepResult, plot: Path | None) -> str:
    spec, rows = result.spec, result.rows
    successes = sum(1 for r in rows if r.get("outcome") == "success")
    lines = [
        f"# Sweep {spec.name}",
        "",
        f"{len(rows)} runs of `{spec.scenario}` from `{spec.path}`; timeout {spec.timeout_s:g} s per run.",
        "",
        f"**Success rate: {_rate(successes, len(rows))}** (Wilson score interval).",
        "",
    ]
    times = sorted(
        float(r["mission_time_s"])
        for r in rows
        if r.get("outcome") == "success" and isinstance(r.get("mission_time_s"), int | float)
    )
    lines += ["## Mission time (successful runs, simulated seconds)", ""]
    if times:
        q = statistics.quantiles(times, n=20, method="inclusive") if len(times) > 1 else [times[0]] * 19
        lines += [
            "| runs | mean | median | min | 5 % | 95 % | max |",
            "|---:|---:|---:|---:|---:|---:|---:|",
            f"| {len(times)} | {statistics.fmean(times):.2f} | {statistics.median(times):.2f} | {times[0]:.2f} "
            f"| {q[0]:.2f} | {q[-1]:.2f} | {times[-1]:.2f} |",
            "",
        ]
    elif successes:
        lines += ["No successful run has a mission time (a behaviour tree's, from its log).", ""]
    else:
        lines += ["No successful run.", ""]
    if plot is not None:
        lines += [f"![mission time]({plot.name})", ""]
    lines += _robots_section(rows)
    for key, values in spec.vary:
        lines += [f"## By `{key}`", "", "| value | success |", "|---|---|"]
        for value in values:
            group = [r for r in rows if r.get(key) == value]
            ok = sum(1 for r in group if r.get("outcome") == "success")
            lines.append(f"| {value} | {_rate(ok, len(group))} |")
        lines.append("")
    failures: dict[str, list[str]] = defaultdict(list)
    for row in rows:
        if row.get("outcome") != "success":
            failures[f"{row.get('outcome')}: {_reason_group(row, result.out_dir)}"].append(str(row["run_id"]))
    lines += ["## Failures by reason", ""]
    if failures:
        lines += ["| runs | reason | run ids |", "|---:|---|---|"]
        for reason, ids in sorted(failures.items(), key=lambda item: (-len(item[1]), item[0])):
            shown = ", ".join(ids[:12]) + (f", ... ({len(ids) - 12} more)" if len(ids) > 12 else "")
            lines.append(f"| {len(ids)} | {reason.replace('|', '/')} | {shown} |")
    else:
        lines.append("None.")
    lines.append("")
    return "\n".join(lines)
