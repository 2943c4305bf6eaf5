"""Robots that are not TurtleBot3s in a run: what their SDF leaves out or names otherwise.

A sensor with no `<update_rate>`, a robot whose links all move, a model named by a path beside the
scenario, Nav2 params naming frames the robot does not have, a model with no drive: each is run
(or refused) as a user would meet it, through `twin.cli.main`.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO
from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from twin.bag import open_bag, read_messages
from twin.bag.provenance import read_provenance
from twin.cli import main
from twin.nav.params import default_params_path

WAFFLE_PARAMS = default_params_path("waffle")

_WHEEL = """
    <link name="{side}_wheel">
      <pose>0 {y} 0.05 -1.5708 0 0</pose>
      <collision name="c"><geometry><cylinder><radius>0.05</radius><length>0.02</length></cylinder></geometry></collision>
    </link>
    <joint name="{side}_wheel_joint" type="revolute">
      <parent>chassis</parent><child>{side}_wheel</child><axis><xyz>0 0 1</xyz></axis>
    </joint>"""


def _robot(folder: Path, *, lidar_rate: str = "<update_rate>5</update_rate>", scan_link: bool = True) -> Path:
    """A two-wheeled robot whose base is `chassis` (no `base_link`), a lidar on its own fixed link or on the chassis."""
    ray = (
        f'<sensor name="laser" type="ray">{lidar_rate}<ray><scan><horizontal><samples>90</samples>'
        "<min_angle>-3.14</min_angle><max_angle>3.14</max_angle></horizontal></scan>"
        '<range><min>0.1</min><max>3.5</max></range></ray><plugin name="laser" filename="libgazebo_ros_ray_sensor.so">'
        "<ros><remapping>~/out:=scan</remapping></ros></plugin></sensor>"
    )
    scanner = (
        f'<link name="scanner"><pose>0 0 0.2 0 0 0</pose>{ray}</link>'
        '<joint name="scanner_joint" type="fixed"><parent>chassis</parent><child>scanner</child></joint>'
    )
    text = f"""<?xml version="1.0"?>
<sdf version="1.7">
  <model name="rover">
    <link name="chassis">
      <pose>0 0 0.1 0 0 0</pose>
      <inertial><mass>3</mass><inertia><ixx>0.02</ixx><iyy>0.02</iyy><izz>0.03</izz></inertia></inertial>
      <collision name="c"><geometry><box><size>0.2 0.2 0.08</size></box></geometry></collision>
      {"" if scan_link else ray}
    </link>
    {scanner if scan_link else ""}
    {_WHEEL.format(side="left", y=0.12)}
    {_WHEEL.format(side="right", y=-0.12)}
  </model>
</sdf>
"""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "model.sdf"
    path.write_text(text)
    return path


def _scenario(folder: Path, values: dict[str, object]) -> Path:
    path = folder / "scenario.yaml"
    path.write_text(yaml.safe_dump({"name": "rover", **values}))
    return path


def _script() -> dict[str, object]:
    return {"type": "cmd_vel_script", "segments": [{"duration_s": 2.0, "linear_mps": 0.1, "angular_radps": 0.2}]}


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def _counts(bag: Path) -> dict[str, int]:
    assert_bag_reads_back(bag)
    return {t.name: t.message_count for t in open_bag(bag).topics}


def test_a_lidar_without_update_rate_scans_every_physics_step_as_gazebo_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _robot(tmp_path / "rover", lidar_rate="")
    path = _scenario(tmp_path, {"robot": {"model": "rover/model.sdf"}, "mission": _script(), "max_duration_s": 3.0})
    code, _, err = _run(["simulate", str(path), "--duration", "0.5", "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    assert "lidar 'laser' has no <update_rate> (or 0): it updates at every physics step, 1000 Hz" in err
    assert _counts(tmp_path / "bag")["/scan"] == 500  # every 1 ms step of the 0.5 s


def test_a_robot_whose_links_all_move_runs_with_amcl(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Every link on a moving joint and AMCL publishing map->odom: no fixed transform is left to send.
    _robot(tmp_path / "rover", scan_link=False)
    values = {
        "robot": {"model": "rover/model.sdf"},
        "mission": _script(),
        "localization": {"type": "amcl"},
        "navigation": {"params": str(WAFFLE_PARAMS), "set": {"amcl.base_frame_id": "chassis"}},
    }
    path = _scenario(tmp_path, values)
    code, _, err = _run(["simulate", str(path), "--duration", "1", "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    counts = _counts(tmp_path / "bag")
    assert counts.get("/tf_static", 0) == 0 and counts["/robot_description"] == 1


def test_a_model_path_is_relative_to_the_scenario_not_the_working_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _robot(tmp_path / "models" / "rover")
    folder = tmp_path / "scenarios"
    folder.mkdir()
    path = _scenario(folder, {"robot": {"model": "../models/rover/model.sdf"}, "mission": _script()})
    (tmp_path / "elsewhere" / "deeper").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "elsewhere" / "deeper")  # where ../models/... names nothing
    code, _, err = _run(["scenario", "check", str(path)], capsys)
    assert code == 0, err
    # run by a relative path: the bag records the model's absolute path (rerun from anywhere)
    relative = Path("..") / ".." / "scenarios" / "scenario.yaml"
    code, _, err = _run(["simulate", str(relative), "--duration", "0.5", "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    recorded = yaml.safe_load(read_provenance(tmp_path / "bag")["scenario_yaml"])  # type: ignore[index]
    assert recorded["robot"]["model"] == str(tmp_path / "models" / "rover" / "model.sdf")


def test_nav2_params_naming_a_frame_the_robot_lacks_are_refused_by_check_and_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The TurtleBot3 params look up base_link; this robot's base is chassis: Nav2 would wait forever.
    _robot(tmp_path / "rover")
    path = _scenario(tmp_path, {"robot": {"model": "rover/model.sdf"}, "navigation": {"params": str(WAFFLE_PARAMS)}})
    for argv in (["scenario", "check", str(path)], ["simulate", str(path), "--out", str(tmp_path / "bag")]):
        code, _, err = _run(argv, capsys)
        assert code == 2, err
        assert_one_line_error(err, contains="'base_link' is no frame of the run's TF tree")
        assert "robot_base_frame" in err and "base frame is 'chassis'" in err
    assert not (tmp_path / "bag").exists()


def test_a_model_with_no_drive_is_refused_by_check_and_run_naming_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = _robot(tmp_path / "rover")
    model.write_text(
        model.read_text().replace("left_wheel_joint", "front_axle").replace("right_wheel_joint", "rear_axle")
    )
    path = _scenario(tmp_path, {"robot": {"model": "rover/model.sdf"}, "mission": _script()})
    for argv in (["scenario", "check", str(path)], ["simulate", str(path), "--out", str(tmp_path / "bag")]):
        code, _, err = _run(argv, capsys)
        assert code == 3, err
        assert_one_line_error(err, contains="has no differential drive the twin can run")
        assert "robot.model:" in err and "'left'/'right'" in err


def test_a_gz_diff_drives_speed_limits_clamp_the_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = _robot(tmp_path / "rover")
    drive = (
        '<plugin name="gz::sim::systems::DiffDrive" filename="libgz-sim8-diff-drive-system.so">'
        "<left_joint>left_wheel_joint</left_joint><right_joint>right_wheel_joint</right_joint>"
        "<wheel_separation>0.24</wheel_separation><wheel_radius>0.05</wheel_radius>"
        "<max_linear_velocity>0.3</max_linear_velocity><max_angular_velocity>0.5</max_angular_velocity>"
        "</plugin>"
    )
    model.write_text(model.read_text().replace("  </model>", f"    {drive}\n  </model>"))
    segments = [
        {"duration_s": 3.0, "linear_mps": 1.0, "angular_radps": 2.0},
        {"duration_s": 3.0, "linear_mps": -0.5, "angular_radps": -1.0},  # no min_ given: reversing is free
    ]
    mission = {"type": "cmd_vel_script", "segments": segments}
    values = {"robot": {"model": "rover/model.sdf"}, "mission": mission, "drive": {"type": "kinematic"}}
    code, _, err = _run(["simulate", str(_scenario(tmp_path, values)), "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    twists = [m.msg.twist.twist for m in read_messages(tmp_path / "bag") if m.topic == "/ground_truth/odom"]
    assert max(t.linear.x for t in twists) == pytest.approx(0.3)
    assert max(t.angular.z for t in twists) == pytest.approx(0.5)
    assert min(t.linear.x for t in twists) == pytest.approx(-0.5) and min(t.angular.z for t in twists) == pytest.approx(
        -1.0
    )


def test_fmu_auto_on_a_robot_that_is_no_turtlebot3_says_whose_motors_it_gets(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _robot(tmp_path / "rover")
    path = _scenario(tmp_path, {"robot": {"model": "rover/model.sdf"}, "mission": _script(), "drive": {"type": "fmu"}})
    code, _, err = _run(["simulate", str(path), "--duration", "0.2", "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    assert "robot rover (3 kg) is no TurtleBot3: drive.fmu: auto gives it a TurtleBot3's wheel motors" in err


def test_several_wheel_pairs_all_turn_on_joint_states_and_tf(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # gz-sim's DiffDrive with a repeated <left_joint>/<right_joint> drives two pairs (a Husky's).
    model = _robot(tmp_path / "rover")
    rear = _WHEEL.format(side="rear_left", y=0.12) + _WHEEL.format(side="rear_right", y=-0.12)
    drive = (
        '<plugin name="gz::sim::systems::DiffDrive" filename="gz-sim-diff-drive-system">'
        "<left_joint>left_wheel_joint</left_joint><left_joint>rear_left_wheel_joint</left_joint>"
        "<right_joint>right_wheel_joint</right_joint><right_joint>rear_right_wheel_joint</right_joint>"
        "<wheel_separation>0.24</wheel_separation><wheel_radius>0.05</wheel_radius></plugin>"
    )
    model.write_text(model.read_text().replace("  </model>", f"{rear}\n    {drive}\n  </model>"))
    mission = {"type": "cmd_vel_script", "segments": [{"duration_s": 2.0, "linear_mps": 0.1, "angular_radps": 0.5}]}
    values = {"robot": {"model": "rover/model.sdf"}, "mission": mission, "drive": {"type": "kinematic"}}
    code, _, err = _run(["simulate", str(_scenario(tmp_path, values)), "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err
    states = [m.msg for m in read_messages(tmp_path / "bag", ["/joint_states"])]
    names = ["left_wheel_joint", "right_wheel_joint", "rear_left_wheel_joint", "rear_right_wheel_joint"]
    assert list(states[-1].name) == names
    left, right, rear_left, rear_right = states[-1].position
    assert (rear_left, rear_right) == (left, right) and left != right  # turning: the sides differ
    wheels = {t.child_frame_id for m in read_messages(tmp_path / "bag", ["/tf"]) for t in m.msg.transforms}
    assert {"left_wheel", "right_wheel", "rear_left_wheel", "rear_right_wheel"} <= wheels


def test_a_fleet_robots_frames_may_carry_its_own_prefix_and_no_other() -> None:
    from twin.nav.params import load_nav2_params
    from twin.sim.navigation import frame_problem
    from twin.world import load_robot

    waffle = load_robot(REPO / "sdf" / "models" / "turtlebot3_waffle")
    for value, refused in (("base_link", False), ("robot1/base_link", False), ("robot2/base_link", True)):
        params = load_nav2_params(WAFFLE_PARAMS, overrides={"local_costmap.robot_base_frame": value})
        problem = frame_problem(params, waffle, amcl=True, nav2=True, namespace="robot1")
        assert (problem is not None) == refused, (value, problem)
    assert frame_problem(load_nav2_params(WAFFLE_PARAMS), waffle, amcl=True, nav2=True) is None
