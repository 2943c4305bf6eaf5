"""nav2_behaviors' DriveOnHeading and BackUp: drive straight a distance, checking the footprint ahead.

DriveOnHeading drives `target_x` m at `speed` m/s, both of one sign (negative: backwards), and
refuses a goal whose signs differ or with a y target; BackUp drives |target_x| at |speed| backwards.
Without acceleration limits the command is the requested speed; with them (both non-zero) it ramps
from the last command by `acceleration_limit` / `deceleration_limit` per cycle and slows to stop at
the distance (sqrt(-2 x deceleration x remaining)); `minimum_speed` is a floor either way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from twin.nav.behaviors.timed_behavior import BehaviorStatus, BehaviorStep, TimedBehavior, collision_free
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["BackUp", "DriveOnHeading"]

Pose = tuple[float, float, float]


class DriveOnHeading(TimedBehavior):
    """Drive straight `target_x` m at `speed` m/s (see the module docstring)."""

    name = "drive_on_heading"

    def _limits(self) -> tuple[float, float, float]:
        accel, decel, minimum = self.params.drive_on_heading_limits
        if accel < 0.0 or decel > 0.0:  # Nav2 logs an error and flips the signs
            accel, decel = abs(accel), -abs(decel)
        return accel, decel, minimum

    def _command(self, request: Mapping[str, Any]) -> tuple[float, float, str]:
        """(target x, speed, refusal) as `onRun` takes them."""
        x, speed = float(request["target_x"]), float(request["speed"])
        if float(request.get("target_y", 0.0)) != 0.0 or float(request.get("target_z", 0.0)) != 0.0:
            return x, speed, "DrivingOnHeading in Y and Z not supported, will only move in X."
        if (x > 0.0) != (speed > 0.0):
            return x, speed, "Speed and command sign did not match"
        return x, speed, ""

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> str:
        """Begin driving; return why the goal is refused ("": accepted)."""
        super().start(request, pose, t_ns)
        self._x, self._speed, refusal = self._command(request)
        self._accel, self._decel, self._minimum = self._limits()
        self._last_vel: float | None = None
        return refusal

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle (Humble's `onCycleUpdate`)."""
        p = self.params
        if self._timed_out(t_ns):
            reason = "Exceeded time allowance before reaching the DriveOnHeading goal - Exiting DriveOnHeading"
            return BehaviorStep(status=BehaviorStatus.FAILED, reason=reason)
        distance = math.hypot(self._start_pose[0] - pose[0], self._start_pose[1] - pose[1])
        if distance >= abs(self._x):
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        forward = self._speed > 0.0
        if self._accel == 0.0 or self._decel == 0.0:
            vx = self._speed
        else:
            current = 0.0 if self._last_vel is None else self._last_vel
            f = p.cycle_frequency_hz
            if forward:
                lo, hi = current + self._decel / f, current + self._accel / f
            else:
                lo, hi = current - self._accel / f, current - self._decel / f
            vx = lo if self._speed < lo else (hi if hi < self._speed else self._speed)
            to_stop = math.sqrt(-2.0 * self._decel * (abs(self._x) - distance))
            if to_stop < abs(vx):
                vx = to_stop if forward else -to_stop
        if abs(vx) < self._minimum:
            vx = self._minimum if forward else -self._minimum
        # isCollisionFree: the command simulated ahead in cycle steps, up to what remains of the distance
        remaining = abs(self._x) - distance
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for k in range(int(p.cycle_frequency_hz * p.simulate_ahead_time_s)):
            change = vx * (k / p.cycle_frequency_hz)
            if remaining - abs(change) <= 0.0:
                break
            if not collision_free(costmap, p.footprint, (pose[0] + change * c, pose[1] + change * s, pose[2])):
                return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting DriveOnHeading")
        self._last_vel = vx
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(vx, 0.0))


class BackUp(DriveOnHeading):
    """Drive |target_x| m backwards at |speed| m/s."""

    name = "backup"

    def _limits(self) -> tuple[float, float, float]:
        accel, decel, minimum = self.params.backup_limits
        if accel < 0.0 or decel > 0.0:
            accel, decel = abs(accel), -abs(decel)
        return accel, decel, minimum

    def _command(self, request: Mapping[str, Any]) -> tuple[float, float, str]:
        x, speed = -abs(float(request["target_x"])), -abs(float(request["speed"]))
        if float(request.get("target_y", 0.0)) != 0.0 or float(request.get("target_z", 0.0)) != 0.0:
            return x, speed, "Backing up in Y and Z not supported, will only move in X."
        return x, speed, ""
