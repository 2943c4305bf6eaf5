"""controller_server's loop around one controller plugin: goal checker, progress checker, failure tolerance.

`FollowPathTask.step` is one cycle of Nav2 Humble's `computeControl` (10 Hz for TB3): check
progress (fail "Failed to make progress" after `movement_time_allowance_s` without leaving a
`required_movement_radius_m` circle), ask the controller for a velocity (a controller failure is
tolerated for `failure_tolerance_s` with a zero command, then the task fails), and succeed with a
zero command once the goal checker says the goal is reached.

`controller_for_plugin` picks the controller by the params file's plugin name. `ControllerServer`
is the server: one `FollowPathTask` per controller plugin, a FollowPath goal advanced one cycle per
`controller_frequency` tick; `ControllerServerNode` publishes its commands on `cmd_vel_nav` and the
active controller's local plan on `/local_plan` (odom).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.bag import PathEncoder, TwistEncoder
from twin.core.errors import ConfigError
from twin.nav.actions import ActionGoal, ActionState
from twin.nav.controller.checkers import PoseProgressChecker, SimpleGoalChecker, SimpleProgressChecker
from twin.nav.costmap_2d.costmap_2d import CostGrid
from twin.nav.costmap_2d.layered_costmap import Costmap
from twin.nav.frames import Frames, invert
from twin.node import PRIORITY_COMMAND, Encoded, Node, node_logger

__all__ = [
    "CONTROLLER_PLUGINS",
    "Controller",
    "ControllerServer",
    "ControllerServerNode",
    "FollowPathTask",
    "FollowStatus",
    "FollowStep",
    "controller_for_plugin",
]


F64 = NDArray[np.float64]
Finish = Callable[..., None]


class Controller(Protocol):
    """A local planner plugin (DWB, RPP): a plan in, a velocity per cycle out."""

    local_plan: NDArray[np.float64]

    def set_plan(self, plan: NDArray[np.float64]) -> None:
        """Take a new global plan (N, 3)."""

    def compute_velocity(
        self, pose: tuple[float, float, float], velocity: tuple[float, float], costmap: CostGrid
    ) -> tuple[float, float]:
        """Return (vx, wz); raise RuntimeError when no command is possible."""


class FollowStatus(enum.Enum):
    """The FollowPath action's state after a cycle."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True, kw_only=True, slots=True)
class FollowStep:
    """One cycle's outcome: status, the command to publish on cmd_vel_nav, and a failure reason."""

    status: FollowStatus
    cmd: tuple[float, float]
    reason: str = ""


class FollowPathTask:
    """One FollowPath goal on controller_server: `start`, `update_plan` (a replanned path), `step` per cycle.

    Args:
        controller: The controller plugin.
        goal_checker: The goal checker (reset on `start`).
        progress_checker: The progress checker (reset on `start`).
        failure_tolerance_s: How long controller failures are tolerated with zero commands (TB3: 0.3).
        velocity_thresholds: controller_server's `min_x_velocity_threshold` and
            `min_theta_velocity_threshold`: odometry speeds below them count as 0.
    """

    def __init__(
        self,
        controller: Controller,
        goal_checker: SimpleGoalChecker | None = None,
        progress_checker: SimpleProgressChecker | None = None,
        *,
        failure_tolerance_s: float = 0.3,
        velocity_thresholds: tuple[float, float] = (0.0001, 0.0001),
    ) -> None:
        self.controller = controller
        self.min_x_velocity_threshold, self.min_theta_velocity_threshold = velocity_thresholds
        self.goal_checker = goal_checker or SimpleGoalChecker()
        self.progress_checker = progress_checker or SimpleProgressChecker()
        self.failure_tolerance_s = failure_tolerance_s
        self._goal: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._last_valid_ns = 0

    def start(self, plan: NDArray[np.float64], t_ns: int) -> None:
        """Begin following a plan (N, 3; its last pose is the goal)."""
        self.goal_checker.reset()
        self.progress_checker.reset()
        self._last_valid_ns = t_ns
        self.update_plan(plan)

    def update_plan(self, plan: NDArray[np.float64]) -> None:
        """Replace the plan (a new path while the action runs).

        The goal checker starts over, as Humble's `setPlannerPath` resets it, and the controller takes
        the plan (DWB resets its critics).
        """
        plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)
        self._goal = (float(plan[-1, 0]), float(plan[-1, 1]), float(plan[-1, 2]))
        self.goal_checker.reset()
        self.controller.set_plan(plan)

    def step(
        self,
        t_ns: int,
        pose: tuple[float, float, float],
        velocity: tuple[float, float],
        costmap: CostGrid,
        *,
        plan_to_costmap: tuple[float, float, float] | None = None,
    ) -> FollowStep:
        """Run one controller cycle with the robot's pose (costmap frame) and odometry velocity.

        In Humble's order: the progress check, the controller's command (its failures tolerated for
        `failure_tolerance_s` with a zero command), then the goal check on the same pose; a reached goal
        ends the action with a zero command. The odometry's velocity is thresholded as controller_server's
        `getThresholdedTwist` does. `plan_to_costmap` is the plan frame's pose in the costmap frame (map
        in odom) when they differ: the controller moves the plan with it and the goal is checked in the
        costmap frame.
        """
        goal = self._goal
        if hasattr(self.controller, "goal_dist_tol_m"):  # RPP reads the goal checker's tolerance each cycle
            self.controller.goal_dist_tol_m = self.goal_checker.xy_goal_tolerance_m
        if plan_to_costmap is not None:
            if hasattr(self.controller, "plan_to_costmap"):
                self.controller.plan_to_costmap = plan_to_costmap
            tx, ty, tyaw = plan_to_costmap
            c, s = math.cos(tyaw), math.sin(tyaw)
            goal = (tx + c * goal[0] - s * goal[1], ty + s * goal[0] + c * goal[1], goal[2] + tyaw)
        if not self.progress_checker.check(pose, t_ns):
            return FollowStep(status=FollowStatus.FAILED, cmd=(0.0, 0.0), reason="Failed to make progress")
        vx = 0.0 if abs(velocity[0]) < self.min_x_velocity_threshold else velocity[0]
        wz = 0.0 if abs(velocity[1]) < self.min_theta_velocity_threshold else velocity[1]
        try:
            cmd = self.controller.compute_velocity(pose, (vx, wz), costmap)
        except RuntimeError as err:
            if t_ns - self._last_valid_ns > round(self.failure_tolerance_s * 1e9):
                return FollowStep(
                    status=FollowStatus.FAILED, cmd=(0.0, 0.0), reason=f"Controller patience exceeded: {err}"
                )
            cmd = (0.0, 0.0)
            reason = str(err)
        else:
            self._last_valid_ns = t_ns
            reason = ""
        if self.goal_checker.is_goal_reached(pose, goal, (vx, wz)):  # the thresholded odometry, as Humble's
            return FollowStep(status=FollowStatus.SUCCEEDED, cmd=(0.0, 0.0))
        return FollowStep(status=FollowStatus.RUNNING, cmd=cmd, reason=reason)


CONTROLLER_PLUGINS = (
    "dwb_core::DWBLocalPlanner",
    "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController",
)


def controller_for_plugin(
    plugin: str,
    section: Mapping[str, object],
    *,
    where: str = "controller_server",
    controller_frequency_hz: float = 20.0,
) -> Controller:
    """Build the controller a params file names by plugin (DWB or Regulated Pure Pursuit).

    Args:
        plugin: The `plugin:` value.
        section: The plugin's parameters (Nav2 names; unknown ones ignored as Nav2 does).
        where: File/key for the error message.
        controller_frequency_hz: controller_server's `controller_frequency`.

    Raises:
        ConfigError: If the plugin is not one the twin implements, or a parameter cannot be used.
    """
    if plugin == CONTROLLER_PLUGINS[0]:
        from twin.nav.controller.dwb.local_planner import DwbController, DwbParams

        params = DwbParams.from_nav2(section, controller_frequency_hz=controller_frequency_hz, where=where)
        return DwbController(params)
    if plugin == CONTROLLER_PLUGINS[1]:
        from twin.nav.controller.regulated_pure_pursuit import RppController, RppParams

        rpp = RppParams.from_nav2(section, controller_frequency_hz=controller_frequency_hz, where=where)
        return RppController(rpp)
    msg = f"{where}.plugin: unknown controller plugin {plugin!r}; the twin has {', '.join(CONTROLLER_PLUGINS)}"
    raise ConfigError(msg)


class ControllerServer:
    """controller_server: FollowPath goals on the controllers a params file names, one cycle per tick.

    Args:
        controllers: Name → (plugin, parameters) as the params file gives them.
        goal_checkers: Name → goal checker; the first is every controller's default.
        frames: The shared transforms (the robot's pose and speed in odom, map→odom for the plan).
        local_costmap: The controller's costmap (odom frame, rolling).
        finish: Called as `finish(goal, state, reason=...)` when a goal ends.
        controller_frequency_hz: `controller_frequency`.
        failure_tolerance_s: `failure_tolerance`.
        velocity_thresholds: `min_x_velocity_threshold`, `min_theta_velocity_threshold`.
        progress_radius_m: The progress checker's `required_movement_radius`.
        progress_allowance_s: The progress checker's `movement_time_allowance`.
        progress_angle_rad: PoseProgressChecker's `required_movement_angle` (None: SimpleProgressChecker).
    """

    def __init__(
        self,
        controllers: Mapping[str, tuple[str, Mapping[str, object]]],
        goal_checkers: Mapping[str, SimpleGoalChecker],
        frames: Frames,
        local_costmap: Costmap,
        *,
        finish: Finish,
        controller_frequency_hz: float,
        failure_tolerance_s: float,
        velocity_thresholds: tuple[float, float],
        progress_radius_m: float,
        progress_allowance_s: float,
        progress_angle_rad: float | None = None,
    ) -> None:
        self._log = node_logger("controller_server")  # its node's lines: `[robot1.controller_server]` in a fleet
        self.frames = frames
        self.local_costmap = local_costmap
        self.goal_checkers = goal_checkers
        self.controller_frequency_hz = controller_frequency_hz
        self._finish = finish
        self.controllers: dict[str, Controller] = {}
        self._tasks: dict[str, FollowPathTask] = {}
        for name, (plugin, section) in controllers.items():
            controller = controller_for_plugin(
                plugin,
                section,
                where=f"controller_server.{name}",
                controller_frequency_hz=controller_frequency_hz,
            )
            self.controllers[name] = controller
            use_costmap = getattr(controller, "use_costmap", None)
            if use_costmap is not None:  # RPP checks the costmap's padded footprint and reads its radii
                use_costmap(
                    local_costmap.footprint,
                    local_costmap.inscribed_radius_m,
                    local_costmap.circumscribed_radius_m,
                    local_costmap.params.track_unknown_space,
                )
            checker = next(iter(goal_checkers.values()), SimpleGoalChecker())
            progress = (
                SimpleProgressChecker(
                    required_movement_radius_m=progress_radius_m, movement_time_allowance_s=progress_allowance_s
                )
                if progress_angle_rad is None
                else PoseProgressChecker(
                    required_movement_radius_m=progress_radius_m,
                    movement_time_allowance_s=progress_allowance_s,
                    required_movement_angle_rad=progress_angle_rad,
                )
            )
            self._tasks[name] = FollowPathTask(
                controller,
                checker,
                progress,
                failure_tolerance_s=failure_tolerance_s,
                velocity_thresholds=velocity_thresholds,
            )
        self._follow: ActionGoal | None = None
        self._follow_task: FollowPathTask | None = None
        self._stop_follow = False

    def start(self, goal: ActionGoal, t_ns: int) -> None:
        """Accept a FollowPath goal: a new path for the running controller preempts its goal."""
        name = str(goal.request.get("controller_id") or "") or next(iter(self._tasks), "")
        task = self._tasks.get(name)
        if task is None:
            self._finish(
                goal,
                ActionState.FAILED,
                reason=f"FollowPath: no controller {name!r} (have {sorted(self._tasks)})",
                error_code=101,  # INVALID_CONTROLLER
            )
            return
        checker_id = str(goal.request.get("goal_checker_id") or "")
        if checker_id and checker_id in self.goal_checkers:
            task.goal_checker = self.goal_checkers[checker_id]
        if self._follow is not None and self._follow_task is task:
            previous = self._follow
            if previous.state is ActionState.RUNNING:
                previous.state = ActionState.FAILED
                previous.reason = "preempted"
            self._follow = goal
            task.update_plan(np.asarray(goal.request["path"], dtype=np.float64))
            return
        self._follow, self._follow_task = goal, task
        task.start(np.asarray(goal.request["path"], dtype=np.float64), t_ns)

    def update(self, goal: ActionGoal, path: Any) -> None:
        """A new path for the running goal (Nav2 preempts it with the new path)."""
        if goal is self._follow and self._follow_task is not None:
            self._follow_task.update_plan(np.asarray(path, dtype=np.float64))

    def cancel(self, goal: ActionGoal) -> None:
        """Stop following if `goal` is the running one (the next cycle publishes a zero command)."""
        if goal is self._follow:
            self._follow = None
            self._stop_follow = True

    def cycle(self, t_ns: int) -> tuple[float, float] | None:
        """One controller_server cycle: the command for `cmd_vel_nav` (None when idle)."""
        if self._follow is None or self._follow_task is None:
            if self._stop_follow:
                self._stop_follow = False
                return (0.0, 0.0)
            return None
        goal = self._follow
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
            self._log.warning("FollowPath failed: %s", step.reason)
            self._finish(goal, ActionState.FAILED, reason=step.reason, error_code=_follow_code(step.reason))
        self._follow = None
        return (0.0, 0.0)

    @property
    def local_plan(self) -> F64 | None:
        """The active controller's local plan (odom frame) while following."""
        if self._follow is None or self._follow_task is None:
            return None
        return self._follow_task.controller.local_plan


class _Servers(Protocol):
    @property
    def controller_server(self) -> ControllerServer: ...


class ControllerServerNode(Node):
    """controller_server: one cycle per `controller_frequency`; `cmd_vel_nav` and `/local_plan`."""

    def __init__(self, servers: _Servers) -> None:
        super().__init__("controller_server")
        server = servers.controller_server
        cmd_pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel_nav", 10)
        plan_pub = self.create_publisher(PathEncoder.msgtype, "local_plan", 10)
        encode = TwistEncoder().encode
        plan_encode = PathEncoder("odom").encode
        cycle = server.cycle

        def on_timer(t_ns: int) -> None:
            cmd = cycle(t_ns)
            if cmd is None:
                return
            cmd_pub.publish(Encoded((encode, cmd, cmd)))
            local = server.local_plan
            if local is not None and len(local):
                plan_pub.publish(Encoded((plan_encode, (t_ns, local), local)))

        self.create_rate_timer(server.controller_frequency_hz, on_timer, priority=PRIORITY_COMMAND)


def _follow_code(reason: str) -> int:
    """FollowPath's nav2_msgs error code (Iron on) for a failure the controller server reports."""
    if reason.startswith("Failed to make progress"):
        return 105  # FAILED_TO_MAKE_PROGRESS
    if reason.startswith("Controller patience exceeded"):
        return 104  # PATIENCE_EXCEEDED
    return 100  # UNKNOWN
