from __future__ import annotations

import math

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid, house_costmap, inflate
from twin.nav.planner.navfn import NavfnParams, NavfnPlanner, Plan, PlanFailure, PlanFailureReason, navfn_costs


def _cells_cost(cost_grid, poses):  # type: ignore[no-untyped-def]
    return np.array([cost_grid.cost_at(x, y) for x, y, _ in poses])


def _box_world(size: int = 120) -> np.ndarray:
    occupied = np.zeros((size, size), dtype=bool)
    occupied[40:80, 55:65] = True  # a 0.5 x 2 m box in the middle
    return occupied


@pytest.fixture(params=[True, False], ids=["native", "python"])
def planner(request: pytest.FixtureRequest) -> NavfnPlanner:
    return NavfnPlanner(native=request.param)


def test_cost_mapping_is_navfns() -> None:
    cost = np.array([[0, 0, 0, 0, 0, 0], [0, 0, 100, 252, 253, 0], [0, 254, 255, 0, 0, 0], [0] * 6], dtype=np.uint8)
    mapped = navfn_costs(cost, allow_unknown=True)
    assert mapped[1, 1] == 50 and mapped[1, 2] == 130 and mapped[1, 3] == 251
    assert mapped[1, 4] == 254 and mapped[2, 1] == 254 and mapped[2, 2] == 253
    assert navfn_costs(cost, allow_unknown=False)[2, 2] == 254
    assert (mapped[0] == 254).all() and (mapped[:, -1] == 254).all()  # the border is forbidden


def test_straight_path_in_free_space(planner: NavfnPlanner) -> None:
    costmap = grid(np.zeros((80, 120), dtype=np.uint8))
    plan = planner.make_plan(costmap, (0.5, 2.0, 0.0), (5.0, 2.0, 0.7))
    assert isinstance(plan, Plan)
    assert np.allclose(plan.poses[:, 1], 2.0, atol=0.03)
    assert plan.length_m == pytest.approx(4.5, abs=0.05)
    assert plan.poses[0, :2] == pytest.approx((0.5, 2.0)) and plan.poses[-1] == pytest.approx((5.0, 2.0, 0.7))
    assert (plan.poses[:-1, 2] == 0.0).all()  # identity orientation but for the last pose
    steps = np.hypot(*np.diff(plan.poses[:, :2], axis=0).T)
    assert np.median(steps) == pytest.approx(0.025) and steps.max() <= 0.05 + 1e-9  # half-cell gradient steps


def test_detour_around_a_box_keeps_off_lethal_and_inscribed_cells(planner: NavfnPlanner) -> None:
    costmap = grid(inflate(_box_world(), 0.05, inscribed_m=0.1, inflation_m=0.55))
    plan = planner.make_plan(costmap, (1.0, 3.0, 0.0), (5.0, 3.0, 0.0))
    assert isinstance(plan, Plan)
    assert (_cells_cost(costmap, plan.poses) < 253).all()
    assert plan.length_m > 4.4  # straight through would be 4.0
    assert plan.poses[-1, :2] == pytest.approx((5.0, 3.0))


def test_native_and_python_paths_are_identical() -> None:
    costmap = grid(inflate(_box_world(), 0.05, inscribed_m=0.1, inflation_m=0.55))
    for astar in (False, True):
        native = NavfnPlanner(NavfnParams(use_astar=astar), native=True)
        python = NavfnPlanner(NavfnParams(use_astar=astar), native=False)
        a = native.make_plan(costmap, (1.0, 1.0, 0.0), (5.2, 4.9, 0.0))
        b = python.make_plan(costmap, (1.0, 1.0, 0.0), (5.2, 4.9, 0.0))
        assert isinstance(a, Plan) and isinstance(b, Plan)
        assert np.array_equal(a.poses, b.poses)


def test_goal_in_a_wall_within_tolerance_succeeds_and_farther_fails(planner: NavfnPlanner) -> None:
    occupied = np.zeros((120, 120), dtype=bool)
    occupied[:, 60:] = True  # everything right of x = 3 m is wall
    costmap = grid(inflate(occupied, 0.05, inscribed_m=0.1, inflation_m=0.3))
    free_edge_x = max(x for x in np.arange(2.0, 3.0, 0.05) if costmap.cost_at(x + 0.025, 3.0) < 253)
    near = planner.make_plan(costmap, (1.0, 3.0, 0.0), (free_edge_x + 0.4, 3.0, 0.0))
    assert isinstance(near, Plan)
    assert math.hypot(near.poses[-1, 0] - (free_edge_x + 0.4), near.poses[-1, 1] - 3.0) <= 0.5
    far = planner.make_plan(costmap, (1.0, 3.0, 0.0), (free_edge_x + 0.7, 3.0, 0.0))
    assert isinstance(far, PlanFailure) and far.reason is PlanFailureReason.NO_VALID_PATH


def test_unknown_space_is_crossed_only_when_allowed() -> None:
    cost = np.zeros((80, 120), dtype=np.uint8)
    cost[:, 50:60] = 255
    costmap = grid(cost)
    assert isinstance(NavfnPlanner(NavfnParams(allow_unknown=True)).make_plan(costmap, (1, 2, 0), (5, 2, 0)), Plan)
    assert isinstance(
        NavfnPlanner(NavfnParams(allow_unknown=False)).make_plan(costmap, (1, 2, 0), (5, 2, 0)), PlanFailure
    )


def test_start_or_goal_outside_the_costmap_fails() -> None:
    costmap = grid(np.zeros((40, 40), dtype=np.uint8))
    planner = NavfnPlanner()
    assert planner.make_plan(costmap, (-1.0, 1.0, 0.0), (1.0, 1.0, 0.0)).reason is PlanFailureReason.START_OUTSIDE_MAP  # type: ignore[union-attr]
    assert planner.make_plan(costmap, (1.0, 1.0, 0.0), (9.0, 1.0, 0.0)).reason is PlanFailureReason.GOAL_OUTSIDE_MAP  # type: ignore[union-attr]


def test_covers_the_whole_map_not_the_obstacles_bounding_box() -> None:
    occupied = np.zeros((200, 300), dtype=bool)
    occupied[95:105, 145:155] = True  # one small box in a 15 x 10 m open floor
    costmap = grid(inflate(occupied, 0.05, inscribed_m=0.22, inflation_m=0.55))
    plan = NavfnPlanner().make_plan(costmap, (0.5, 0.5, 0.0), (14.4, 9.4, 0.0))
    assert isinstance(plan, Plan)
    assert plan.length_m < 1.05 * math.hypot(13.9, 8.9)


@pytest.mark.parametrize("astar", [False, True])
def test_house_plan_between_rooms_stays_out_of_inscribed_cells(astar: bool) -> None:
    costmap = house_costmap()
    plan = NavfnPlanner(NavfnParams(use_astar=astar)).make_plan(costmap, (-1.0, -0.5, 0.0), (0.5, 4.0, 1.57))
    assert isinstance(plan, Plan)
    assert (_cells_cost(costmap, plan.poses[1:-1]) < 253).all()
    assert plan.poses[-1] == pytest.approx((0.5, 4.0, 1.57))


def test_the_path_leaves_the_robot_at_once_and_ends_on_its_node() -> None:
    # NavFn's calcPath stops once the point's *nearest* node has a potential below 50 (the robot's
    # node): a path that only checked the node below the point circled the robot for many steps
    from tests.unit.nav.costmaps import house_costmap

    house = house_costmap()
    plan = NavfnPlanner().make_plan(house, (0.0, 0.0, 0.0), (4.0, 0.5, 1.571))
    assert isinstance(plan, Plan)
    steps = np.hypot(*np.diff(plan.poses[:, :2], axis=0).T)
    assert (steps > 0.0).all() and steps.max() <= 0.05 * math.sqrt(2) + 1e-9  # none repeated; at most a diagonal
    assert plan.length_m < 1.15 * math.hypot(4.0, 0.5)
    robot_node = (round((0.0 - house.origin_x_m) / 0.05), round((0.0 - house.origin_y_m) / 0.05))
    first = ((plan.poses[0, 0] - house.origin_x_m) / 0.05, (plan.poses[0, 1] - house.origin_y_m) / 0.05)
    assert first == pytest.approx(robot_node)


def test_start_equal_to_goal_is_one_pose_refused_on_a_lethal_cell(planner: NavfnPlanner) -> None:
    # Nav2's createPlan: the same x and y give the start with the goal's yaw, unless its cell is lethal
    cost = np.zeros((20, 20), dtype=np.uint8)
    cost[10, 10] = 254
    cost[10, 11] = 253
    costmap = grid(cost)
    refused = planner.make_plan(costmap, (0.52, 0.52, 0.0), (0.52, 0.52, 1.0))
    assert isinstance(refused, PlanFailure) and refused.reason is PlanFailureReason.START_IN_LETHAL
    inscribed = planner.make_plan(costmap, (0.57, 0.52, 0.0), (0.57, 0.52, 1.0))
    assert isinstance(inscribed, Plan) and inscribed.poses.tolist() == [[0.57, 0.52, 1.0]]
    # the same node but not the same point: NavFn runs (the lethal start's node is cleared), the path
    # is the robot's node and the goal
    near = planner.make_plan(costmap, (0.52, 0.52, 0.0), (0.52, 0.49, 1.0))
    assert isinstance(near, Plan) and near.poses.tolist() == [[0.5, 0.5, 0.0], [0.52, 0.49, 1.0]]


def test_world_points_halfway_between_nodes_round_away_from_zero(planner: NavfnPlanner) -> None:
    # std::round, not Python's round-half-to-even: x = 2.5 cells belongs to node 3, 4.5 to node 5
    costmap = grid(np.zeros((20, 20), dtype=np.uint8), resolution_m=0.5)
    plan = planner.make_plan(costmap, (1.25, 2.25, 0.0), (6.0, 2.0, 0.0))
    assert isinstance(plan, Plan)
    assert plan.poses[0, :2].tolist() == [1.5, 2.5]


def test_a_goal_beyond_navfns_batch_budget_is_not_found(planner: NavfnPlanner) -> None:
    # NavFn runs at most max(cells / 20, cols + rows) batches; down a long serpentine the goal never gets a value
    cost = np.zeros((41, 41), dtype=np.uint8)
    for i, row in enumerate(range(4, 40, 4)):
        cost[row, :] = 254
        cost[row, 1 if i % 2 else 39] = 0
    costmap = grid(cost)
    far = planner.make_plan(costmap, (0.1, 0.1, 0.0), (1.9, 1.9, 0.0))
    assert isinstance(far, PlanFailure) and far.reason is PlanFailureReason.NO_VALID_PATH
    assert isinstance(planner.make_plan(costmap, (0.1, 0.1, 0.0), (1.9, 0.5, 0.0)), Plan)
    assert planner.potential.dtype == np.float32
