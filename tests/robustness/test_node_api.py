"""The node API's edge cases, as a demanding user meets them.

Found by probing: `sys.exit(3)` in a callback ended `twin simulate` with exit 3 (the world-error
code) and no output, `sys.exit(0)` with exit 0 and no summary; `create_timer(1e-12)` rounded to a
0 ns period and fired once; a timer created inside a callback never fired (rclpy fires both);
`twin graph` had no watchdog (a spinning node hung it) and a node stuck in `__init__` hung
`simulate`. Now: a node's `SystemExit` is a node fault (exit 8, naming node, callback and sim time);
timers keep rclpy's rules; both commands end a stuck node by the watchdog, in one line.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from twin.bag import read_messages
from twin.cli import main

_MODULE = """
import os, sys, time
from twin.msgs import String
from twin.node import Node

class Quitter(Node):
    def __init__(self):
        super().__init__("quitter")
        self.code = self.declare_parameter("code", 3).value
        self.create_timer(1.0, self.on_timer)

    def on_timer(self):
        sys.exit(self.code)

class Tiny(Node):
    def __init__(self):
        super().__init__("tiny")
        self.create_timer(1e-12, lambda: None)

class Late(Node):
    '''Creates a 0.2 s timer in its first callback (at 0.5 s).'''

    def __init__(self):
        super().__init__("late")
        self.pub = self.create_publisher(String, "/chatter", 10)
        self.first = self.create_timer(0.5, self.on_first)

    def on_first(self):
        self.destroy_timer(self.first)
        self.create_timer(0.2, self.on_late)

    def on_late(self):
        self.pub.publish(String(data=str(self.get_clock().now().nanoseconds)))

class Fast(Node):
    '''A 1 us timer: shorter than the 1 ms physics step.'''

    def __init__(self):
        super().__init__("fast")
        self.pub = self.create_publisher(String, "/chatter", 10)
        self.create_timer(1e-6, lambda: self.pub.publish(String(data="x")))

class Spinner(Node):
    def __init__(self):
        super().__init__("spinner")
        self.create_timer(0.5, self.on_timer)

    def on_timer(self):
        while True:
            pass

class NoSuper(Node):
    def __init__(self):
        self.ready = True  # forgot super().__init__("no_super")

class StuckInit(Node):
    def __init__(self):
        super().__init__("stuck_init")
        ready = os.environ.get("TWIN_TEST_READY")
        if ready:
            open(ready, "w").close()
        if os.environ.get("TWIN_TEST_HOW") == "sleep":
            time.sleep(3600)  # in C: the watchdog cannot unwind it, it ends the process
        while True:
            pass
"""


def _scenario(folder: Path, nodes: str) -> Path:
    (folder / "api_nodes.py").write_text(_MODULE)
    path = folder / "scenario.yaml"
    path.write_text(
        "name: node_api\nmission: {type: none}\nlocalization: {type: none}\ndrive: {type: kinematic}\n"
        + "nodes:\n"
        + textwrap.indent(textwrap.dedent(nodes), "  ")
    )
    return path


@pytest.mark.parametrize("code", [3, 0])
def test_sys_exit_in_a_callback_is_a_node_fault(code: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(tmp_path, f"- plugin: api_nodes:Quitter\n  parameters: {{code: {code}}}\n")
    bag = tmp_path / "bag"
    exit_code = main(["simulate", str(scenario), "--duration", "10", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert exit_code == 8, err
    assert_one_line_error(
        err, contains=f"node quitter: timer callback Quitter.on_timer called sys.exit({code}) at t=1.000 s"
    )
    assert_bag_reads_back(bag)


@pytest.mark.parametrize(
    ("nodes", "message"),
    [
        # was an internal error (AttributeError: no attribute '_namespace'), exit 70
        ("- plugin: api_nodes:NoSuper\n", "nodes[0]: NoSuper.__init__ does not call super().__init__('node_name')"),
        # was run as `/bad ns/fast`, a name no ROS tool takes
        ("- {plugin: api_nodes:Fast, namespace: 'bad ns'}\n", "node fast: namespace '/bad ns' is not a ROS namespace"),
    ],
)
def test_a_node_that_is_not_set_up_as_a_node_is_refused(
    nodes: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, nodes)
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "1", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert_one_line_error(err, contains=message)
    assert not bag.exists()


def test_a_timer_period_below_a_nanosecond_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:Tiny\n")
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "1", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert_one_line_error(err, contains="node tiny: timer period 1e-12 s is below the clock's resolution (1 ns)")
    assert not bag.exists()


def test_a_timer_created_in_a_callback_fires_one_period_later(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:Late\n")
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "2", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 0, err
    stamps = [m.t_ns for m in read_messages(bag, topics=["/chatter"])]
    assert stamps == [700_000_000 + 200_000_000 * i for i in range(7)]  # 0.7 .. 1.9 s


def test_a_timer_shorter_than_a_step_fires_once_a_step(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:Fast\n")
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "0.1", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 0, err
    stamps = [m.t_ns for m in read_messages(bag, topics=["/chatter"])]
    assert stamps == [1_000_000 * k for k in range(1, 100)]  # one per 1 ms step, as rclpy skips missed periods


def _twin(args: list[str], extra_env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO), **(extra_env or {})}
    return subprocess.Popen(
        [sys.executable, "-m", "twin", *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_twin_graph_ends_a_spinning_callback_by_the_watchdog(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:Spinner\n")
    proc = _twin(["graph", str(scenario), "--measure-s", "2", "--watchdog-s", "2"])
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 8, err
    line = assert_one_line_error(err, contains="the step at t=0.500 s has not returned for")
    assert "Spinner.on_timer" in line or "on_timer" in line


@pytest.mark.parametrize("command", ["simulate", "graph"])
@pytest.mark.parametrize("how", ["python", "sleep"])
def test_a_node_stuck_in_its_constructor_ends_by_the_watchdog(command: str, how: str, tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:StuckInit\n")
    bag = tmp_path / "bag"
    args = [command, str(scenario), "--watchdog-s", "2"]
    args += ["--out", str(bag)] if command == "simulate" else ["--measure-s", "1"]
    proc = _twin(args, {"TWIN_TEST_HOW": how})
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 8, err
    assert_one_line_error(err, contains="the constructor of node class StuckInit has not returned for")
    assert "nothing was recorded" in err
    assert not bag.exists()


def test_sigterm_during_start_up_stops_it_at_once_with_no_half_made_bag(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, "- plugin: api_nodes:StuckInit\n")
    bag, ready = tmp_path / "bag", tmp_path / "ready"
    proc = _twin(
        ["simulate", str(scenario), "--watchdog-s", "inf", "--out", str(bag)],
        {"TWIN_TEST_HOW": "sleep", "TWIN_TEST_READY": str(ready)},
    )
    try:
        deadline = time.monotonic() + 300  # generous: only bounds a broken start-up
        while not ready.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ready.exists(), proc.stderr.read() if proc.stderr else ""
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert_one_line_error(err, contains="stopped by SIGTERM before the run started; nothing was recorded")
    assert not bag.exists()


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        ("{code: .nan}", "parameters.code: is NaN"),
        ("{gains: [1.0, 1.0e+300]}", "parameters.gains[1]: 1e+300 is out of range"),
    ],
)
def test_a_node_parameter_that_is_no_usable_number_is_refused(
    parameters: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Every other number of a scenario was checked; a node's parameters reached declare_parameter as they were
    scenario = _scenario(tmp_path, f"- plugin: api_nodes:Quitter\n  parameters: {parameters}\n")
    for argv in (["scenario", "check", str(scenario)], ["simulate", str(scenario), "--out", str(tmp_path / "bag")]):
        assert main(argv) == 2
        assert_one_line_error(capsys.readouterr().err, contains=expected)
    assert not (tmp_path / "bag").exists()
