"""LookForObject on frames the camera renders: the demos' thresholds find the demos' blocks in the house."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.bt import BehaviorTreeFactory, ManualClock, NodeStatus
from twin.mission.bt_nodes import load_locations
from twin.mission.look_for_object import HSV_THRESHOLDS, ImageSlot, find_blobs, register_vision_nodes
from twin.sim.obstacles import BLOCK_COLORS
from twin.world import load_robot, load_world
from twin.world.render import CameraModel, Renderer, box_mesh, lighting_of, world_visuals

ROOT = Path(__file__).resolve().parents[3]
LOCATIONS = load_locations(ROOT / "trees" / "sim_house_locations.yaml")
COLOURS = dict(BLOCK_COLORS)


@pytest.fixture(scope="module")
def house() -> tuple[Renderer, object, np.ndarray]:
    world = load_world(ROOT / "sdf" / "worlds" / "house.sdf")
    lighting = lighting_of(world)
    (spec,) = load_robot("turtlebot3_waffle", model_path=[ROOT / "sdf" / "models"]).cameras
    camera = CameraModel(width=640, height=480, hfov_rad=spec.hfov_rad, near_m=spec.near_m, far_m=spec.far_m)
    return Renderer(camera, world_visuals(world, lighting), lighting), lighting, np.asarray(spec.T_base_sensor)


def _planar(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]])


def _frame_at(house, location: str, colour: str | None, seed: int = 0) -> np.ndarray:
    """The Waffle's view at a location, with the demos' block 0.6 m ahead (block_spawner's offset)."""
    renderer, lighting, T_base_sensor = house
    x, y, yaw = LOCATIONS[location]
    blocks = None
    if colour is not None:
        bx, by = x + 0.6 * math.cos(yaw), y + 0.6 * math.sin(yaw)
        blocks = box_mesh([((0.1, 0.1, 0.1), _planar(bx, by, yaw, 0.05), COLOURS[colour][:3])], lighting)
    return renderer.render(_planar(x, y, yaw) @ T_base_sensor, blocks, noise_std=0.007, seed=seed).rgb


@pytest.mark.parametrize("location", list(LOCATIONS))
@pytest.mark.parametrize("colour", ["red", "green", "blue"])
def test_the_block_at_a_location_is_found_in_its_colour_only(house, location: str, colour: str) -> None:
    rgb = _frame_at(house, location, colour)
    for target in HSV_THRESHOLDS:
        blobs = find_blobs(rgb, target)
        assert bool(blobs) == (target == colour), (target, blobs)


@pytest.mark.parametrize("location", list(LOCATIONS))
def test_grey_walls_and_floor_are_no_colour(house, location: str) -> None:
    rgb = _frame_at(house, location, None)
    assert all(not find_blobs(rgb, target) for target in HSV_THRESHOLDS)


def test_the_blocks_pixels_fall_inside_the_demos_hsv_ranges(house) -> None:
    import cv2

    for colour in ("red", "green", "blue"):
        rgb = _frame_at(house, "location2", colour)
        clean = _frame_at(house, "location2", None)
        block = np.any(rgb.astype(int) - clean.astype(int) > 20, axis=2) | np.any(clean.astype(int) - rgb > 20, axis=2)
        hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[block]
        low, high = HSV_THRESHOLDS[colour]
        inside = np.all((hsv >= low) & (hsv <= high), axis=1)
        assert block.sum() > 100
        assert inside.mean() > 0.95, (colour, inside.mean())


class _Camera:
    """A camera that yields a frame at a given tree time."""

    def __init__(self, image: np.ndarray | None, at_ns: int) -> None:
        self.image, self.at_ns, self.now_ns, self.wants = image, at_ns, 0, 0

    def want(self, on: bool) -> None:
        self.wants += 1 if on else -1

    def latest(self):
        if self.image is None or self.now_ns < self.at_ns:
            return None
        return (self.at_ns, self.image)


def _tree(camera: _Camera | None, colour: str):
    factory = BehaviorTreeFactory()
    slot = ImageSlot()
    slot.source = camera
    register_vision_nodes(factory, slot=slot, target_color=colour)
    clock = ManualClock()
    xml = '<root BTCPP_format="4"><BehaviorTree ID="T"><LookForObject name="look"/></BehaviorTree></root>'
    return factory.create_tree_from_text(xml, clock=clock), clock


def _run(tree, clock, camera: _Camera | None) -> list[NodeStatus]:
    out = []
    for _ in range(20):
        status = tree.tick_once()
        out.append(status)
        if status.is_completed:
            break
        clock.advance(500_000_000)
        if camera is not None:
            camera.now_ns = clock()
    return out


def test_look_for_object_waits_for_a_frame_then_succeeds_on_its_colour(house) -> None:
    camera = _Camera(_frame_at(house, "location3", "green"), at_ns=1_000_000_000)
    tree, clock = _tree(camera, "green")
    statuses = _run(tree, clock, camera)
    assert statuses == [NodeStatus.RUNNING, NodeStatus.RUNNING, NodeStatus.SUCCESS]
    assert camera.wants == 0  # it stopped asking for frames


def test_look_for_object_fails_on_another_colour(house) -> None:
    camera = _Camera(_frame_at(house, "location3", "green"), at_ns=0)
    tree, clock = _tree(camera, "blue")
    assert _run(tree, clock, camera) == [NodeStatus.FAILURE]


def test_look_for_object_fails_after_the_demos_image_timeout() -> None:
    camera = _Camera(None, at_ns=0)
    tree, clock = _tree(camera, "red")
    statuses = _run(tree, clock, camera)
    assert statuses[-1] is NodeStatus.FAILURE
    assert len(statuses) == 7  # RUNNING at 0, 0.5, ... 2.5 s; FAILURE at 3 s
    assert camera.wants == 0


def test_an_unknown_target_color_is_refused() -> None:
    factory = BehaviorTreeFactory()
    register_vision_nodes(factory, slot=ImageSlot(), target_color="purple")
    xml = '<root BTCPP_format="4"><BehaviorTree ID="T"><LookForObject/></BehaviorTree></root>'
    with pytest.raises(Exception, match="target_color 'purple' is not one of red, green, blue"):
        factory.create_tree_from_text(xml, clock=ManualClock())


@pytest.mark.parametrize("tree_file", ["search_naive.xml", "search_queue.xml"])
def test_the_demos_trees_search_until_the_camera_sees_the_colour(house, tree_file: str) -> None:
    """The demos' trees as they are (SetLocations with only num_locs; the queue on the blackboard)."""
    import random

    from twin.mission.bt_nodes import ScriptedNavigator, register_mission_nodes

    navigator = ScriptedNavigator(polls_to_arrive=2)
    frames = {name: _frame_at(house, name, "green" if name == "location3" else None) for name in LOCATIONS}

    class AtTheGoal:
        """The camera of a robot standing where the navigator last sent it."""

        def __init__(self) -> None:
            self.now_ns = 0

        def want(self, on: bool) -> None:
            pass

        def latest(self):
            if not navigator.goals:
                return None
            pose = navigator.goals[-1][0]
            name = next(n for n, p in LOCATIONS.items() if (p.x_m, p.y_m) == (pose.x_m, pose.y_m))
            return (self.now_ns, frames[name])

    camera = AtTheGoal()
    factory = BehaviorTreeFactory()
    register_mission_nodes(factory, navigator=navigator, rng=random.Random(4))
    slot = ImageSlot()
    slot.source = camera
    register_vision_nodes(factory, slot=slot, target_color="green")
    clock = ManualClock()
    tree = factory.create_tree_from_file(ROOT / "trees" / tree_file, clock=clock)
    tree.root_blackboard.set("location_file", str(ROOT / "trees" / "sim_house_locations.yaml"))
    statuses = []
    for _ in range(100):
        status = tree.tick_once()
        statuses.append(status)
        if status.is_completed:
            break
        clock.advance(500_000_000)
        camera.now_ns = clock()
    assert statuses[-1] is NodeStatus.SUCCESS
    last = navigator.goals[-1][0]
    assert (last.x_m, last.y_m) == (LOCATIONS["location3"].x_m, LOCATIONS["location3"].y_m)
    if tree_file == "search_naive.xml":  # locations in file order: 1, 2, then 3 where the block is
        assert len(navigator.goals) == 3
