"""The sweep file: expansion into runs (grid, zip, seeds, seeded draws) and one-line errors for bad input."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO, run_twin
from twin.core.errors import ConfigError
from twin.sim.scenario_file import load_scenario
from twin.sweep import expand_runs, load_sweep, wilson_interval

DEFAULT = REPO / "scenarios" / "default.yaml"


def _sweep(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(f"scenario: {DEFAULT}\n{text}", encoding="utf-8")
    return path


def test_a_grid_runs_every_combination_for_every_seed(tmp_path: Path) -> None:
    text = "runs: 2\nvary:\n  robot.model: [turtlebot3_waffle, turtlebot3_burger]\n  max_duration_s: [5, 6, 7]\n"
    runs = expand_runs(load_sweep(_sweep(tmp_path, text)))
    assert len(runs) == 2 * 3 * 2
    assert [r.run_id for r in runs[:3]] == ["r0000", "r0001", "r0002"]
    combos = {(dict(r.values)["robot.model"], dict(r.values)["max_duration_s"], r.seed) for r in runs}
    assert len(combos) == 12


def test_zip_pairs_the_lists(tmp_path: Path) -> None:
    text = "zip: true\nvary:\n  robot.model: [turtlebot3_waffle, turtlebot3_burger]\n  robot.initial_pose.x_m: [0.1, 0.2]\n"
    runs = expand_runs(load_sweep(_sweep(tmp_path, text)))
    assert [dict(r.values) for r in runs] == [
        {"robot.model": "turtlebot3_waffle", "robot.initial_pose.x_m": 0.1},
        {"robot.model": "turtlebot3_burger", "robot.initial_pose.x_m": 0.2},
    ]


def test_a_run_scenario_sets_its_values_and_keeps_the_base(tmp_path: Path) -> None:
    text = "seeds: [3]\nvary:\n  robot.initial_pose.y_m: [0.25]\n  mission.tick_rate_hz: [4.0]\n"
    (run,) = expand_runs(load_sweep(_sweep(tmp_path, text)))
    scenario = yaml.safe_load(run.scenario_yaml)
    assert scenario["name"] == "house_waffle"
    assert scenario["robot"]["initial_pose"] == {"y_m": 0.25}
    assert scenario["mission"] == {"tick_rate_hz": 4.0}
    assert run.seed == 3


def test_relative_paths_become_absolute_so_any_worker_reads_the_same_files(tmp_path: Path) -> None:
    (tmp_path / "base").mkdir()
    (tmp_path / "base" / "s.yaml").write_text("mission: {type: behavior_tree, tree: ../t.xml}\n", encoding="utf-8")
    path = tmp_path / "sweep.yaml"
    path.write_text("scenario: base/s.yaml\nvary:\n  world.sdf: [w.sdf]\n", encoding="utf-8")
    (run,) = expand_runs(load_sweep(path))
    scenario = yaml.safe_load(run.scenario_yaml)
    assert scenario["mission"]["tree"] == str(tmp_path / "t.xml")
    assert scenario["world"]["sdf"] == str(tmp_path / "w.sdf")
    # a random choice's paths and a robot model named by a path beside the sweep file, the same way
    (tmp_path / "m" / "rover").mkdir(parents=True)
    (tmp_path / "m" / "rover" / "model.sdf").write_text("<sdf version='1.6'><model name='r'/></sdf>")
    path.write_text(
        "scenario: base/s.yaml\nrandom:\n  world.sdf: {choice: [w.sdf]}\n  robot.model: {choice: [m/rover/model.sdf]}\n"
        "vary:\n  robot.initial_pose.x_m: [0.0]\n",
        encoding="utf-8",
    )
    (run,) = expand_runs(load_sweep(path))
    scenario = yaml.safe_load(run.scenario_yaml)
    assert scenario["world"]["sdf"] == str(tmp_path / "w.sdf")
    assert scenario["robot"]["model"] == str(tmp_path / "m" / "rover" / "model.sdf")


def test_random_draws_are_seeded_within_bounds_and_repeat(tmp_path: Path) -> None:
    text = (
        "runs: 20\nrandom:\n  robot.initial_pose.x_m: {uniform: [-0.2, 0.2]}\n"
        "  robot.initial_pose.yaw_rad: {normal: [0.0, 0.1]}\n"
        "  robot.model: {choice: [turtlebot3_waffle, turtlebot3_burger]}\n"
    )
    first = expand_runs(load_sweep(_sweep(tmp_path, text)))
    again = expand_runs(load_sweep(_sweep(tmp_path, text)))
    assert [r.values for r in first] == [r.values for r in again]
    assert [r.key for r in first] == [r.key for r in again]
    xs = [dict(r.values)["robot.initial_pose.x_m"] for r in first]
    assert all(-0.2 <= x <= 0.2 for x in xs)
    assert len(set(xs)) == 20
    assert {dict(r.values)["robot.model"] for r in first} == {"turtlebot3_waffle", "turtlebot3_burger"}
    other = expand_runs(load_sweep(_sweep(tmp_path, text + "random_seed: 1\n")))
    assert [r.values for r in other] != [r.values for r in first]


FLEET = REPO / "scenarios" / "house_two_waffles.yaml"


def _fleet_sweep(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "fleet_sweep.yaml"
    path.write_text(f"scenario: {FLEET}\n{text}", encoding="utf-8")
    return path


def test_a_fleet_robot_is_varied_by_its_index_and_keeps_its_other_keys(tmp_path: Path) -> None:
    text = (
        "runs: 3\nvary:\n  robots[1].robot.initial_pose.x_m: [1.4, 1.6]\n"
        "random:\n  robots[0].robot.initial_pose.yaw_rad: {uniform: [-0.1, 0.1]}\n"
    )
    runs = expand_runs(load_sweep(_fleet_sweep(tmp_path, text)))
    assert len(runs) == 2 * 3
    for run in runs:
        values = dict(run.values)
        robot1, robot2 = yaml.safe_load(run.scenario_yaml)["robots"]
        assert robot2["name"] == "robot2" and robot2["mission"]["locations"].endswith("_reversed.yaml")
        assert robot2["robot"]["initial_pose"] == {"x_m": values["robots[1].robot.initial_pose.x_m"], "y_m": -0.2,
                                                    "yaw_rad": 0.0}  # fmt: skip
        assert robot1["robot"]["initial_pose"]["yaw_rad"] == values["robots[0].robot.initial_pose.yaw_rad"]
        assert -0.1 <= robot1["robot"]["initial_pose"]["yaw_rad"] <= 0.1
        assert robot1["robot"]["initial_pose"]["x_m"] == 0.0
    assert {dict(r.values)["robots[1].robot.initial_pose.x_m"] for r in runs} == {1.4, 1.6}


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "vary:\n  robots[2].robot.model: [turtlebot3_burger]\n",
            "vary.robots[2].robot.model: the base scenario has robots[0] to robots[1]; vary one it has",
        ),
        ("vary:\n  robots.robot.model: [a]\n", "robots is a list; name one entry, e.g. robots[0]"),
        ("vary:\n  robots[0].robto.model: [a]\n", "robots[0] has no key 'robto'; did you mean 'robot'?"),
        (  # a key one section too high (as the issue writes it): each section it belongs to named
            "vary:\n  robots[1].initial_pose.x_m: [1.5]\n",
            "robots[1] has no key 'initial_pose'; did you mean 'robots[1].robot.initial_pose.x_m' or "
            "'robots[1].localization.initial_pose.x_m'?",
        ),
        ("vary:\n  robot.x_m: [0.5]\n", "robot has no key 'x_m'; did you mean 'robot.initial_pose.x_m'?"),
        ("vary:\n  model: [a]\n", "the scenario has no key 'model'; did you mean 'robot.model'?"),
        ("vary:\n  robot[0].model: [a]\n", "robot is not a list; write robot without [0]"),
        ("vary:\n  robots[x].name: [a]\n", "not a dotted key"),
    ],
)
def test_bad_fleet_keys_fail_in_one_line(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_sweep(_fleet_sweep(tmp_path, text))
    assert expected in str(err.value)
    assert "\n" not in str(err.value)


_SMALL_FLEET = """name: small_fleet
max_duration_s: 20
robots:
  - name: robot1
    robot: {initial_pose: {x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}
  - name: robot2
    robot: {initial_pose: {x_m: 1.5, y_m: -0.2, yaw_rad: 0.0}}
"""


def _small_fleet_sweep(tmp_path: Path, text: str) -> Path:
    (tmp_path / "base.yaml").write_text(_SMALL_FLEET, encoding="utf-8")
    path = tmp_path / "sweep.yaml"
    path.write_text(f"scenario: base.yaml\n{text}", encoding="utf-8")
    return path


def test_a_whole_fleet_entry_replaces_that_entry_and_keeps_the_others(tmp_path: Path) -> None:
    """`robots[1]: [{...}]` replaces robots[1] (it once turned `robots:` into that one mapping)."""
    text = "vary:\n  robots[1]: [{name: robot2, robot: {initial_pose: {x_m: 2.0, y_m: 0.3}}}, {name: robot3}]\n"
    runs = expand_runs(load_sweep(_small_fleet_sweep(tmp_path, text)))
    assert [dict(r.values)["robots[1]"]["name"] for r in runs] == ["robot2", "robot3"]
    for run in runs:
        robots = yaml.safe_load(run.scenario_yaml)["robots"]
        assert robots == [yaml.safe_load(_SMALL_FLEET)["robots"][0], dict(run.values)["robots[1]"]]
        path = tmp_path / f"{run.run_id}.yaml"
        path.write_text(run.scenario_yaml, encoding="utf-8")
        assert [entry.name for entry in load_scenario(path).robots] == ["robot1", dict(run.values)["robots[1]"]["name"]]


def test_a_list_entry_below_a_section_is_replaced_in_its_list(tmp_path: Path) -> None:
    (tmp_path / "base.yaml").write_text(
        "mission:\n  type: cmd_vel_script\n  segments: [{duration_s: 1.0, linear_mps: 0.1}, {duration_s: 2.0}]\n",
        encoding="utf-8",
    )
    path = tmp_path / "sweep.yaml"
    path.write_text("scenario: base.yaml\nvary:\n  mission.segments[1]: [{duration_s: 0.5, angular_radps: 0.2}]\n")
    (run,) = expand_runs(load_sweep(path))
    assert yaml.safe_load(run.scenario_yaml)["mission"]["segments"] == [
        {"duration_s": 1.0, "linear_mps": 0.1},
        {"duration_s": 0.5, "angular_radps": 0.2},
    ]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "vary:\n  robots[1]: [robot2]\n",
            "sweep.yaml:3: vary.robots[1]: robots[1] is a section: each value is a mapping of its keys, got "
            "'robot2'; write e.g. {name: ...}, or vary one of its keys, e.g. robots[1].name",
        ),
        ("vary:\n  robots[1]: [{nmae: robot2}]\n", "vary.robots[1]: robots[1] has no key 'nmae'; did you mean 'name'?"),
        (
            "vary:\n  robots[1]: [{name: r, robot: {initial_pose: {x: 1.0}}}]\n",
            "vary.robots[1]: robots[1].robot.initial_pose has no key 'x'; did you mean 'x_m'?",
        ),
        ("vary:\n  robots[1].robot: [1.5]\n", "robots[1].robot is a section: each value is a mapping of its keys"),
        ("vary:\n  robots[2]: [{name: robot3}]\n", "the base scenario has robots[0] to robots[1]; vary one it has"),
        ("random:\n  robots[1]: {choice: [{name: robot2}, robot3]}\n", "random.robots[1].choice: robots[1] is a"),
        ("random:\n  robots[1]: {uniform: [0, 1]}\n", "random.robots[1].uniform: robots[1] is a section"),
    ],
)
def test_a_bad_whole_entry_fails_in_one_line(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_sweep(_small_fleet_sweep(tmp_path, text))
    assert expected in str(err.value)
    assert "\n" not in str(err.value)


def test_the_cli_refuses_a_whole_entry_that_is_not_a_mapping_with_exit_2(tmp_path: Path) -> None:
    sweep = _small_fleet_sweep(tmp_path, "vary:\n  robots[1]: [robot2]\n")
    result = run_twin("sweep", str(sweep), "--workers", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0
    assert f"{sweep}:3: vary.robots[1]: robots[1] is a section" in result.stderr
    assert not (tmp_path / "out" / "runs").exists()


def test_a_robot_index_needs_a_fleet_in_the_base_scenario(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="the base scenario has no robots; vary one it has"):
        load_sweep(_sweep(tmp_path, "vary:\n  robots[0].robot.model: [turtlebot3_burger]\n"))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "vary:\n  robot.modle: [a]\n",
            "sweep.yaml:3: vary.robot.modle: robot has no key 'modle'; did you mean 'model'?",
        ),
        ("vary:\n  robot.initial_pose.x: [1]\n", "did you mean 'x_m'?"),
        (
            "random:\n  sensor.imu.enabled: {choice: [true]}\n",
            "random.sensor.imu.enabled: the scenario has no key 'sensor'",
        ),
        ("zip: true\nvary:\n  seed: [1, 2]\n  robot.model: [a]\n", "lengths differ (seed: 2, robot.model: 1)"),
        ("runs: 3\nseeds: [1]\n", "give runs: N (seeds 0..N-1) or seeds: [..], not both"),
        ("runs: 3\nvary:\n  seed: [1, 2]\n", "seed: vary the seed or give runs:/seeds:, not both"),
        ("timeout: 5\n", "timeout: unknown key; did you mean 'timeout_s'?"),
        ("random:\n  seed: {poisson: [1]}\n", "unknown distribution 'poisson'"),
        (  # (these drew from a reversed range, or a negative spread, without a word)
            "random:\n  robot.initial_pose.x_m: {uniform: [1, -1]}\n",
            "random.robot.initial_pose.x_m.uniform: expected [low, high] with low <= high, got [1, -1]; swap them",
        ),
        ("random:\n  robot.initial_pose.x_m: {normal: [0, -1]}\n", "expected [mean, std] with std >= 0"),
        ("random:\n  robot.initial_pose.x_m: {uniform: [0, .inf]}\n", "expected finite numbers"),
    ],
)
def test_bad_sweep_files_fail_in_one_line(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_sweep(_sweep(tmp_path, text))
    assert expected in str(err.value)
    assert "\n" not in str(err.value)


def test_the_cli_reports_a_bad_key_in_one_line_with_exit_2(tmp_path: Path) -> None:
    result = run_twin("sweep", str(_sweep(tmp_path, "vary:\n  robot.modle: [a]\n")))
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0
    assert "did you mean 'model'?" in result.stderr


def test_an_unreachable_scheduler_names_the_address_and_how_to_start_one(tmp_path: Path) -> None:
    result = run_twin("sweep", str(_sweep(tmp_path, "")), "--scheduler", "tcp://127.0.0.1:9")
    assert result.returncode == 2
    line = result.stderr.strip()
    assert "\n" not in line
    assert "tcp://127.0.0.1:9" in line
    assert "`dask scheduler`" in line
    assert "`dask worker tcp://127.0.0.1:9`" in line


@pytest.mark.parametrize(
    ("successes", "runs", "low", "high"),
    [(5, 10, 0.2366, 0.7634), (0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (47, 50, 0.8378, 0.9794)],
)
def test_wilson_interval_matches_published_values(successes: int, runs: int, low: float, high: float) -> None:
    got = wilson_interval(successes, runs)
    assert math.isclose(got[0], low, abs_tol=6e-5)
    assert math.isclose(got[1], high, abs_tol=6e-5)


def test_a_run_key_covers_the_code_so_a_changed_twin_runs_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A sweep re-run into its folder reuses finished runs by key: the key changes with the twin's code."""
    import twin.sweep.spec as spec_module

    text = "runs: 2\nvary:\n  max_duration_s: [5]\n"
    first = [r.key for r in expand_runs(load_sweep(_sweep(tmp_path, text)))]
    assert first == [r.key for r in expand_runs(load_sweep(_sweep(tmp_path, text)))]
    monkeypatch.setattr(spec_module, "code_digest", lambda: "another-build")
    changed = [r.key for r in expand_runs(load_sweep(_sweep(tmp_path, text)))]
    assert not set(changed) & set(first)


def test_the_code_digest_follows_the_sources(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from twin.core import code_identity

    package = tmp_path / "twin"
    (package / "nav").mkdir(parents=True)
    (package / "nav" / "kernel.c").write_text("int f(void) { return 1; }\n")
    (package / "notes.txt").write_text("not a source")
    monkeypatch.setattr(code_identity, "_PACKAGE", package)
    monkeypatch.setattr(code_identity, "_FMUS", tmp_path / "fmus")
    digests = []
    for change in (None, ("notes.txt", "edited"), ("nav/kernel.c", "int f(void) { return 2; }\n")):
        if change is not None:
            (package / change[0]).write_text(change[1])
        code_identity.code_digest.cache_clear()
        digests.append(code_identity.code_digest())
    code_identity.code_digest.cache_clear()
    assert digests[0] == digests[1]  # a file that is not a source does not count
    assert digests[2] != digests[0]  # a changed C source does


def test_each_row_names_the_seed_its_run_ran_with(tmp_path: Path) -> None:
    # Without runs:/seeds: a run takes its scenario's own seed (here 7, or the varied one).
    from twin.sweep.engine import _with_inputs

    base = tmp_path / "base.yaml"
    base.write_text(f"{DEFAULT.read_text()}\nseed: 7\n")
    (tmp_path / "sweep.yaml").write_text(f"scenario: {base}\nvary:\n  max_duration_s: [5, 6]\n")
    own = expand_runs(load_sweep(tmp_path / "sweep.yaml"))
    assert [_with_inputs({}, r)["seed"] for r in own] == [7, 7]
    varied = expand_runs(load_sweep(_sweep(tmp_path, "vary:\n  seed: [3, 4]\n")))
    assert [_with_inputs({}, r)["seed"] for r in varied] == [3, 4]
    seeded = expand_runs(load_sweep(_sweep(tmp_path, "seeds: [11]\n")))
    assert [_with_inputs({}, r)["seed"] for r in seeded] == [11]
