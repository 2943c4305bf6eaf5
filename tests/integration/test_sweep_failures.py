"""A sweep survives its runs' failures: a run that raises, one past its timeout, and one whose Dask worker
is killed mid-run are marked with their reasons; the other runs complete, and the sweep exits 1."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.integration.sweep_helpers import env, read_table, write_inputs
from tests.robustness.helpers import assert_bag_reads_back

SPIN = "{type: cmd_vel_script, segments: [{duration_s: 100000, angular_radps: 0.3}]}"
NEAR = "{type: behavior_tree, tree: tree.xml, locations: near.yaml}"

# Timeouts are wall clock: a run that never ends is cut at timeout_s however loaded the machine is,
# and the runs that must finish get a timeout no machine reaches.
FAILURES = f"""scenario: base.yaml
zip: true
vary:
  robot.model: [turtlebot3_waffle, no_such_robot, turtlebot3_waffle]
  mission: [{NEAR}, {NEAR}, {SPIN}]
  max_duration_s: [30, 30, 100000]
timeout_s: 900
"""

TIMEOUT = f"""scenario: base.yaml
vary:
  mission: [{SPIN}]
  max_duration_s: [100000]
timeout_s: 5
"""


def _children(pid: int) -> dict[int, list[str]]:
    """The processes whose parent is `pid`, with their command lines."""
    out: dict[int, list[str]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            status = (entry / "status").read_text()
            cmdline = (entry / "cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        match = re.search(r"^PPid:\s+(\d+)$", status, re.MULTILINE)
        if match and int(match.group(1)) == pid:
            out[int(entry.name)] = cmdline
    return out


def _descendants(pid: int) -> dict[int, tuple[int, list[str]]]:
    """Every process below `pid` (workers are forked by Dask's forkserver, a child of the sweep): parent, command line."""
    out: dict[int, tuple[int, list[str]]] = {}
    parents = [pid]
    while parents:
        parent = parents.pop()
        for child, cmdline in _children(parent).items():
            out[child] = (parent, cmdline)
            parents.append(child)
    return out


def _kill_worker_running(sweep: subprocess.Popen[str], run_id: str, timeout_s: float) -> int:
    """Find the worker process (under the sweep) whose `twin simulate` runs `run_id`; SIGKILL it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and sweep.poll() is None:
        for worker, cmdline in _descendants(sweep.pid).values():
            if "simulate" in cmdline and any(f"/runs/{run_id}/scenario.yaml" in arg for arg in cmdline):
                os.kill(worker, signal.SIGKILL)
                return worker
        time.sleep(0.2)
    msg = f"no worker ran {run_id} within {timeout_s} s"
    raise AssertionError(msg)


def _sweep(folder: Path, text: str, workers: int) -> subprocess.Popen[str]:
    sweep_file = write_inputs(folder, text)
    command = [sys.executable, "-m", "twin", "sweep", str(sweep_file), "--workers", str(workers), "--out"]
    return subprocess.Popen(
        [*command, str(folder / "out")], env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def test_a_run_that_raises_and_one_whose_worker_is_killed_fail_alone(tmp_path: Path) -> None:
    with _sweep(tmp_path, FAILURES, workers=2) as sweep:
        try:
            _kill_worker_running(sweep, "r0002", timeout_s=300)
            stdout, stderr = sweep.communicate(timeout=600)
        finally:
            if sweep.poll() is None:
                sweep.kill()
    assert sweep.returncode == 1, stderr  # runs that did not complete: the sweep says so
    assert "3 runs: 1 succeeded" in stdout
    assert "twin: error: 2 of 3 runs did not complete (1 error, 1 worker lost); first, r0001: " in stderr
    out = tmp_path / "out"
    rows = {r["run_id"]: r for r in read_table(out)}
    assert rows["r0000"]["outcome"] == "success"
    assert rows["r0000"]["goals_reached"] == "1"
    assert rows["r0001"]["outcome"] == "error"
    assert "no_such_robot" in rows["r0001"]["reason"]
    assert rows["r0002"]["outcome"] == "worker lost"
    assert rows["r0002"]["reason"] == "the Dask worker running it died"
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "| 1 | worker lost: the Dask worker running it died | r0002 |" in summary
    # The killed worker's run did not outlive it (it was told to stop when its worker died).
    assert _running(str(out / "runs" / "r0002")) == []


def test_a_run_past_its_timeout_is_stopped_and_marked(tmp_path: Path) -> None:
    with _sweep(tmp_path, TIMEOUT, workers=1) as sweep:
        stdout, stderr = sweep.communicate(timeout=600)
    assert sweep.returncode == 1, stderr
    assert "1 runs: 0 succeeded" in stdout
    out = tmp_path / "out"
    (row,) = read_table(out)
    assert row["outcome"] == "timeout"
    assert row["reason"] == "still running after timeout_s=5 s"
    assert float(row["wall_s"]) >= 5.0
    # SIGTERM was honoured within the grace (no SIGKILL): the bag is complete and reads back.
    assert row["bag_path"] and (Path(row["bag_path"]) / "metadata.yaml").exists()
    assert_bag_reads_back(Path(row["bag_path"]))
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "| 1 | timeout: still running after timeout_s=5 s | r0000 |" in summary
    assert _running(str(out / "runs" / "r0000")) == []


def _running(fragment: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and fragment in (entry / "cmdline").read_bytes().decode(errors="replace"):
                found.append(int(entry.name))
        except OSError:
            continue
    return found


def test_a_sweep_stopped_by_sigterm_exits_143_and_says_how_to_finish(tmp_path: Path) -> None:
    # SIGTERM exited 130, as if Ctrl-C, with "interrupted" and no word of the finished runs
    with _sweep(tmp_path, TIMEOUT.replace("timeout_s: 5", "timeout_s: 900"), workers=1) as sweep:
        deadline = time.monotonic() + 300
        while not _running(str(tmp_path / "out" / "runs" / "r0000")) and time.monotonic() < deadline:
            time.sleep(0.2)  # the spinning run has started
        sweep.send_signal(signal.SIGTERM)
        _, stderr = sweep.communicate(timeout=300)
    assert sweep.returncode == 143, stderr
    assert "twin: sweep stopped by SIGTERM; the runs that finished are kept in their folders" in stderr
    assert "Traceback" not in stderr
    assert _running(str(tmp_path / "out" / "runs" / "r0000")) == []  # its run was told to stop
