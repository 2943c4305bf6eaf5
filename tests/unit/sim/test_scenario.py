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


def test_overriding_one_key_keeps_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nrobot: {model: turtlebot3_burger}\nrecording: {storage: sqlite3}\n")
    scenario = load_scenario(path)
    assert scenario.robot.model == "turtlebot3_burger"
    assert scenario.robot.initial_pose.x_m == 0.0
    assert scenario.recording.storage == "sqlite3"
    assert scenario.recording.distro == "humble"
