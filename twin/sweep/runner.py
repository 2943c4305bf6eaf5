"""One run of a sweep, as a Dask task runs it: an isolated `twin simulate` process, then its metrics.

`execute_run` is what a worker executes. It writes the run's scenario into the run's folder, runs
`python -m twin simulate` on it with the sweep's wall-clock timeout, reads the metrics from the
bag, keeps or removes the bag, and writes `result.json` (the row; a run with one is finished). A
crash, an error or a timeout fails that run only, with its reason; nothing here raises for them.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

__all__ = [
    "FLEET_COLUMNS",
    "METRIC_COLUMNS",
    "OUTCOMES",
    "ROBOT_COLUMNS",
    "SUCCEEDED",
    "RunTask",
    "execute_run",
    "read_result",
]

OUTCOMES = ("success", "failure", "error", "crash", "timeout", "worker lost")
"""`success`: the mission succeeded (`SUCCEEDED`; a fleet's: every robot's). `failure`: the run completed
but the mission did not succeed. `error`: `twin simulate` refused the run (its error line is the reason).
`crash`: the process died (a signal or an internal error). `timeout`: it ran past `timeout_s`. `worker
lost`: the Dask worker running it died (set by the client)."""

SUCCEEDED = ("SUCCESS", "complete", "none")
"""The mission results that are a success: a tree's SUCCESS, the end of a mission that has no
SUCCESS (a cmd_vel script, waypoints, a replay), which `twin simulate` reports as `complete`, and
`none` (`mission: {type: none}`: nothing to fail; the run went its duration)."""

KeepBags = Literal["failed", "none", "all"]

_TERM_GRACE_S = 5.0  # after SIGTERM a run closes its bag; then it is killed
# A run is one process on one core: numerical libraries must not start a thread per core, or runs
# on neighbouring workers fight over the cores (Dask's nanny sets the same for its workers).
_ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}
_PR_SET_PDEATHSIG = 1


@dataclass(frozen=True, kw_only=True, slots=True)
class RunTask:
    """What a worker needs for one run (plain data; pickled to the worker)."""

    run_id: str
    key: str
    seed: int | None
    scenario_yaml: str
    run_dir: str
    timeout_s: float
    keep_bags: KeepBags


def read_result(run_dir: Path, key: str) -> dict[str, Any] | None:
    """Return the row a finished run left in `run_dir`, or None if it has none for this `key`."""
    try:
        row: dict[str, Any] = json.loads((run_dir / "result.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return row if row.get("key") == key else None


def execute_run(task: RunTask) -> dict[str, Any]:
    """Run one scenario in its own `twin simulate` process and return its row (see `OUTCOMES`)."""
    run_dir = Path(task.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = run_dir / "scenario.yaml"
    scenario.write_text(task.scenario_yaml, encoding="utf-8")
    bag = run_dir / "bag"
    if bag.exists():  # a run cut short before: start over
        shutil.rmtree(bag)
    command = [sys.executable, "-m", "twin", "simulate", str(scenario), "--out", str(bag), "--json", "--quiet"]
    if task.seed is not None:
        command += ["--seed", str(task.seed)]
    start = time.monotonic()
    stdout, stderr, returncode, timed_out = _run(command, task.timeout_s, run_dir)
    wall_s = time.monotonic() - start
    (run_dir / "stderr.txt").write_text(stderr, encoding="utf-8")
    row: dict[str, Any] = {"run_id": task.run_id, "key": task.key, "wall_s": round(wall_s, 3)}
    summary: dict[str, Any] = {}
    if timed_out:
        row |= {"outcome": "timeout", "reason": f"still running after timeout_s={task.timeout_s:g} s"}
    elif returncode != 0 and not (returncode == 1 and stdout.lstrip().startswith("{")):
        row |= _failed(returncode, stderr)
    else:  # 0, or 1 with its summary: the mission ended in FAILURE and the bag is complete
        try:
            summary = json.loads(stdout)
        except ValueError:
            row |= {"outcome": "crash", "reason": "twin simulate printed no JSON summary"}
    if summary:
        result = summary.get("mission_result", "")
        # A fleet's: each robot's own (the run's says only complete when they ended well in different ways).
        results = (summary.get("robots") or {"": result}).values()
        if all(r in SUCCEEDED for r in results):
            row |= {"outcome": "success", "reason": ""}
        else:
            why = summary.get("mission_failure") or summary.get("ended_by", "")
            robots = summary.get("robots") or {}
            if robots and not summary.get("mission_failure"):  # a fleet cut short: name who had not ended well
                why += " (" + ", ".join(f"{ns} {r}" for ns, r in robots.items() if r not in SUCCEEDED) + ")"
            row |= {"outcome": "failure", "reason": f"mission {result or 'unfinished'}: {why}"}
    # A run cut short by its timeout or a crash is not analysed (its bag, if any, is kept as asked).
    if row["outcome"] in ("success", "failure", "error") and (bag / "metadata.yaml").exists():
        try:
            row |= _metrics(bag, summary.get("robots") or {})
        except Exception as err:  # a bag that does not read back fails this run, not the sweep
            row |= {"outcome": "error", "reason": f"reading its bag: {type(err).__name__}: {err}".splitlines()[0]}
    failed = row["outcome"] != "success"
    keep = task.keep_bags == "all" or (task.keep_bags == "failed" and failed)
    if bag.exists() and not keep:
        shutil.rmtree(bag, ignore_errors=True)
    row["bag_path"] = str(bag) if bag.exists() else ""
    _write_atomic(run_dir / "result.json", json.dumps(row, indent=2))
    return row


METRIC_COLUMNS = (
    "goals_reached",
    "goals",
    "mission_time_s",
    "path_length_m",
    "contacts",
    "recoveries",
    "localization_error_median_m",
    "localization_error_p95_m",
    "localization_error_max_m",
)
"""The metric columns of a row, from `twin.analysis.run_metrics` (the code behind `twin analyze`)."""


ROBOT_COLUMNS = ("result", "goals_reached", "goals", "mission_time_s", "path_length_m", "contacts", "robot_contacts")
"""A fleet's columns for each robot, `<ns>.<column>`: its mission's result (SUCCESS, FAILURE, complete, running)
as the run's summary gives it, its metrics from its own topics, and its contacts with the other robots."""

FLEET_COLUMNS = ("robot_contacts",)
"""A fleet run's columns besides `METRIC_COLUMNS`: the contacts between robots (each one once)."""


def _metrics(bag: Path, robots: dict[str, str]) -> dict[str, Any]:
    """The run's metrics, read from its bag by the same code as `twin analyze` (each robot's, for a fleet)."""
    if robots:
        return _fleet_metrics(bag, robots)
    from twin.analysis import run_metrics

    m = run_metrics(bag)
    return {
        "goals_reached": m.goals_succeeded,
        "goals": len(m.goals),
        "mission_time_s": m.mission_duration_s,
        "path_length_m": m.path_length_m,
        "contacts": m.contacts,
        "recoveries": m.recoveries,
        "localization_error_median_m": m.localization_error_median_m,
        "localization_error_p95_m": m.localization_error_p95_m,
        "localization_error_max_m": m.localization_error_max_m,
    }


def _fleet_metrics(bag: Path, robots: dict[str, str]) -> dict[str, Any]:
    """A fleet run's row: each robot's columns (`ROBOT_COLUMNS`) and the fleet's in `METRIC_COLUMNS`.

    The fleet's: goals, contacts, recoveries and path length summed over the robots (goals and
    recoveries over those with a tree, the others have none); mission time
    the longest robot's (the run's mission ends with its last robot's); localization error the
    worst robot's; `robot_contacts` the contacts between robots, each counted once (`pair_contacts`).
    """
    from twin.analysis.fleet import fleet_metrics, pair_contacts

    per = fleet_metrics(bag)
    row: dict[str, Any] = {"robots": list(robots)}
    for ns, result in robots.items():
        found = per.get(ns)
        m, others = found if found is not None else (None, {})
        row[f"{ns}.result"] = result
        row[f"{ns}.goals_reached"] = m.goals_succeeded if m is not None else None
        row[f"{ns}.goals"] = len(m.goals) if m is not None else None
        row[f"{ns}.mission_time_s"] = m.mission_duration_s if m is not None else None
        row[f"{ns}.path_length_m"] = m.path_length_m if m is not None else None
        row[f"{ns}.contacts"] = m.contacts if m is not None else None
        row[f"{ns}.robot_contacts"] = sum(others.values()) if found is not None else None
    metrics = [p[0] for p in per.values()]

    def total(values: list[Any]) -> Any:
        return None if not values or any(v is None for v in values) else sum(values)

    def navigating(values: list[Any]) -> Any:  # goals and recoveries: a robot without a tree has none
        known = [v for v in values if v is not None]
        return sum(known) if known else None

    def worst(values: list[Any]) -> Any:
        known = [v for v in values if v is not None]
        return max(known) if known else None

    row |= {
        "goals_reached": navigating([m.goals_succeeded for m in metrics]),
        "goals": navigating([len(m.goals) for m in metrics]),
        "mission_time_s": worst([m.mission_duration_s for m in metrics]),
        "path_length_m": total([m.path_length_m for m in metrics]),
        "contacts": total([m.contacts for m in metrics]),
        "recoveries": navigating([m.recoveries for m in metrics]),
        "localization_error_median_m": worst([m.localization_error_median_m for m in metrics]),
        "localization_error_p95_m": worst([m.localization_error_p95_m for m in metrics]),
        "localization_error_max_m": worst([m.localization_error_max_m for m in metrics]),
        "robot_contacts": pair_contacts({ns: p[1] for ns, p in per.items()}),
    }
    return row


def _failed(returncode: int, stderr: str) -> dict[str, str]:
    lines = [line for line in stderr.splitlines() if line.strip()]
    said = next((line for line in reversed(lines) if line.startswith("twin: ")), lines[-1] if lines else "")
    if returncode < 0:
        name = signal.Signals(-returncode).name if -returncode in signal.Signals._value2member_map_ else -returncode
        return {"outcome": "crash", "reason": f"killed by {name}"}
    if said.startswith("twin: error: "):
        return {"outcome": "error", "reason": said.removeprefix("twin: error: ")}
    text = said.removeprefix("twin: ") or f"exit status {returncode}"
    return {"outcome": "crash", "reason": text}


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Ask Linux to SIGTERM the run if the worker that started it dies (a killed worker leaves no orphans)."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def _run(command: list[str], timeout_s: float, cwd: Path) -> tuple[str, str, int, bool]:
    """Run `command`; past `timeout_s` send SIGTERM (the bag is closed), then SIGKILL."""
    preexec = _die_with_parent if sys.platform.startswith("linux") else None
    with subprocess.Popen(
        command,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=preexec,  # noqa: PLW1509 - only prctl, async-signal-safe
        env={**os.environ, **_ONE_THREAD, "PYTHONUNBUFFERED": "1"},
    ) as process:
        try:
            stdout, stderr = process.communicate(timeout=timeout_s)
            return stdout, stderr, process.returncode, False
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGTERM)
            try:
                stdout, stderr = process.communicate(timeout=_TERM_GRACE_S)
            except subprocess.TimeoutExpired:
                process.kill()
                stdout, stderr = process.communicate()
            return stdout, stderr, process.returncode, True


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
