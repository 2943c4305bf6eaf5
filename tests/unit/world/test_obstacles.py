"""ObstacleField: where obstacles are over time, what the lidar sees of them, and contact with the robot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.robot.lidar import Lidar
from twin.world import build_scene, load_world
from twin.world.obstacles import ObstacleField, ObstaclePose, ObstacleSpec
from twin.world.robot_model import load_robot
from twin.world.scene import RobotBody

REPO = Path(__file__).resolve().parents[3]
EMPTY_WORLD = REPO.parent / "shared" / "fixtures" / "gazebo_classic" / "worlds" / "empty_world.world"
PERIOD_NS = 10_000_000
FAR = (50.0, 50.0, 0.0)  # a robot pose far from every obstacle


def _body() -> RobotBody:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    return RobotBody(robot.collisions, base_height_m=robot.base_height_m)


def _box(x: float, y: float, size: float = 0.3, height: float = 0.4, **kw: object) -> ObstacleSpec:
    return ObstacleSpec(shape="box", size_m=(size, size, height), pose=ObstaclePose(x_m=x, y_m=y), **kw)  # type: ignore[arg-type]


def _at(field: ObstacleField, t_s: float, robot: tuple[float, float, float] = FAR) -> dict[str, tuple[float, ...]]:
    field.update(round(t_s * 1e9), robot)
    return {m.name: (m.pose[0], m.pose[1], 2.0 * math.atan2(m.pose[5], m.pose[6])) for m in field.markers()}


def test_a_walker_stops_at_its_path_end_or_walks_back_and_forth() -> None:
    path = ((0.0, 0.0), (2.0, 0.0), (2.0, 1.0))
    walker = ObstacleSpec(shape="cylinder", radius_m=0.2, height_m=1.7, path_xy_m=path, speed_mps=1.0, name="w")
    stops = ObstacleField([walker], _body(), update_period_ns=PERIOD_NS)
    assert _at(stops, 1.0)["w"] == pytest.approx((1.0, 0.0, 0.0))
    assert _at(stops, 2.5)["w"] == pytest.approx((2.0, 0.5, math.pi / 2))
    assert _at(stops, 9.0)["w"] == pytest.approx((2.0, 1.0, math.pi / 2))  # stopped at the end, facing its way
    assert stops.next_change_ns(round(9e9)) is None  # nothing moves any more
    loops = ObstacleField(
        [
            ObstacleSpec(
                shape="cylinder", radius_m=0.2, height_m=1.7, path_xy_m=path, speed_mps=1.0, loop=True, name="w"
            )
        ],
        _body(),
        update_period_ns=PERIOD_NS,
    )
    assert _at(loops, 3.5)["w"] == pytest.approx((2.0, 0.5, -math.pi / 2))  # 0.5 m back down the last leg
    assert _at(loops, 5.5)["w"] == pytest.approx((0.5, 0.0, math.pi))
    assert _at(loops, 6.5)["w"] == pytest.approx((0.5, 0.0, 0.0))  # out again


def test_a_walker_starts_walking_when_it_appears() -> None:
    walker = ObstacleSpec(
        shape="cylinder", radius_m=0.2, height_m=1.7, path_xy_m=((0, 0), (4, 0)), speed_mps=0.5, appear_s=2.0, name="w"
    )
    field = ObstacleField([walker], _body(), update_period_ns=PERIOD_NS)
    assert _at(field, 1.99) == {}
    assert _at(field, 2.0)["w"] == pytest.approx((0.0, 0.0, 0.0))
    assert _at(field, 4.0)["w"] == pytest.approx((1.0, 0.0, 0.0))


def test_appearing_and_vanishing_take_effect_at_the_first_update_at_or_after_their_times() -> None:
    field = ObstacleField([_box(1.0, 0.0, appear_s=1.003, vanish_s=2.0, name="b")], _body(), update_period_ns=PERIOD_NS)
    assert _at(field, 1.0) == {}
    assert "b" in _at(field, 1.01)
    assert "b" in _at(field, 1.99)
    assert _at(field, 2.0) == {}
    assert field.next_change_ns(round(2.0e9) + 1) is None  # after the update at 2 s nothing more happens


def test_a_demo_block_is_below_a_waffle_lidar_and_a_tall_box_is_seen_at_its_face() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    assert robot.lidar is not None
    height = robot.base_height_m + robot.lidar.mount.z_m  # 0.132 m
    block = ObstacleField([_box(1.0, 0.0, size=0.1, height=0.1)], _body(), update_period_ns=PERIOD_NS)
    block.update(0, FAR)
    assert block.caster(height) is None
    tall = ObstacleField([_box(1.0, 0.0, size=0.1, height=0.4)], _body(), update_period_ns=PERIOD_NS)
    tall.update(0, FAR)
    caster = tall.caster(height)
    assert caster is not None
    ranges = caster.cast_rays((0.0, 0.0), np.array([0.0, 0.04, math.pi]), 10.0)
    assert ranges[0] == pytest.approx(0.95)
    assert ranges[1] == pytest.approx(0.95 / math.cos(0.04))
    assert math.isinf(ranges[2])


@pytest.mark.parametrize("native", [True, False])
def test_scans_without_an_obstacle_present_are_the_scans_without_obstacles(native: bool) -> None:
    """Same ranges and the same noise draws; with an obstacle, only its beams change."""
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    assert robot.lidar is not None
    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf"))
    caster = scene.ray_caster(robot.base_height_m + robot.lidar.mount.z_m, native=native)
    field = ObstacleField([_box(1.2, 0.0, appear_s=5.0)], _body(), update_period_ns=PERIOD_NS)
    plain = Lidar(robot.lidar, caster, np.random.default_rng(7))
    with_field = Lidar(robot.lidar, caster, np.random.default_rng(7), obstacles=field)
    field.update(0, FAR)
    np.testing.assert_array_equal(plain.scan(0.0, 0.0, 0.0), with_field.scan(0.0, 0.0, 0.0))
    field.update(round(5e9), FAR)
    before, after = plain.scan(0.0, 0.0, 0.0), with_field.scan(0.0, 0.0, 0.0)
    changed = np.flatnonzero(before != after)
    assert len(changed) > 0 and set(changed) <= set(range(-10, 11)) | set(range(350, 360))
    assert after[0] == pytest.approx(1.05 - robot.lidar.mount.x_m, abs=0.05)  # 2 cm noise


def test_the_robot_touches_a_box_at_its_face_and_the_free_distance_is_a_lower_bound() -> None:
    field = ObstacleField([_box(1.0, 0.0, name="crate")], _body(), update_period_ns=PERIOD_NS)
    changed, contacts = field.update(0, (0.0, 0.0, 0.0))
    assert changed and contacts == ()
    free = field.free_m(0.0, 0.0, 0.0)
    assert 0.0 < free <= 0.85 - 0.073  # the Waffle reaches 0.073 m ahead of its base frame
    x = 0.0
    while not field.check(x, 0.0, 0.0):
        x += 0.001
    assert x == pytest.approx(0.85 - 0.073, abs=2e-3)
    contact = field.check(x, 0.0, 0.0)[0]
    assert contact.model == "crate" and contact.collision == "box"
    assert contact.normal[0] == pytest.approx(-1.0, abs=1e-6)  # from the obstacle towards the robot
    assert field.queries < 40  # far from the box the bounding circles answer, not FCL


def test_a_walker_reaching_a_standing_robot_is_reported_by_update() -> None:
    walker = ObstacleSpec(
        shape="cylinder", radius_m=0.15, height_m=1.7, path_xy_m=((0, -1), (0, 1)), speed_mps=0.5, name="w"
    )
    field = ObstacleField([walker], _body(), update_period_ns=PERIOD_NS)
    touching = []
    for k in range(0, 401):
        _, contacts = field.update(k * PERIOD_NS, (0.0, 0.0, 0.0))
        touching.append(bool(contacts))
    first, last = touching.index(True), len(touching) - 1 - touching[::-1].index(True)
    assert all(touching[first : last + 1])
    # It touches while its centre is within about its radius plus the Waffle's half width of the robot.
    y_first, y_last = -1 + 0.5 * first * 0.01, -1 + 0.5 * last * 0.01
    assert -0.35 < y_first < -0.2 and 0.2 < y_last < 0.35


def test_a_walker_in_the_empty_world_fixture_blocks_nothing_else() -> None:
    scene = build_scene(load_world(EMPTY_WORLD))
    assert scene.obstacles == ()  # only the ground plane: every range in the integration tests is an obstacle's


def test_far_walkers_step_every_0_1_s_near_ones_every_10_ms_and_no_contact_is_missed() -> None:
    walker = ObstacleSpec(
        shape="box", size_m=(0.4, 0.3, 1.7), path_xy_m=((0, -4), (0, 4)), speed_mps=0.5, name="w"
    )  # a box, so turning at a corner counts too
    robot = (0.0, 0.0, 0.0)
    every = ObstacleField([walker], _body(), update_period_ns=PERIOD_NS)
    first_every = next(k * PERIOD_NS for k in range(2000) if every.update(k * PERIOD_NS, robot)[1])
    field = ObstacleField([walker], _body(), update_period_ns=PERIOD_NS)
    t, steps, first = 0, [], None
    while t is not None and t < 16_000_000_000 and first is None:
        _, contacts = field.update(t, robot)
        if contacts:
            first = t
        nxt = field.next_update_ns(t)
        if nxt is not None:
            steps.append(nxt - t)
        t = nxt
    assert first == first_every  # the coarse schedule finds the contact at the same update
    assert steps[0] == 100 * 1_000_000  # 3.6 m away at first: the next multiple of 0.1 s
    assert steps[-1] == PERIOD_NS  # within reach: every 10 ms
    assert len(steps) < first_every // PERIOD_NS // 2  # far fewer updates than every 10 ms
