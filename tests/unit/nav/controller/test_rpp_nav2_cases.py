"""Regulated Pure Pursuit against Nav2 Humble's own: every case in `rpp_cases/` (see its README).

Equal means: per cycle the same status (a command or which exception), the same plan poses erased
and kept, the same branch (rotate to the goal's yaw, rotate to the path, track), the same number of
poses the collision check projected, and the lookahead, carrot, curvature and command within 1e-9.
The tests below the replay pin what the twin's RPP did differently before it was held to these cases.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid
from twin.core.errors import ConfigError
from twin.nav.conformance import check_case, load_case
from twin.nav.controller.checkers import SimpleGoalChecker
from twin.nav.controller.controller_server import FollowPathTask
from twin.nav.controller.regulated_pure_pursuit import NoValidCommand, RppController, RppParams
from twin.nav.params import load_nav2_params
from twin.nav.server_params import nav2_config

CASES = Path(__file__).with_name("rpp_cases")
FILES = sorted(CASES.glob("*.npz"))


def test_the_recorded_set_covers_the_issue() -> None:
    cases = [load_case(f) for f in FILES]
    assert len(cases) >= 75
    metas = [m for m, _ in cases]
    assert {m["component"] for m in metas} == {"rpp"}
    assert {m["oracle"] for m in metas} == {"re-typed"}
    assert len({m["nav2_commit"] for m in metas}) == 1
    assert {"synthetic", "goal", "reversing", "pruning", "obstacles", "house"} <= {m["group"] for m in metas}
    statuses = np.concatenate([a["out_status"] for _, a in cases])
    branches = np.concatenate([a["out_branch"] for _, a in cases])
    assert {0, 1, 2, 3, 4} <= set(statuses.tolist())  # commands, no plan, no pose near, collision, off the costmap
    assert {0, 1, 2} <= set(branches.tolist())  # rotate to the goal's yaw, rotate to the path, track
    assert len(statuses) >= 3000
    params = [m["params"] for m in metas]
    for flag in ("use_velocity_scaled_lookahead_dist", "use_interpolation", "use_rotate_to_heading", "allow_reversing"):
        assert {p[flag] for p in params} == {True, False}
    assert any(a["out_float"][:, 5].max() > 0 and a["out_erased"].sum() > 0 for _, a in cases)


@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_rpp_equals_nav2(case: Path) -> None:
    result = check_case(case)
    assert result.component == "rpp"
    assert result.equal, "; ".join(result.differences)


def _straight() -> np.ndarray:
    xs = np.arange(-2.0, 2.5, 0.05)
    return np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])


def test_rotates_to_the_goal_heading_within_the_goal_checkers_tolerance() -> None:
    # Nav2 turns in place once the *carrot* is closer than the goal checker's xy tolerance, which
    # controller_server hands over each cycle; the twin used a fixed 0.25 m and the goal's distance
    plan = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.1, 0.0, 1.5]])
    costmap = grid(np.zeros((60, 60), dtype=np.uint8), origin_m=(-1.5, -1.5))
    task = FollowPathTask(RppController(), SimpleGoalChecker(xy_goal_tolerance_m=0.15))
    task.start(plan, 0)
    step = task.step(0, (-0.1, 0.0, 0.0), (0.0, 0.0), costmap)
    assert task.controller.goal_dist_tol_m == 0.15
    assert step.cmd[0] > 0.0  # the carrot (the plan's end, 0.2 m away) is outside 0.15 m: drive
    task = FollowPathTask(RppController(), SimpleGoalChecker(xy_goal_tolerance_m=0.25))
    task.start(plan, 0)
    step = task.step(0, (-0.1, 0.0, 0.0), (0.0, 0.0), costmap)
    assert step.cmd[0] == 0.0 and step.cmd[1] > 0.0  # inside 0.25 m: turn towards the goal's yaw


def test_slows_its_turn_in_place_so_as_not_to_overshoot() -> None:
    # rotateToHeading caps the turn rate at sqrt(2 * max_angular_accel * angle left)
    controller = RppController(RppParams(rotate_to_heading_angular_vel=1.8))
    controller.set_plan(np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.05]]))
    costmap = grid(np.zeros((60, 60), dtype=np.uint8), origin_m=(-1.5, -1.5))
    v, w = controller.compute_velocity((0.0, 0.0, 0.0), (0.0, 1.0), costmap)
    assert v == 0.0 and w == pytest.approx(math.sqrt(2 * 3.2 * 0.05))


def test_checks_the_footprint_not_only_the_centre_for_collisions() -> None:
    # a lethal cell 0.2 m beside the straight path: the centre line is clear, the footprint is not
    cost = np.zeros((120, 120), dtype=np.uint8)
    cost[64, 70] = 254  # (0.5, 0.2) with the origin at (-3, -3)
    costmap = grid(cost, origin_m=(-3.0, -3.0))
    controller = RppController(RppParams(use_cost_regulated_linear_velocity_scaling=False))
    controller.set_plan(_straight())
    with pytest.raises(NoValidCommand, match="detected collision ahead"):
        controller.compute_velocity((0.2, 0.0, 0.0), (0.5, 0.0), costmap)


def test_the_robot_off_the_costmap_is_an_error_not_a_free_cell() -> None:
    controller = RppController(RppParams(use_rotate_to_heading=False))
    controller.set_plan(_straight())
    costmap = grid(np.zeros((40, 40), dtype=np.uint8), origin_m=(-3.0, -1.0))  # x in [-3, -1)
    with pytest.raises(NoValidCommand, match="Dimensions of the costmap are too small"):
        controller.compute_velocity((-0.5, 0.0, 0.0), (0.0, 0.0), costmap)


def test_from_nav2_reads_humbles_names_and_defaults() -> None:
    assert RppParams.from_nav2({}) == RppParams()
    assert RppParams().desired_linear_vel == 0.5 and RppParams().rotate_to_heading_angular_vel == 1.8
    section = {
        "plugin": "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController",
        "desired_linear_vel": 0.22,
        "inflation_cost_scaling_factor": 10,
        "max_robot_pose_search_dist": 2.0,
        "use_interpolation": False,
        "allow_reversing": True,
        "transform_tolerance": 0.2,
    }
    params = RppParams.from_nav2(section, controller_frequency_hz=10.0)
    assert params.desired_linear_vel == 0.22 and params.inflation_cost_scaling_factor == 10.0
    assert params.max_robot_pose_search_dist_m == 2.0 and not params.use_interpolation and params.allow_reversing
    assert params.controller_frequency_hz == 10.0
    assert RppParams.from_nav2({"max_angular_vel": 1.0, "lookahead_distance": 0.4}) == RppParams()  # as Nav2


def test_a_params_file_names_the_keys_humbles_rpp_does_not_read(fixtures: Path) -> None:
    # Nav2 ignores them silently; the twin's one unused-parameters line names them (a typo, a DWB key left over)
    overrides = {
        "controller_server.FollowPath.plugin": "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController",
        "controller_server.FollowPath.desired_linear_vel": 0.22,
        "controller_server.FollowPath.lookahead_distance": 0.4,
    }
    params = load_nav2_params(fixtures / "nav2" / "nav2_humble" / "nav2_params.yaml", overrides=overrides)
    config = nav2_config(params)
    warning = params.warning(config.used) or ""
    assert "controller_server.FollowPath.lookahead_distance" in warning
    assert "controller_server.FollowPath.max_vel_x" in warning  # DWB's, in Nav2's file, unread by RPP
    assert "controller_server.FollowPath.desired_linear_vel" not in warning
    _, section = config.controllers["FollowPath"]
    assert RppParams.from_nav2(section).desired_linear_vel == 0.22


@pytest.mark.parametrize(("key", "value"), [("desired_linear_vel", "fast"), ("use_interpolation", 1)])
def test_from_nav2_refuses_a_value_of_the_wrong_type(key: str, value: object) -> None:
    with pytest.raises(ConfigError, match=rf"^FollowPath\.{key}: expected .*; fix the params file$"):
        RppParams.from_nav2({key: value})
