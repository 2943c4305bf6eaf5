"""Bad inputs, by class: every one is refused with its exit code and one line, never a traceback or exit 70.

Classes (the hardening issue's): scenario values that cannot be honoured, referenced files missing
or broken, files that do not decode (non-UTF-8, binary, nested too deeply), options that cannot be
honoured, YAML numbers as people write them, and whole runs (a failed mission exits 1 with a bag
that reads back). A refused `simulate` leaves no bag folder. Cases run in-process through
`twin.cli.main`, the same path as the `twin` command (the watchdog and kill tests use processes).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.conftest import REPO
from tests.robustness.helpers import DATA, assert_bag_reads_back, assert_one_line_error
from twin.cli import main

SCENARIOS = REPO / "scenarios"
TREES = REPO / "trees"


def overlay(values: dict[str, Any]) -> dict[str, Any]:
    """{"a.b": 1} -> {"a": {"b": 1}}."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        node = out
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return out


def write_scenario(folder: Path, values: dict[str, Any], text: str | None = None) -> Path:
    path = folder / "scenario.yaml"
    path.write_text(text if text is not None else yaml.safe_dump({"name": "case", **overlay(values)}))
    return path


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# -- scenario values: `scenario check` and `simulate` refuse them alike, simulate before any bag ------

NAN, INF = float("nan"), float("inf")
VALUE_CASES: dict[str, tuple[dict[str, Any], str]] = {
    "nan_step": ({"physics.step_s": NAN}, "step_s"),
    "nan_pose": ({"robot.initial_pose.x_m": NAN}, "is NaN"),
    "inf_duration": ({"max_duration_s": INF}, "max_duration_s"),
    "minus_inf_yaw": ({"robot.initial_pose.yaw_rad": -INF}, "finite"),
    "negative_seed": ({"seed": -1}, "seed"),
    "zero_clock_rate": ({"sensors.clock.rate_hz": 0.0}, "rate_hz"),
    "negative_tick_rate": ({"mission.tick_rate_hz": -2.0}, "tick_rate_hz"),
    "range_min_above_max": ({"sensors.lidar.range_min_m": 5.0, "sensors.lidar.range_max_m": 1.0}, "range_min_m"),
    "range_min_equals_max": ({"sensors.lidar.range_min_m": 2.0, "sensors.lidar.range_max_m": 2.0}, "range_min_m"),
    "zero_samples": ({"sensors.lidar.samples": 0}, "samples"),
    "huge_samples": ({"sensors.lidar.samples": 2**40}, "samples"),
    "tiny_rate": ({"sensors.clock.rate_hz": 2.2e-311}, "rate_hz"),
    "range_min_above_sdf_max": ({"sensors.lidar.range_min_m": 5.0}, "range_min_m"),
    "range_max_below_sdf_min": ({"sensors.lidar.range_max_m": 1e-9}, "range_max_m"),
    "negative_samples": ({"sensors.lidar.samples": -360}, "samples"),
    "lidar_above_physics": ({"sensors.lidar.rate_hz": 2000.0}, "above the physics rate"),
    "clock_above_physics": ({"physics.step_s": 0.01, "sensors.clock.rate_hz": 200.0}, "above the physics rate"),
    "negative_noise": ({"sensors.lidar.noise_std_m": -0.01}, "noise_std_m"),
    "negative_tolerance": (
        {"mission.type": "waypoints", "mission.points": [[0.0, 0.0], [1.0, 0.0]], "mission.follower.tolerance_m": -0.1},
        "tolerance_m",
    ),
    "zero_max_duration": ({"max_duration_s": 0.0}, "max_duration_s"),
    "angle_min_above_max": ({"sensors.lidar.angle_min_rad": 1.0, "sensors.lidar.angle_max_rad": -1.0}, "angle_min"),
    "seed_text": ({"seed": "seven"}, "seed"),
    "negative_floor_height": ({"world.floor_height_m": -0.1}, "floor_height_m"),
    "range_beyond_float32": ({"sensors.lidar.range_max_m": 3.4028235677973366e38}, "range_max_m: 3.40282e+38 m"),
    # One finite-and-bounded check for every number (hardening issue, defect 5): these overflowed in the run.
    "max_duration_1e300": ({"max_duration_s": 1e300}, "max_duration_s: 1e+300 s is out of range"),
    "obstacle_path_1e300": (
        {
            "obstacles": [
                {"shape": "box", "size_m": [0.3, 0.3, 0.4], "path_xy_m": [[3, 3], [1e300, 3]], "speed_mps": 0.5}
            ]
        },
        "obstacles[0].path_xy_m[1][0]: 1e+300 m is out of range",
    ),
    "appear_1e300": (
        {"obstacles": [{"shape": "box", "size_m": [0.3, 0.3, 0.4], "pose": {"x_m": 3, "y_m": 3}, "appear_s": 1e300}]},
        "appear_s: 1e+300 s is out of range",
    ),
    "seed_beyond_int64": ({"seed": 2**70}, "seed: 1180591620717411303424 does not fit a 64-bit whole number"),
    "noise_1e300": ({"sensors.lidar.noise_std_m": 1e300}, "noise_std_m: 1e+300 m is out of range"),
    "voltage_1e300": (
        {"drive.type": "fmu", "drive.speed_loop.voltage_limit_v": 1e300},
        "voltage_limit_v: 1e+300 is out",
    ),
}


@pytest.mark.parametrize("case", VALUE_CASES, ids=str)
def test_scenario_value_is_refused_by_check_and_by_simulate(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    values, contains = VALUE_CASES[case]
    path = write_scenario(tmp_path, values)
    code, _, err = run(["scenario", "check", str(path)], capsys)
    assert code == 2, err
    assert_one_line_error(err, contains=contains)
    bag = tmp_path / "bag"
    code, _, err = run(["simulate", str(path), "--duration", "0.5", "--out", str(bag)], capsys)
    assert code == 2, err
    assert_one_line_error(err, contains=contains)
    assert not bag.exists()


# -- referenced files -----------------------------------------------------------------------------

FILE_CASES: dict[str, tuple[dict[str, Any], int, str]] = {
    "world_missing": ({"world.sdf": "nowhere.sdf"}, 2, "world.sdf"),
    "tree_missing": ({"mission.tree": "nowhere.xml"}, 2, "mission.tree"),
    "locations_missing": ({"mission.locations": "nowhere.yaml"}, 2, "mission.locations"),
    "locations_not_a_mapping": ({"mission.locations": "locations_list.yaml"}, 2, "mission.locations"),
    "locations_empty": ({"mission.locations": "locations_empty.yaml"}, 2, "holds no locations"),
    "mapping_missing": ({"drive.type": "fmu", "drive.mapping": "nowhere.yaml"}, 2, "drive.mapping"),
    "mapping_binary": ({"drive.type": "fmu", "drive.mapping": "binary.bin"}, 2, "binary file"),
    "fmu_file_missing": ({"drive.type": "fmu", "drive.fmu_file": "nowhere.fmu"}, 2, "drive.fmu_file"),
    "model_path_missing": ({"world.model_path": ["no_models_here"]}, 2, "world.model_path"),
    "tree_binary": ({"mission.tree": "binary.bin"}, 6, "binary file"),
    "tree_latin1": ({"mission.tree": "latin1.xml"}, 6, "not UTF-8"),
    "tree_no_main": ({"mission.tree": "no_main.xml"}, 6, "names no tree"),
    "tree_too_deep": ({"mission.tree": "deep.xml"}, 6, "nested deeper than"),
    "world_binary": ({"world.sdf": "binary.bin"}, 3, "binary.bin"),
    "robot_model_missing": ({"robot.model": "no_such_robot"}, 3, "robot.model: model 'no_such_robot' not found"),
    # A device read for 13 s into a MemoryError; a FIFO would block for ever.
    "world_dev_zero": ({"world.sdf": "/dev/zero"}, 2, "world.sdf: /dev/zero: not a regular file"),
    "tree_dev_zero": ({"mission.tree": "/dev/zero"}, 2, "mission.tree: /dev/zero: not a regular file"),
    "locations_fifo": ({"mission.locations": "fifo"}, 2, "fifo: not a regular file"),
}


def _fixture_files(folder: Path) -> None:
    os.mkfifo(folder / "fifo")
    (folder / "locations_list.yaml").write_text("- [1.0, 2.0, 0.0]\n")
    (folder / "locations_empty.yaml").write_text("{}\n")
    (folder / "binary.bin").write_bytes(bytes(range(256)) * 8)
    (folder / "latin1.xml").write_bytes(
        b'<root BTCPP_format="4"><BehaviorTree ID="A"><AlwaysSuccess name="caf\xe9"/></BehaviorTree></root>'
    )
    (folder / "no_main.xml").write_text(
        '<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree></root>'
    )
    depth = 5000
    (folder / "deep.xml").write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="A">'
        + "<Sequence>" * depth
        + "<AlwaysSuccess/>"
        + "</Sequence>" * depth
        + "</BehaviorTree></root>"
    )


@pytest.mark.parametrize("case", FILE_CASES, ids=str)
def test_referenced_file_problem_is_one_line(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    values, exit_code, contains = FILE_CASES[case]
    _fixture_files(tmp_path)
    path = write_scenario(tmp_path, values)
    code, _, err = run(["scenario", "check", str(path)], capsys)
    assert code == exit_code, err
    assert_one_line_error(err, contains=contains)
    bag = tmp_path / "bag"
    code, _, err = run(["simulate", str(path), "--duration", "0.5", "--out", str(bag)], capsys)
    assert code == exit_code, err
    assert_one_line_error(err, contains=contains)
    assert not bag.exists()


# -- files that do not decode, for every command that reads one -----------------------------------

LATIN1_YAML = b"name: caf\xe9\n"
BINARY = bytes(range(256)) * 8
DEEP_YAML = ("a: " + "[" * 3000 + "]" * 3000 + "\n").encode()

DECODE_CASES: dict[str, tuple[list[str], str, bytes, int, str]] = {
    # name: (argv with {f} for the file, file name, content, exit code, text in the line)
    "scenario_latin1": (["scenario", "check", "{f}"], "s.yaml", LATIN1_YAML, 2, "not UTF-8"),
    "scenario_binary": (["scenario", "check", "{f}"], "s.yaml", BINARY, 2, "binary file"),
    "scenario_deep": (["scenario", "check", "{f}"], "s.yaml", DEEP_YAML, 2, "nested too deeply"),
    "scenario_folder": (["scenario", "check", "{d}"], "s.yaml", b"", 2, "is a folder"),
    "simulate_latin1": (["simulate", "{f}", "--out", "{d}/bag"], "s.yaml", LATIN1_YAML, 2, "not UTF-8"),
    "simulate_binary": (["simulate", "{f}", "--out", "{d}/bag"], "s.yaml", BINARY, 2, "binary file"),
    "world_info_binary": (["world", "info", "{f}"], "w.world", BINARY, 3, "w.world"),
    "world_info_latin1": (["world", "info", "{f}"], "w.world", b"<sdf version='1.6'>\xe9</sdf>", 3, "w.world"),
    "fmu_check_binary": (["fmu", "check", "{f}"], "x.fmu", BINARY, 4, "x.fmu"),
    "bag_info_metadata_latin1": (
        ["bag", "info", "{d}"],
        "metadata.yaml",
        b"rosbag2_bagfile_information: \xe9\n",
        5,
        "UTF-8",
    ),
    "bag_info_metadata_binary": (["bag", "info", "{d}"], "metadata.yaml", BINARY, 5, "metadata.yaml"),
    "bag_info_metadata_bad_count": (
        ["bag", "info", "{d}"],
        "metadata.yaml",
        b"rosbag2_bagfile_information:\n  version: 8\n  message_count: 1 1534\n",
        5,
        "metadata.yaml",
    ),
    "bag_recover_metadata_bad_count": (
        ["bag", "recover", "{d}"],
        "metadata.yaml",
        b"rosbag2_bagfile_information:\n  version: 8\n  message_count: 1 1534\n",
        5,
        "no .mcap or .db3",
    ),
}


@pytest.mark.parametrize("case", DECODE_CASES, ids=str)
def test_a_file_that_does_not_decode_is_one_line(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv, name, content, exit_code, contains = DECODE_CASES[case]
    (tmp_path / name).write_bytes(content)
    args = [a.replace("{f}", str(tmp_path / name)).replace("{d}", str(tmp_path)) for a in argv]
    code, _, err = run(args, capsys)
    assert code == exit_code, err
    assert_one_line_error(err, contains=contains)
    assert not (tmp_path / "bag").exists()


def test_tree_validate_fails_when_main_tree_to_execute_names_no_tree(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _fixture_files(tmp_path)
    code, out, err = run(["tree", "validate", str(tmp_path / "no_main.xml")], capsys)
    assert code == 6
    assert "main_tree_to_execute='Main' names no tree" in out + err
    assert "Traceback" not in out + err


# -- options ----------------------------------------------------------------------------------------

OPTION_CASES: dict[str, tuple[list[str], str]] = {
    "duration_inf": (["--duration", "inf"], "--duration"),
    "duration_nan": (["--duration", "nan"], "--duration"),
    "duration_negative": (["--duration", "-1"], "--duration"),
    "duration_zero": (["--duration", "0"], "--duration"),
    "seed_negative": (["--seed", "-3"], "--seed"),
    "watchdog_zero": (["--watchdog-s", "0"], "--watchdog-s"),
    "watchdog_nan": (["--watchdog-s", "nan"], "--watchdog-s"),
    "duration_1e300": (["--duration", "1e300"], "--duration 1e+300 s is out of range"),
    "seed_beyond_int64": (["--seed", str(2**70)], "seed"),
}


@pytest.mark.parametrize("case", OPTION_CASES, ids=str)
def test_an_option_that_cannot_be_honoured_is_exit_2(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    options, contains = OPTION_CASES[case]
    bag = tmp_path / "bag"
    code, _, err = run(["simulate", *options, "--out", str(bag)], capsys)
    assert code == 2, err
    assert_one_line_error(err, contains=contains)
    assert not bag.exists()


@pytest.mark.parametrize("where", ["before", "after"])
def test_global_options_work_before_and_after_the_command(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_scenario(tmp_path, {"seed": -1})
    argv = (
        ["--debug", "scenario", "check", str(path)]
        if where == "before"
        else ["scenario", "check", str(path), "--debug"]
    )
    code, _, err = run(argv, capsys)
    assert code == 2
    assert "Traceback" in err  # --debug shows it, on either side


def test_simulate_help_documents_every_exit_code(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = capsys.readouterr().out
    section = text[text.index("exit codes:") :]
    for code in ("0", "1", "2", "3", "4", "5", "6", "7", "8", "70", "130", "143"):
        assert f"\n  {code} " in section, code


# -- YAML numbers as people write them --------------------------------------------------------------


@pytest.mark.parametrize("text", ["1e1", "1.0e1", "1e+1", "10.0e0"])
def test_yaml_exponent_numbers_are_numbers(text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_scenario(tmp_path, {}, text=f"name: numbers\nmax_duration_s: {text}\n")
    code, out, err = run(["scenario", "check", str(path), "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["max_duration_s"] == 10.0


# -- whole runs ------------------------------------------------------------------------------------


def test_a_failed_mission_exits_1_naming_the_goal_and_why(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "bag"
    code, out, err = run(["simulate", str(DATA / "unreachable.yaml"), "--out", str(bag), "--json"], capsys)
    assert code == 1, err
    summary = json.loads(out)
    assert summary["mission_result"] == "FAILURE"
    assert "'far_away'" in summary["mission_failure"] and "no path" in summary["mission_failure"]
    assert "twin: mission FAILURE: goal 'far_away'" in err and "Traceback" not in err
    assert_bag_reads_back(bag)


def test_an_error_inside_a_tick_keeps_its_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tree = tmp_path / "unknown.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="A"><Sequence><Script code="where := \'nowhere\'"/>'
        '<GoToPose loc="{where}"/></Sequence></BehaviorTree></root>'
    )
    path = write_scenario(
        tmp_path, {"mission.tree": str(tree), "mission.locations": str(DATA / "unreachable_locations.yaml")}
    )
    bag = tmp_path / "bag"
    code, _, err = run(["simulate", str(path), "--out", str(bag)], capsys)
    assert code == 6, err
    assert_one_line_error(err, contains="unknown location 'nowhere' (the locations are far_away)")
    assert_bag_reads_back(bag)


def test_a_location_the_tree_names_and_the_file_lacks_is_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # (it failed at its first tick, seconds into the run, after `scenario check` had passed it)
    tree = tmp_path / "unknown.xml"
    tree.write_text('<root BTCPP_format="4"><BehaviorTree ID="A">\n<GoToPose loc="far_awy"/></BehaviorTree></root>')
    locations = DATA / "unreachable_locations.yaml"
    path = write_scenario(tmp_path, {"mission.tree": str(tree), "mission.locations": str(locations)})
    bag = tmp_path / "bag"
    for argv in (["scenario", "check", str(path)], ["simulate", str(path), "--out", str(bag)]):
        code, _, err = run(argv, capsys)
        assert code == 6, err
        assert_one_line_error(
            err,
            contains=f"{tree}:2: <GoToPose loc='far_awy'>: {locations} has no location 'far_awy'; did you mean "
            "'far_away'? (the locations are far_away)",
        )
    assert not bag.exists()


def test_a_script_error_inside_a_tick_keeps_its_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tree = tmp_path / "script.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="A"><Script code="x := missing + 1"/></BehaviorTree></root>'
    )
    path = write_scenario(tmp_path, {"mission.tree": str(tree)})
    bag = tmp_path / "bag"
    code, _, err = run(["simulate", str(path), "--out", str(bag)], capsys)
    assert code == 6, err
    assert_one_line_error(err, contains="missing")
    assert_bag_reads_back(bag)


# -- other commands' options and outputs ---------------------------------------------------------------

CLI_CASES: dict[str, tuple[list[str], int, str]] = {
    "step_response_step_zero": (["fmu", "step-response", "builtin:xm430_w210", "--step-ms", "0"], 2, "--step-ms"),
    "step_response_step_nan": (["fmu", "step-response", "builtin:xm430_w210", "--step-ms", "nan"], 2, "--step-ms"),
    "step_response_duration_negative": (
        ["fmu", "step-response", "builtin:xm430_w210", "--duration-s", "-1"],
        2,
        "--duration-s",
    ),
    "step_response_out_unwritable": (
        ["fmu", "step-response", "builtin:xm430_w210", "--out", "/proc/twin-step.png"],
        5,
        "cannot write the plot",
    ),
    "step_response_out_folder": (["fmu", "step-response", "builtin:xm430_w210", "--out", "{d}"], 2, "--out"),
    "ekf_replay_out_unwritable": (
        ["ekf", "replay", "{fixtures}/bags/tb3_waffle_gazebo_humble", "--out", "/proc/twin-ekf"],
        5,
        "cannot write",
    ),
    "step_response_step_1e-300": (
        ["fmu", "step-response", "builtin:xm430_w210", "--step-ms", "1e-300"],
        2,
        "--step-ms must be a communication step from 1e-06 ms (1 ns)",
    ),
    "step_response_voltage_1e300": (
        ["fmu", "step-response", "builtin:xm430_w210", "--voltage", "1e300"],
        2,
        "--voltage must be a finite number of volts, at most 1000 V",
    ),
    "graph_measure_1e300": (["graph", "--measure-s", "1e300"], 2, "--measure-s 1e+300 s is out of range"),
    "map_save_resolution_1e-300": (
        [
            "map",
            "save",
            "{fixtures}/gazebo_classic/worlds/empty_world.world",
            "--out",
            "{d}/m.yaml",
            "--resolution",
            "1e-300",
        ],
        2,
        "--resolution must be a cell size from 0.005 to 10 m",
    ),
    "map_save_height_1e300": (
        [
            "map",
            "save",
            "{fixtures}/gazebo_classic/worlds/empty_world.world",
            "--out",
            "{d}/m.yaml",
            "--height",
            "1e300",
        ],
        2,
        "--height must be a height >= 0 m: 1e+300 m is out of range",
    ),
    "world_info_dev_zero": (["world", "info", "/dev/zero"], 3, "/dev/zero: cannot read: not a regular file"),
    # each of these was exit 70 (an OverflowError, AttributeErrors, a NaN to int, matplotlib's format refusal)
    "replay_pose_topic_scan": (
        [
            "replay",
            "{fixtures}/bags/tb3_waffle_gazebo_humble",
            "--world",
            "{fixtures}/gazebo_classic/worlds/turtlebot3_world.world",
            "--model-path",
            "{fixtures}/gazebo_classic/models",
            "--pose-topic",
            "/scan",
            "--out",
            "{d}/r",
        ],
        5,
        "mission.pose_topic (twin replay --pose-topic) '/scan' is sensor_msgs/msg/LaserScan, which carries no pose",
    ),
    # a NaN threshold turned the check off (exit 0), inf passed as a wheel, one bag was a bag error (exit 5)
    "compare_threshold_nan": (
        [
            "analyze",
            "compare",
            "{fixtures}/bags/tb3_waffle_gazebo_humble",
            "{fixtures}/bags/tb3_waffle_gazebo_humble",
            "--max-position-error",
            "nan",
        ],
        2,
        "--max-position-error must be a distance >= 0 m",
    ),
    "compare_one_bag": (
        ["analyze", "compare", "{fixtures}/bags/tb3_waffle_gazebo_humble"],
        2,
        "analyze compare needs two bags A B, got 1",
    ),
    "ekf_wheel_radius_inf": (
        ["ekf", "replay", "{fixtures}/bags/tb3_waffle_gazebo_humble", "--wheel-radius", "inf", "--out", "{d}/e"],
        2,
        "--wheel-radius must be a length in metres above 0 and at most 100, got inf",
    ),
    "tree_log_seed_negative": (["tree", "log", "trees/tree.xml", "--seed", "-1"], 2, "--seed must be a non-negative"),
    "tree_log_period_zero": (["tree", "log", "trees/tree.xml", "--period-ms", "0"], 2, "--period-ms and --ticks"),
    "map_save_free_nan": (
        [
            "map",
            "save",
            "{fixtures}/gazebo_classic/worlds/empty_world.world",
            "--free",
            "nan",
            "0",
            "--out",
            "{d}/m.yaml",
        ],
        2,
        "--free X (of the point X Y, m): is NaN",
    ),
    "step_response_out_txt": (
        ["fmu", "step-response", "builtin:xm430_w210", "--out", "{d}/resp.txt"],
        2,
        "the plot is a PNG; give a file name ending in .png",
    ),
    "sweep_workers_1e20": (["sweep", "{d}/nowhere.yaml", "--workers", str(10**20)], 2, "--workers 1000"),
    "fmu_check_missing": (["fmu", "check", "{d}/nowhere.fmu"], 4, "nowhere.fmu"),
    "bag_info_missing": (["bag", "info", "{d}/nowhere"], 5, "nowhere"),
    "world_info_missing": (["world", "info", "{d}/nowhere.world"], 3, "nowhere.world"),
    "tree_validate_missing": (["tree", "validate", "{d}/nowhere.xml"], 6, "nowhere.xml"),
    # A model path that does not exist was silently searched: 87 warnings, exit 0, on a real world.
    "world_info_model_path_missing": (
        ["world", "info", "{fixtures}/gazebo_classic/worlds/empty_world.world", "--model-path", "{d}/nowhere"],
        2,
        "--model-path {d}/nowhere: no such folder",
    ),
    "world_info_model_path_in_a_list": (
        ["world", "info", "{fixtures}/gazebo_classic/worlds/empty_world.world", "--model-path", "{d}:{d}/nowhere"],
        2,
        "--model-path {d}/nowhere: no such folder",
    ),
    "map_save_model_path_missing": (
        [
            "map",
            "save",
            "{fixtures}/gazebo_classic/worlds/empty_world.world",
            "--out",
            "{d}/map.yaml",
            "--model-path",
            "{d}/nowhere",
        ],
        2,
        "--model-path {d}/nowhere: no such folder",
    ),
}


@pytest.mark.parametrize("case", CLI_CASES, ids=str)
def test_other_commands_refuse_with_one_line(
    case: str, tmp_path: Path, fixtures: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, exit_code, contains = CLI_CASES[case]
    args = [a.replace("{d}", str(tmp_path)).replace("{fixtures}", str(fixtures)) for a in argv]
    contains = contains.replace("{d}", str(tmp_path))
    code, out, err = run(args, capsys)
    assert code == exit_code, out + err
    if "twin: error:" in err:
        assert_one_line_error(err, contains=contains)
    else:  # tree validate reports its problems one per line, then a count
        assert contains in out + err and "Traceback" not in out + err


def test_ekf_replay_default_output_does_not_collide(
    tmp_path: Path, fixtures: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    bag = str(fixtures / "bags" / "tb3_waffle_gazebo_humble")
    for _ in range(2):
        code, _, err = run(["ekf", "replay", bag, "--json"], capsys)
        assert code == 0, err
    names = sorted(p.name for p in (tmp_path / "bags").iterdir())
    assert names == ["tb3_waffle_gazebo_humble_ekf", "tb3_waffle_gazebo_humble_ekf_2"]


def test_model_uri_cannot_escape_the_model_path(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "secret").mkdir()
    (tmp_path / "secret" / "x.stl").write_bytes(bytes(84))  # a valid, empty binary STL outside the models
    model = tmp_path / "models" / "m"
    model.mkdir(parents=True)
    (model / "model.sdf").write_text(
        "<sdf version='1.6'><model name='m'><link name='l'><collision name='c'><geometry><mesh>"
        "<uri>model://m/../../secret/x.stl</uri></mesh></geometry></collision></link></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text("<sdf version='1.6'><world name='w'><include><uri>model://m</uri></include></world></sdf>")
    code, _, err = run(["world", "info", str(world), "--model-path", str(tmp_path / "models")], capsys)
    assert code == 3, err
    assert "model://m/../../secret/x.stl: refused: '..' would leave the model path" in err
    assert_one_line_error(err, contains="not found")


def test_a_scenario_model_path_keeps_the_projects_robot_models(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # world.model_path replaces the default list; robot.model: turtlebot3_waffle must still be found.
    crate = tmp_path / "models" / "crate"
    crate.mkdir(parents=True)
    (crate / "model.sdf").write_text(
        "<sdf version='1.6'><model name='crate'><static>1</static><link name='l'><collision name='c'>"
        "<geometry><box><size>0.5 0.5 0.5</size></box></geometry></collision></link></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><include><uri>model://crate</uri><pose>3 0 0.25 0 0 0</pose>"
        "</include></world></sdf>"
    )
    path = write_scenario(tmp_path, {"world.sdf": "w.world", "world.model_path": ["models"]})
    code, _, err = run(["scenario", "check", str(path)], capsys)
    assert code == 0, err


def test_signed_values_are_not_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    values = {
        "robot.initial_pose.x_m": -1.0,
        "robot.initial_pose.yaw_rad": -3.0,
        "drive.type": "fmu",
        "drive.slip.regions": [{"x_min_m": -2.0, "x_max_m": -1.5, "y_min_m": -1.0, "y_max_m": 1.0, "slip": 0.3}],
    }
    code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, values))], capsys)
    assert code == 0, err


def test_a_floor_slab_above_z_0_names_floor_height_and_then_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a 10 x 10 m floor slab whose top is 1.5 cm above z = 0 (as some AWS worlds have), walls around it
    walls = "".join(
        f"<model name='wall{i}'><static>1</static><pose>{x} {y} 0.5 0 0 {yaw}</pose><link name='l'><collision name='c'>"
        "<geometry><box><size>10 0.1 1</size></box></geometry></collision></link></model>"
        for i, (x, y, yaw) in enumerate(((0, 4, 0), (0, -4, 0), (4, 0, 1.5708), (-4, 0, 1.5708)))
    )
    world = tmp_path / "slab.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='slab'><static>1</static><pose>0 0 -0.035 0 0 0</pose>"
        "<link name='floor'><collision name='c'><geometry><box><size>10 10 0.1</size></box></geometry></collision>"
        f"</link></model>{walls}</world></sdf>"
    )
    values: dict[str, Any] = {
        "world.sdf": str(world),
        "mission": {"type": "cmd_vel_script", "segments": [{"duration_s": 2.0, "linear_mps": 0.1}]},
        "localization.type": "none",
    }
    code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, values))], capsys)
    assert code == 2, err
    line = assert_one_line_error(err, contains="inside slab")
    assert "its top is 1.5 cm above z = 0), set world.floor_height_m to 0.02" in line
    values["world.floor_height_m"] = 0.02
    scenario = write_scenario(tmp_path, values)
    code, _, err = run(["simulate", str(scenario), "--out", str(tmp_path / "bag"), "--duration", "2"], capsys)
    assert code == 0, err


def test_a_thick_floor_is_not_taken_as_floor(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # gazebo_models' cafe stands on a floor box 19 cm high: taking it as floor (world.floor_height_m 0.2)
    # would leave the robot at z = 0 with the furniture 19 cm up, above its lidar: not suggested, warned
    world = tmp_path / "platform.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='platform'><static>1</static><pose>0 0 0.095 0 0 0</pose>"
        "<link name='floor'><collision name='c'><geometry><box><size>10 10 0.19</size></box></geometry></collision>"
        "</link></model></world></sdf>"
    )
    values: dict[str, Any] = {
        "world.sdf": str(world),
        "mission": {"type": "cmd_vel_script", "segments": [{"duration_s": 1.0, "linear_mps": 0.1}]},
        "localization.type": "none",
    }
    code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, values))], capsys)
    assert code == 2, err
    line = assert_one_line_error(err, contains="inside platform")
    assert "its top is 19.0 cm above z = 0), lower the world's models by 0.190 m (their <pose> z)" in line
    assert "set world.floor_height_m" not in line
    values["world.floor_height_m"] = 0.2
    code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, values))], capsys)
    assert "world.floor_height_m is 0.2 m: shapes whose top is at or below it are neither seen nor touched" in err


def test_a_world_too_large_to_map_names_the_world_and_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # two pillars 400 m apart (as gz-sim's 3k_shapes spans 1.5 km): the world, not the spawn pose, is too large
    pillars = "".join(
        f"<model name='p{i}'><static>1</static><pose>{x} 3 0.5 0 0 0</pose><link name='l'><collision name='c'>"
        "<geometry><box><size>0.2 0.2 1</size></box></geometry></collision></link></model>"
        for i, x in enumerate((-200, 200))
    )
    world = tmp_path / "wide.world"
    world.write_text(f"<sdf version='1.6'><world name='w'>{pillars}</world></sdf>")
    code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, {"world.sdf": str(world)}))], capsys)
    assert code == 2, err
    line = assert_one_line_error(err, contains=f"{world}: the world's obstacles span 400.2 x 0.2 m")
    assert "give `map:` a map_server YAML" in line


def test_spawning_inside_an_included_model_names_its_link_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    box = tmp_path / "models" / "box"
    box.mkdir(parents=True)
    (box / "model.sdf").write_text(
        "<sdf version='1.6'><model name='box'><static>1</static><link name='box_link'><collision name='c'>"
        "<geometry><box><size>1 1 1</size></box></geometry></collision></link></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><include><uri>model://box</uri><pose>0 0 0.5 0 0 0</pose></include>"
        "<model name='shelf'><static>1</static><pose>5 0 0.5 0 0 0</pose><include><uri>model://box</uri></include>"
        "</model></world></sdf>"
    )
    for x_m, inside in ((0.0, "inside box::box_link;"), (5.0, "inside shelf::box::box_link;")):
        values = {"world.sdf": "w.world", "world.model_path": ["models"], "robot.initial_pose.x_m": x_m}
        code, _, err = run(["scenario", "check", str(write_scenario(tmp_path, values))], capsys)
        assert code == 2, err
        assert_one_line_error(err, contains=inside)


# -- bag metadata times that no rosbag2 writes (int64 nanoseconds) --------------------------------------

YEAR_318857_NS = (318857 - 1970) * 365_2425 * 86_400 * 10**5  # about 1e22 ns since the epoch


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        ("nanoseconds: 29842068479", "nanoseconds: 1e30", "nanoseconds"),
        (
            "nanoseconds_since_epoch: 1701217690319080701",
            f"nanoseconds_since_epoch: {YEAR_318857_NS}",
            "nanoseconds_since_epoch",
        ),
    ],
    ids=["duration_1e30_ns", "start_in_year_318857"],
)
def test_bag_info_refuses_a_metadata_time_beyond_int64(
    old: str, new: str, key: str, tmp_path: Path, fixtures: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = fixtures / "bags" / "tb3_waffle_gazebo_humble"
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "rosbag_0.db3").write_bytes((source / "rosbag_0.db3").read_bytes())
    (bag / "metadata.yaml").write_text((source / "metadata.yaml").read_text().replace(old, new, 1))
    code, _, err = run(["bag", "info", str(bag)], capsys)
    assert code == 5, err
    assert_one_line_error(err, contains=f"{key}: ")
    assert "does not fit a 64-bit whole number" in err


def test_an_obstacle_too_slow_to_reach_its_path_end_in_any_run_still_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    obstacle = {"shape": "box", "size_m": [0.3, 0.3, 0.4], "path_xy_m": [[3, 3], [4, 3]], "speed_mps": 1e-300}
    path = write_scenario(tmp_path, {"obstacles": [obstacle], "drive.type": "kinematic", "mission": {"type": "none"}})
    code, _, err = run(["simulate", str(path), "--duration", "0.5", "--out", str(tmp_path / "bag")], capsys)
    assert code == 0, err


@pytest.mark.parametrize("command", ["play", "simulate"])
def test_a_speed_too_slow_for_a_clock_is_refused(
    command: str, tmp_path: Path, fixtures: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # --speed 1e-300 put the next message centuries on: an OverflowError in the pacer, exit 70
    target = [str(fixtures / "bags" / "tb3_waffle_gazebo_humble")] if command == "play" else []
    with pytest.raises(SystemExit) as stop:
        main(
            [command, *target, "--speed", "1e-300", "--out", str(tmp_path / "bag")]
            if command == "simulate"
            else [command, *target, "--speed", "1e-300"]
        )
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "--speed must be at least 1e-06 (a million times slower than real time)" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_spawn_far_outside_the_world_is_warned_of(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 100 m east of the house: nothing of it within the lidar's 3.5 m, a Nav2 mission finds no path.
    path = write_scenario(tmp_path, {"robot.initial_pose.x_m": 100.0})
    code, _, err = run(["scenario", "check", str(path)], capsys)
    assert code == 0, err
    assert "robot.initial_pose: (100, 0) is 93.7 m outside the world's models" in err
    near = write_scenario(tmp_path, {"robot.initial_pose.x_m": 0.5})
    code, _, err = run(["scenario", "check", str(near)], capsys)
    assert code == 0 and "outside the world" not in err, err


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("name: x\nseed: -1\n", ":2: seed: must be a non-negative whole number"),
        ("name: x\nsensors:\n  lidar: {rate_hz: -5}\n", ":3: sensors.lidar.rate_hz: must be a rate"),
        ("name: x\nmission:\n  type: behavior_tree\n  tree: nonexist.xml\n", ":4: mission.tree: "),
        ("name: x\nrobot:\n  model: nothere\n", ":3: robot.model: model 'nothere' not found"),
        ("name: x\nnodes:\n  - {plugin: 'nomod:Cls'}\n", ":3: nodes[0].plugin: module 'nomod' not found"),
    ],
)
def test_a_refused_scenario_value_names_its_line(
    text: str, where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_scenario(tmp_path, {}, text)
    for argv in (["scenario", "check", str(path)], ["simulate", str(path), "--out", str(tmp_path / "bag")]):
        code, _, err = run(argv, capsys)
        assert code != 0, err
        line = assert_one_line_error(err)
        assert line.startswith(f"twin: error: {path}{where}"), line  # the file once, then its line


def test_scenario_check_prints_what_each_key_resolves_to(capsys: pytest.CaptureFixture[str]) -> None:
    # The default scenario, resolved: the motor FMU `fmu: auto` picks, the tree and locations files,
    # the Nav2 params and navigator tree the run reads, and whether AMCL runs.
    code, out, err = run(["scenario", "check", str(SCENARIOS / "default.yaml")], capsys)
    assert code == 0, err
    lines = dict(line.split(None, 1) for line in out.splitlines()[1:])
    assert lines["drive"] == "fmu builtin:xm430_w210_servo (auto), velocity-servo"
    assert lines["mission"] == f"behavior_tree {TREES / 'tree.xml'}, {TREES / 'sim_house_locations.yaml'}"
    assert lines["nav2"].startswith(f"params {REPO / 'twin' / 'data' / 'nav2' / 'waffle.yaml'}, tree ")
    assert lines["nav2"].endswith("navigate_to_pose_w_replanning_and_recovery.xml, map from_world, localization AMCL")


def test_a_search_tree_without_the_camera_is_warned_of_by_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_scenario(tmp_path, {"mission.type": "behavior_tree", "mission.tree": str(TREES / "search_naive.xml")})
    code, _, err = run(["scenario", "check", str(path)], capsys)
    assert code == 0, err
    assert "look_for_obj_in_location1, look_for_obj_in_location2" in err and "enable sensors.camera" in err
    code, _, err = run(["scenario", "check", str(SCENARIOS / "house_search_naive.yaml")], capsys)
    assert code == 0 and "enable sensors.camera" not in err, err


def test_scenario_check_resolves_a_model_named_by_path_by_the_model_it_loads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_scenario(tmp_path, {"robot.model": str(REPO / "sdf" / "models" / "turtlebot3_burger")})
    code, out, err = run(["scenario", "check", str(path)], capsys)
    assert code == 0, err
    assert (
        "builtin:xl430_w250_servo (auto)" in out and f"params {REPO / 'twin' / 'data' / 'nav2' / 'burger.yaml'}" in out
    )
