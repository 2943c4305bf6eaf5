"""Nav2 params files and maps are inputs like the scenario: one line naming file, line or key, and the fix; exit 2.

Each case is TurtleBot3's Humble waffle params (or its turtlebot3_world map) with one thing changed,
as a user would change it, run through `scenario check` and `simulate` in-process: both refuse it
with exit 2 and one line, `simulate` before it makes a bag folder. Before these checks the values
crashed the run (ZeroDivisionError, "rate must be positive", MemoryError of terabytes, a kernel
killing the process at 24 GB, PIL's DecompressionBombError) or ran a controller that could do
nothing, and `navigation.set` typos were silently ignored.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.robustness.helpers import assert_one_line_error
from tests.robustness.nav2_fuzz import FIXTURE_MAP, WAFFLE
from tests.robustness.test_inputs import run

TB3_WORLD: dict[str, Any] = {
    "world": {"sdf": str(WAFFLE.parents[3] / "sdf" / "worlds" / "turtlebot3_world.sdf")},
    "robot": {"initial_pose": {"x_m": -2.0, "y_m": -0.5, "yaw_rad": 0.0}},
    "mission": {"locations": str(WAFFLE.parents[3] / "trees" / "turtlebot3_world_locations.yaml")},
}


def _params(folder: Path, changes: dict[str, Any] | None = None, text: str | None = None) -> Path:
    """TB3's waffle params with `changes` ({"node/sub.param.path": value}) applied, written to `folder`."""
    path = folder / "params.yaml"
    if text is not None:
        path.write_text(text)
        return path
    doc = yaml.safe_load(WAFFLE.read_text())
    for key, value in (changes or {}).items():
        node, _, param = key.partition(".")
        section = doc
        for part in node.split("/"):
            section = section.setdefault(part, {})
        section = section.setdefault("ros__parameters", {})
        *parents, leaf = param.split(".")
        for part in parents:
            section = section.setdefault(part, {})
        section[leaf] = value
    path.write_text(yaml.safe_dump(doc))
    return path


_GONE = object()  # a map change that removes the key


def _map(folder: Path, changes: dict[str, Any], image: bytes | None = None) -> Path:
    doc = yaml.safe_load((FIXTURE_MAP / "map.yaml").read_text())
    doc.update(changes)
    doc = {k: v for k, v in doc.items() if v is not _GONE}
    if image is not None:
        (folder / "gen.pgm").write_bytes(image)
        doc["image"] = "gen.pgm"
    else:
        doc["image"] = str(FIXTURE_MAP / "map.pgm")
    path = folder / "map.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _scenario(folder: Path, **sections: Any) -> Path:
    path = folder / "scenario.yaml"
    path.write_text(yaml.safe_dump({"name": "case", **TB3_WORLD, **sections}))
    return path


def _refused_alike(scenario: Path, capsys: pytest.CaptureFixture[str], *contains: str) -> str:
    """`scenario check` and `simulate` both exit 2 with one line holding `contains`; no bag folder is left."""
    code, _, err = run(["scenario", "check", str(scenario)], capsys)
    assert code == 2, err
    line = assert_one_line_error(err)
    bag = scenario.parent / "bag"
    sim_code, _, sim_err = run(["simulate", str(scenario), "--duration", "1", "--out", str(bag)], capsys)
    assert sim_code == 2, sim_err
    sim_line = assert_one_line_error(sim_err)
    assert not bag.exists()
    for text in contains:
        assert text in line, line
        assert text in sim_line, sim_line
    return sim_line


# -- params files: file:line: node.key, the problem, the fix -----------------------------------------

PARAMS_CASES: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "unknown_goal_checker": (
        {"controller_server.general_goal_checker.plugin": "nav2_controller::PositionGoalChecker"},
        ("general_goal_checker.plugin: unknown goal checker plugin", "nav2_controller::StoppedGoalChecker"),
    ),
    "unknown_progress_checker": (
        {"controller_server.progress_checker.plugin": "my_pkg::Checker"},
        ("progress_checker.plugin: unknown progress checker plugin", "nav2_controller::PoseProgressChecker"),
    ),
    "zero_controller_frequency": (
        {"controller_server.controller_frequency": 0.0},
        ("controller_server.controller_frequency: must be at least", "got 0.0"),
    ),
    "negative_controller_frequency": (
        {"controller_server.controller_frequency": -20.0},
        ("controller_server.controller_frequency", "got -20.0"),
    ),
    "huge_local_costmap": (
        {"local_costmap/local_costmap.width": 100000, "local_costmap/local_costmap.height": 100000},
        ("local_costmap/local_costmap.width: local_costmap's grid of 2000000 x 2000000 cells", "TiB"),
    ),
    "fine_global_costmap": (
        {"global_costmap/global_costmap.resolution": 1e-5},
        ("global_costmap/global_costmap.resolution: global_costmap's grid", "TiB"),
    ),
    "dwb_sample_grid": (
        {"controller_server.FollowPath.vx_samples": 10**8, "controller_server.FollowPath.vtheta_samples": 10**5},
        ("controller_server.FollowPath.vx_samples: DWB's 100000000 x 100000 velocity samples", "TiB"),
    ),
    "dwb_samples_not_integer": (
        {"controller_server.FollowPath.vx_samples": 20.5},
        ("controller_server.FollowPath.vx_samples: expected an integer",),
    ),
    "billion_particles": (
        {"amcl.max_particles": 10**9},
        ("amcl.max_particles: AMCL's set of 1000000000 particles would take", "GiB", "lower max_particles"),
    ),
    "negative_sigma_hit": ({"amcl.sigma_hit": -0.2}, ("amcl.sigma_hit: must be above 0",)),
    "smoother_positive_decel": (
        {"velocity_smoother.max_decel": [2.5, 0.0, 3.2]},
        ("velocity_smoother.max_decel: must be negative or 0",),
    ),
    "planner_flag_as_text": (
        {"planner_server.GridBased.use_astar": "false"},
        ("planner_server.GridBased.use_astar: expected true or false",),
    ),
}


@pytest.mark.parametrize("case", sorted(PARAMS_CASES))
def test_bad_params_file_is_refused_with_file_line_and_key(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    changes, contains = PARAMS_CASES[case]
    params = _params(tmp_path, changes)
    line = _refused_alike(_scenario(tmp_path, navigation={"params": str(params)}), capsys, *contains)
    assert f"{params}:" in line  # the params file, and the line of the key where the file has it
    first = next(iter(changes)).rsplit(".", 1)[-1]
    if first in params.read_text():
        assert line.split(f"{params}:", 1)[1].split(":", 1)[0].isdigit(), line


@pytest.mark.parametrize(
    "text", ["", "amcl:\n  ros__parameters:\n    max_particles: 3000\n"], ids=["empty", "only_amcl"]
)
def test_params_file_without_a_controller_is_refused_as_nav2_refuses_it(
    text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Nav2 Humble's DWB throws "No critics defined for FollowPath" and controller_server does not configure;
    # the twin used to run a controller with "No valid trajectories out of 0!" instead. A file holding
    # amcl alone is the localization half of a split pair (TurtleBot4's, Clearpath's): said so.
    params = _params(tmp_path, text=text)
    _refused_alike(
        _scenario(tmp_path, navigation={"params": str(params)}),
        capsys,
        "holds no controller_server and no planner_server section",
        "No critics defined for FollowPath",
        "merge a split pair",
    )


def test_params_file_with_only_amcl_localises_when_nothing_navigates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # AMCL alone reads only its own section; Nav2's other nodes take their defaults and are not built.
    params = _params(tmp_path, text="amcl:\n  ros__parameters:\n    max_particles: 3000\n")
    scenario = _scenario(tmp_path, navigation={"params": str(params)})
    doc = yaml.safe_load(scenario.read_text())
    doc["mission"] = {"type": "none"}
    scenario.write_text(yaml.safe_dump(doc))
    code, _, err = run(["scenario", "check", str(scenario)], capsys)
    assert code == 0, err


def test_an_empty_ros_parameters_says_what_to_do(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    params = _params(tmp_path, text="amcl:\n  ros__parameters:\n")
    _refused_alike(
        _scenario(tmp_path, navigation={"params": str(params)}),
        capsys,
        "amcl.ros__parameters is empty",
        "indent the node's parameters under it, or remove 'amcl:' if it has none",
    )


def test_a_tree_calling_a_behaviour_the_params_do_not_load_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Nav2's BackUp leaf waits for the `backup` action server when the tree is created and throws without
    # it: with behavior_plugins [spin, wait] Nav2 cannot create its default navigator tree
    params = _params(
        tmp_path,
        {
            "behavior_server.behavior_plugins": ["spin", "wait"],
            "behavior_server.spin.plugin": "nav2_behaviors/Spin",
            "behavior_server.wait.plugin": "nav2_behaviors/Wait",
        },
    )
    line = _refused_alike(
        _scenario(tmp_path, navigation={"params": str(params)}),
        capsys,
        "<BackUp> calls the 'backup' action, which behavior_server does not load (behavior_plugins: spin, wait)",
        "add 'backup' to behavior_plugins with its plugin type",
    )
    assert "navigate_to_pose_w_replanning_and_recovery.xml:" in line


def test_a_behaviour_list_without_plugin_types_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    params = _params(tmp_path, {"behavior_server.behavior_plugins": ["spin", "backup", "wait", "turn"]})
    _refused_alike(
        _scenario(tmp_path, navigation={"params": str(params)}),
        capsys,
        "behavior_server.turn.plugin: not set",
        "nav2_behaviors/Spin",
    )


def test_unknown_keys_in_a_params_file_stay_one_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    params = _params(tmp_path, {"amcl.sigma_hitt": 0.1})  # ROS keeps undeclared parameters too
    code, _, err = run(["scenario", "check", str(_scenario(tmp_path, navigation={"params": str(params)}))], capsys)
    assert code == 0, err


# -- navigation.set: keys the twin reads, errors that name the scenario ------------------------------

SET_CASES: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "typo_dwb": (
        {"controller_server.FollowPath.max_vel_xx": 0.2},
        (
            "navigation.set.controller_server.FollowPath.max_vel_xx",
            "did you mean 'controller_server.FollowPath.max_vel_x'?",
        ),
    ),
    "typo_amcl": ({"amcl.sigma_hitt": 0.1}, ("navigation.set.amcl.sigma_hitt", "did you mean 'amcl.sigma_hit'?")),
    # the node's namespace written twice: the line read "no parameter 'X' ...; did you mean 'X'?"
    "node_twice": (
        {"global_costmap.global_costmap.inflation_layer.inflate_around_unknown": False},
        (
            "the twin reads no parameter 'global_costmap.global_costmap.inflation_layer.inflate_around_unknown'; "
            "did you mean 'global_costmap.inflation_layer.inflate_around_unknown'?",
        ),
    ),
    "typo_node": ({"amlc.sigma_hit": 0.1}, ("navigation.set.amlc.sigma_hit", "did you mean 'amcl'?")),
    "made_up": ({"controller_server.warp_drive": True}, ("navigation.set.controller_server.warp_drive", "remove it")),
    "bad_value": ({"amcl.sigma_hit": -0.1}, ("navigation.set.amcl.sigma_hit: must be above 0",)),
    "zero_rate": (
        {"controller_server.controller_frequency": 0.0},
        ("navigation.set.controller_server.controller_frequency: must be at least",),
    ),
    "billion_particles": ({"amcl.max_particles": 10**9}, ("navigation.set.amcl.max_particles: AMCL's set",)),
    "wrong_type": ({"local_costmap.width": "wide"}, ("navigation.set.local_costmap.width: expected a finite number",)),
}


@pytest.mark.parametrize("case", sorted(SET_CASES))
def test_navigation_set_is_checked_and_names_the_scenario(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    overrides, contains = SET_CASES[case]
    scenario = _scenario(tmp_path, navigation={"set": overrides})
    line = _refused_alike(scenario, capsys, *contains)
    assert line.startswith(f"twin: error: {scenario}: navigation.set."), line
    assert "waffle.yaml" not in line  # the packaged file is not what is wrong


def test_navigation_set_keys_the_twin_reads_are_taken(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    overrides = {
        "amcl.max_particles": 1000,
        "controller_server.FollowPath.max_vel_x": 0.2,
        "local_costmap.inflation_layer.inflation_radius": 0.4,
        "velocity_smoother.max_velocity": [0.2, 0.0, 1.0],
    }
    code, _, err = run(["scenario", "check", str(_scenario(tmp_path, navigation={"set": overrides}))], capsys)
    assert code == 0, err


# -- map files ------------------------------------------------------------------------------------

MAP_CASES: dict[str, tuple[dict[str, Any], bytes | None, tuple[str, ...]]] = {
    "nan_origin": ({"origin": [float("nan"), -10.0, 0.0]}, None, ("'origin' x must be a finite number",)),
    "huge_resolution": ({"resolution": 1e300}, None, ("'resolution' must be between",)),
    "tiny_resolution": ({"resolution": 1e-9}, None, ("map.yaml: 'resolution' 1e-09 m", "would take")),
    "thresholds_swapped": ({"mode": "scale", "free_thresh": 0.7}, None, ("'free_thresh' (0.7) must be below",)),
    # map_server (Humble) requires these three: without free_thresh the 205-grey unknown became free
    "no_free_thresh": ({"free_thresh": _GONE}, None, ("'free_thresh' is missing", "add 'free_thresh: 0.25'")),
    "no_occupied_thresh": ({"occupied_thresh": _GONE}, None, ("'occupied_thresh' is missing",)),
    "no_negate": ({"negate": _GONE}, None, ("'negate' is missing", "add 'negate: 0'")),
    "pgm_bomb": ({}, b"P5\n20000 20000\n255\n" + b"\xfe" * 64, ("20000 x 20000 pixels", "GiB")),
    "pgm_truncated": ({}, b"P5\n300 300\n255\n" + b"\xfe" * 64, ("cannot be read",)),
}


@pytest.mark.parametrize("case", sorted(MAP_CASES))
def test_bad_map_is_refused_with_one_line(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    changes, image, contains = MAP_CASES[case]
    map_yaml = _map(tmp_path, changes, image)
    line = _refused_alike(_scenario(tmp_path, map=str(map_yaml)), capsys, *contains)
    assert f"{map_yaml}:" in line, line


def test_a_pose_off_a_given_map_is_refused_by_check_as_by_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The map moved 10 m east: AMCL's initial estimate (the spawn pose) lies off it. `scenario check`
    # passed this and the run refused it; both refuse it now, in the same line.
    map_yaml = _map(tmp_path, {"origin": [10.0, 10.0, 0.0]})
    _refused_alike(
        _scenario(tmp_path, map=str(map_yaml)),
        capsys,
        "localization.initial_pose: (",
        "lies outside the map (x 10.00..",
    )


def test_an_initial_estimate_off_the_map_made_from_the_world_is_refused_by_check_as_by_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # No `map:`: the run makes the map from the world and refused the estimate; `scenario check` passed it.
    _refused_alike(
        _scenario(tmp_path, localization={"initial_pose": {"x_m": 100.0}}),
        capsys,
        "localization.initial_pose: (100.000, -0.500) lies outside the map (x ",
    )


def test_a_map_origin_yaw_is_warned_of(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # map_server's documentation: "many parts of the system currently ignore yaw" (the costmaps and AMCL)
    map_yaml = _map(tmp_path, {"origin": [-10.0, -10.0, 0.3]})
    code, _, err = run(
        ["simulate", str(_scenario(tmp_path, map=str(map_yaml))), "--duration", "1", "--out", str(tmp_path / "b")],
        capsys,
    )
    assert code == 0, err
    assert f"{map_yaml}: the map's origin yaw (0.3 rad) is published on /map but" in err


def test_map_numbers_as_yaml_1_2_writes_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # `5e-2` is a number to ROS's yaml-cpp; PyYAML alone reads it as text
    map_yaml = _map(tmp_path, {})
    map_yaml.write_text(map_yaml.read_text().replace("resolution: 0.05", "resolution: 5e-2"))
    code, _, err = run(["scenario", "check", str(_scenario(tmp_path, map=str(map_yaml)))], capsys)
    assert code == 0, err


def test_a_map_yaml_given_as_the_params_file_is_told_where_it_goes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    the_map = FIXTURE_MAP / "map.yaml"
    line = _refused_alike(_scenario(tmp_path, navigation={"params": str(the_map)}), capsys, "is a map_server map YAML")
    assert f"{the_map}: is a map_server map YAML" in line and "the scenario's map:" in line
