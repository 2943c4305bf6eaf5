"""The camera renderer: geometry against the pinhole model, depth, colours, occlusion, clipping, noise."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.world import load_world
from twin.world.render import CameraModel, Renderer, box_mesh, lighting_of, world_visuals

HFOV = 1.02974  # the Waffle's R200
CAM = CameraModel(width=640, height=480, hfov_rad=HFOV, near_m=0.02, far_m=10.0)


def _world(tmp_path: Path, boxes: str, scene: str = "<scene><ambient>1 1 1 1</ambient></scene>") -> Path:
    path = tmp_path / "w.sdf"
    path.write_text(
        f"""<?xml version="1.0"?>
<sdf version="1.7"><world name="w">{scene}
<model name="things"><static>true</static>{boxes}</model>
</world></sdf>"""
    )
    return path


def _box(name: str, x: float, y: float, z: float, size: tuple[float, float, float], material: str) -> str:
    sx, sy, sz = size
    return (
        f'<link name="{name}"><pose>{x} {y} {z} 0 0 0</pose><visual name="v"><geometry><box><size>{sx} {sy} {sz}'
        f"</size></box></geometry><material>{material}</material></visual></link>"
    )


def _renderer(path: Path, camera: CameraModel = CAM, *, native: bool = True) -> Renderer:
    world = load_world(path)
    lighting = lighting_of(world)
    return Renderer(camera, world_visuals(world, lighting), lighting, native=native)


RED = "<ambient>0.8 0 0.2 1</ambient><diffuse>0.8 0 0.2 1</diffuse>"


def test_a_box_ahead_has_its_colour_and_exact_depth_at_the_image_centre(tmp_path: Path) -> None:
    renderer = _renderer(_world(tmp_path, _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), RED)))
    frame = renderer.render(np.eye(4))
    assert frame.rgb.shape == (480, 640, 3)
    assert tuple(frame.rgb[240, 320]) == (204, 0, 51)  # full ambient: the material colour
    assert frame.depth_m[240, 320] == pytest.approx(1.75, abs=1e-3)
    # Depth is along the optical axis: the same on the whole front face, not the ray's length.
    assert frame.depth_m[240, 300] == pytest.approx(1.75, abs=1e-3)


@pytest.mark.parametrize(("x", "y", "z"), [(2.0, 0.0, 0.0), (2.0, 0.6, 0.2), (3.0, -1.4, -0.5), (1.5, 0.75, 0.5)])
def test_a_small_box_appears_where_the_camera_info_K_puts_it(tmp_path: Path, x: float, y: float, z: float) -> None:
    size = 0.04
    renderer = _renderer(_world(tmp_path, _box("b", x, y, z, (size, size, size), RED)))
    frame = renderer.render(np.eye(4))
    fx, _, cx, _, fy, cy, *_ = CAM.K()
    # The front face's centre, in the optical frame (x right = -y, y down = -z, z forward = x).
    X, Y, Z = -y, -z, x - size / 2
    # The front face's pixels: all at its depth (a side face seen obliquely is farther).
    rows, cols = np.nonzero(np.abs(frame.depth_m - Z) < 1e-3)
    assert len(rows) > 4
    u_K, v_K = fx * X / Z + cx, fy * Y / Z + cy
    # K's cx = (width + 1) / 2 counts pixels from 1 at the first pixel's centre; arrays count from 0.
    assert cols.mean() + 1 == pytest.approx(u_K, abs=1.0)
    assert rows.mean() + 1 == pytest.approx(v_K, abs=1.0)


def test_camera_info_K_and_P_follow_gazebos_formula() -> None:
    cam = CameraModel(width=1920, height=1080, hfov_rad=HFOV, near_m=0.02, far_m=300.0)
    f = 960.0 / math.tan(HFOV / 2)
    assert cam.K() == pytest.approx((f, 0, 960.5, 0, f, 540.5, 0, 0, 1))
    assert cam.P() == pytest.approx((f, 0, 960.5, 0, 0, f, 540.5, 0, 0, 0, 1, 0))


def test_a_wall_hides_a_block_behind_it(tmp_path: Path) -> None:
    grey = "<ambient>0.5 0.5 0.5 1</ambient><diffuse>0.5 0.5 0.5 1</diffuse>"
    boxes = _box("block", 3.0, 0.0, 0.0, (0.2, 0.2, 0.2), RED) + _box("wall", 2.0, 0.0, 0.0, (0.1, 4.0, 2.0), grey)
    frame = _renderer(_world(tmp_path, boxes)).render(np.eye(4))
    assert tuple(frame.rgb[240, 320]) == (128, 128, 128)
    assert frame.depth_m[240, 320] == pytest.approx(1.95, abs=1e-3)
    assert not np.any((frame.rgb[..., 0] == 204) & (frame.rgb[..., 2] == 51))


def test_beyond_the_far_clip_is_background_and_infinite_depth(tmp_path: Path) -> None:
    scene = "<scene><ambient>1 1 1 1</ambient><background>0 0 1 1</background></scene>"
    near = CameraModel(width=64, height=48, hfov_rad=HFOV, near_m=0.02, far_m=1.0)
    frame = _renderer(_world(tmp_path, _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), RED), scene), near).render(np.eye(4))
    assert np.all(np.isposinf(frame.depth_m))
    assert np.all(frame.rgb == np.array([0, 0, 255], dtype=np.uint8))


def test_the_near_clip_cuts_a_surface_the_camera_stands_in(tmp_path: Path) -> None:
    """Geometry nearer than clip.near is cut away, as OGRE's near plane does: the box behind shows."""
    grey = "<ambient>0.5 0.5 0.5 1</ambient><diffuse>0.5 0.5 0.5 1</diffuse>"
    boxes = _box("thin", 0.01, 0.0, 0.0, (0.005, 1.0, 1.0), grey) + _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), RED)
    frame = _renderer(_world(tmp_path, boxes)).render(np.eye(4))
    assert tuple(frame.rgb[240, 320]) == (204, 0, 51)


def test_gazebo_script_materials_have_their_colours(tmp_path: Path) -> None:
    script = "<script><uri>file://media/materials/scripts/gazebo.material</uri><name>Gazebo/Green</name></script>"
    frame = _renderer(_world(tmp_path, _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), script))).render(np.eye(4))
    assert tuple(frame.rgb[240, 320]) == (0, 255, 0)


def test_the_sun_lights_faces_by_lambert(tmp_path: Path) -> None:
    scene = (
        "<scene><ambient>0.2 0.2 0.2 1</ambient></scene>"
        '<light name="sun" type="directional"><direction>1 0 0</direction><diffuse>0.5 0.5 0.5 1</diffuse></light>'
    )
    white = "<diffuse>1 1 1 1</diffuse>"
    frame = _renderer(_world(tmp_path, _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), white), scene)).render(np.eye(4))
    # The face toward the camera faces the light (it shines along +x onto -x faces): 0.2 + 0.5.
    assert tuple(frame.rgb[240, 320]) == (179, 179, 179)


def test_the_numpy_path_draws_the_same_images_as_the_kernel(tmp_path: Path) -> None:
    house = Path(__file__).parents[3] / "sdf" / "worlds" / "house.sdf"
    world = load_world(house)
    lighting = lighting_of(world)
    mesh = world_visuals(world, lighting)
    small = CameraModel(width=160, height=120, hfov_rad=HFOV, near_m=0.02, far_m=300.0)
    T = np.eye(4)
    T[:3, 3] = (-0.5, 0.2, 0.2)
    block = box_mesh([((0.1, 0.1, 0.1), np.array([[1, 0, 0, 0.5], [0, 1, 0, 0.2], [0, 0, 1, 0.05], [0, 0, 0, 1.0]]),
                       (0.0, 0.0, 0.8))], lighting)  # fmt: skip
    a = Renderer(small, mesh, lighting).render(T, block, noise_std=0.007, seed=7)
    b = Renderer(small, mesh, lighting, native=False).render(T, block, noise_std=0.007, seed=7)
    assert np.array_equal(a.rgb, b.rgb)
    assert np.array_equal(a.depth_m, b.depth_m)


def test_the_same_seed_gives_the_same_noisy_image_and_another_seed_another(tmp_path: Path) -> None:
    renderer = _renderer(_world(tmp_path, _box("b", 2.0, 0.0, 0.0, (0.5, 0.5, 0.5), RED)))
    one = renderer.render(np.eye(4), noise_std=0.007, seed=1)
    assert one.rgb.tobytes() == renderer.render(np.eye(4), noise_std=0.007, seed=1).rgb.tobytes()
    other = renderer.render(np.eye(4), noise_std=0.007, seed=2)
    assert one.rgb.tobytes() != other.rgb.tobytes()
    clean = renderer.render(np.eye(4)).rgb.astype(float)
    noise = one.rgb.astype(float) - clean
    # Gaussian with stddev 0.007 in [0, 1] units: about 1.8 levels, the same on the three channels
    # where none is clamped (the green channel is 0 there, so compare red and blue).
    assert noise[..., 0].std() == pytest.approx(0.007 * 255, rel=0.15)
    unclamped = (clean[..., 2] > 10) & (clean[..., 0] < 245)
    assert np.array_equal(noise[..., 0][unclamped], noise[..., 2][unclamped])


def test_the_robots_own_body_is_drawn_where_it_stands_and_the_r200_does_not_see_it(tmp_path: Path) -> None:
    from twin.world import load_robot
    from twin.world.render import body_of

    robot = load_robot("turtlebot3_waffle", model_path=[Path(__file__).parents[3] / "sdf" / "models"])
    body = body_of(robot.model.all_links(), robot.T_base_model)
    renderer = _renderer(_world(tmp_path, _box("far", 9.0, 0.0, 0.0, (0.1, 8.0, 4.0), RED)))
    lighting = lighting_of(load_world(tmp_path / "w.sdf"))
    robot_at = np.eye(4)
    robot_at[:3, 3] = (2.0, 0.0, 0.0)
    # A camera at the origin, 2 m behind the robot, sees its body in front of the far wall.
    seen = renderer.render(np.eye(4), body.placed(robot_at, lighting))
    alone = renderer.render(np.eye(4))
    assert np.count_nonzero(np.any(seen.rgb != alone.rgb, axis=2)) > 500
    assert np.nanmin(seen.depth_m[np.isfinite(seen.depth_m)]) == pytest.approx(2.0 - 0.197, abs=0.01)
    # The R200 on that robot sees the wall, not its own body.
    T_sensor = robot_at @ np.asarray(robot.cameras[0].T_base_sensor)
    own = renderer.render(T_sensor, body.placed(robot_at, lighting))
    assert np.array_equal(own.rgb, renderer.render(T_sensor).rgb)
