"""sensors.camera in a scenario: bad values refused in one line naming the key; the SDF's camera overridden."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.core.errors import ConfigError
from twin.sim.camera import camera_spec
from twin.sim.scenario import CameraSection
from twin.sim.scenario_file import load_scenario
from twin.world import load_robot

MODELS = Path(__file__).resolve().parents[3] / "sdf" / "models"


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        ("{enabled: true, width: 0}", "width must be from 1 to 8192 pixels, got 0"),
        ("{enabled: true, height: 9000}", "height must be from 1 to 8192 pixels, got 9000"),
        ("{enabled: true, rate_hz: -1}", "rate_hz must be a positive number, got -1"),
        ("{enabled: true, jpeg: true}", "jpeg"),
    ],
)
def test_bad_camera_settings_are_refused_naming_the_key(tmp_path: Path, camera: str, message: str) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"sensors:\n  camera: {camera}\n")
    with pytest.raises(ConfigError, match=message) as err:
        load_scenario(path)
    assert "sensors.camera" in str(err.value)
    assert "\n" not in str(err.value)


def test_the_scenario_overrides_the_sdfs_size_rate_and_noise() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[MODELS])
    spec = camera_spec(robot, CameraSection(enabled=True, width=320, height=240, rate_hz=5.0, noise=False))
    assert (spec.width, spec.height, spec.rate_hz, spec.noise_std) == (320, 240, 5.0, 0.0)
    kept = camera_spec(robot, CameraSection(enabled=True))
    assert (kept.width, kept.height, kept.rate_hz, kept.noise_std) == (1920, 1080, 30.0, 0.007)


def test_a_camera_on_a_robot_without_one_is_refused() -> None:
    robot = load_robot("turtlebot3_burger", model_path=[MODELS])
    with pytest.raises(ConfigError, match=r"robot 'turtlebot3_burger' has no <sensor type=\"camera\"> in its SDF"):
        camera_spec(robot, CameraSection(enabled=True))


def test_scenario_check_refuses_a_camera_on_a_robot_without_one(tmp_path: Path) -> None:
    from twin.sim.check import check_scenario

    path = tmp_path / "s.yaml"
    path.write_text("robot: {model: turtlebot3_burger}\nsensors:\n  camera: {enabled: true}\n")
    with pytest.raises(ConfigError, match=r"s.yaml: sensors.camera.enabled: robot 'turtlebot3_burger' has no"):
        check_scenario(load_scenario(path), path)
    path.write_text("sensors:\n  camera: {enabled: true}\n")  # the default robot, the Waffle, has one
    check_scenario(load_scenario(path), path)
