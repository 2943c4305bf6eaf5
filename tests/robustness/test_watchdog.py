"""A step that never returns: the watchdog ends the run by itself (exit 8), and SIGTERM/SIGINT still work.

Three kinds of stuck step, as a user meets them:
- a behaviour tree whose first tick does not return for half a minute or more: `Repeat
  num_cycles="-1"` over 64,000 instant actions, re-ticked 1000 times in that tick (the main thread
  spins in Python);
- a vendor FMU that hangs in `doStep` (the project's faulty test motor, `fault_mode` hang: it waits
  in `pause()` forever, in the same process: `drive.isolation: none`);
- a step stuck in native code that releases the GIL, as ctypes calls do: a C busy loop compiled
  here and called from the kinematic drive's step once sim time passes 1 s (injected with a
  `sitecustomize` module, so the `twin simulate` process itself is unchanged).

In every case the process ends with the documented exit code, one error line naming where it was
stuck, and a bag that reads back; its memory does not grow while it is stuck.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.robustness.helpers import DATA, assert_bag_reads_back, assert_one_line_error
from tests.unit.cosim.helpers import FAULTS, faulty
from twin.bag import open_bag
from twin.core.native import compile_shared, find_compiler

_HANG_C = """
void twin_test_hang_in_c(void) {
    volatile unsigned long spins = 0;
    for (;;) spins++;  /* never returns, never looks at signals: a hung doStep */
}
"""

_SITECUSTOMIZE = """
import ctypes, os
from twin.robot.kinematic import KinematicDrivetrain

_lib = ctypes.CDLL(os.environ["TWIN_TEST_HANG_LIB"])  # ctypes.CDLL releases the GIL during calls
_advance = KinematicDrivetrain.advance
_steps = [0]

def advance(self, n_steps):
    _steps[0] += n_steps
    if _steps[0] * self._dt > 1.0:
        _lib.twin_test_hang_in_c()
    _advance(self, n_steps)

KinematicDrivetrain.advance = advance
"""


@pytest.fixture(scope="module")
def hang_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """An environment whose `twin simulate` hangs in C once sim time passes 1 s."""
    folder = tmp_path_factory.mktemp("hang")
    compiler = find_compiler()
    assert compiler is not None, "a C compiler is needed (twin.core.native builds with it too)"
    source = folder / "hang.c"
    source.write_text(_HANG_C)
    lib = folder / "libhang.so"
    compile_shared(compiler, [source], lib, flags=("-O0", "-shared", "-fPIC"))
    (folder / "sitecustomize.py").write_text(_SITECUSTOMIZE)
    return {"PYTHONPATH": f"{folder}{os.pathsep}{REPO}", "TWIN_TEST_HANG_LIB": str(lib)}


def _start(args: list[str], extra_env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO), **(extra_env or {})}
    return subprocess.Popen(
        [sys.executable, "-m", "twin", "simulate", *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def _wait_stuck(proc: subprocess.Popen[str], bag: Path) -> None:
    """Wait until the run has started recording (it is stuck soon after)."""
    deadline = time.monotonic() + 120
    while not any(bag.glob("*_0.*")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.05)
    time.sleep(2.0)


def test_a_tree_that_never_returns_ends_by_the_watchdog(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    proc = _start([str(DATA / "forever.yaml"), "--watchdog-s", "2", "--debug", "--out", str(bag)])
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 8, err
    line = assert_one_line_error(err, contains="has not returned for")
    assert "(watchdog)" in line and "tree node" in line and str(bag) in line
    assert "stuck main thread:" in err and "tick" in err  # --debug: the stuck stack
    assert_bag_reads_back(bag)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_tree_that_never_returns_stops_on_a_signal(tmp_path: Path, signum: int, code: int) -> None:
    bag = tmp_path / "bag"
    proc = _start([str(DATA / "forever.yaml"), "--out", str(bag)])  # default watchdog: 10 s
    _wait_stuck(proc, bag)
    rss0 = _rss_kib(proc.pid)
    time.sleep(1.0)
    rss1 = _rss_kib(proc.pid)
    assert rss1 - rss0 < 20_000, f"memory grows while stuck: {rss0} -> {rss1} KiB"
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert_one_line_error(err, contains=f"stopped by {signal.Signals(signum).name}")
    assert_bag_reads_back(bag)


def _kinematic(tmp_path: Path) -> str:
    scenario = tmp_path / "kinematic.yaml"
    scenario.write_text("name: kinematic\ndrive: {type: kinematic}\n")
    return str(scenario)


def _hung_fmu(tmp_path: Path) -> str:
    scenario = tmp_path / "hung_fmu.yaml"
    scenario.write_text(
        "name: hung_fmu\n"
        "drive:\n"
        "  type: fmu\n"
        f"  fmu_file: {faulty()}\n"
        "  profile: velocity-servo\n"
        f"  mapping: {{parameters: {{fault_mode: {FAULTS['hang']}, fault_time: 1.0}}}}\n"
        "  isolation: none\n"
    )
    return str(scenario)


def test_an_fmu_hung_in_do_step_ends_by_the_watchdog(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    proc = _start([_hung_fmu(tmp_path), "--duration", "30", "--watchdog-s", "2", "--out", str(bag)])
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 8, err
    line = assert_one_line_error(err, contains="has not returned for")
    assert "t=1.0" in line and str(bag) in line
    assert_bag_reads_back(bag)
    assert open_bag(bag).end_ns >= 900_000_000  # what was recorded before the hang is kept


def test_an_fmu_hung_in_do_step_stops_on_sigterm(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    proc = _start([_hung_fmu(tmp_path), "--duration", "30", "--out", str(bag)])  # default watchdog: 10 s
    _wait_stuck(proc, bag)
    rss0 = _rss_kib(proc.pid)
    time.sleep(1.0)
    assert _rss_kib(proc.pid) - rss0 < 20_000
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert_one_line_error(err, contains="stopped by SIGTERM")
    assert_bag_reads_back(bag)
    assert open_bag(bag).end_ns >= 900_000_000


def test_a_step_hung_in_c_ends_by_the_watchdog(tmp_path: Path, hang_env: dict[str, str]) -> None:
    bag = tmp_path / "bag"
    proc = _start([_kinematic(tmp_path), "--duration", "30", "--watchdog-s", "2", "--out", str(bag)], hang_env)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 8, err
    line = assert_one_line_error(err, contains="has not returned for")
    assert "advance" in line  # the function that called into C
    assert_bag_reads_back(bag)
    assert open_bag(bag).end_ns >= 900_000_000  # what was recorded before the hang is kept


def test_a_step_hung_in_c_stops_on_sigterm(tmp_path: Path, hang_env: dict[str, str]) -> None:
    bag = tmp_path / "bag"
    proc = _start([_kinematic(tmp_path), "--duration", "30", "--out", str(bag)], hang_env)  # watchdog: 10 s
    _wait_stuck(proc, bag)
    rss0 = _rss_kib(proc.pid)
    time.sleep(1.0)
    assert _rss_kib(proc.pid) - rss0 < 20_000
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert_one_line_error(err, contains="stopped by SIGTERM")
    assert_bag_reads_back(bag)
    assert open_bag(bag).end_ns >= 900_000_000
