"""nav2_behaviors' Spin: turn in place by a relative angle, checking the footprint ahead."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from twin.nav.behaviors.timed_behavior import BehaviorStatus, BehaviorStep, TimedBehavior, collision_free
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["Spin"]

Pose = tuple[float, float, float]


class Spin(TimedBehavior):
    """Turn in place by `target_yaw` rad (sign gives the direction)."""

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> str:
        """Begin a spin."""
        super().start(request, pose, t_ns)
        self._target = float(request["target_yaw"])
        self._relative = 0.0
        self._prev_yaw = pose[2]
        return ""

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        p = self.params
        if self._timed_out(t_ns):
            reason = "Exceeded time allowance before reaching the Spin goal - Exiting Spin"
            return BehaviorStep(status=BehaviorStatus.FAILED, reason=reason)
        delta = pose[2] - self._prev_yaw
        if abs(delta) > math.pi:
            delta = math.copysign(2.0 * math.pi - abs(delta), self._prev_yaw)
        self._relative += delta
        self._prev_yaw = pose[2]
        remaining = abs(self._target) - abs(self._relative)
        if remaining < 1e-6:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        vel = min(max(math.sqrt(2.0 * p.rotational_acc_lim * remaining), p.min_rotational_vel), p.max_rotational_vel)
        w = math.copysign(vel, self._target)
        for k in range(int(p.cycle_frequency_hz * p.simulate_ahead_time_s)):  # Spin::isCollisionFree
            change = w * (k / p.cycle_frequency_hz)
            if abs(self._relative) - abs(change) <= 0.0:  # Humble simulates as far as it has turned so far
                break
            if not collision_free(costmap, p.footprint, (pose[0], pose[1], pose[2] + change)):
                return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting Spin")
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(0.0, w))
