"""The navigation nodes' pure parts: Nav2's cost translation, frames, the servers' parameters, path smoothing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.core.errors import ConfigError
from twin.nav.controller.checkers import SimpleGoalChecker, StoppedGoalChecker
from twin.nav.controller.dwb.dwb_params import DwbParams
from twin.nav.costmap_2d.costmap_node import costmap_translation
from twin.nav.frames import Frames, compose, invert
from twin.nav.params import default_params_path, load_nav2_params
from twin.nav.server_params import nav2_config
from twin.nav.smoother.simple_smoother import smooth_path
from twin.nav.velocity_smoother.velocity_smoother import Feedback


def test_costmap_translation_is_nav2s_table() -> None:
    table = costmap_translation()
    assert table[0] == 0 and table[253] == 99 and table[254] == 100 and table[255] == -1
    assert table[1] == 1 and table[252] == 98  # 1 + 97 (c - 1) / 251, integer division
    assert table[128] == 1 + (97 * 127) // 251
    assert np.all(np.diff(table[:255].astype(int)) >= 0)


def test_compose_and_invert_are_planar_transforms() -> None:
    a = (1.0, 2.0, 0.5)
    b = (0.3, -0.4, 1.2)
    ab = compose(a, b)
    back = compose(invert(a), ab)
    assert back == pytest.approx(b)
    assert compose(a, invert(a)) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # a point 1 m ahead of a robot facing +y lies at +y
    assert compose((0.0, 0.0, math.pi / 2), (1.0, 0.0, 0.0))[:2] == pytest.approx((0.0, 1.0))


def test_frames_give_the_map_pose_through_map_to_odom() -> None:
    frames = Frames()
    frames.map_odom = (1.0, 0.0, math.pi / 2)
    frames.odom_pose = (2.0, 0.0, 0.0)
    assert frames.map_pose() == pytest.approx((1.0, 2.0, math.pi / 2))
    assert frames.map_to_odom(frames.map_pose()) == pytest.approx(frames.odom_pose)


def test_tb3_params_give_nav2s_server_values() -> None:
    cfg = nav2_config(load_nav2_params(default_params_path("waffle")))
    assert cfg.controller_frequency_hz == 10.0 and cfg.failure_tolerance_s == 0.3
    assert list(cfg.controllers) == ["FollowPath"] and cfg.controllers["FollowPath"][0] == "dwb_core::DWBLocalPlanner"
    checker = cfg.goal_checkers["general_goal_checker"]
    assert (checker.xy_goal_tolerance_m, checker.yaw_goal_tolerance_rad, checker.stateful) == (0.25, 0.25, True)
    assert (cfg.progress_radius_m, cfg.progress_allowance_s) == (0.5, 10.0)
    assert (cfg.planner.tolerance_m, cfg.planner.use_astar, cfg.planner.allow_unknown) == (0.5, False, True)
    assert cfg.bt_loop_duration_s == pytest.approx(0.01)
    # no velocity_smoother or behavior_server section in TB3's file: Humble's code defaults
    assert cfg.smoother.smoothing_frequency_hz == 20.0 and cfg.smoother.max_velocity == (0.5, 0.0, 2.5)
    assert cfg.behaviors.cycle_frequency_hz == 10.0


def test_stopped_goal_and_pose_progress_checkers_are_taken_as_plugins() -> None:
    overrides = {
        "controller_server.general_goal_checker.plugin": "nav2_controller::StoppedGoalChecker",
        "controller_server.general_goal_checker.trans_stopped_velocity": 0.05,
        "controller_server.progress_checker.plugin": "nav2_controller::PoseProgressChecker",
        "controller_server.progress_checker.required_movement_angle": 0.4,
    }
    cfg = nav2_config(load_nav2_params(default_params_path("waffle"), overrides=overrides))
    checker = cfg.goal_checkers["general_goal_checker"]
    assert isinstance(checker, StoppedGoalChecker)
    assert (checker.trans_stopped_velocity_mps, checker.rot_stopped_velocity_radps) == (0.05, 0.25)
    assert cfg.progress_angle_rad == 0.4
    assert "general_goal_checker.trans_stopped_velocity" in cfg.used["controller_server"]
    plain = nav2_config(load_nav2_params(default_params_path("waffle")))
    assert type(plain.goal_checkers["general_goal_checker"]) is SimpleGoalChecker and plain.progress_angle_rad is None


def test_dwb_keys_it_does_not_read_are_named_unused_and_critics_read_under_their_listed_names(tmp_path: Path) -> None:
    # A typo (max_vel_xx) was taken as used, so no warning named it; a critic listed by its class name
    # reads its parameters under that name, as DWB passes each critic the list's name.
    text = default_params_path("waffle").read_text()
    text = text.replace(
        'critics: ["RotateToGoal",', 'max_vel_xx: 0.3\n      critics: ["dwb_critics::RotateToGoalCritic",'
    )
    text = text.replace(
        "RotateToGoal.scale: 32.0", "RotateToGoal.scale: 32.0\n      dwb_critics::RotateToGoalCritic.scale: 7.0"
    )
    path = tmp_path / "params.yaml"
    path.write_text(text)
    params = load_nav2_params(path)
    cfg = nav2_config(params)
    used = set(cfg.used["controller_server"])
    assert "FollowPath.max_vel_x" in used and "FollowPath.max_vel_xx" not in used
    assert "FollowPath.dwb_critics::RotateToGoalCritic.scale" in used and "FollowPath.RotateToGoal.scale" not in used
    warning = params.warning(cfg.used)
    assert warning is not None and "controller_server.FollowPath.max_vel_xx" in warning
    section = cfg.controllers["FollowPath"][1]
    assert DwbParams.from_nav2(section).rotate_to_goal_scale == 7.0
    plain = nav2_config(load_nav2_params(default_params_path("waffle"))).controllers["FollowPath"][1]
    assert DwbParams.from_nav2(plain).rotate_to_goal_scale == 32.0


def test_nav2s_own_params_file_reads_its_smoother_limits(fixtures: Path) -> None:
    cfg = nav2_config(load_nav2_params(fixtures / "nav2" / "nav2_humble" / "nav2_params.yaml"))
    assert cfg.controller_frequency_hz == 20.0
    assert cfg.smoother.max_velocity == (0.26, 0.0, 1.0)
    assert cfg.smoother.feedback is Feedback.OPEN_LOOP and cfg.smoother.odom_duration_s == 0.1


def test_the_smoother_runs_closed_loop_and_refuses_other_feedback() -> None:
    overrides = {"velocity_smoother.feedback": "CLOSED_LOOP", "velocity_smoother.odom_duration": 0.3}
    cfg = nav2_config(load_nav2_params(default_params_path("burger"), overrides=overrides))
    assert cfg.smoother.feedback is Feedback.CLOSED_LOOP and cfg.smoother.odom_duration_s == 0.3
    bad = load_nav2_params(default_params_path("burger"), overrides={"velocity_smoother.feedback": "OPENLOOP"})
    with pytest.raises(ConfigError, match="feedback: expected OPEN_LOOP or CLOSED_LOOP"):
        nav2_config(bad)


def test_the_smoother_reads_its_odom_topic_and_refuses_a_name_that_is_not_a_topic() -> None:
    assert nav2_config(load_nav2_params(default_params_path("burger"))).smoother.odom_topic == "odom"
    topic = {"velocity_smoother.odom_topic": "odometry/filtered"}
    cfg = nav2_config(load_nav2_params(default_params_path("burger"), overrides=topic))
    assert cfg.smoother.odom_topic == "odometry/filtered"
    bad = load_nav2_params(default_params_path("burger"), overrides={"velocity_smoother.odom_topic": "2odom"})
    with pytest.raises(
        ConfigError, match=r"velocity_smoother\.odom_topic: '2odom' is not a topic name.*fix the params"
    ):
        nav2_config(bad)


def test_an_unknown_controller_or_planner_plugin_is_a_config_error(tmp_path: Path) -> None:
    params = load_nav2_params(
        default_params_path("burger"), overrides={"controller_server.FollowPath.plugin": "acme::Teleporter"}
    )
    with pytest.raises(ConfigError, match="unknown controller plugin 'acme::Teleporter'"):
        nav2_config(params)
    params = load_nav2_params(
        default_params_path("burger"), overrides={"planner_server.GridBased.plugin": "nav2_smac_planner/SmacPlanner2D"}
    )
    with pytest.raises(ConfigError, match="unknown planner plugin"):
        nav2_config(params)


def test_smooth_path_keeps_the_ends_and_pulls_corners_in() -> None:
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [2.0, 2.0, 0.0]])
    out = smooth_path(path)
    assert out[0] == pytest.approx(path[0]) and out[-1] == pytest.approx(path[-1])
    # the corner at (1, 0) moves towards the inside of the turn, and the path gets shorter
    assert out[1, 0] < 1.0 and out[1, 1] > 0.0
    length = lambda p: float(np.sum(np.hypot(*np.diff(p[:, :2], axis=0).T)))  # noqa: E731
    assert length(out) < length(path)
    # an interior pose faces along its neighbours' chord
    chord = out[3, :2] - out[1, :2]
    assert out[2, 2] == pytest.approx(math.atan2(chord[1], chord[0]))


def test_a_sensor_source_the_twin_does_not_simulate_is_named(tmp_path: Path) -> None:
    # TurtleBot3's waffle_pi-style depth camera source: a PointCloud2 the twin does not publish
    from twin.sim.navigation import unsimulated_sources

    assert unsimulated_sources(load_nav2_params(default_params_path("waffle"))) == []
    text = default_params_path("waffle").read_text().replace('data_type: "LaserScan"', 'data_type: "PointCloud2"', 1)
    path = tmp_path / "params.yaml"
    path.write_text(text)
    (line,) = unsimulated_sources(load_nav2_params(path))
    assert line.startswith(f"{path}: ") and "a PointCloud2 source (/scan) gets no data" in line


@pytest.mark.parametrize(
    ("old", "new", "line", "key", "problem"),
    [
        ('plugin: "nav2_navfn_planner/NavfnPlanner"', 'plugin: "nav2_smac_planner/SmacPlannerHybrid"', 308,
         "planner_server.GridBased.plugin", "unknown planner plugin 'nav2_smac_planner/SmacPlannerHybrid'"),
        ("RotateToGoal.lookahead_time: -1.0", "RotateToGoal.lookahead_time: 2.0", 164,
         "controller_server.FollowPath.RotateToGoal.lookahead_time", "only -1.0 (the trajectory's end) is implemented"),
    ],
)  # fmt: skip
def test_a_servers_parameter_the_twin_cannot_use_is_named_with_its_line(
    tmp_path: Path, old: str, new: str, line: int, key: str, problem: str
) -> None:
    # Clearpath's and Smac users' files: the line was named for some refusals, not for these
    text = default_params_path("burger").read_text()
    assert text.splitlines()[line - 1].strip() == old
    params = tmp_path / "params.yaml"
    params.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError) as raised:
        nav2_config(load_nav2_params(params))
    assert str(raised.value).startswith(f"{params}:{line}: {key}: {problem}")
