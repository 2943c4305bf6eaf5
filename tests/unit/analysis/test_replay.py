"""`twin replay` and the `type: replay` mission on the real Gazebo bag; compare's one-line refusals."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.analysis.test_analyze_cli import _copy_topics, _one_line_error
from twin.analysis.compare import compare_bags
from twin.bag import read_messages


def _replay(fixtures: Path, gazebo_bag: Path, out: Path, drive: str) -> dict:
    proc = run_twin(
        "replay",
        str(gazebo_bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
        "--model-path",
        str(fixtures / "gazebo_classic" / "models"),
        "--drive",
        drive,
        "--out",
        str(out),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _odom(bag: Path, topic: str) -> list[tuple[float, float, float]]:
    rows = []
    for m in read_messages(bag, [topic]):
        s = m.msg.header.stamp
        rows.append((s.sec + s.nanosec * 1e-9, m.msg.pose.pose.position.x, m.msg.pose.pose.position.y))
    return rows


def _error_at(src: list, twin: list, t_rel: float) -> float:
    """Position error at t_rel s after each bag's first pose, by linear interpolation in each."""

    def at(rows: list, t: float) -> tuple[float, float]:
        t0 = rows[0][0]
        for (ta, xa, ya), (tb, xb, yb) in itertools.pairwise(rows):
            if ta - t0 <= t <= tb - t0:
                f = (t - (ta - t0)) / (tb - ta)
                return xa + f * (xb - xa), ya + f * (yb - ya)
        return rows[-1][1], rows[-1][2]

    return math.dist(at(src, t_rel), at(twin, t_rel))


@pytest.fixture(scope="module")
def kinematic_replay(fixtures: Path, gazebo_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("replay_kinematic")
    return _replay(fixtures, gazebo_bag, out, "kinematic"), out


def test_kinematic_replay_of_the_gazebo_bag_stays_within_5_cm(
    kinematic_replay: tuple[dict, Path], gazebo_bag: Path
) -> None:
    result, out = kinematic_replay
    assert result["robot"] == "turtlebot3_waffle_pi"  # from the bag's /robot_description
    src = _odom(gazebo_bag, "/odom")
    twin = _odom(out / "bag", "/ground_truth/odom")
    end = src[-1][0] - src[0][0]
    assert end > 25.0
    assert _error_at(src, twin, 25.0) <= 0.05
    assert _error_at(src, twin, end) <= 0.05
    # The reported comparison says the same.
    assert result["position_error_final_m"] == pytest.approx(_error_at(src, twin, result["matched_span_s"]), abs=1e-6)
    assert result["position_error_max_m"] <= 0.05
    assert (out / "overlay.png").exists() and (out / "scenario.yaml").exists()


def test_replay_starts_at_the_bags_first_pose(kinematic_replay: tuple[dict, Path], gazebo_bag: Path) -> None:
    _, out = kinematic_replay
    first_src = _odom(gazebo_bag, "/odom")[0]
    first_twin = _odom(out / "bag", "/ground_truth/odom")[0]
    assert math.dist(first_src[1:], first_twin[1:]) < 1e-9


def test_fmu_replay_figure(fixtures: Path, gazebo_bag: Path, tmp_path: Path) -> None:
    result = _replay(fixtures, gazebo_bag, tmp_path / "fmu", "fmu")
    src = _odom(gazebo_bag, "/odom")
    twin = _odom(tmp_path / "fmu" / "bag", "/ground_truth/odom")
    at_25, at_end = _error_at(src, twin, 25.0), _error_at(src, twin, src[-1][0] - src[0][0])
    # Measured: 4 cm at 25 s and 11 cm at the end (the XM430 FMU turns more slowly than Gazebo's
    # ideal diff drive in the final turns); a regression guard, not the kinematic 5 cm.
    assert at_25 <= 0.06
    assert at_end <= 0.15
    assert result["drive"] == "fmu"


def test_scenario_file_replay_mission_runs_under_simulate(fixtures: Path, gazebo_bag: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "replay.yaml"
    scenario.write_text(
        "name: replay_test\n"
        f"world: {{sdf: {fixtures}/gazebo_classic/worlds/turtlebot3_world.world, "
        f"model_path: [{fixtures}/gazebo_classic/models]}}\n"
        "robot: {model: turtlebot3_waffle_pi}\n"
        f"mission: {{type: replay, bag: {gazebo_bag}, topic: /cmd_vel}}\n"
    )
    proc = run_twin("simulate", str(scenario), "--out", str(tmp_path / "run"), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["ended_by"] == "mission complete"
    result = compare_bags(gazebo_bag, tmp_path / "run", topics=("/odom", "/ground_truth/odom"))
    assert result.final_position_error_m <= 0.05


def test_replay_bag_without_cmd_vel_is_one_line(fixtures: Path, twin_bag: Path, tmp_path: Path) -> None:
    bag = _copy_topics(twin_bag, tmp_path / "no_cmd", ["/odom", "/clock"])
    proc = run_twin(
        "replay",
        str(bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
        "--model-path",
        str(fixtures / "gazebo_classic" / "models"),
        "--out",
        str(tmp_path / "out"),
    )
    line = _one_line_error(proc)
    assert "/cmd_vel" in line and str(bag) in line


def test_compare_without_common_pose_topic_is_one_line(twin_bag: Path, tmp_path: Path) -> None:
    a = _copy_topics(twin_bag, tmp_path / "a", ["/odom"])
    b = _copy_topics(twin_bag, tmp_path / "b", ["/ground_truth/odom"])
    line = _one_line_error(run_twin("analyze", "compare", str(a), str(b)))
    assert "--topic" in line and "no pose topic" in line


def test_compare_exit_code_follows_the_threshold(twin_bag: Path, tmp_path: Path) -> None:
    other = tmp_path / "seed3"
    assert run_twin("simulate", "--duration", "20", "--seed", "3", "--out", str(other)).returncode == 0
    result = compare_bags(twin_bag, other)
    loose = run_twin("analyze", "compare", str(twin_bag), str(other), "--max-position-error", "1.0")
    tight = run_twin("analyze", "compare", str(twin_bag), str(other), "--max-position-error", "1e-9")
    assert loose.returncode == 0, loose.stderr
    assert tight.returncode == 1, tight.stderr
    assert result.max_position_error_m > 1e-9


def test_replayed_commands_match_the_bags_at_their_sim_times(
    kinematic_replay: tuple[dict, Path], gazebo_bag: Path
) -> None:
    _, out = kinematic_replay
    result = compare_bags(gazebo_bag, out / "bag", topics=("/odom", "/ground_truth/odom"))
    cmd = {f["field"]: f for f in result.fields if f["topic"] == "/cmd_vel"}
    # Held commands on one sim clock: equal but within the 5 ms the loop may apply them late.
    assert cmd["linear.x"]["rms_diff"] < 1e-3
    assert cmd["angular.z"]["rms_diff"] < 1e-3
