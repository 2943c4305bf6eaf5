"""The navigator behind `GoToPose`: plan on the grid, follow the plan, report success or failure.

It answers the behaviour tree's `Navigator` protocol (`send_goal`, `goal_status`) the way Nav2's
`NavigateToPose` action would: a goal is planned from where the robot is when the controller next
runs, followed with the path follower, and ends SUCCEEDED at the goal pose, or FAILED when no path
exists or the robot stops making progress (Nav2's SimpleProgressChecker: 0.5 m within 10 s). A new
goal replaces the current one; a halted `GoToPose` does not cancel, as in the thesis's node.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from twin.bt.mission_nodes import NavigationStatus, Pose2D
from twin.core.clock import s_to_ns
from twin.nav.follower import FollowerParams, PathFollower
from twin.nav.planner import GridPlanner

__all__ = ["GridNavigator", "ProgressParams"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True, slots=True)
class ProgressParams:
    """Nav2's SimpleProgressChecker: the robot must move this far within this time, or the goal fails."""

    required_movement_radius_m: float = 0.5
    movement_time_allowance_s: float = 10.0


class GridNavigator:
    """Plans and follows one goal at a time; call `command` at the controller rate."""

    def __init__(self, planner: GridPlanner, follower: FollowerParams, progress: ProgressParams) -> None:
        self._planner = planner
        self._follower = PathFollower(follower)
        self._progress = progress
        self._allowance_ns = s_to_ns(progress.movement_time_allowance_s)
        self._goal_id = 0
        self._goal: Pose2D | None = None
        self._planned = False
        self._status: dict[int, NavigationStatus] = {}
        self._reasons: dict[int, str] = {}
        self._anchor: tuple[float, float, int] | None = None
        self.path: list[tuple[float, float]] = []
        """The current plan's waypoints (for recording as /plan)."""
        self.plans = 0

    # -- the behaviour tree's side ---------------------------------------------------------------

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        """Accept a goal in `frame_id` (the map; the world frame here) and return its id."""
        if self._goal is not None and self._status.get(self._goal_id) is NavigationStatus.RUNNING:
            self._status[self._goal_id] = NavigationStatus.FAILED  # preempted, as an aborted action
            self._reasons[self._goal_id] = "preempted by a new goal"
        self._goal_id += 1
        self._goal = pose
        self._planned = False
        self._status[self._goal_id] = NavigationStatus.RUNNING
        _log.info("navigation goal %d: (%.3f, %.3f, %.3f) in %s", self._goal_id, *pose, frame_id)
        return self._goal_id

    def goal_status(self, goal_id: int) -> NavigationStatus:
        """Return how goal `goal_id` stands."""
        return self._status.get(goal_id, NavigationStatus.FAILED)

    def failure_reason(self, goal_id: int) -> str:
        """Why goal `goal_id` failed (empty if it did not, or is unknown)."""
        return self._reasons.get(goal_id, "")

    # -- the controller's side -------------------------------------------------------------------

    @property
    def active(self) -> bool:
        """True while a goal is being followed."""
        return self._goal is not None and self._status.get(self._goal_id) is NavigationStatus.RUNNING

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the velocity command at this pose (zero when there is no active goal)."""
        if not self.active:
            return (0.0, 0.0)
        goal = self._goal
        assert goal is not None
        if not self._planned:
            self._planned = True
            self.plans += 1
            path = self._planner.plan((x_m, y_m), (goal.x_m, goal.y_m))
            if path is None:
                _log.warning(
                    "navigation goal %d: no path from (%.2f, %.2f) to (%.2f, %.2f)",
                    self._goal_id,
                    x_m,
                    y_m,
                    goal.x_m,
                    goal.y_m,
                )
                reason = f"no path from ({x_m:.2f}, {y_m:.2f}) to ({goal.x_m:.2f}, {goal.y_m:.2f})"
                return self._end(NavigationStatus.FAILED, reason)
            self.path = [(x_m, y_m), *path]
            self._follower.set_path(path, goal.yaw_rad)
            self._anchor = (x_m, y_m, t_ns)
        v, w = self._follower.command(x_m, y_m, yaw_rad)
        if self._follower.done:
            _log.info("navigation goal %d: reached", self._goal_id)
            return self._end(NavigationStatus.SUCCEEDED)
        anchor = self._anchor
        assert anchor is not None
        if math.hypot(x_m - anchor[0], y_m - anchor[1]) >= self._progress.required_movement_radius_m:
            self._anchor = (x_m, y_m, t_ns)
        elif t_ns - anchor[2] > self._allowance_ns and self._follower.remaining > 0:
            _log.warning(
                "navigation goal %d: no progress in %.0f s; aborting",
                self._goal_id,
                self._progress.movement_time_allowance_s,
            )
            allowance = self._progress.movement_time_allowance_s
            return self._end(NavigationStatus.FAILED, f"no progress in {allowance:.0f} s (blocked?)")
        return (v, w)

    def _end(self, status: NavigationStatus, reason: str = "") -> tuple[float, float]:
        self._status[self._goal_id] = status
        if reason:
            self._reasons[self._goal_id] = reason
        self._goal = None
        return (0.0, 0.0)
