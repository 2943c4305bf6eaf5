from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from twin.core.errors import ConfigError
from twin.sim.scenario import DEFAULTS_PATH, Scenario, default_scenario_path
from twin.sim.scenario_file import load_scenario


def test_default_scenario_loads_and_points_at_shipped_files(repo: Path) -> None:
    scenario = load_scenario(default_scenario_path())
    assert scenario.world.sdf == repo / "sdf" / "worlds" / "house.sdf"
    assert scenario.world.model_path == (repo / "sdf" / "models",)
    assert scenario.robot.model == "turtlebot3_waffle"


def test_packaged_defaults_agree_with_dataclass_defaults(tmp_path: Path) -> None:
    """The defaults file is the documented reference; the dataclass defaults must not drift from it."""
    empty = tmp_path / "empty.yaml"
    empty.write_text("{}\n")
    loaded = load_scenario(empty)
    for f in dataclasses.fields(Scenario):
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            continue
        if f.name == "source_path":  # set by the loader to the file it read
            continue
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        assert getattr(loaded, f.name) == default, f"{DEFAULTS_PATH}: {f.name} differs from Scenario.{f.name}"


def test_scenario_typo_names_file_line_key_and_fix(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nsensors:\n  lidar:\n    noise_std: 0.02\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:4: sensors.lidar.noise_std: unknown key; did you mean 'noise_std_m'\?"
    ):
        load_scenario(path)


def test_a_key_without_its_unit_is_pointed_to_the_unit_named_one(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("robot:\n  initial_pose: {x_m: 1.0, yaw: 0.5}\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:2: robot.initial_pose.yaw: unknown key; did you mean 'yaw_rad'\? \(settings name"
    ):
        load_scenario(path)


def test_a_key_one_section_too_high_is_pointed_to_its_sections(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("robot:\n  x_m: 1.0\nrobots:\n  - name: r1\n    model: turtlebot3_burger\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:2: robot.x_m: unknown key; did you mean 'robot.initial_pose.x_m'\?$"
    ):
        load_scenario(path)
    path.write_text("robots:\n  - name: r1\n    model: turtlebot3_burger\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:3: robots\[0\].model: unknown key; did you mean 'robots\[0\].robot.model'\?$"
    ):
        load_scenario(path)


def test_yaml_merge_keys_lay_out_as_a_yaml_loader_does(tmp_path: Path) -> None:
    # `<<: *robot` is how a YAML user shares an entry; the mapping's own keys win over the merged ones.
    path = tmp_path / "s.yaml"
    path.write_text(
        "name: t\n<<: {seed: 3, max_duration_s: 9}\nseed: 4\nrobots:\n"
        "  - &r {name: a, sensors: {lidar: {samples: 180}}, robot: {initial_pose: {x_m: 0.0}}}\n"
        "  - {<<: *r, name: b, robot: {initial_pose: {x_m: 1.5}}}\n"
    )
    sc = load_scenario(path)
    assert (sc.seed, sc.max_duration_s) == (4, 9.0)
    a, b = sc.robots
    assert (a.name, b.name) == ("a", "b") and b.sensors.lidar.samples == 180 and b.robot.initial_pose.x_m == 1.5
    path.write_text("name: t\n<<: 3\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:2: '<<' \(a YAML merge key\) takes a mapping or a list of mappings$"
    ):
        load_scenario(path)


@pytest.mark.parametrize("name", ["../../escape", "a/b", "x" * 101, ".hidden", "trailing "])
def test_a_scenario_name_that_cannot_name_a_bag_folder_is_refused(tmp_path: Path, name: str) -> None:
    # The bag folder is <out_dir>/<name>_<time>: `../x` wrote outside it, 300 characters was an OSError.
    path = tmp_path / "s.yaml"
    path.write_text(f"name: {name!r}\n")
    with pytest.raises(ConfigError, match=rf"^{path}:1: name: .* cannot name the bag folder"):
        load_scenario(path)
    path.write_text("name: 'my run v1.2-b'\n")
    assert load_scenario(path).name == "my run v1.2-b"


def test_a_key_given_twice_is_refused_where_it_is(tmp_path: Path) -> None:
    # PyYAML kept the last silently: `seed: 1` then `seed: 2` ran seed 2
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nseed: 1\nrobot:\n  model: turtlebot3_burger\nseed: 2\n")
    with pytest.raises(
        ConfigError, match=rf"^{path}:5: 'seed' is given twice in one mapping \(first at line 2\); keep one$"
    ):
        load_scenario(path)
    path.write_text("robots:\n  - {name: a, name: b}\n")  # inside a flow mapping of a list too
    with pytest.raises(ConfigError, match="'name' is given twice"):
        load_scenario(path)


@pytest.mark.parametrize(
    ("mission", "expected"),
    [
        ("{type: cmd_vel_script, segments: []}", "mission: segments is empty"),
        ("{type: waypoints, points: []}", "mission: points is empty"),
    ],
)
def test_a_mission_with_nothing_to_do_is_refused(tmp_path: Path, mission: str, expected: str) -> None:
    # (it ran 0 ms, wrote a 14-message bag and exited 0: a typo passed as a success)
    path = tmp_path / "s.yaml"
    path.write_text(f"name: t\nmission: {mission}\n")
    with pytest.raises(ConfigError, match=rf"^{path}:2: {expected}"):
        load_scenario(path)


def test_overriding_one_key_keeps_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nrobot: {model: turtlebot3_burger}\nrecording: {storage: sqlite3}\n")
    scenario = load_scenario(path)
    assert scenario.robot.model == "turtlebot3_burger"
    assert scenario.robot.initial_pose.x_m == 0.0
    assert scenario.recording.storage == "sqlite3"
    assert scenario.recording.distro == "humble"


def test_the_retired_grid_navigator_is_named_gone_with_its_line(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nnavigation:\n  type: grid\n")
    with pytest.raises(
        ConfigError,
        match=rf"^{path}:3: navigation: type 'grid': the grid stand-in is gone, Nav2's stack is the navigator",
    ):
        load_scenario(path)


def test_a_navigator_other_than_nav2_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nnavigation:\n  type: navfn_only\n")
    with pytest.raises(ConfigError, match=r"navigation: type 'navfn_only' is not allowed; the navigator is 'nav2'"):
        load_scenario(path)


def test_the_grid_planners_mission_keys_are_unknown_now(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nmission:\n  planner:\n    resolution_m: 0.05\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3: mission.planner: unknown key"):
        load_scenario(path)


def test_a_bag_recorded_before_the_grid_was_retired_loads_without_its_grid_keys(tmp_path: Path) -> None:
    # An older twin recorded the grid stand-in's mission keys (their defaults) in every tree mission's provenance.
    import yaml

    from twin.sim.provenance import scenario_yaml
    from twin.sim.scenario_file import without_retired_keys

    scenario = load_scenario(default_scenario_path())
    data = yaml.safe_load(scenario_yaml(scenario))
    data["mission"]["follower"] = {"max_linear_mps": 0.22, "tolerance_m": 0.1}
    data["mission"]["planner"] = {"resolution_m": 0.05, "robot_radius_m": None}
    data["mission"]["progress"] = {"required_movement_radius_m": 0.5}
    recorded = yaml.safe_dump(data, sort_keys=False)
    strict = tmp_path / "as_written.yaml"
    strict.write_text(recorded)
    with pytest.raises(ConfigError, match=r"mission.follower: unknown key"):
        load_scenario(strict)  # a file a user writes keeps failing on them
    cleaned = tmp_path / "from_bag.yaml"
    cleaned.write_text(without_retired_keys(recorded))
    again = load_scenario(cleaned)
    assert dataclasses.replace(again, source_path=None) == dataclasses.replace(scenario, source_path=None)


def test_a_robots_entry_is_laid_over_the_top_level_sections(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(
        "name: t\n"
        "drive: {type: kinematic}\n"
        "robots:\n"
        "  - {name: robot1}\n"
        "  - name: robot2\n"
        "    namespace: /fleet/second\n"
        "    robot: {initial_pose: {x_m: 1.5}}\n"
        "    drive: {max_wheel_acceleration_mps2: 2.0}\n"
    )
    scenario = load_scenario(path)
    (ns1, one), (ns2, two) = scenario.robot_scenarios()
    assert (ns1, ns2) == ("robot1", "fleet/second")
    assert one.robot.initial_pose.x_m == 0.0 and two.robot.initial_pose.x_m == 1.5
    assert one.robot.model == two.robot.model == "turtlebot3_waffle"  # the top level's, kept under the entry's pose
    assert one.drive.type == two.drive.type == "kinematic"
    assert (one.drive.max_wheel_acceleration_mps2, two.drive.max_wheel_acceleration_mps2) == (1.0, 2.0)
    assert one.robots == () and one.world == scenario.world  # a robot's view: its sections, the one world


def test_without_robots_the_scenario_is_the_one_robot_without_a_namespace() -> None:
    scenario = load_scenario(default_scenario_path())
    assert scenario.robot_scenarios() == [("", scenario)]


def test_a_recorded_fleet_scenario_loads_back_the_same(tmp_path: Path) -> None:
    from twin.sim.provenance import scenario_yaml

    path = tmp_path / "s.yaml"
    path.write_text("name: t\nrobots: [{name: a}, {name: b, robot: {initial_pose: {y_m: 1.0}}}]\n")
    scenario = load_scenario(path)
    again = tmp_path / "again.yaml"
    again.write_text(scenario_yaml(scenario))
    assert load_scenario(again).robots == scenario.robots


def test_a_robots_entry_that_is_not_a_mapping_is_named(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nrobots: [robot1]\n")
    with pytest.raises(ConfigError, match=rf"^{path}:2: robots\[0\]: expected a mapping"):
        load_scenario(path)


def test_the_default_tf_mode_leaves_the_recorded_scenario_as_before(tmp_path: Path) -> None:
    """A run without `tf:` records no `tf` key (its bag's provenance is as before the option existed)."""
    from twin.sim.provenance import scenario_yaml

    one = tmp_path / "one.yaml"
    one.write_text("name: one\n")
    assert "\ntf:" not in scenario_yaml(load_scenario(one))
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text("name: two\ntf: {mode: frame_prefix}\nrobots: [{name: a}, {name: b}]\n")
    recorded = tmp_path / "recorded.yaml"
    recorded.write_text(scenario_yaml(load_scenario(fleet)))
    assert load_scenario(recorded).tf.mode == "frame_prefix"  # and a prefixed fleet's loads back as it ran


@pytest.mark.parametrize("out_dir", ["/dev/null", "{file}/bags"])
def test_an_out_dir_where_no_folder_can_go_is_refused_naming_the_key(tmp_path: Path, out_dir: str) -> None:
    # It said "the bag folder exists and is not empty" (exit 5): nothing was there, a file was in the way.
    from tests.conftest import run_twin

    file = tmp_path / "a_file"
    file.write_text("")
    out_dir = out_dir.format(file=file)
    path = tmp_path / "s.yaml"
    path.write_text(f"name: t\nmax_duration_s: 1\nrecording: {{out_dir: {out_dir}}}\n")
    result = run_twin("simulate", str(path))
    assert result.returncode == 2, result.stderr
    blocker = "/dev/null" if out_dir == "/dev/null" else str(file)
    assert result.stderr.strip().splitlines() == [
        f"twin: error: {path}: recording.out_dir: {out_dir}: {blocker} is not a folder; give a folder for the bags "
        "(or --out)"
    ]


def test_an_unknown_built_in_fmu_names_the_key_and_the_nearest_built_in(tmp_path: Path) -> None:
    # It said "unknown built-in FMU 'xm430_w21'" with exit 4: no file, no key, no nearest name.
    from tests.conftest import run_twin

    path = tmp_path / "s.yaml"
    path.write_text(
        "name: t\nrobots:\n  - {name: a}\n  - {name: b, robot: {initial_pose: {x_m: 1.5}}, drive: {fmu: 'builtin:xm430_w21'}}\n"
    )
    for command in (("scenario", "check", str(path)), ("simulate", str(path), "--out", str(tmp_path / "bag"))):
        result = run_twin(*command)
        assert result.returncode == 2, result.stderr
        assert result.stderr.strip().splitlines() == [
            f"twin: error: {path}:4: robots[1].drive.fmu: unknown built-in FMU 'xm430_w21'; did you mean 'xm430_w210'?"
        ]
