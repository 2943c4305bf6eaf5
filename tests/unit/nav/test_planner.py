from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from twin.bt.mission_nodes import NavigationStatus, Pose2D
from twin.nav import GridNavigator, GridPlanner, build_grid
from twin.nav.follower import FollowerParams, PathFollower
from twin.nav.navigator import ProgressParams
from twin.world import build_scene, load_world

REPO = Path(__file__).resolve().parents[3]
HOUSE = REPO / "sdf" / "worlds" / "house.sdf"
LOCATIONS = {"location1": (-1.0, -0.5), "location2": (0.5, 4.0), "location3": (4.0, 0.5), "location4": (2.75, 2.5)}


@pytest.fixture(scope="module")
def house_planner() -> GridPlanner:
    scene = build_scene(load_world(HOUSE, model_path=[REPO / "sdf" / "models"]))
    grid = build_grid(scene, heights_m=(0.05, 0.15))
    return GridPlanner(grid, robot_radius_m=0.24)


def test_grid_marks_walls_and_measures_distance_to_them(tmp_path: Path) -> None:
    world = tmp_path / "w.sdf"
    world.write_text(
        '<sdf version="1.7"><world name="w"><model name="wall"><static>true</static><pose>1 0 0.5 0 0 0</pose>'
        '<link name="l"><collision name="c"><geometry><box><size>0.1 4 1</size></box></geometry></collision>'
        "</link></model></world></sdf>"
    )
    grid = build_grid(build_scene(load_world(world, model_path=[])), heights_m=(0.1,), resolution_m=0.05)
    wall = grid.cell(0.95, 0.0)
    assert wall is not None and grid.occupied[wall]
    free = grid.cell(0.0, 0.0)
    assert free is not None and not grid.occupied[free]
    assert grid.distance_m[free] == pytest.approx(0.95, abs=0.06)


def test_every_thesis_location_is_reachable_from_the_spawn_point(house_planner: GridPlanner) -> None:
    for name, goal in LOCATIONS.items():
        path = house_planner.plan((0.0, 0.0), goal)
        assert path is not None, name
        assert path[-1] == goal


def test_planned_legs_keep_the_robot_off_the_walls(house_planner: GridPlanner) -> None:
    grid = house_planner.grid
    path = house_planner.plan((-1.0, -0.5), (0.5, 4.0))
    assert path is not None
    points = [(-1.0, -0.5), *path]
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        for t in np.linspace(0.0, 1.0, 50):
            cell = grid.cell(x0 + t * (x1 - x0), y0 + t * (y1 - y0))
            assert cell is not None and grid.distance_m[cell] >= 0.24 - grid.resolution_m


def test_a_path_goes_around_a_wall_not_through_it(house_planner: GridPlanner) -> None:
    # location2 to location3 crosses the house's middle wall (x = 1.45): the path must be longer.
    path = house_planner.plan((0.5, 4.0), (4.0, 0.5))
    assert path is not None
    points = [(0.5, 4.0), *path]
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(points))
    assert length > math.dist((0.5, 4.0), (4.0, 0.5)) + 0.5


def test_goals_inside_walls_or_outside_the_house_have_no_path(house_planner: GridPlanner) -> None:
    assert house_planner.plan((0.0, 0.0), (20.0, 20.0)) is None
    # Inside Wall_0: the free side is 0.3 m away, within NavFn's 0.5 m tolerance, not within 0.1 m.
    assert house_planner.plan((0.0, 0.0), (-0.536, -1.356)) is not None
    strict = GridPlanner(house_planner.grid, robot_radius_m=0.24, tolerance_m=0.1)
    assert strict.plan((0.0, 0.0), (-0.536, -1.356)) is None


def test_follower_turns_in_place_then_drives_then_turns_to_the_final_heading() -> None:
    follower = PathFollower(FollowerParams())
    follower.set_path([(1.0, 0.0)], final_yaw_rad=math.pi / 2)
    assert follower.command(0.0, 0.0, math.pi) == (0.0, pytest.approx(-1.0))  # heading error pi: turn, capped
    v, w = follower.command(0.0, 0.0, 0.0)
    assert v == pytest.approx(0.22) and w == pytest.approx(0.0)
    assert follower.command(0.95, 0.0, 0.0) == (0.0, pytest.approx(1.0))  # at the point: turn to pi/2
    assert follower.command(0.95, 0.0, math.pi / 2) == (0.0, 0.0)
    assert follower.done


def test_navigator_succeeds_at_the_goal_and_fails_without_progress(house_planner: GridPlanner) -> None:
    nav = GridNavigator(house_planner, FollowerParams(), ProgressParams())
    goal = nav.send_goal(Pose2D(1.0, 0.0, 0.0), "map")
    assert nav.goal_status(goal) is NavigationStatus.RUNNING
    x = 0.0
    for k in range(200):
        v, _ = nav.command(k * 100_000_000, x, 0.0, 0.0)
        x += v * 0.1
    assert nav.goal_status(goal) is NavigationStatus.SUCCEEDED
    stuck = nav.send_goal(Pose2D(-1.0, -0.5, 0.0), "map")
    for k in range(200):  # the robot never moves: after 10 s the goal is aborted
        nav.command(k * 100_000_000, 1.0, 0.0, math.pi)
    assert nav.goal_status(stuck) is NavigationStatus.FAILED


def test_a_new_goal_preempts_the_running_one(house_planner: GridPlanner) -> None:
    nav = GridNavigator(house_planner, FollowerParams(), ProgressParams())
    first = nav.send_goal(Pose2D(1.0, 0.0, 0.0), "map")
    second = nav.send_goal(Pose2D(-1.0, -0.5, 0.0), "map")
    assert nav.goal_status(first) is NavigationStatus.FAILED
    assert nav.goal_status(second) is NavigationStatus.RUNNING


def test_unreachable_goal_fails_at_planning(house_planner: GridPlanner) -> None:
    nav = GridNavigator(house_planner, FollowerParams(), ProgressParams())
    goal = nav.send_goal(Pose2D(20.0, 20.0, 0.0), "map")
    assert nav.command(0, 0.0, 0.0, 0.0) == (0.0, 0.0)
    assert nav.goal_status(goal) is NavigationStatus.FAILED
