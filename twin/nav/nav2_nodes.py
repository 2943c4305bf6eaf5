"""Nav2's navigation servers as nodes: planner, controller, velocity smoother, behaviours, bt_navigator.

`Nav2Servers` is the one object behind the behaviour tree's `NavigationServices`: the BT leaves
send goals to it by Nav2's action names and it answers as Nav2's servers do, within the simulated
time the servers take: a path is computed when asked (NavFn on the global costmap, map frame), a
FollowPath goal advances one controller cycle per `controller_frequency` tick, a behaviour one
cycle per `cycle_frequency` tick. The nodes wrap those cycles and publish what Nav2 publishes:

- planner_server: `/plan` (nav_msgs/Path, map) for each computed path;
- controller_server: `cmd_vel_nav` and `/local_plan` (odom) each cycle while following;
- velocity_smoother: `/cmd_vel` at its smoothing frequency from `cmd_vel_nav` (open loop);
- behavior_server: `/cmd_vel` during Spin, BackUp, DriveOnHeading, straight to the robot: Humble's
  `navigation_launch.py` remaps only the controller's `cmd_vel` to `cmd_vel_nav`, so the behaviours
  bypass the smoother, which (open loop) keeps publishing its ramp to zero on `/cmd_vel` until its
  `velocity_timeout` after the controller's last command: both reach the drive in a recovery's
  first second, as they do on a Humble robot;
- bt_navigator: the NavigateToPose action, running a Nav2 behaviour-tree XML unchanged every
  `bt_loop_duration`; status changes on `/behavior_tree_log`; feedback (current pose, navigation
  time, distance remaining, recoveries) on `/navigate_to_pose/feedback` (twin_msgs/NavigationFeedback,
  the fields of NavigateToPose's feedback) at 10 Hz.

The mission's `GoToPose` reaches the navigator through `Nav2Navigator` (send_goal / goal_status).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag import BehaviorTreeLogEncoder, NavigationFeedbackEncoder, PathEncoder, TwistEncoder
from twin.bt.log import StatusChangeBuffer
from twin.bt.mission_nodes import NavigationStatus, Pose2D
from twin.bt.status import NodeStatus
from twin.core.errors import ConfigError
from twin.nav.behaviors import BehaviorParams, BehaviorStatus, make_behavior
from twin.nav.bt_leaves import ActionState, ActionUpdate
from twin.nav.bt_nodes import nav2_factory
from twin.nav.controller import (
    Controller,
    FollowPathTask,
    FollowStatus,
    SimpleGoalChecker,
    SimpleProgressChecker,
    controller_for_plugin,
)
from twin.nav.costmap import Costmap
from twin.nav.frames import Frames, invert
from twin.nav.navfn import NavfnParams, NavfnPlanner, PlanFailure
from twin.nav.params import Nav2Params
from twin.nav.smoother import SmootherParams, VelocitySmoother
from twin.node import PRIORITY_COMMAND, PRIORITY_TREE, Encoded, Node

__all__ = [
    "BehaviorServerNode",
    "BtNavigator",
    "BtNavigatorNode",
    "ControllerServerNode",
    "Nav2Config",
    "Nav2Navigator",
    "Nav2Servers",
    "PlannerServerNode",
    "VelocitySmootherNode",
    "nav2_config",
    "smooth_path",
]

_log = logging.getLogger(__name__)

Pose = tuple[float, float, float]
F64 = NDArray[np.float64]

_BEHAVIORS = ("spin", "backup", "drive_on_heading", "wait")
_BRAKE_ACCEL_LIMIT = -10.0  # Nav2 IsStuck's brake_accel_limit, m/s^2


# --- parameters ----------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True, slots=True)
class Nav2Config:
    """What the navigation servers read from a Nav2 params file (TB3 Humble values by default)."""

    controller_frequency_hz: float = 10.0
    failure_tolerance_s: float = 0.3
    velocity_thresholds: tuple[float, float] = (0.001, 0.001)
    controllers: Mapping[str, tuple[str, Mapping[str, object]]] = field(default_factory=dict)
    goal_checkers: Mapping[str, SimpleGoalChecker] = field(default_factory=dict)
    progress_radius_m: float = 0.5
    progress_allowance_s: float = 10.0
    planner: NavfnParams = field(default_factory=NavfnParams)
    behaviors: BehaviorParams = field(default_factory=BehaviorParams)
    smoother: SmootherParams = field(default_factory=SmootherParams)
    bt_loop_duration_s: float = 0.01
    used: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


def _num(section: Mapping[str, Any], key: str, default: float, where: str) -> float:
    value = section.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"{where}.{key}: expected a number, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return float(value)


def _flag(section: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
    value = section.get(key, default)
    if not isinstance(value, bool):
        msg = f"{where}.{key}: expected true or false, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return value


def _names(section: Mapping[str, Any], key: str, default: Sequence[str], where: str) -> tuple[str, ...]:
    value = section.get(key, list(default))
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        msg = f"{where}.{key}: expected a list of names, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return tuple(value)


def _sub(section: Mapping[str, Any], prefix: str) -> dict[str, object]:
    return {k[len(prefix) + 1 :]: v for k, v in section.items() if k.startswith(prefix + ".")}


def _triple(section: Mapping[str, Any], key: str, default: tuple[float, float], where: str) -> tuple[float, float]:
    value = section.get(key)
    if value is None:
        return default
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(v, int | float) for v in value):
        msg = f"{where}.{key}: expected [x, y, theta], got {value!r}; fix the params file"
        raise ConfigError(msg)
    return (float(value[0]), float(value[2]))


def nav2_config(params: Nav2Params) -> Nav2Config:
    """Read the controller, planner, behaviour, smoother and navigator parameters of a Nav2 params file.

    Raises:
        ConfigError: A value of the wrong type, or a controller plugin the twin does not implement.
    """
    src = params.source
    cs = params.node("controller_server")
    where = f"{src}: controller_server"
    used: dict[str, list[str]] = {"controller_server": [], "planner_server": [], "bt_navigator": []}
    cu = used["controller_server"]
    plugins = _names(cs, "controller_plugins", ("FollowPath",), where)
    frequency = _num(cs, "controller_frequency", 20.0, where)
    controllers: dict[str, tuple[str, Mapping[str, object]]] = {}
    for name in plugins:
        section = _sub(cs, name)
        plugin = str(section.get("plugin", "dwb_core::DWBLocalPlanner"))
        # refuses unknown plugins, critics and bad values now, before the run
        controller_for_plugin(plugin, section, where=f"{where}.{name}", controller_frequency_hz=frequency)
        controllers[name] = (plugin, section)
        cu.extend(f"{name}.{k}" for k in section)
    checker_names = _names(cs, "goal_checker_plugins", (), where) or (
        str(cs.get("goal_checker_plugin", "goal_checker")),
    )
    checkers = {}
    for name in checker_names:
        section = _sub(cs, name)
        checkers[name] = SimpleGoalChecker(
            xy_goal_tolerance_m=_num(section, "xy_goal_tolerance", 0.25, f"{where}.{name}"),
            yaw_goal_tolerance_rad=_num(section, "yaw_goal_tolerance", 0.25, f"{where}.{name}"),
            stateful=bool(section.get("stateful", True)),
        )
        cu.extend(f"{name}.{k}" for k in section)
    progress_name = str(cs.get("progress_checker_plugin", "progress_checker"))
    progress = _sub(cs, progress_name)
    cu.extend(f"{progress_name}.{k}" for k in progress)
    cu += ["controller_frequency", "failure_tolerance", "controller_plugins", "goal_checker_plugins"]
    cu += ["min_x_velocity_threshold", "min_theta_velocity_threshold"]
    cu += ["goal_checker_plugin", "progress_checker_plugin"]
    ps = params.node("planner_server")
    pwhere = f"{src}: planner_server"
    planner_names = _names(ps, "planner_plugins", ("GridBased",), pwhere)
    grid = _sub(ps, planner_names[0])
    plugin = str(grid.get("plugin", "nav2_navfn_planner/NavfnPlanner"))
    if plugin.replace("::", "/") != "nav2_navfn_planner/NavfnPlanner":
        msg = (
            f"{pwhere}.{planner_names[0]}.plugin: unknown planner plugin {plugin!r}; "
            "the twin has nav2_navfn_planner/NavfnPlanner"
        )
        raise ConfigError(msg)
    planner = NavfnParams(
        tolerance_m=_num(grid, "tolerance", 0.5, f"{pwhere}.{planner_names[0]}"),
        use_astar=bool(grid.get("use_astar", False)),
        allow_unknown=bool(grid.get("allow_unknown", True)),
    )
    used["planner_server"] = ["planner_plugins", *(f"{planner_names[0]}.{k}" for k in grid)]
    bt = params.node("bt_navigator")
    loop_ms = _num(bt, "bt_loop_duration", 10.0, f"{src}: bt_navigator")
    used["bt_navigator"] = ["bt_loop_duration", "global_frame", "robot_base_frame", "odom_topic"]
    vs = params.node("velocity_smoother")
    vwhere = f"{src}: velocity_smoother"
    if str(vs.get("feedback", "OPEN_LOOP")) != "OPEN_LOOP":
        msg = f"{vwhere}.feedback: only OPEN_LOOP (Nav2's default) is implemented, got {vs['feedback']!r}"
        raise ConfigError(msg)
    defaults = SmootherParams()
    smoother = SmootherParams(
        smoothing_frequency_hz=_num(vs, "smoothing_frequency", defaults.smoothing_frequency_hz, vwhere),
        max_velocity=_triple(vs, "max_velocity", defaults.max_velocity, vwhere),
        min_velocity=_triple(vs, "min_velocity", defaults.min_velocity, vwhere),
        max_accel=_triple(vs, "max_accel", defaults.max_accel, vwhere),
        max_decel=_triple(vs, "max_decel", defaults.max_decel, vwhere),
        deadband_velocity=_triple(vs, "deadband_velocity", defaults.deadband_velocity, vwhere),
        velocity_timeout_s=_num(vs, "velocity_timeout", defaults.velocity_timeout_s, vwhere),
        scale_velocities=_flag(vs, "scale_velocities", defaults.scale_velocities, vwhere),
    )
    used["velocity_smoother"] = [
        "smoothing_frequency", "max_velocity", "min_velocity", "max_accel", "max_decel",
        "deadband_velocity", "velocity_timeout", "feedback", "scale_velocities",
    ]  # fmt: skip
    bs = params.node("behavior_server")
    bwhere = f"{src}: behavior_server"
    bd = BehaviorParams()
    behaviors = BehaviorParams(
        cycle_frequency_hz=_num(bs, "cycle_frequency", bd.cycle_frequency_hz, bwhere),
        simulate_ahead_time_s=_num(bs, "simulate_ahead_time", bd.simulate_ahead_time_s, bwhere),
        max_rotational_vel=_num(bs, "max_rotational_vel", bd.max_rotational_vel, bwhere),
        min_rotational_vel=_num(bs, "min_rotational_vel", bd.min_rotational_vel, bwhere),
        rotational_acc_lim=_num(bs, "rotational_acc_lim", bd.rotational_acc_lim, bwhere),
    )
    used["behavior_server"] = [
        "cycle_frequency", "simulate_ahead_time", "max_rotational_vel", "min_rotational_vel", "rotational_acc_lim",
    ]  # fmt: skip
    return Nav2Config(
        controller_frequency_hz=frequency,
        failure_tolerance_s=_num(cs, "failure_tolerance", 0.0, where),
        velocity_thresholds=(
            _num(cs, "min_x_velocity_threshold", 0.0001, where),
            _num(cs, "min_theta_velocity_threshold", 0.0001, where),
        ),
        controllers=controllers,
        goal_checkers=checkers,
        progress_radius_m=_num(progress, "required_movement_radius", 0.5, f"{where}.{progress_name}"),
        progress_allowance_s=_num(progress, "movement_time_allowance", 10.0, f"{where}.{progress_name}"),
        planner=planner,
        behaviors=behaviors,
        smoother=smoother,
        bt_loop_duration_s=loop_ms / 1000.0,
        used={k: tuple(v) for k, v in used.items()},
    )


# --- path smoothing (smoother_server's SimpleSmoother) -------------------------------------------


def smooth_path(
    path: F64, *, w_data: float = 0.2, w_smooth: float = 0.3, tolerance: float = 1e-10, max_its: int = 1000
) -> F64:
    """Nav2's SimpleSmoother: pull interior points towards their neighbours and their original place.

    The end points stay; orientations of the interior poses follow the smoothed segments.
    """
    poses = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    if len(poses) < 3:
        return poses.copy()
    orig = poses[:, :2].copy()
    new = orig.copy()
    for _ in range(max_its):
        change = 0.0
        for i in range(1, len(new) - 1):  # Gauss-Seidel, point by point, as the smoother iterates
            before = new[i].copy()
            new[i] += w_data * (orig[i] - new[i]) + w_smooth * (new[i - 1] + new[i + 1] - 2.0 * new[i])
            change += float(np.abs(new[i] - before).sum())
        if change < tolerance:
            break
    out = poses.copy()
    out[:, :2] = new
    d = np.diff(new, axis=0)
    out[1:-1, 2] = np.arctan2(d[:-1, 1] + d[1:, 1], d[:-1, 0] + d[1:, 0])
    return out


# --- the servers ---------------------------------------------------------------------------------


@dataclass(slots=True)
class _Goal:
    server: str
    request: dict[str, Any]
    state: ActionState = ActionState.RUNNING
    result: dict[str, Any] = field(default_factory=dict)
    reason: str = ""


class Nav2Servers:
    """planner_server, controller_server, smoother_server, behavior_server and the costmaps' services.

    Args:
        config: The servers' parameters.
        frames: The shared transforms (robot pose in odom and map).
        global_costmap: The planner's costmap (map frame).
        local_costmap: The controller's and behaviours' costmap (odom frame, rolling).
        now: The simulation clock, ns.
    """

    def __init__(
        self,
        config: Nav2Config,
        frames: Frames,
        global_costmap: Costmap,
        local_costmap: Costmap,
        *,
        now: Callable[[], int],
        native: bool = True,
    ) -> None:
        self.config = config
        self.frames = frames
        self.global_costmap = global_costmap
        self.local_costmap = local_costmap
        self.now = now
        self.planner = NavfnPlanner(config.planner, native=native)
        self.controllers: dict[str, Controller] = {}
        self._tasks: dict[str, FollowPathTask] = {}
        for name, (plugin, section) in config.controllers.items():
            controller = controller_for_plugin(
                plugin,
                section,
                where=f"controller_server.{name}",
                controller_frequency_hz=config.controller_frequency_hz,
            )
            self.controllers[name] = controller
            checker = next(iter(config.goal_checkers.values()), SimpleGoalChecker())
            progress = SimpleProgressChecker(
                required_movement_radius_m=config.progress_radius_m,
                movement_time_allowance_s=config.progress_allowance_s,
            )
            self._tasks[name] = FollowPathTask(
                controller,
                checker,
                progress,
                failure_tolerance_s=config.failure_tolerance_s,
                velocity_thresholds=config.velocity_thresholds,
            )
        self._goals: dict[int, _Goal] = {}
        self._next_id = 0
        self._follow: int | None = None
        self._follow_task: FollowPathTask | None = None
        self._behavior: int | None = None
        self._behavior_impl: Any = None
        self.recoveries = 0
        self._generation = 0
        #: Called with (t_ns, path) for every computed path (planner_server publishes `/plan`).
        self.on_plan: Callable[[int, F64], None] | None = None
        #: The last failure any server reported (the navigator's failure reason).
        self.last_error = ""

    # -- NavigationServices ---------------------------------------------------------------------

    @property
    def generation(self) -> int:
        """Changes whenever a goal is sent, updated, canceled or finished (what a leaf's poll can see)."""
        return self._generation

    def send_goal(self, server: str, request: Mapping[str, Any]) -> int:
        """Accept a goal on an action server (see `twin.nav.bt_leaves.NavigationServices`)."""
        self._generation += 1
        self._next_id += 1
        goal = _Goal(server=server, request=dict(request))
        self._goals[self._next_id] = goal
        if len(self._goals) > 64:  # finished goals are kept only for the leaves' polls
            for gid in [g for g, v in self._goals.items() if v.state is not ActionState.RUNNING][:32]:
                del self._goals[gid]
        gid = self._next_id
        t_ns = self.now()
        if server == "compute_path_to_pose":
            self._plan(goal, [request["goal"]], request.get("start"), t_ns)
        elif server == "compute_path_through_poses":
            self._plan(goal, list(request.get("goals") or []), request.get("start"), t_ns)
        elif server == "smooth_path":
            path = np.asarray(request["path"], dtype=np.float64).reshape(-1, 3)
            self._finish(
                goal, ActionState.SUCCEEDED, path=smooth_path(path), smoothing_duration=0.0, was_completed=True
            )
        elif server == "follow_path":
            self._start_follow(gid, goal, t_ns)
        elif server in _BEHAVIORS:
            self._start_behavior(gid, goal, t_ns)
        else:
            self._finish(goal, ActionState.FAILED, reason=f"the twin has no {server!r} action server")
        return gid

    def update_goal(self, goal_id: int, request: Mapping[str, Any]) -> None:
        """A new path for a running FollowPath goal (Nav2 preempts it with the new path)."""
        goal = self._goals.get(goal_id)
        if goal is None or goal.state is not ActionState.RUNNING:
            return
        self._generation += 1
        goal.request = dict(request)
        if goal_id == self._follow and self._follow_task is not None:
            self._follow_task.update_plan(np.asarray(request["path"], dtype=np.float64))

    def poll(self, goal_id: int) -> ActionUpdate:
        """The goal's state."""
        goal = self._goals.get(goal_id)
        if goal is None:
            return ActionUpdate(state=ActionState.FAILED)
        return ActionUpdate(state=goal.state, result=goal.result)

    def cancel(self, goal_id: int) -> None:
        """Cancel a goal (a halted leaf)."""
        goal = self._goals.get(goal_id)
        if goal is None or goal.state is not ActionState.RUNNING:
            return
        self._generation += 1
        goal.state = ActionState.FAILED
        goal.reason = "canceled"
        if goal_id == self._follow:
            self._follow = None
            self._stop_follow = True
        if goal_id == self._behavior:
            self._behavior = None

    def cancel_all(self, server: str) -> None:
        """Cancel every running goal on a server."""
        for gid, goal in list(self._goals.items()):
            if goal.server == server:
                self.cancel(gid)

    def call_service(self, service: str, request: Mapping[str, Any]) -> bool:
        """Costmap clearing services; `reinitialize_global_localization` is not offered."""
        kind = str(request.get("kind", "clear_entirely"))
        targets = [c for key, c in (("global", self.global_costmap), ("local", self.local_costmap)) if key in service]
        if not targets:
            _log.warning("no service %r in the twin (costmap clearing services only)", service)
            return False
        for costmap in targets:
            if kind == "clear_entirely":
                costmap.clear_entirely()
                continue
            distance = request.get("reset_distance")
            distance = 1.0 if distance is None else float(distance)
            x, y, _ = self.frames.map_pose() if costmap is self.global_costmap else self.frames.odom_pose
            if kind == "clear_around_robot":
                costmap.clear_around_robot(x, y, distance)
            else:
                costmap.clear_except_region(x, y, distance)
        for costmap in targets:  # the master grid again from the layers kept (the static map), at once
            x, y, yaw = self.frames.map_pose() if costmap is self.global_costmap else self.frames.odom_pose
            costmap.update(x, y, yaw, ())
        return True

    def robot_pose(self) -> Pose:
        """The robot's map pose."""
        return self.frames.map_pose()

    def robot_speed(self) -> float:
        """The odometry's linear speed."""
        return abs(self.frames.velocity[0])

    def is_path_valid(self, path: np.ndarray) -> bool:
        """planner_server's is_path_valid: no lethal or inscribed cell under the path (Humble)."""
        grid = self.global_costmap.grid
        p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
        col = np.floor((p[:, 0] - grid.origin_x_m) / grid.resolution_m).astype(np.int64)
        row = np.floor((p[:, 1] - grid.origin_y_m) / grid.resolution_m).astype(np.int64)
        rows, cols = grid.cost.shape
        inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        cost = grid.cost[row[inside], col[inside]]
        return not bool(((cost == 253) | (cost == 254)).any())

    def selection(self, topic: str) -> str | None:
        """Nothing publishes on the selector topics in the twin: the selectors keep their defaults."""
        return None

    def updated_goal(self) -> Pose | None:
        """Nothing publishes on `goal_update` in the twin."""
        return None

    def is_stuck(self) -> bool:
        """Nav2's IsStuck: the odometry decelerates harder than the brake limit."""
        v, _ = self.frames.velocity
        pv, _, pt = self.frames.prev_velocity
        dt = (self.frames.odom_stamp_ns - pt) / 1e9
        return pt >= 0 and dt > 0 and (v - pv) / dt < _BRAKE_ACCEL_LIMIT

    # -- planner_server -------------------------------------------------------------------------

    def _plan(self, goal: _Goal, targets: list[Any], start: Any, t_ns: int) -> None:
        if not targets:
            self._finish(goal, ActionState.FAILED, reason="no goal poses to plan through")
            return
        here = self.frames.map_pose() if start is None else tuple(float(v) for v in start)
        pieces: list[F64] = []
        grid = self.global_costmap.grid
        for target in targets:
            end = (float(target[0]), float(target[1]), float(target[2]))
            result = self.planner.make_plan(grid, here, end)  # type: ignore[arg-type]
            if isinstance(result, PlanFailure):
                _log.warning("GridBased: failed to create plan: %s", result.message)
                self._finish(goal, ActionState.FAILED, reason=f"planner: {result.message}")
                return
            pieces.append(result.poses if not pieces else result.poses[1:])
            here = end
        path = np.concatenate(pieces) if len(pieces) > 1 else pieces[0]
        if self.on_plan is not None:
            self.on_plan(t_ns, path)
        self._finish(goal, ActionState.SUCCEEDED, path=path)

    # -- controller_server ----------------------------------------------------------------------

    _stop_follow = False

    def _start_follow(self, gid: int, goal: _Goal, t_ns: int) -> None:
        name = str(goal.request.get("controller_id") or "") or next(iter(self._tasks), "")
        task = self._tasks.get(name)
        if task is None:
            self._finish(
                goal, ActionState.FAILED, reason=f"FollowPath: no controller {name!r} (have {sorted(self._tasks)})"
            )
            return
        checker_id = str(goal.request.get("goal_checker_id") or "")
        if checker_id and checker_id in self.config.goal_checkers:
            task.goal_checker = self.config.goal_checkers[checker_id]
        if self._follow is not None and self._follow_task is task:
            previous = self._goals.get(self._follow)
            if previous is not None and previous.state is ActionState.RUNNING:
                previous.state = ActionState.FAILED
                previous.reason = "preempted"
            self._follow = gid
            task.update_plan(np.asarray(goal.request["path"], dtype=np.float64))
            return
        self._follow, self._follow_task = gid, task
        task.start(np.asarray(goal.request["path"], dtype=np.float64), t_ns)

    def controller_cycle(self, t_ns: int) -> tuple[float, float] | None:
        """One controller_server cycle: the command for `cmd_vel_nav` (None when idle)."""
        if self._follow is None or self._follow_task is None:
            if self._stop_follow:
                self._stop_follow = False
                return (0.0, 0.0)
            return None
        goal = self._goals[self._follow]
        task = self._follow_task
        plan_to_odom = invert(self.frames.map_odom)
        step = task.step(
            t_ns, self.frames.odom_pose, self.frames.velocity, self.local_costmap.grid, plan_to_costmap=plan_to_odom
        )
        if step.status is FollowStatus.RUNNING:
            return step.cmd
        if step.status is FollowStatus.SUCCEEDED:
            self._finish(goal, ActionState.SUCCEEDED)
        else:
            _log.warning("FollowPath failed: %s", step.reason)
            self._finish(goal, ActionState.FAILED, reason=step.reason)
        self._follow = None
        return (0.0, 0.0)

    @property
    def local_plan(self) -> F64 | None:
        """The active controller's local plan (odom frame) while following."""
        if self._follow is None or self._follow_task is None:
            return None
        return self._follow_task.controller.local_plan

    # -- behavior_server ------------------------------------------------------------------------

    def _start_behavior(self, gid: int, goal: _Goal, t_ns: int) -> None:
        if self._behavior is not None:
            self.cancel(self._behavior)
        request = dict(goal.request)
        if goal.server == "wait" and "time_s" not in request:
            request["time_s"] = request.get("wait_duration", 1.0)
        # the behaviours check the local costmap's footprint, as behavior_server reads it from that costmap
        params = dataclasses.replace(self.config.behaviors, footprint=tuple(self.local_costmap.footprint))
        behavior = make_behavior(goal.server, params)
        behavior.start(request, self.frames.odom_pose, t_ns)
        self._behavior, self._behavior_impl = gid, behavior
        self.recoveries += 1
        _log.info("Running %s", goal.server)

    def behavior_cycle(self, t_ns: int) -> tuple[float, float] | None:
        """One behavior_server cycle: the command for `/cmd_vel` (None when idle or waiting)."""
        if self._behavior is None:
            return None
        goal = self._goals[self._behavior]
        step = self._behavior_impl.step(t_ns, self.frames.odom_pose, self.local_costmap.grid)
        if step.status is BehaviorStatus.RUNNING:
            return None if goal.server == "wait" else step.cmd
        if step.status is BehaviorStatus.SUCCEEDED:
            self._finish(goal, ActionState.SUCCEEDED)
        else:
            _log.warning("%s failed: %s", goal.server, step.reason)
            self._finish(goal, ActionState.FAILED, reason=step.reason)
        self._behavior = None
        return None if goal.server == "wait" else (0.0, 0.0)

    def _finish(self, goal: _Goal, state: ActionState, *, reason: str = "", **result: Any) -> None:
        self._generation += 1
        goal.state = state
        goal.result = result
        goal.reason = reason
        if reason:
            self.last_error = f"{goal.server}: {reason}"


# --- bt_navigator ---------------------------------------------------------------------------------


class BtNavigator:
    """NavigateToPose: runs a Nav2 behaviour-tree XML for each goal, one tick per `bt_loop_duration`.

    Raises:
        TreeError: If the XML cannot be loaded with Nav2's nodes (a leaf the twin lacks is named).
    """

    def __init__(self, servers: Nav2Servers, bt_xml: Path, *, now: Callable[[], int]) -> None:
        self.servers = servers
        self.bt_xml = bt_xml
        factory = nav2_factory(servers)
        self.tree = factory.create_tree_from_file(bt_xml, clock=now)
        self.changes = StatusChangeBuffer()
        self.tree.add_listener(self.changes)
        self.now = now
        self._status: dict[int, NavigationStatus] = {}
        self._reasons: dict[int, str] = {}
        self._goal_id = 0
        self.active = False
        self.goal: Pose = (0.0, 0.0, 0.0)
        self.started_ns = 0
        self.recoveries_at_start = 0
        self._path_seen: Any = None
        self._path_xy: F64 = np.zeros((0, 2))
        self._path_left: F64 = np.zeros(0)

    def navigate(self, pose: Pose) -> int:
        """Accept a NavigateToPose goal; a running goal is preempted (the tree sees the new goal).

        As Nav2's bt_navigator, a goal sent before the robot's pose in the map is known (AMCL without
        an initial pose yet) is rejected: it fails at once.
        """
        if not self.servers.frames.localized:
            self._goal_id += 1
            self._status[self._goal_id] = NavigationStatus.FAILED
            self._reasons[self._goal_id] = "Initial robot pose is not available (AMCL has no initial pose yet)"
            _log.warning("NavigateToPose goal rejected: the robot's pose in map is not available yet")
            return self._goal_id
        if self.active:
            self._status[self._goal_id] = NavigationStatus.FAILED
            self._reasons[self._goal_id] = "preempted by a new goal"
        self._goal_id += 1
        self.goal = pose
        bb = self.tree.root_blackboard
        bb.set("goal", pose)
        bb.set("goals", [pose])
        bb.set("initial_pose_received", self.servers.frames.localized)
        if not self.active:
            self.started_ns = self.now()
            self.recoveries_at_start = self.servers.recoveries
            self.servers.last_error = ""
        self.active = True
        self._status[self._goal_id] = NavigationStatus.RUNNING
        _log.info("Begin navigating from current location to (%.2f, %.2f)", pose[0], pose[1])
        return self._goal_id

    def status(self, goal_id: int) -> NavigationStatus:
        """The state of a NavigateToPose goal."""
        return self._status.get(goal_id, NavigationStatus.FAILED)

    def reason(self, goal_id: int) -> str:
        """Why a goal failed."""
        return self._reasons.get(goal_id, "")

    def tick(self) -> bool:
        """One bt_navigator loop iteration (only while a goal runs); True while the goal still runs."""
        if not self.active:
            return False
        servers = self.servers
        status = self.tree.tick_unless_settled(lambda: servers.generation)
        if status is None or status is NodeStatus.RUNNING:  # None: the tick would have repeated the last one
            return True
        self.tree.halt_tree()
        self.active = False
        if status is NodeStatus.SUCCESS:
            self._status[self._goal_id] = NavigationStatus.SUCCEEDED
            _log.info("Goal succeeded")
        else:
            self._status[self._goal_id] = NavigationStatus.FAILED
            reason = self.servers.last_error or "the navigation tree failed"
            self._reasons[self._goal_id] = reason
            _log.warning("Goal failed: %s", reason)
        return False

    def distance_remaining(self, pose: Pose) -> float:
        """Along the current path from the pose nearest the robot to its end (Nav2's feedback)."""
        entry = self.tree.root_blackboard.get_entry("path")
        path = entry.value if entry is not None else None
        if path is None:
            return math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1])
        if path is not self._path_seen:  # each plan is a new array: its lengths once
            p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
            seg = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
            self._path_seen, self._path_xy = path, p[:, :2]
            self._path_left = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]]) if len(p) else np.zeros(0)
        if len(self._path_xy) == 0:
            return 0.0
        d = self._path_xy - (pose[0], pose[1])
        i = int(np.argmin(np.einsum("ij,ij->i", d, d)))
        return float(self._path_left[i])


class Nav2Navigator:
    """The mission's navigator: `GoToPose` sends NavigateToPose goals to the bt_navigator."""

    plans = 0
    path: Sequence[tuple[float, float]] = ()

    def __init__(self, navigator: Callable[[], BtNavigator | None]) -> None:
        self._navigator = navigator

    def _nav(self) -> BtNavigator:
        nav = self._navigator()
        if nav is None:
            msg = "the mission sent a goal before bt_navigator was started"
            raise RuntimeError(msg)
        return nav

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        """Send a NavigateToPose goal (map frame)."""
        return self._nav().navigate((pose.x_m, pose.y_m, pose.yaw_rad))

    def goal_status(self, goal_id: int) -> NavigationStatus:
        """The goal's state."""
        return self._nav().status(goal_id)

    def failure_reason(self, goal_id: int) -> str:
        """Why the goal failed."""
        return self._nav().reason(goal_id)

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Nav2 commands the robot itself; the mission publishes nothing."""
        return (0.0, 0.0)


# --- the nodes ------------------------------------------------------------------------------------


def _twist(pub: Any, encode: Callable[..., bytes], cmd: tuple[float, float]) -> None:
    pub.publish(Encoded((encode, cmd, cmd)))


class PlannerServerNode(Node):
    """planner_server: publishes `/plan` for each path it computes."""

    def __init__(self, servers: Nav2Servers) -> None:
        super().__init__("planner_server")
        pub = self.create_publisher(PathEncoder.msgtype, "plan", 10)
        encode = PathEncoder("map").encode

        def on_plan(t_ns: int, path: F64) -> None:
            pub.publish(Encoded((encode, (t_ns, path), path)))

        servers.on_plan = on_plan


class ControllerServerNode(Node):
    """controller_server: one cycle per `controller_frequency`; `cmd_vel_nav` and `/local_plan`."""

    def __init__(self, servers: Nav2Servers) -> None:
        super().__init__("controller_server")
        cmd_pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel_nav", 10)
        plan_pub = self.create_publisher(PathEncoder.msgtype, "local_plan", 10)
        encode = TwistEncoder().encode
        plan_encode = PathEncoder("odom").encode
        cycle = servers.controller_cycle

        def on_timer(t_ns: int) -> None:
            cmd = cycle(t_ns)
            if cmd is None:
                return
            _twist(cmd_pub, encode, cmd)
            local = servers.local_plan
            if local is not None and len(local):
                plan_pub.publish(Encoded((plan_encode, (t_ns, local), local)))

        self.create_rate_timer(servers.config.controller_frequency_hz, on_timer, priority=PRIORITY_COMMAND)


class VelocitySmootherNode(Node):
    """velocity_smoother: `cmd_vel_nav` in, `/cmd_vel` out at its smoothing frequency (open loop)."""

    def __init__(self, params: SmootherParams) -> None:
        super().__init__("velocity_smoother")
        smoother = VelocitySmoother(params)
        pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode
        now = self._graph_now

        def on_cmd(msg: Any) -> None:
            if type(msg) is Encoded:
                v, w = msg[2]
            else:
                v, w = float(msg.linear.x), float(msg.angular.z)
            smoother.command(v, w, now())

        def on_timer(t_ns: int) -> None:
            out = smoother.step(t_ns)
            if out is not None:
                _twist(pub, encode, out)

        self.create_subscription("geometry_msgs/msg/Twist", "cmd_vel_nav", on_cmd, 10, raw=True)
        self.create_rate_timer(params.smoothing_frequency_hz, on_timer, priority=PRIORITY_COMMAND + 1)


class BehaviorServerNode(Node):
    """behavior_server: Spin, BackUp, DriveOnHeading and Wait, one cycle per `cycle_frequency`, on `/cmd_vel`.

    Humble's bringup does not remap the behaviours' `cmd_vel`: their commands reach the drive
    unsmoothed, beside the velocity smoother's.
    """

    def __init__(self, servers: Nav2Servers) -> None:
        super().__init__("behavior_server")
        pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode
        cycle = servers.behavior_cycle

        def on_timer(t_ns: int) -> None:
            cmd = cycle(t_ns)
            if cmd is not None:
                _twist(pub, encode, cmd)

        self.create_rate_timer(servers.config.behaviors.cycle_frequency_hz, on_timer, priority=PRIORITY_COMMAND)


class BtNavigatorNode(Node):
    """bt_navigator: ticks the navigation tree every bt_loop_duration while a goal runs."""

    FEEDBACK_TOPIC = "navigate_to_pose/feedback"

    def __init__(self, navigator: BtNavigator, frames: Frames) -> None:
        super().__init__("bt_navigator")
        log_pub = self.create_publisher(BehaviorTreeLogEncoder.msgtype, "behavior_tree_log", 10)
        log_encode = BehaviorTreeLogEncoder().encode
        feedback_pub = self.create_publisher(NavigationFeedbackEncoder.msgtype, self.FEEDBACK_TOPIC, 10)
        feedback_encode = NavigationFeedbackEncoder().encode
        tree = navigator.tree
        changes = navigator.changes
        loops = [0]
        period = max(1, round(0.1 / max(navigator.servers.config.bt_loop_duration_s, 1e-3)))

        def on_timer(t_ns: int) -> None:
            if not navigator.active:
                return
            running = navigator.tick()
            flushed = changes.flush()
            if flushed:
                events = [(c.t_ns, tree.node_by_uid(c.uid).name, c.prev.name, c.new.name) for c in flushed]
                log_pub.publish(Encoded((log_encode, (t_ns, events), events)))
            loops[0] += 1
            if running and loops[0] % period == 0:
                args = self._feedback(navigator, frames, t_ns)
                feedback_pub.publish(Encoded((feedback_encode, args, args)))

        rate = 1.0 / navigator.servers.config.bt_loop_duration_s
        self.create_rate_timer(rate, on_timer, priority=PRIORITY_TREE + 1)

    @staticmethod
    def _feedback(navigator: BtNavigator, frames: Frames, t_ns: int) -> tuple[Any, ...]:
        """NavigateToPose's feedback now, as NavigationFeedbackEncoder.encode takes it."""
        pose = frames.map_pose()
        remaining = navigator.distance_remaining(pose)
        speed = abs(frames.velocity[0])
        eta_ns = round(remaining / speed * 1e9) if speed > 0.01 else 0
        recoveries = navigator.servers.recoveries - navigator.recoveries_at_start
        return (t_ns, pose, (max(0, t_ns - navigator.started_ns), eta_ns), recoveries, remaining)
