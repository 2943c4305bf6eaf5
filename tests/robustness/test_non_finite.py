"""A user's node publishing NaN or infinity where the twin's own nodes read numbers.

Found by probing: a node publishing `Twist(linear.x=nan)` every 0.1 s with `mission: {type: none}`
ran to exit 0 with no warning while the FMU drive went to its 0.266 m/s limit and the kinematic one
accelerated into a wall. Now such a message never reaches the twin's nodes (the drive holds its last
finite command, as Nav2's velocity smoother drops a NaN Twist), one warning names the publisher, the
summary counts them, the bag still records what was published, and `non_finite_messages: error`
ends the run with exit 8.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from twin.bag import read_messages
from twin.cli import main

_MODULE = """
from twin.msgs import PoseWithCovarianceStamped, Twist
from twin.node import Node

class NanDriver(Node):
    '''One finite command (0.1 m/s) at 0.1 s, then a non-finite one every 0.1 s.'''

    def __init__(self):
        super().__init__("nan_driver")
        self.declare_parameter("bad", "nan")
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_timer(0.1, self.on_timer)
        self.n = 0

    def on_timer(self):
        self.n += 1
        msg = Twist()
        msg.linear.x = 0.1 if self.n == 1 else float(self.get_parameter("bad").value)
        self.pub.publish(msg)

class NanPose(Node):
    def __init__(self):
        super().__init__("nan_pose")
        self.pub = self.create_publisher(PoseWithCovarianceStamped, "/initialpose", 10)
        self.create_timer(0.5, self.on_timer)

    def on_timer(self):
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = "map"
        msg.pose.pose.position.x = float("nan")
        msg.pose.pose.orientation.w = 1.0
        self.pub.publish(msg)
"""


def _scenario(folder: Path, body: str) -> Path:
    (folder / "bad_nodes.py").write_text(_MODULE)
    path = folder / "scenario.yaml"
    path.write_text("name: non_finite\n" + textwrap.dedent(body))
    return path


def _final_x(bag: Path) -> float:
    odom = [m.msg for m in read_messages(bag, topics=["/ground_truth/odom"])]
    return float(odom[-1].pose.pose.position.x)


@pytest.mark.parametrize("drive", ["kinematic", "fmu"])
@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_a_non_finite_cmd_vel_is_refused_and_the_drive_holds_its_last_command(
    drive: str, bad: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(
        tmp_path,
        f"""\
        mission: {{type: none}}
        localization: {{type: none}}
        drive: {{type: {drive}}}
        nodes:
          - plugin: bad_nodes:NanDriver
            parameters: {{bad: "{bad}"}}
        """,
    )
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "3", "--out", str(bag), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "nan_driver" in line]
    assert len(warnings) == 1, err  # once, naming the publisher
    assert f"node nan_driver published linear.x = {float(bad)} on /cmd_vel at t=0.200 s: refused" in warnings[0]
    summary = json.loads(out)
    assert summary["refused_messages"] == {"/cmd_vel": 28}  # 0.2 s .. 2.9 s
    # The bag records what the node published; the drive held 0.1 m/s (not the FMU's 0.266 m/s limit).
    commands = [m.msg.linear.x for m in read_messages(bag, topics=["/cmd_vel"])]
    assert len(commands) == 29 and commands[0] == 0.1 and all(not math.isfinite(v) for v in commands[1:])
    assert 0.2 < _final_x(bag) < 0.3  # 0.1 m/s for 2.9 s, less the wheels' ramp
    assert_bag_reads_back(bag)


def test_the_summary_line_counts_the_refused_messages(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(
        tmp_path,
        """\
        mission: {type: none}
        localization: {type: none}
        drive: {type: kinematic}
        nodes: [{plugin: bad_nodes:NanDriver}]
        """,
    )
    code = main(["simulate", str(scenario), "--duration", "1", "--out", str(tmp_path / "bag")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "8 non-finite messages refused (8 on /cmd_vel)" in out


def test_non_finite_messages_error_ends_the_run_with_exit_8(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(
        tmp_path,
        """\
        mission: {type: none}
        localization: {type: none}
        drive: {type: kinematic}
        non_finite_messages: error
        nodes: [{plugin: bad_nodes:NanDriver}]
        """,
    )
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "3", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 8, err
    assert_one_line_error(err, contains="node nan_driver published linear.x = nan on /cmd_vel at t=0.200 s")
    assert_bag_reads_back(bag)


def test_a_non_finite_initial_pose_never_reaches_amcl(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(
        tmp_path,
        """\
        mission: {type: none}
        localization: {type: amcl}
        drive: {type: kinematic}
        nodes: [{plugin: bad_nodes:NanPose}]
        """,
    )
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "2", "--out", str(bag), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "node nan_pose published pose.pose.position.x = nan on /initialpose at t=0.500 s: refused" in err
    assert json.loads(out)["refused_messages"] == {"/initialpose": 3}  # 0.5, 1.0, 1.5 s
    # AMCL still localises from the scenario's own initial pose: /amcl_pose stays finite.
    poses = [m.msg.pose.pose.position for m in read_messages(bag, topics=["/amcl_pose"])]
    assert poses and all(math.isfinite(p.x) and math.isfinite(p.y) for p in poses)


def test_a_replayed_bags_non_finite_commands_are_skipped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    # A recorded /cmd_vel with NaN (another robot's bag) reaches the drive through the replay mission,
    # not a user's node: it is refused the same way, the drive keeping the command before it.
    import numpy as np

    from twin.sim import mission
    from twin.sim.replay import RecordedCommands
    from twin.sim.scenario import ReplayMission

    recorded = RecordedCommands(
        t_ns=np.array([0, 100_000_000, 200_000_000, 300_000_000], dtype=np.int64),
        v_mps=np.array([0.1, float("nan"), 0.2, float("inf")]),
        w_radps=np.array([0.0, 0.0, 0.1, 0.0]),
        start_pose=(0.0, 0.0, 0.0),
        start_velocity=(float("nan"), 0.0),
        end_ns=1_000_000_000,
        pose_topic="/odom",
        time_source="header stamps",
    )
    monkeypatch.setattr(mission, "load_commands", lambda spec: recorded)
    replay = mission.BagReplay(ReplayMission(bag=tmp_path / "bag"))
    assert "2 of 4 commands on /cmd_vel hold NaN or infinity (the first at 0.100 s: nan, 0.0): skipped" in caplog.text
    times_ns = (0, 150_000_000, 250_000_000, 350_000_000)
    # Each finite command is sent once, when due; a skipped one sends nothing, so the drive holds the one before.
    assert [replay.command(t, 0.0, 0.0, 0.0) for t in times_ns] == [(0.1, 0.0), None, (0.2, 0.1), None]
    assert [replay.command_in_force(t) for t in times_ns] == [(0.1, 0.0), (0.1, 0.0), (0.2, 0.1), (0.2, 0.1)]
