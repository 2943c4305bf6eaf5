"""nav2_controller's goal and progress checkers: SimpleGoalChecker and SimpleProgressChecker."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SimpleGoalChecker", "SimpleProgressChecker"]


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
