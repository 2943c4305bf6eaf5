"""SIGTERM in a world that runs slower than real time: the run stops at once, and its bag is complete.

Found by probing: a sweep's timed-out run in a 10,000-obstacle world took 6.6-11.4 s to honour
SIGTERM (the stop flag was read once a simulated second, and a SIGTERM during start-up killed the
process outright), so the sweep SIGKILLed it after its 5 s grace, leaving a bag without metadata.
Now start-up unwinds on SIGTERM (no half-made bag is left) and the run looks every 20 ms of sim time.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO
from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error


def _many_obstacles(folder: Path, count: int = 10_000) -> Path:
    rng = random.Random(1)
    obstacles = []
    while len(obstacles) < count:
        x, y = rng.uniform(-60, 60), rng.uniform(-60, 60)
        if abs(x) > 3 or abs(y) > 3:
            obstacles.append({"shape": "box", "size_m": [0.2, 0.2, 0.5], "pose": {"x_m": x, "y_m": y}})
    scenario = {
        "name": "many_obstacles",
        "mission": {"type": "cmd_vel_script", "segments": [{"duration_s": 100000, "angular_radps": 0.3}]},
        "max_duration_s": 100000,
        "localization": {"type": "none"},
        "obstacles": obstacles,
    }
    path = folder / "many.yaml"
    path.write_text(yaml.safe_dump(scenario))
    return path


@pytest.mark.parametrize("moment", ["bag_created", "running"])
def test_sigterm_in_a_10000_obstacle_world_leaves_a_complete_bag_or_none(moment: str, tmp_path: Path) -> None:
    scenario = _many_obstacles(tmp_path)
    bag = tmp_path / "bag"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin", "simulate", str(scenario), "--out", str(bag), "--watchdog-s", "600"],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 600  # generous: only bounds a start-up that never ends
        storage = bag / f"{bag.name}_0.mcap"
        while not storage.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        if moment == "running":
            time.sleep(3.0)  # well into the run (the wait is not what the test measures)
        assert proc.poll() is None, proc.communicate()[1]
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert "Traceback" not in err
    if "before the run started" in err:  # it was still starting: nothing half-made is left
        assert_one_line_error(err, contains="stopped by SIGTERM before the run started; nothing was recorded")
        assert not bag.exists()
    else:
        assert "the bag is complete" in err or "the bag up to" in err, err
        assert (bag / "metadata.yaml").exists()
        assert_bag_reads_back(bag)
