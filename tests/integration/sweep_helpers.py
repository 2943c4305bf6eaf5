"""A small sweep for the integration tests: one nearby goal in the house, a few simulated seconds a run."""

from __future__ import annotations

import csv
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from tests.conftest import REPO

TREE = """<?xml version="1.0"?>
<root main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <Sequence name="sequence">
      <GoToPose name="go_to_location1" loc="location1"/>
    </Sequence>
  </BehaviorTree>
</root>
"""

BASE = """name: sweep_test
mission:
  type: behavior_tree
  tree: tree.xml
  locations: near.yaml
max_duration_s: 30
"""

GOAL_XY = (1.5, -0.2)  # along the corridor east of the spawn point

SIX_RUNS = """scenario: base.yaml
runs: 2
vary:
  robot.initial_pose.y_m: [0.0, 0.1, -0.1]
random:
  robot.initial_pose.x_m: {uniform: [-0.05, 0.05]}
timeout_s: 120
"""


def write_inputs(folder: Path, sweep: str = SIX_RUNS) -> Path:
    """Write the base scenario, its tree and locations, and `sweep` as sweep.yaml; return its path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "tree.xml").write_text(TREE, encoding="utf-8")
    (folder / "near.yaml").write_text(f"location1: [{GOAL_XY[0]}, {GOAL_XY[1]}, 0.0]\n", encoding="utf-8")
    (folder / "base.yaml").write_text(BASE, encoding="utf-8")
    path = folder / "sweep.yaml"
    path.write_text(sweep, encoding="utf-8")
    return path


def env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO)}


def read_table(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def wait_for_port(port: int, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    msg = f"nothing listens on 127.0.0.1:{port} after {timeout_s} s"
    raise TimeoutError(msg)


def stop(processes: list[subprocess.Popen[bytes]]) -> None:
    """Terminate processes we started (bounded waits, then kill)."""
    for p in processes:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in processes:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=20)


def dask_cli() -> str:
    return str(Path(sys.executable).parent / "dask")
