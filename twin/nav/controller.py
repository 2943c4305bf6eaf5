"""controller_server's loop around one controller plugin: goal checker, progress checker, failure tolerance.

`FollowPathTask.step` is one cycle of Nav2 Humble's `computeControl` (10 Hz for TB3): check
progress (fail "Failed to make progress" after `movement_time_allowance_s` without leaving a
`required_movement_radius_m` circle), ask the controller for a velocity (a controller failure is
tolerated for `failure_tolerance_s` with a zero command, then the task fails), and succeed with a
zero command once the goal checker says the goal is reached.

`controller_for_plugin` picks the controller by the params file's plugin name.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import ConfigError
from twin.nav.costmap_grid import CostGrid

__all__ = [
    "CONTROLLER_PLUGINS",
    "Controller",
    "FollowPathTask",
    "FollowStatus",
    "FollowStep",
    "SimpleGoalChecker",
    "SimpleProgressChecker",
    "controller_for_plugin",
]


class Controller(Protocol):
    """A local planner plugin (DWB, RPP): a plan in, a velocity per cycle out."""

    local_plan: NDArray[np.float64]

    def set_plan(self, plan: NDArray[np.float64]) -> None:
        """Take a new global plan (N, 3)."""

    def compute_velocity(
        self, pose: tuple[float, float, float], velocity: tuple[float, float], costmap: CostGrid
    ) -> tuple[float, float]:
        """Return (vx, wz); raise RuntimeError when no command is possible."""


@dataclass(slots=True)
class SimpleGoalChecker:
    """nav2_controller::SimpleGoalChecker: within `xy_goal_tolerance_m`, then (stateful: latched) the yaw."""

    xy_goal_tolerance_m: float = 0.25
    yaw_goal_tolerance_rad: float = 0.25
    stateful: bool = True
    _xy_reached: bool = False

    def reset(self) -> None:
        """Forget a latched position (a new goal)."""
        self._xy_reached = False

    def is_goal_reached(self, pose: tuple[float, float, float], goal: tuple[float, float, float]) -> bool:
        """True when the position (or a latched one) and the yaw are within tolerance."""
        if not (self.stateful and self._xy_reached):
            if math.hypot(pose[0] - goal[0], pose[1] - goal[1]) > self.xy_goal_tolerance_m:
                return False
            if self.stateful:
                self._xy_reached = True
        dyaw = (pose[2] - goal[2] + math.pi) % (2.0 * math.pi) - math.pi
        return abs(dyaw) <= self.yaw_goal_tolerance_rad


@dataclass(slots=True)
class SimpleProgressChecker:
    """nav2_controller::SimpleProgressChecker: the robot must leave a radius within a time allowance."""

    required_movement_radius_m: float = 0.5
    movement_time_allowance_s: float = 10.0
    _baseline: tuple[float, float] | None = None
    _baseline_ns: int = 0

    def reset(self) -> None:
        """Start over from the next pose checked."""
        self._baseline = None

    def check(self, pose: tuple[float, float, float], t_ns: int) -> bool:
        """False once the robot has stayed inside the radius longer than the allowance."""
        if self._baseline is None or math.hypot(pose[0] - self._baseline[0], pose[1] - self._baseline[1]) > (
            self.required_movement_radius_m
        ):
            self._baseline = (pose[0], pose[1])
            self._baseline_ns = t_ns
            return True
        return (t_ns - self._baseline_ns) <= round(self.movement_time_allowance_s * 1e9)


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
        if self.goal_checker.is_goal_reached(pose, goal):
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
        from twin.nav.dwb import DwbController, DwbParams

        params = DwbParams.from_nav2(section, controller_frequency_hz=controller_frequency_hz, where=where)
        return DwbController(params)
    if plugin == CONTROLLER_PLUGINS[1]:
        from twin.nav.rpp import RppController, RppParams

        return RppController(RppParams.from_nav2(dict(section)))
    msg = f"{where}.plugin: unknown controller plugin {plugin!r}; the twin has {', '.join(CONTROLLER_PLUGINS)}"
    raise ConfigError(msg)
