from __future__ import annotations

import math

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid, inflate
from twin.core.errors import ConfigError
from twin.nav.controller.checkers import (
    PoseProgressChecker,
    SimpleGoalChecker,
    SimpleProgressChecker,
    StoppedGoalChecker,
)
from twin.nav.controller.controller_server import FollowPathTask, FollowStatus, controller_for_plugin
from twin.nav.controller.dwb.local_planner import DwbController, DwbParams
from twin.nav.controller.regulated_pure_pursuit import RppController, RppParams
from twin.nav.params import load_nav2_params

PERIOD_NS = 100_000_000  # 10 Hz


def _tb3_rpp() -> RppController:
    """RPP at TurtleBot3's speeds on this file's 10 Hz loop (Nav2's code defaults drive at 0.5 m/s)."""
    return RppController(
        RppParams(desired_linear_vel=0.22, rotate_to_heading_angular_vel=1.0, controller_frequency_hz=10)
    )


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
@pytest.mark.parametrize("make", [DwbController, _tb3_rpp], ids=["dwb", "rpp"])
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


def test_dwb_trajectories_ramp_under_the_acceleration_limits() -> None:
    # StandardTrajectoryGenerator: each time step moves the velocity towards the sample by at most acc x dt
    traj = DwbController().sample((0.0, 0.0))
    i = int(np.argmin(np.abs(traj.velocity[:, 0] - 0.22) + np.abs(traj.velocity[:, 1] - 1.0)))
    steps = int(traj.steps[i])
    poses = traj.poses[i, : steps + 1]
    dt = 2.0 / steps
    speed = np.hypot(*np.diff(poses[:, :2], axis=0).T) / dt
    turn = np.diff(poses[:, 2]) / dt
    t = dt * np.arange(1, steps + 1)
    vx, wz = traj.velocity[i]
    assert speed == pytest.approx(np.minimum(vx, 2.5 * t))
    assert turn == pytest.approx(np.minimum(wz, 3.2 * t))


@pytest.mark.parametrize("make", [DwbController, _tb3_rpp], ids=["dwb", "rpp"])
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


def test_stopped_goal_checker_also_needs_the_robot_stopped() -> None:
    # nav2_controller::StoppedGoalChecker: SimpleGoalChecker's test (latching the position as it
    # does), then |v| and |w| at or below trans_stopped_velocity and rot_stopped_velocity
    checker = StoppedGoalChecker(trans_stopped_velocity_mps=0.1, rot_stopped_velocity_radps=0.2)
    goal = (1.0, 1.0, 0.0)
    assert not checker.is_goal_reached((1.1, 1.0, 0.0), goal, (0.15, 0.0))  # there, still driving
    assert not checker.is_goal_reached((1.3, 1.0, 0.0), goal, (0.0, 0.3))  # (latched) turning too fast
    assert checker.is_goal_reached((1.3, 1.0, 0.0), goal, (0.1, -0.2))  # latched, stopped enough
    simple = SimpleGoalChecker()
    assert simple.is_goal_reached((1.1, 1.0, 0.0), goal, (0.15, 0.0))  # the Simple one ignores the speed


def test_pose_progress_checker_counts_turning_as_progress() -> None:
    # nav2_controller::PoseProgressChecker: leaving the radius or turning past required_movement_angle
    simple, pose = SimpleProgressChecker(), PoseProgressChecker(required_movement_angle_rad=0.5)
    for checker in (simple, pose):
        assert checker.check((0.0, 0.0, 0.0), 0)
    # turning in place by 0.6 rad, then waiting past the allowance from the start
    assert simple.check((0.0, 0.0, 0.6), 5_000_000_000) and pose.check((0.0, 0.0, 0.6), 5_000_000_000)
    assert not simple.check((0.0, 0.0, 0.6), 10_100_000_000)  # the turn is no progress to it
    assert pose.check((0.0, 0.0, 0.6), 10_100_000_000)  # its baseline moved with the turn at 5 s
    assert not pose.check((0.0, 0.0, 0.9), 15_100_000_000)  # 0.3 rad more is not enough: 10.1 s since


def test_dwb_samples_what_sim_time_can_reach_as_humble_does() -> None:
    # StandardTrajectoryGenerator widens the window by sim_time (2 s) of acceleration: TB3's whole range,
    # 20 x 40 samples with a zero inserted where theta crosses it, and (0, 0) left out
    traj = DwbController().sample((0.1, 0.0))
    vx = np.unique(traj.velocity[:, 0])
    assert vx.min() == 0.0 and vx.max() == pytest.approx(0.22) and len(vx) == 20
    wz = np.unique(traj.velocity[:, 1])
    assert wz.min() == pytest.approx(-1.0) and wz.max() == pytest.approx(1.0) and len(wz) == 41 and 0.0 in wz
    assert len(traj.velocity) == 20 * 41 - 1
    assert not ((traj.velocity[:, 0] == 0.0) & (traj.velocity[:, 1] == 0.0)).any()
    # x outer, theta inner
    assert (np.diff(traj.velocity[:, 0]) >= 0).all()


def test_dwb_limited_accel_generator_samples_one_controller_period() -> None:
    params = DwbParams(trajectory_generator="dwb_plugins::LimitedAccelGenerator")
    traj = DwbController(params).sample((0.1, 0.0))
    vx = np.unique(traj.velocity[:, 0])
    assert vx.min() == 0.0 and vx.max() == pytest.approx(0.22)
    wz = np.unique(traj.velocity[:, 1])
    assert wz.min() == pytest.approx(-0.32) and wz.max() == pytest.approx(0.32)


def test_controller_plugin_by_name() -> None:
    dwb = controller_for_plugin("dwb_core::DWBLocalPlanner", {"sim_time": 1.5, "max_vel_x": 0.22, "critics": []})
    assert isinstance(dwb, DwbController)
    # what the section leaves out takes Nav2 Humble's code defaults
    assert dwb.params.sim_time_s == 1.5 and dwb.params.max_vel_x == 0.22
    assert dwb.params.vtheta_samples == 20 and dwb.params.linear_granularity_m == 0.5 and dwb.params.critics == ()
    rpp = controller_for_plugin("nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController", {})
    assert isinstance(rpp, RppController)
    with pytest.raises(ConfigError, match="unknown controller plugin 'mppi'; the twin has dwb_core"):
        controller_for_plugin("mppi", {})


@pytest.mark.parametrize("model", ["burger", "waffle", "waffle_pi"])
def test_dwb_reads_tb3s_humble_files_as_they_are(model: str, fixtures) -> None:  # type: ignore[no-untyped-def]
    path = fixtures / "nav2" / "turtlebot3_navigation2_humble" / "param" / "humble" / f"{model}.yaml"
    cs = load_nav2_params(path).node("controller_server")
    section = {k.removeprefix("FollowPath."): v for k, v in cs.items() if k.startswith("FollowPath.")}
    params = DwbParams.from_nav2(section, controller_frequency_hz=float(cs["controller_frequency"]))
    expected = DwbParams() if model != "burger" else DwbParams(sim_time_s=1.5)
    assert params == expected


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("critics", ["BaseObstacle", "ObstacleFootprint"], "no DWB critic 'ObstacleFootprint'"),
        ("trajectory_generator_name", "my::Generator", "unknown generator 'my::Generator'"),
        ("max_vel_y", 0.2, "differential drive"),
        ("sim_time", "long", "expected a number"),
    ],
)
def test_dwb_refuses_what_it_cannot_run(key: str, value: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        controller_for_plugin(
            "dwb_core::DWBLocalPlanner", {key: value}, where="params.yaml: controller_server.FollowPath"
        )


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


def _window(costmap, x: float, y: float, size_m: float = 3.0):  # type: ignore[no-untyped-def]
    """A local-costmap-like window of a larger costmap around (x, y), unknown beyond it."""
    res = costmap.resolution_m
    n = round(size_m / res)
    c0 = int((x - costmap.origin_x_m) / res) - n // 2
    r0 = int((y - costmap.origin_y_m) / res) - n // 2
    cost = np.full((n, n), 255, dtype=np.uint8)
    rs = slice(max(r0, 0), min(r0 + n, costmap.rows))
    cs = slice(max(c0, 0), min(c0 + n, costmap.cols))
    cost[rs.start - r0 : rs.stop - r0, cs.start - c0 : cs.stop - c0] = costmap.cost[rs, cs]
    return grid(cost, resolution_m=res, origin_m=(costmap.origin_x_m + c0 * res, costmap.origin_y_m + r0 * res))


def test_dwb_native_and_numpy_agree_along_a_house_plan() -> None:
    # the C cycle and the numpy reference: same commands, local plans, failures and critic state, cycle by
    # cycle, on local windows of the house along a NavFn plan, through a map->odom offset, with the
    # oscillation and rotate-to-goal critics engaged near the goal
    from tests.unit.nav.costmaps import house_costmap
    from twin.nav.controller.dwb.local_planner import NoValidTrajectory
    from twin.nav.planner.navfn import NavfnPlanner

    house = house_costmap(inflation_m=1.0)
    plan = NavfnPlanner().make_plan(house, (-1.0, -0.5, 0.0), (0.5, 4.0, 1.57))
    offset = (0.03, -0.02, 0.01)
    fast, slow = DwbController(native=True), DwbController(native=False)
    assert fast.native and not slow.native
    rng = np.random.default_rng(5)
    outcomes = {"command": 0, "failure": 0}
    for dwb in (fast, slow):
        dwb.set_plan(plan.poses)
        dwb.plan_to_costmap = offset
    c, s = math.cos(offset[2]), math.sin(offset[2])
    gx, gy = plan.poses[-1, :2]
    wall = np.argwhere(house.cost == 254)[len(np.argwhere(house.cost == 254)) // 2]
    cases = [(px, py, 0.05) for px, py, _ in plan.poses[::6]]
    cases += [(gx, gy, 0.02)] * 6  # near the goal: RotateToGoal's window, then turning in place
    cases += [(*house.cell_centre(int(wall[0]), int(wall[1])), 0.0)]  # on a wall: nothing is legal
    for k, (px, py, noise) in enumerate(cases):
        x = offset[0] + c * px - s * py + rng.normal(0, noise)
        y = offset[1] + s * px + c * py + rng.normal(0, noise)
        yaw = float(rng.uniform(-math.pi, math.pi))
        vel = (float(rng.uniform(0, 0.22)), float(rng.uniform(-1, 1)) if k % 3 else 0.0)
        window = _window(house, x, y)
        results = []
        for dwb in (fast, slow):
            try:
                results.append(dwb.compute_velocity((x, y, yaw), vel, window))
            except NoValidTrajectory as err:
                results.append(str(err))
        assert results[0] == results[1], (k, x, y, yaw, vel)
        outcomes["failure" if isinstance(results[0], str) else "command"] += 1
        if not isinstance(results[0], str):
            assert np.allclose(fast.local_plan, slow.local_plan, atol=1e-9)
        assert len(fast._plan) == len(slow._plan)
        for attr in ("in_window", "rotating"):
            assert getattr(fast._critics, attr) == getattr(slow._critics, attr)
        assert fast._critics.x == slow._critics.x and fast._critics.theta == slow._critics.theta
    assert outcomes["command"] > 10 and outcomes["failure"] > 0
    assert fast._critics.in_window
