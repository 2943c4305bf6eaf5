"""A native crash inside the `twin simulate` process: the bag keeps what was flushed, and `bag recover` completes it.

The drive is the faulty test motor in the simulate process itself (`drive.isolation: none`) with
`fault_mode` segfault at t = 3 s: a write through a NULL pointer in `doStep`. The process dies by
SIGSEGV with no Python traceback (there is no Python frame to blame); the recorder flushes by
simulated time as well as wall time, so every message handed more than 0.5 s of simulated time
before the last one is in the recovered bag. The process logs each handed message
(`TWIN_BAG_WRITE_LOG`, as the SIGKILL test in tests/integration/test_kill.py does).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.robustness.helpers import assert_bag_reads_back
from tests.unit.cosim.helpers import FAULTS, faulty
from twin.bag import open_bag, read_messages

FAULT_TIME_S = 3.0
SIM_MARGIN_NS = 500_000_000  # the recorder's promise: at most 0.5 s of simulated time is lost


def _scenario(tmp_path: Path) -> Path:
    scenario = tmp_path / "segfault.yaml"
    scenario.write_text(
        "name: segfault_in_process\n"
        "drive:\n"
        "  type: fmu\n"
        f"  fmu_file: {faulty()}\n"
        "  profile: velocity-servo\n"
        f"  mapping: {{parameters: {{fault_mode: {FAULTS['segfault']}, fault_time: {FAULT_TIME_S}}}}}\n"
        "  isolation: none\n"
    )
    return scenario


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_segfault_in_the_simulate_process_leaves_a_recoverable_bag(tmp_path: Path, storage: str) -> None:
    bag, log = tmp_path / "bag", tmp_path / "handed.log"
    env = {**os.environ, "PYTHONPATH": str(REPO), "TWIN_BAG_WRITE_LOG": str(log)}
    command = ["simulate", str(_scenario(tmp_path)), "--duration", "20", "--storage", storage, "--out", str(bag)]
    run = subprocess.run(
        [sys.executable, "-m", "twin", *command],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert run.returncode == -signal.SIGSEGV, run.stderr
    assert "Traceback" not in run.stderr
    assert not (bag / "metadata.yaml").exists()  # it really died mid-recording

    recover = subprocess.run(
        [sys.executable, "-m", "twin", "bag", "recover", str(bag)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert recover.returncode == 0, recover.stderr
    assert "recovered" in recover.stdout
    count = assert_bag_reads_back(bag)

    handed = [line.split(" ") for line in log.read_text().splitlines()]
    handed_t = [(topic, int(t_ns)) for topic, t_ns, _ in handed]
    last_t = max(t for _, t in handed_t)
    assert last_t <= FAULT_TIME_S * 1e9  # nothing was handed after the crash...
    assert last_t >= (FAULT_TIME_S - 0.1) * 1e9  # ... and the run got to the fault
    got = Counter((m.topic, m.t_ns) for m in read_messages(bag, decode=False))
    must_have = Counter((topic, t) for topic, t in handed_t if t < last_t - SIM_MARGIN_NS)
    missing = must_have - got
    assert not missing, f"{sum(missing.values())} messages > 0.5 s of sim time before the crash are lost"
    assert count <= len(handed_t) + 1
    info = open_bag(bag)
    assert info.end_ns >= (FAULT_TIME_S - 0.5) * 1e9
    topics = {m.topic for m in read_messages(bag, decode=False)}
    assert {"/clock", "/odom", "/scan", "/motor_state"} <= topics
