from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import trimesh

from twin.world import load_world
from twin.world.meshes import MeshCache, geometry_arrays, geometry_mesh
from twin.world.robot_model import load_robot
from twin.world.scene import CollisionMonitor, RayCaster, Scene, build_scene, obstacle_extent
from twin.world.types import Box, Capsule, Cone, Cylinder, Ellipsoid, Sphere

REPO = Path(__file__).resolve().parents[3]
FIXTURES = REPO.parent / "shared" / "fixtures"
BEAMS = np.linspace(-math.pi, math.pi, 721)


def _world(tmp_path: Path, body: str, version: str = "1.7") -> Scene:
    path = tmp_path / "w.sdf"
    path.write_text(f'<sdf version="{version}"><world name="w">{body}</world></sdf>')
    return build_scene(load_world(path))


def _static(name: str, pose: str, geometry: str, *, height: float = 0.0) -> str:
    return (
        f'<model name="{name}"><static>1</static><pose>{pose}</pose><link name="l">'
        f'<collision name="c"><pose>0 0 {height} 0 0 0</pose><geometry>{geometry}</geometry></collision></link></model>'
    )


def _casters(scene: Scene, z: float) -> list[RayCaster]:
    return [scene.ray_caster(z), scene.ray_caster(z, native=False)]


def _ray_box(origin: np.ndarray, angle: float, centre: np.ndarray, yaw: float, half: np.ndarray) -> float:
    """Slab test in the box frame: distance to the first face hit, inf if missed."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, s], [-s, c]])
    o = rot @ (origin - centre)
    d = rot @ np.array([math.cos(angle), math.sin(angle)])
    lo, hi = -math.inf, math.inf
    for i in range(2):
        if abs(d[i]) < 1e-15:
            if abs(o[i]) > half[i]:
                return math.inf
            continue
        t1, t2 = (-half[i] - o[i]) / d[i], (half[i] - o[i]) / d[i]
        lo, hi = max(lo, min(t1, t2)), min(hi, max(t1, t2))
    if lo > hi or hi < 0:
        return math.inf
    return lo if lo >= 0 else hi


@pytest.mark.parametrize("yaw", [0.0, 0.3, 1.0, -2.2])
def test_rays_hit_rotated_boxes_at_the_analytic_distance(tmp_path: Path, yaw: float) -> None:
    centre = np.array([2.0, -1.0])
    scene = _world(tmp_path, _static("b", f"2 -1 0.5 0 0 {yaw}", "<box><size>1.2 0.4 1</size></box>"))
    origin = np.array([0.3, 0.2])
    expected = np.array([_ray_box(origin, a, centre, yaw, np.array([0.6, 0.2])) for a in BEAMS])
    assert np.isfinite(expected).sum() > 20
    for caster in _casters(scene, 0.3):
        got = caster.cast_rays(tuple(origin), BEAMS, 10.0)
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        hit = np.isfinite(expected)
        assert np.max(np.abs(got[hit] - expected[hit])) < 1e-6


def test_rays_hit_upright_cylinders_at_the_analytic_distance(tmp_path: Path) -> None:
    scene = _world(
        tmp_path,
        _static("c", "1.5 0.5 0 0 0 0.7", "<cylinder><radius>0.3</radius><length>1</length></cylinder>", height=0.5),
    )
    origin = np.array([-0.2, 0.1])
    q = np.array([1.5, 0.5]) - origin
    for caster in _casters(scene, 0.4):
        got = caster.cast_rays(tuple(origin), BEAMS, 10.0)
        d = np.stack([np.cos(BEAMS), np.sin(BEAMS)], axis=1)
        b = d @ q
        disc = b * b - (q @ q - 0.09)
        expected = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
        expected[b < 0] = np.inf
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        hit = np.isfinite(expected)
        assert hit.sum() > 10
        assert np.max(np.abs(got[hit] - expected[hit])) < 1e-6


@pytest.mark.parametrize("yaw", [0.0, 0.9, -2.5])
def test_rays_hit_rotated_meshes_at_the_analytic_distance(tmp_path: Path, yaw: float) -> None:
    # A triangulated box written as STL, placed by a rotated pose: its slice must be exact.
    mesh = trimesh.creation.box(extents=(0.8, 0.5, 1.0))
    mesh.apply_translation((0, 0, 0.5))
    (tmp_path / "crate.stl").write_bytes(mesh.export(file_type="stl"))
    scene = _world(tmp_path, _static("m", f"-1 2 0 0 0 {yaw}", "<mesh><uri>crate.stl</uri></mesh>"))
    origin = np.array([0.5, 0.5])
    expected = np.array([_ray_box(origin, a, np.array([-1.0, 2.0]), yaw, np.array([0.4, 0.25])) for a in BEAMS])
    for caster in _casters(scene, 0.37):
        got = caster.cast_rays(tuple(origin), BEAMS, 10.0)
        hit = np.isfinite(expected)
        assert hit.sum() > 10
        assert np.array_equal(np.isfinite(got), hit)
        assert np.max(np.abs(got[hit] - expected[hit])) < 1e-6


def test_slice_height_decides_what_is_seen(tmp_path: Path) -> None:
    scene = _world(
        tmp_path,
        _static("low", "2 0 0.05 0 0 0", "<box><size>0.2 2 0.1</size></box>")
        + _static("ball", "0 2 0.5 0 0 0", "<sphere><radius>0.5</radius></sphere>"),
    )
    at_low = scene.ray_caster(0.05).cast_rays((0.0, 0.0), np.array([0.0, math.pi / 2]), 10.0)
    assert at_low == pytest.approx([1.9, 2.0 - math.sqrt(0.25 - 0.45**2)])
    at_high = scene.ray_caster(0.5).cast_rays((0.0, 0.0), np.array([0.0, math.pi / 2]), 10.0)
    assert at_high[0] == math.inf and at_high[1] == pytest.approx(1.5)


def test_min_range_skips_near_surfaces_and_reports_the_exit_from_inside(tmp_path: Path) -> None:
    scene = _world(tmp_path, _static("wall", "0.1 0 0.5 0 0 0", "<box><size>0.1 4 1</size></box>"))
    for caster in _casters(scene, 0.2):
        # The wall spans x in [0.05, 0.15]; rays start 0.12 m out, inside it, so they report its far face.
        got = caster.cast_fan((0.0, 0.0), 0.0, 0.1, 1, 3.5, min_range_m=0.12)
        assert got[0] == pytest.approx(0.15)
        assert caster.cast_fan((0.0, 0.0), 0.0, 0.1, 1, 3.5, min_range_m=0.2)[0] == math.inf


def test_fan_and_arbitrary_rays_agree_in_a_real_world() -> None:
    world = load_world(
        FIXTURES / "gazebo_classic" / "worlds" / "turtlebot3_world.world",
        model_path=[FIXTURES / "gazebo_classic" / "models"],
    )
    scene = build_scene(world)
    rng = np.random.default_rng(3)
    step = 6.28 / 359
    for caster in _casters(scene, 0.18):
        for _ in range(20):
            x, y, yaw = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-math.pi, math.pi)
            fan = caster.cast_fan((x, y), yaw, step, 360, 3.5, min_range_m=0.12)
            rays = caster.cast_rays((x, y), yaw + step * np.arange(360), 3.5, min_range_m=0.12)
            assert np.array_equal(np.isfinite(fan), np.isfinite(rays))
            hit = np.isfinite(fan)
            assert np.max(np.abs(fan[hit] - rays[hit]), initial=0.0) < 1e-9


def test_planes_and_floor_slabs_are_not_obstacles(tmp_path: Path) -> None:
    scene = _world(
        tmp_path,
        _static("floor", "0 0 -0.05 0 0 0", "<box><size>10 10 0.1</size></box>")
        + _static("ground", "0 0 0 0 0 0", "<plane><normal>0 0 1</normal></plane>"),
    )
    assert scene.obstacles == ()
    assert scene.bounds is None


def _robot_scene(tmp_path: Path) -> tuple[Scene, CollisionMonitor]:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    scene = _world(tmp_path, _static("wall", "1 0 0.5 0 0 0", "<box><size>0.1 4 1</size></box>"))
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    return scene, CollisionMonitor(scene, body)


def test_robot_contact_names_the_obstacle_and_points_away_from_it(tmp_path: Path) -> None:
    scene, monitor = _robot_scene(tmp_path)
    body = monitor.body
    # The waffle reaches x = 0.073 m ahead of base_footprint (the R200 camera box); the wall face is at x = 0.95.
    assert scene.collides(body, 0.85, 0.0, 0.0) == ()
    contacts = scene.collides(body, 0.9, 0.0, 0.0)
    assert contacts
    deepest = contacts[0]
    assert deepest.model == "wall" and deepest.link == "wall::l" and deepest.collision == "c"
    assert deepest.robot_link.startswith("turtlebot3_waffle::")
    assert deepest.normal[0] == pytest.approx(-1.0, abs=1e-6)
    assert deepest.depth_m == pytest.approx(0.9 + 0.073 - 0.95, abs=2e-3)


def test_clearance_is_a_lower_bound_and_the_monitor_skips_far_checks(tmp_path: Path) -> None:
    scene, monitor = _robot_scene(tmp_path)
    clearance = scene.clearance(monitor.body, 0.0, 0.0, 0.0)
    assert 0.0 < clearance <= 0.95 - 0.073
    assert clearance >= 0.95 - monitor.body.radius_m - 1e-6
    assert monitor.check(0.0, 0.0, 0.0) == ()
    queries = monitor.queries
    for k in range(100):  # 1 mm steps: no query until the free distance is used up
        monitor.check(0.001 * k, 0.0, 0.0)
    assert monitor.queries <= queries + 2
    x = 0.0
    while not monitor.check(x, 0.0, 0.0):
        x += 0.001
    assert x == pytest.approx(0.95 - 0.073, abs=2e-3)


def test_grazing_inside_the_margin_queries_a_few_times_not_every_step(tmp_path: Path) -> None:
    _, monitor = _robot_scene(tmp_path)
    # Drive along the wall (y) with the robot's front 3 mm from its face: inside the 5 mm margin.
    x = 0.95 - 0.073 - 0.003
    assert monitor.check(x, -1.0, 0.0) == ()
    queries = monitor.queries
    for k in range(1, 1001):  # 1 m in 1 mm steps
        assert monitor.check(x, -1.0 + 0.001 * k, 0.0) == ()
    assert monitor.queries - queries < 1000  # not two queries per step, as a zero free distance would cost


def test_a_robot_pressed_against_a_wall_is_answered_without_new_queries(tmp_path: Path) -> None:
    scene, monitor = _robot_scene(tmp_path)
    # Approach the wall in 0.5 mm steps, then try the same refused step again and again, as a drive
    # pressed against it does; now and then also a refused turn in place (two poses in turn).
    track: list[tuple[float, float, float]] = [(0.8 + 0.0005 * k, 0.0, 0.0) for k in range(200)]
    refused_move, refused_turn = (0.8805, 0.0, 0.0), (0.8795, 0.0, 0.2)
    for k in range(3000):
        track.append(refused_move)
        if k % 3 == 0:
            track.append(refused_turn)
    track += [(0.8 - 0.001 * k, 0.0, 0.0) for k in range(50)]  # backing off
    answers = []
    queries_at_wall = 0
    for k, pose in enumerate(track):
        answers.append(monitor.check(*pose))
        if k == 200:
            queries_at_wall = monitor.queries
    assert scene.collides(monitor.body, *refused_move)  # the repeated poses are in contact
    assert scene.collides(monitor.body, *refused_turn)
    assert monitor.queries - queries_at_wall <= 8  # the 4000 repeats cost no FCL queries
    assert monitor.repeats >= 3900
    # The same answers as a monitor asked about each pose once (no memory of earlier poses).
    for pose, answer in zip(track[195:215] + track[-60:], answers[195:215] + answers[-60:], strict=True):
        fresh = CollisionMonitor(scene, monitor.body)
        assert fresh.check(*pose) == answer
    for pose, answer in zip(track[200:], answers[200:], strict=True):
        if pose in (refused_move, refused_turn):
            assert answer == scene.collides(monitor.body, *pose)


def test_the_monitor_answers_a_repeated_pose_with_the_same_free_distance(tmp_path: Path) -> None:
    _, monitor = _robot_scene(tmp_path)
    near = (0.95 - 0.073 - 0.003, 0.0, 0.0)  # 3 mm from the wall: inside the margin
    assert monitor.check(*near) == ()
    free = monitor.free_m(*near)
    assert monitor.check(0.5, 0.0, 0.0) == ()  # far away: a new query
    assert monitor.check(*near) == ()
    assert monitor.free_m(*near) == free


@pytest.mark.parametrize("name", ["turtlebot3_world.world", "turtlebot3_house.world", "empty_world.world"])
def test_obstacle_extent_is_what_the_scene_holds(name: str) -> None:
    world = load_world(
        FIXTURES / "gazebo_classic" / "worlds" / name,
        model_path=[FIXTURES / "gazebo_classic" / "models"],
        missing_includes="warn",
    )
    scene = build_scene(world)
    count, bounds = obstacle_extent(world)
    assert count == len(scene.obstacles)
    if scene.bounds is None:
        assert bounds is None
        return
    assert bounds is not None
    for mine, theirs in zip(bounds, scene.bounds, strict=True):
        assert mine == pytest.approx(theirs, abs=1e-12)
    # Each obstacle's mesh is its collision's own mesh, placed in the world (as trimesh places it),
    # a mesh file's without its floor-level triangles (all three corners at or below 0.01 m).
    cache = MeshCache()
    for obstacle, mesh in zip(scene.obstacles, scene.meshes(), strict=True):
        expected = geometry_mesh(obstacle.geometry, cache, obstacle.where)
        assert expected is not None
        expected = expected.copy()
        expected.apply_transform(np.asarray(obstacle.T_world))
        faces = expected.faces
        if not isinstance(obstacle.geometry, (Box, Cylinder, Sphere, Capsule, Ellipsoid)):
            faces = faces[expected.vertices[:, 2][faces].max(axis=1) > 0.01]
        assert np.array_equal(mesh.faces, faces)
        assert np.allclose(mesh.vertices, expected.vertices, rtol=0.0, atol=1e-12)


def test_obstacle_extent_leaves_out_planes_floor_slabs_and_excluded_models(tmp_path: Path) -> None:
    body = (
        _static("ground", "0 0 0 0 0 0", "<plane><normal>0 0 1</normal><size>10 10</size></plane>")
        + _static("slab", "0 0 0.004 0 0 0", "<box><size>4 4 0.008</size></box>")
        + _static("wall", "1 0 0.5 0 0 0.3", "<box><size>0.1 4 1</size></box>")
        + _static("post", "-2 1 0.25 0 0 0", "<cylinder><radius>0.1</radius><length>0.5</length></cylinder>")
    )
    (tmp_path / "w.world").write_text(f"<sdf version='1.7'><world name='w'>{body}</world></sdf>")
    world = load_world(tmp_path / "w.world")
    count, bounds = obstacle_extent(world)
    assert count == len(build_scene(world).obstacles) == 2
    assert bounds == build_scene(world).bounds
    assert obstacle_extent(world, exclude_models=["wall"])[0] == 1


@pytest.mark.parametrize(
    ("geometry", "fresh"),
    [
        (
            Cylinder(radius_m=0.033, length_m=0.018),
            lambda: trimesh.creation.cylinder(radius=0.033, height=0.018, sections=48),
        ),
        (Sphere(radius_m=0.2), lambda: trimesh.creation.icosphere(subdivisions=3, radius=0.2)),
    ],
    ids=["cylinder", "sphere"],
)
def test_a_curved_shape_read_back_from_the_cache_is_trimeshs_tessellation(
    geometry: Cylinder | Sphere, fresh: Callable[[], trimesh.Trimesh], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    first = geometry_arrays(geometry, MeshCache())
    assert list((tmp_path / "tessellations").iterdir())  # stored for the next process
    again = geometry_arrays(geometry, MeshCache())  # a new cache reads the file
    expected = fresh()
    for mesh in (first, again):
        assert mesh is not None
        assert np.array_equal(mesh.vertices, expected.vertices)
        assert np.array_equal(mesh.faces, expected.faces)


def test_a_box_is_a_closed_outward_facing_mesh_with_trimeshs_corners() -> None:
    mesh = geometry_arrays(Box(size_m=(2.5, 0.15, 1.0)), MeshCache())
    assert mesh is not None
    as_trimesh = mesh.to_trimesh()
    assert as_trimesh.is_watertight and as_trimesh.is_winding_consistent
    assert as_trimesh.volume == pytest.approx(2.5 * 0.15 * 1.0)  # positive: the normals point out
    assert np.array_equal(mesh.vertices, trimesh.creation.box(extents=(2.5, 0.15, 1.0)).vertices)


def test_a_floor_mesh_with_a_step_keeps_the_step_and_not_the_ground(tmp_path: Path) -> None:
    # one mesh: a 4 x 4 m ground slab topping out at z = 0 and a 0.175 m step on it from x = 1.25 m
    # (as the AWS hospital's floor); the robot stands on the slab and is stopped by the step
    ground = trimesh.creation.box(extents=(4.0, 4.0, 0.1))
    ground.apply_translation((0.0, 0.0, -0.05))
    step = trimesh.creation.box(extents=(0.5, 4.0, 0.175))
    step.apply_translation((1.5, 0.0, 0.0875))
    (tmp_path / "floor.stl").write_bytes(trimesh.util.concatenate([ground, step]).export(file_type="stl"))
    scene = _world(tmp_path, _static("floor", "0 0 0 0 0 0", "<mesh><uri>floor.stl</uri></mesh>"))
    assert len(scene.obstacles) == 1
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    # on the ground: free, with the step as the nearest thing (not the ground under the wheels)
    assert scene.collides(body, 0.0, 0.0, 0.0) == ()
    assert scene.distance(body, 0.0, 0.0, 0.0) > 1.0
    assert scene.collides(body, 1.25 - 0.05, 0.0, 0.0)  # the waffle's front (x + 0.073) is in the step
    # the lidar sees the step's face, not the ground
    ranges = scene.ray_caster(0.132).cast_fan((0.0, 0.0), 0.0, 1.0, 1, 10.0)
    assert ranges[0] == pytest.approx(1.25, abs=1e-6)


def _cone_world(tmp_path: Path) -> Scene:
    # A cone of base radius 0.4 m, 1 m tall, standing on the floor 2 m ahead (its frame at half height).
    return _world(
        tmp_path,
        _static("cone", "2 0 0.5 0 0 0", "<cone><radius>0.4</radius><length>1</length></cone>"),
        version="1.11",
    )


@pytest.mark.parametrize("z", [0.1, 0.5, 0.9])
def test_rays_hit_a_cone_where_its_radius_at_that_height_is(tmp_path: Path, z: float) -> None:
    scene = _cone_world(tmp_path)
    (collision,) = scene.obstacles
    assert collision.geometry == Cone(radius_m=0.4, length_m=1.0)
    radius = 0.4 * (1.0 - z)  # base at z = 0, apex at z = 1
    angles = np.linspace(-0.8 * radius / 2, 0.8 * radius / 2, 9)  # beams that hit, towards the cone's axis
    for caster in _casters(scene, z):
        got = caster.cast_rays((0.0, 0.0), angles, 10.0)
        hits = got[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        from_axis = np.hypot(hits[:, 0] - 2.0, hits[:, 1])
        # The slice is the 48-gon through points of the circle: between its inner circle and the circle.
        assert np.all(from_axis >= radius * math.cos(math.pi / 48) - 1e-9)
        assert np.all(from_axis <= radius + 1e-9)
    assert scene.ray_caster(1.05).cast_rays((0.0, 0.0), np.array([0.0]), 10.0)[0] == math.inf  # above the apex


def test_the_robot_touches_a_cone_at_its_base_not_at_its_apex_height(tmp_path: Path) -> None:
    scene = _cone_world(tmp_path)
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    # The waffle reaches 0.073 m ahead of base_footprint near the floor, where the cone is 0.4 m wide.
    assert scene.collides(body, 2.0 - 0.4 - 0.073 - 0.01, 0.0, 0.0) == ()
    (contact, *_) = scene.collides(body, 2.0 - 0.4 - 0.073 + 0.02, 0.0, 0.0)
    assert contact.link == "cone::l" and contact.collision == "c"


def test_cone_mesh_is_closed_and_placed_as_sdf_defines() -> None:
    mesh = geometry_mesh(Cone(radius_m=0.4, length_m=1.0), MeshCache())
    assert mesh is not None and mesh.is_watertight and mesh.volume > 0  # outward faces
    assert mesh.bounds[:, 2] == pytest.approx([-0.5, 0.5])
    assert mesh.volume == pytest.approx(math.pi * 0.4**2 / 3, rel=0.01)
    apex = mesh.vertices[np.argmax(mesh.vertices[:, 2])]
    assert apex == pytest.approx([0, 0, 0.5])


def test_a_plane_that_is_not_the_ground_is_warned_of_once_as_no_obstacle(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # A vertical <plane> meant as a wall was dropped without a word: the twin's planes are the ground.
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n<model name='m'><static>1</static><link name='l'>"
        "<collision name='ground'><geometry><plane><normal>0 0 1</normal></plane></geometry></collision>\n"
        "<collision name='wall'><pose>2 0 0 0 0 0</pose><geometry><plane><normal>1 0 0</normal></plane></geometry>"
        "</collision>\n<collision name='turned'><pose>0 0 0 1.5707963 0 0</pose><geometry><plane><normal>0 0 1"
        "</normal></plane></geometry></collision></link></model></world></sdf>"
    )
    loaded = load_world(world)
    with caplog.at_level("WARNING", logger="twin.world.scene"):
        obstacle_extent(loaded)
        build_scene(loaded)
    lines = [r.getMessage() for r in caplog.records if "<plane>" in r.getMessage()]
    assert len(lines) == 2  # the wall and the plane turned upright, once each; never the ground
    assert lines[0].startswith(f"{world}:3: <plane> 'wall' has a normal of (1, 0, 0)") and "a <box>" in lines[0]
    assert lines[1].startswith(f"{world}:4: <plane> 'turned' has a normal of (0, -1,")
