from __future__ import annotations

import math

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid, inflate
from twin.core.errors import ConfigError
from twin.nav.controller import (
    FollowPathTask,
    FollowStatus,
    SimpleGoalChecker,
    SimpleProgressChecker,
    controller_for_plugin,
)
from twin.nav.dwb import DwbController, DwbParams
from twin.nav.rpp import RppController

PERIOD_NS = 100_000_000  # 10 Hz


def _straight() -> np.ndarray:
    xs = np.arange(1.0, 4.0 + 1e-9, 0.025)
    return np.column_stack([xs, np.full_like(xs, 2.5), np.zeros_like(xs)])


def _curve() -> np.ndarray:
    a = np.linspace(-math.pi / 2, 0.0, 120)
    xs, ys = 1.0 + 2.0 * np.cos(a), 3.0 + 2.0 * np.sin(a)  # quarter circle r = 2 from (1, 1) to (3, 3)
    poses = np.column_stack([xs, ys, np.zeros_like(xs)])
    poses[-1, 2] = math.pi / 2
    return poses


def _drive(task: FollowPathTask, costmap, start, plan, *, seconds: float = 60.0):  # type: ignore[no-untyped-def]
    """Unicycle robot executing each command for one controller period."""
    x, y, yaw = start
    v = w = 0.0
    task.start(plan, 0)
    cmds, poses = [], []
    for k in range(int(seconds * 10)):
        step = task.step(k * PERIOD_NS, (x, y, yaw), (v, w), costmap)
        if step.status is not FollowStatus.RUNNING:
            return step, np.array(cmds), np.array(poses)
        v, w = step.cmd
        cmds.append(step.cmd)
        for _ in range(10):
            x += v * math.cos(yaw) * 0.01
            y += v * math.sin(yaw) * 0.01
            yaw += w * 0.01
        poses.append((x, y, yaw))
    return step, np.array(cmds), np.array(poses)


def _empty():  # type: ignore[no-untyped-def]
    return grid(np.zeros((120, 120), dtype=np.uint8))


@pytest.mark.parametrize("plan_name", ["straight", "curve"])
@pytest.mark.parametrize("make", [DwbController, RppController], ids=["dwb", "rpp"])
def test_follows_a_path_within_tb3_limits_and_stops_at_the_goal(plan_name: str, make) -> None:  # type: ignore[no-untyped-def]
    plan = _straight() if plan_name == "straight" else _curve()
    start = (float(plan[0, 0]), float(plan[0, 1]), float(math.atan2(plan[1, 1] - plan[0, 1], plan[1, 0] - plan[0, 0])))
    task = FollowPathTask(make())
    step, cmds, poses = _drive(task, _empty(), start, plan)
    assert step.status is FollowStatus.SUCCEEDED, step.reason
    assert step.cmd == (0.0, 0.0)
    assert np.abs(cmds[:, 0]).max() <= 0.22 + 1e-9 and np.abs(cmds[:, 1]).max() <= 1.0 + 1e-9
    goal = plan[-1]
    end = poses[-1]
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) <= 0.25
    assert abs((end[2] - goal[2] + math.pi) % (2 * math.pi) - math.pi) <= 0.25
    # the robot stays near the path
    d = np.min(np.hypot(poses[:, None, 0] - plan[None, :, 0], poses[:, None, 1] - plan[None, :, 1]), axis=1)
    assert d.max() < 0.3


def test_dwb_accelerations_stay_within_limits() -> None:
    task = FollowPathTask(DwbController())
    _, cmds, _ = _drive(task, _empty(), (1.0, 2.5, 0.0), _straight())
    acc = np.abs(np.diff(np.vstack([[0.0, 0.0], cmds]), axis=0)) / 0.1
    assert acc[:, 0].max() <= 2.5 + 1e-6 and acc[:, 1].max() <= 3.2 + 1e-6


@pytest.mark.parametrize("make", [DwbController, RppController], ids=["dwb", "rpp"])
def test_refuses_to_drive_into_a_lethal_cell(make) -> None:  # type: ignore[no-untyped-def]
    occupied = np.zeros((120, 120), dtype=bool)
    occupied[:, 60:62] = True  # a wall across the path at x = 3 m
    costmap = grid(inflate(occupied, 0.05, inscribed_m=0.22, inflation_m=0.6))
    task = FollowPathTask(make())
    step, _, poses = _drive(task, costmap, (1.0, 2.5, 0.0), _straight(), seconds=30.0)
    assert step.status is FollowStatus.FAILED
    assert all(costmap.cost_at(x, y) < 253 for x, y, _ in poses)


def test_goal_checker_is_stateful() -> None:
    checker = SimpleGoalChecker()
    goal = (1.0, 1.0, 0.0)
    assert not checker.is_goal_reached((1.1, 1.0, 1.0), goal)  # position in, yaw out: latched
    assert checker.is_goal_reached((1.3, 1.0, 0.1), goal)  # position drifted out, still latched
    checker.reset()
    assert not checker.is_goal_reached((1.3, 1.0, 0.1), goal)


def test_progress_checker_fails_after_the_allowance_without_movement() -> None:
    checker = SimpleProgressChecker()
    assert checker.check((0.0, 0.0, 0.0), 0)
    assert checker.check((0.4, 0.0, 0.0), 10_000_000_000)
    assert not checker.check((0.4, 0.0, 0.0), 10_100_000_000)
    assert checker.check((0.6, 0.0, 0.0), 10_200_000_000)  # moved out of the radius: new baseline


def test_dwb_samples_the_dynamic_window() -> None:
    traj = DwbController().sample((0.1, 0.0))
    vx = np.unique(traj.velocity[:, 0])
    assert vx.min() == pytest.approx(0.0) and vx.max() == pytest.approx(0.22)
    assert len(vx) == 20
    wz = np.unique(traj.velocity[:, 1])
    assert wz.min() == pytest.approx(-0.32) and wz.max() == pytest.approx(0.32) and len(wz) == 40


def test_controller_plugin_by_name() -> None:
    dwb = controller_for_plugin("dwb_core::DWBLocalPlanner", {"sim_time": 1.5, "max_vel_x": 0.22, "critics": []})
    assert isinstance(dwb, DwbController) and dwb.params == DwbParams(sim_time_s=1.5)
    rpp = controller_for_plugin("nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController", {})
    assert isinstance(rpp, RppController)
    with pytest.raises(ConfigError, match="unknown controller plugin 'mppi'; the twin has dwb_core"):
        controller_for_plugin("mppi", {})


def test_dwb_native_and_numpy_rollouts_choose_the_same_commands() -> None:
    occupied = np.zeros((120, 120), dtype=bool)
    occupied[40:60, 70:80] = True
    costmap = grid(inflate(occupied, 0.05, inscribed_m=0.22, inflation_m=1.0))
    plan = _curve()
    fast, slow = DwbController(native=True), DwbController(native=False)
    fast.set_plan(plan)
    slow.set_plan(plan)
    for pose, vel in [((1.0, 1.0, 0.0), (0.0, 0.0)), ((2.0, 1.3, 0.5), (0.2, 0.3)), ((2.8, 2.2, 1.2), (0.22, -0.5))]:
        assert fast.compute_velocity(pose, vel, costmap) == slow.compute_velocity(pose, vel, costmap)
        assert np.allclose(fast.local_plan, slow.local_plan)
