from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from twin.core.geometry import Pose
from twin.robot.lidar import Lidar
from twin.world import load_world
from twin.world.robot_model import LidarSpec, load_robot
from twin.world.scene import Scene, build_scene

REPO = Path(__file__).resolve().parents[3]


def _scene(tmp_path: Path, body: str) -> Scene:
    path = tmp_path / "w.sdf"
    path.write_text(f'<sdf version="1.7"><world name="w">{body}</world></sdf>')
    return build_scene(load_world(path))


def _drum(radius: float, x: float = 0.0, y: float = 0.0) -> str:
    """A hollow drum: a cylinder the lidar sits inside, so every beam reports its wall."""
    return (
        f'<model name="drum"><static>1</static><pose>{x} {y} 0.5 0 0 0</pose><link name="l"><collision name="c">'
        f"<geometry><cylinder><radius>{radius}</radius><length>1</length></cylinder></geometry></collision></link></model>"
    )


def _lds(**changes: object) -> LidarSpec:
    spec = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"]).lidar
    assert spec is not None
    return dataclasses.replace(spec, **changes)  # type: ignore[arg-type]


def test_published_geometry_is_gazebos_angle_step() -> None:
    spec = _lds()
    assert (spec.samples, spec.angle_min_rad, spec.angle_max_rad) == (360, 0.0, 6.28)
    assert (spec.range_min_m, spec.range_max_m, spec.rate_hz, spec.noise_std_m) == (0.12, 3.5, 5.0, 0.01)
    assert spec.angle_increment_rad == pytest.approx(6.28 / 359)
    assert spec.angle_increment_rad != pytest.approx(2 * math.pi / 360)


def test_noise_free_ranges_are_the_distances_to_a_rotated_wall(tmp_path: Path) -> None:
    wall_yaw = 0.4
    scene = _scene(
        tmp_path,
        f'<model name="wall"><static>1</static><pose>2 0.5 0.5 0 0 {wall_yaw}</pose><link name="l"><collision name="c">'
        "<geometry><box><size>0.2 6 1</size></box></geometry></collision></link></model>",
    )
    spec = _lds(noise_std_m=0.0)
    lidar = Lidar(spec, scene.ray_caster(spec.mount.z_m))
    x, y, yaw = 0.3, -0.2, 0.25
    ranges = lidar.scan(x, y, yaw)
    assert ranges.dtype == np.float32 and ranges.shape == (360,)
    ox = x + math.cos(yaw) * spec.mount.x_m - math.sin(yaw) * spec.mount.y_m
    oy = y + math.sin(yaw) * spec.mount.x_m + math.cos(yaw) * spec.mount.y_m
    normal = np.array([math.cos(wall_yaw), math.sin(wall_yaw)])
    face = np.array([2.0, 0.5]) - 0.1 * normal  # the near face of the 0.2 m thick wall
    for i in range(360):
        angle = yaw + i * spec.angle_increment_rad
        d = np.array([math.cos(angle), math.sin(angle)])
        denom = d @ normal
        t = (face - np.array([ox, oy])) @ normal / denom if denom > 1e-9 else math.inf
        along = np.array([ox, oy]) + t * d - np.array([2.0, 0.5])
        tangent = np.array([-normal[1], normal[0]])
        if math.isfinite(t) and abs(along @ tangent) <= 3.0 and spec.range_min_m < t < spec.range_max_m:
            assert ranges[i] == pytest.approx(t, abs=1e-5)  # float32 at ~2 m
        else:
            assert ranges[i] == math.inf


def test_out_of_range_is_inf_and_nothing_to_see_is_inf(tmp_path: Path) -> None:
    scene = _scene(tmp_path, _drum(5.0))
    spec = _lds(noise_std_m=0.0)
    ranges = Lidar(spec, scene.ray_caster(spec.mount.z_m)).scan(0.0, 0.0, 0.0)
    assert np.all(ranges == np.inf)


def _drum_samples(tmp_path: Path, spec: LidarSpec, rng: np.random.Generator, scans: int) -> np.ndarray:
    scene = _scene(tmp_path, _drum(2.0, spec.mount.x_m, spec.mount.y_m))
    lidar = Lidar(spec, scene.ray_caster(spec.mount.z_m), rng)
    return np.concatenate([lidar.scan(0.0, 0.0, 0.0) for _ in range(scans)]).astype(np.float64)


def test_noise_has_the_configured_standard_deviation(tmp_path: Path) -> None:
    spec = _lds()
    samples = _drum_samples(tmp_path, spec, np.random.default_rng(7), 28)  # 10 080 beams at 2 m
    assert samples.size >= 10_000
    error = samples - 2.0
    assert abs(error.std() / spec.noise_std_m - 1.0) < 0.05
    assert abs(error.mean()) < 4 * spec.noise_std_m / math.sqrt(samples.size)


def test_noise_is_clamped_to_the_range_limits(tmp_path: Path) -> None:
    spec = _lds(noise_std_m=1.0)
    samples = _drum_samples(tmp_path, spec, np.random.default_rng(1), 5)
    assert np.all(np.isfinite(samples))
    assert samples.min() == pytest.approx(0.12) and samples.max() == pytest.approx(3.5)


def test_same_seed_same_scans_and_noise_needs_a_generator(tmp_path: Path) -> None:
    spec = _lds()
    first = _drum_samples(tmp_path, spec, np.random.default_rng(42), 3)
    again = _drum_samples(tmp_path, spec, np.random.default_rng(42), 3)
    other = _drum_samples(tmp_path, spec, np.random.default_rng(43), 3)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)
    with pytest.raises(ValueError, match="pass a numpy.random.Generator"):
        Lidar(spec, _scene(tmp_path, _drum(2.0)).ray_caster(0.2))


def test_resolution_above_one_interpolates_between_rays(tmp_path: Path) -> None:
    scene = _scene(
        tmp_path,
        '<model name="wall"><static>1</static><pose>1 0 0.5 0 0 0</pose><link name="l"><collision name="c">'
        "<geometry><box><size>0.1 8 1</size></box></geometry></collision></link></model>",
    )
    spec = LidarSpec(
        samples=3,
        resolution=2.0,
        angle_min_rad=-0.5,
        angle_max_rad=0.5,
        range_min_m=0.1,
        range_max_m=10.0,
        mount=Pose(z_m=0.2),
    )
    lidar = Lidar(spec, scene.ray_caster(0.2))
    assert lidar.geometry.num_ranges == 6
    assert lidar.geometry.angle_increment_rad == pytest.approx(1.0 / 5)
    rays = 0.95 / np.cos(np.array([-0.5, 0.0, 0.5]))
    position = np.arange(6) * 2 / 5
    expected = np.interp(position, [0, 1, 2], rays)
    assert lidar.scan(0.0, 0.0, 0.0) == pytest.approx(expected, abs=1e-6)


def test_lidar_in_the_project_house_sees_walls_all_round() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf"))
    lidar = Lidar.from_robot(robot, scene, np.random.default_rng(0))
    ranges = lidar.scan(0.0, 0.0, 0.0)
    assert np.isfinite(ranges).sum() > 100
    assert np.nanmin(np.where(np.isfinite(ranges), ranges, np.nan)) > 0.5


def test_compiled_and_numpy_scans_are_the_same() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    assert robot.lidar is not None
    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf"))
    height = robot.base_height_m + robot.lidar.mount.z_m
    native = Lidar(robot.lidar, scene.ray_caster(height), np.random.default_rng(5))
    plain = Lidar(robot.lidar, scene.ray_caster(height, native=False), np.random.default_rng(5))
    for x, y, yaw in [(0.0, 0.0, 0.0), (2.75, 2.5, -1.571), (4.0, 0.5, 1.571), (-1.0, -0.5, -2.25)]:
        assert np.array_equal(native.scan(x, y, yaw), plain.scan(x, y, yaw))
