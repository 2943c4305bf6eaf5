"""nav2_controller's goal checkers (Simple, Stopped) and progress checkers (Simple, Pose), as in Humble."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "GOAL_CHECKER_PLUGINS",
    "PROGRESS_CHECKER_PLUGINS",
    "PoseProgressChecker",
    "SimpleGoalChecker",
    "SimpleProgressChecker",
    "StoppedGoalChecker",
]

GOAL_CHECKER_PLUGINS = ("nav2_controller::SimpleGoalChecker", "nav2_controller::StoppedGoalChecker")
PROGRESS_CHECKER_PLUGINS = ("nav2_controller::SimpleProgressChecker", "nav2_controller::PoseProgressChecker")


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

    def is_goal_reached(
        self,
        pose: tuple[float, float, float],
        goal: tuple[float, float, float],
        velocity: tuple[float, float] = (0.0, 0.0),
    ) -> bool:
        """True when the position (or a latched one) and the yaw are within tolerance (`velocity` unused)."""
        if not (self.stateful and self._xy_reached):
            if math.hypot(pose[0] - goal[0], pose[1] - goal[1]) > self.xy_goal_tolerance_m:
                return False
            if self.stateful:
                self._xy_reached = True
        dyaw = (pose[2] - goal[2] + math.pi) % (2.0 * math.pi) - math.pi
        return abs(dyaw) <= self.yaw_goal_tolerance_rad


@dataclass(slots=True)
class StoppedGoalChecker(SimpleGoalChecker):
    """nav2_controller::StoppedGoalChecker: SimpleGoalChecker's test, and the robot (nearly) stopped.

    `velocity` is the odometry's (v m/s, ω rad/s) as controller_server thresholds it.
    """

    trans_stopped_velocity_mps: float = 0.25
    rot_stopped_velocity_radps: float = 0.25

    def is_goal_reached(
        self,
        pose: tuple[float, float, float],
        goal: tuple[float, float, float],
        velocity: tuple[float, float] = (0.0, 0.0),
    ) -> bool:
        """True when SimpleGoalChecker's test holds (latching the position as it does) and the speeds are low."""
        if not SimpleGoalChecker.is_goal_reached(self, pose, goal, velocity):
            return False
        return abs(velocity[1]) <= self.rot_stopped_velocity_radps and abs(velocity[0]) <= (
            self.trans_stopped_velocity_mps
        )


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


@dataclass(slots=True)
class PoseProgressChecker(SimpleProgressChecker):
    """nav2_controller::PoseProgressChecker: progress is leaving the radius or turning past an angle."""

    required_movement_angle_rad: float = 0.5
    _baseline_yaw: float = 0.0

    def check(self, pose: tuple[float, float, float], t_ns: int) -> bool:
        """False once the robot has stayed inside the radius and the angle longer than the allowance."""
        turned = abs((pose[2] - self._baseline_yaw + math.pi) % (2.0 * math.pi) - math.pi)
        if (
            self._baseline is None
            or math.hypot(pose[0] - self._baseline[0], pose[1] - self._baseline[1]) > self.required_movement_radius_m
            or turned > self.required_movement_angle_rad
        ):
            self._baseline = (pose[0], pose[1])
            self._baseline_yaw = pose[2]
            self._baseline_ns = t_ns
            return True
        return (t_ns - self._baseline_ns) <= round(self.movement_time_allowance_s * 1e9)
