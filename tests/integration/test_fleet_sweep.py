"""`twin sweep` over a fleet: each robot's result, time and contacts per run, and success only when every mission is."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.integration.fleet_helpers import ONE_GOAL_TREE
from tests.integration.sweep_helpers import read_table
from twin.analysis import run_metrics

GIVE_UP = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree"><AlwaysFailure name="give_up"/></BehaviorTree>
</root>
"""

BASE = """name: two_waffles
max_duration_s: 120
mission: {{tree: {tree}}}
robots:
  - name: robot1
    mission: {{locations: {goal1}}}
  - name: robot2
    robot: {{initial_pose: {{x_m: 1.5, y_m: -0.2, yaw_rad: 0.0}}}}
    mission: {{locations: {goal2}}}
"""


@pytest.fixture(scope="module")
def fleet_sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, str]], str]:
    tmp = tmp_path_factory.mktemp("fleet_sweep")
    (tmp / "tree.xml").write_text(ONE_GOAL_TREE)
    (tmp / "give_up.xml").write_text(GIVE_UP)
    (tmp / "g1.yaml").write_text("goal: [-1.0, -0.5, -2.25]\n")
    (tmp / "g2.yaml").write_text("goal: [4.0, 0.5, 1.571]\n")
    (tmp / "base.yaml").write_text(
        BASE.format(tree=tmp / "tree.xml", goal1=tmp / "g1.yaml", goal2=tmp / "g2.yaml"), encoding="utf-8"
    )
    sweep = tmp / "sweep.yaml"
    sweep.write_text(
        f"scenario: base.yaml\nvary:\n  robots[1].mission.tree: [{tmp / 'tree.xml'}, {tmp / 'give_up.xml'}]\n"
        "timeout_s: 300\n",
        encoding="utf-8",
    )
    out = tmp / "out"
    result = run_twin("sweep", str(sweep), "--workers", "1", "--keep-bags", "all", "--out", str(out))
    assert "2 runs: 1 succeeded" in result.stdout, (result.stdout, result.stderr)
    return out, read_table(out), (out / "summary.md").read_text(encoding="utf-8")


def test_each_robot_has_its_own_columns(fleet_sweep: tuple[Path, list[dict[str, str]], str]) -> None:
    _, rows, _ = fleet_sweep
    for ns in ("robot1", "robot2"):
        for column in ("result", "goals_reached", "goals", "mission_time_s", "path_length_m", "contacts"):
            assert f"{ns}.{column}" in rows[0], (ns, column)
    assert "robot_contacts" in rows[0]
    both, one_gave_up = rows
    assert (both["robot1.result"], both["robot2.result"]) == ("SUCCESS", "SUCCESS")
    assert (one_gave_up["robot1.result"], one_gave_up["robot2.result"]) == ("SUCCESS", "FAILURE")
    assert (both["robot2.goals_reached"], both["robot2.goals"]) == ("1", "1")
    assert one_gave_up["robot2.goals"] == "0"  # it never sent its goal


def test_a_run_succeeds_only_when_every_robots_mission_does(
    fleet_sweep: tuple[Path, list[dict[str, str]], str],
) -> None:
    _, rows, _ = fleet_sweep
    both, one_gave_up = rows
    assert both["outcome"] == "success"
    assert one_gave_up["outcome"] == "failure"
    assert "robot2" in one_gave_up["reason"] and "robot1" not in one_gave_up["reason"]


def test_each_robots_columns_are_what_its_own_topics_say(fleet_sweep: tuple[Path, list[dict[str, str]], str]) -> None:
    _, rows, _ = fleet_sweep
    for row in rows:
        times = []
        for ns in ("robot1", "robot2"):
            m = run_metrics(Path(row["bag_path"]), namespace=ns)
            assert int(row[f"{ns}.contacts"]) == m.contacts
            if m.mission_duration_s is not None:
                assert float(row[f"{ns}.mission_time_s"]) == pytest.approx(m.mission_duration_s)
                times.append(m.mission_duration_s)
        assert float(row["mission_time_s"]) == pytest.approx(max(times))  # the fleet's: its last robot's
        assert int(row["goals"]) == int(row["robot1.goals"]) + int(row["robot2.goals"])
    assert float(rows[0]["robot1.mission_time_s"]) != float(rows[0]["robot2.mission_time_s"])  # each its own


def test_the_summary_has_a_table_of_robots(fleet_sweep: tuple[Path, list[dict[str, str]], str]) -> None:
    _, _, summary = fleet_sweep
    assert "**Success rate: 1 of 2" in summary
    assert "## Robots" in summary
    lines = {line.split("|")[1].strip(): line for line in summary.splitlines() if line.startswith("| robot")}
    assert "2 of 2" in lines["robot1"] and "1 of 2" in lines["robot2"], lines


DONE = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree"><AlwaysSuccess name="done"/></BehaviorTree>
</root>
"""


def test_a_robot_whose_script_completes_has_succeeded(tmp_path: Path) -> None:
    """robot1 runs a cmd_vel script ("complete", no SUCCESS); robot2 a script, a tree that succeeds, one that fails."""
    (tmp_path / "done.xml").write_text(DONE)
    (tmp_path / "give_up.xml").write_text(GIVE_UP)
    (tmp_path / "base.yaml").write_text(
        "name: scripts\nmax_duration_s: 10\ndrive: {type: kinematic}\n"
        "mission: {type: cmd_vel_script, segments: [{duration_s: 1.0, linear_mps: 0.1}]}\n"
        "robots:\n  - name: robot1\n  - name: robot2\n    robot: {initial_pose: {x_m: 1.5, y_m: -0.2, yaw_rad: 0.0}}\n",
        encoding="utf-8",
    )
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(
        "scenario: base.yaml\nvary:\n  robots[1].mission:\n"
        "    - {type: cmd_vel_script, segments: [{duration_s: 0.5, angular_radps: 0.3}]}\n"
        "    - {type: behavior_tree, tree: done.xml}\n    - {type: behavior_tree, tree: give_up.xml}\n"
        "    - {type: cmd_vel_script, segments: [{duration_s: 30.0, angular_radps: 0.3}]}\n",
        encoding="utf-8",
    )
    out = tmp_path / "out"
    result = run_twin("sweep", str(sweep), "--workers", "1", "--out", str(out))
    assert result.returncode == 0, result.stderr
    rows = read_table(out)
    assert [(r["robot1.result"], r["robot2.result"]) for r in rows] == [
        ("complete", "complete"),
        ("complete", "SUCCESS"),
        ("complete", "FAILURE"),
        ("complete", "running"),
    ]
    assert [r["outcome"] for r in rows] == ["success", "success", "failure", "failure"]
    assert "robot2" in rows[2]["reason"] and "robot1" not in rows[2]["reason"]
    # Cut short by max_duration_s: the reason names the robot whose mission had not ended, and only it.
    assert "max_duration_s reached" in rows[3]["reason"] and "robot2 running" in rows[3]["reason"], rows[3]
    assert "robot1" not in rows[3]["reason"]
    # A fleet's goals count its robots with a tree; a script's robot has none, so no blank total.
    assert [(r["goals"], r["recoveries"]) for r in rows[1:3]] == [("0", "0"), ("0", "0")]
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "**Success rate: 2 of 4" in summary
    lines = {line.split("|")[1].strip(): line for line in summary.splitlines() if line.startswith("| robot")}
    assert "4 of 4" in lines["robot1"] and "2 of 4" in lines["robot2"], lines
