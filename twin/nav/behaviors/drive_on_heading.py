"""nav2_behaviors' DriveOnHeading and BackUp: drive straight a distance, checking the footprint ahead."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from twin.nav.behaviors.timed_behavior import BehaviorStatus, BehaviorStep, TimedBehavior, collision_free
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["BackUp", "DriveOnHeading"]

Pose = tuple[float, float, float]


class DriveOnHeading(TimedBehavior):
    """Drive straight `target_x` m at `speed` m/s (backwards for BackUp)."""

    reverse = False

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> None:
        """Begin driving."""
        super().start(request, pose, t_ns)
        self._distance = abs(float(request["target_x"]))
        speed = abs(float(request["speed"]))
        self._speed = -speed if self.reverse else speed

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        p = self.params
        if self._timed_out(t_ns):
            reason = "Exceeded time allowance before reaching the DriveOnHeading goal - Exiting DriveOnHeading"
            return BehaviorStep(status=BehaviorStatus.FAILED, reason=reason)
        travelled = math.hypot(pose[0] - self._start_pose[0], pose[1] - self._start_pose[1])
        if travelled >= self._distance:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for k in range(int(p.cycle_frequency_hz * p.simulate_ahead_time_s)):  # DriveOnHeading::isCollisionFree
            change = self._speed * (k / p.cycle_frequency_hz)
            if self._distance - travelled - abs(change) <= 0.0:
                break
            if not collision_free(costmap, p.footprint, (pose[0] + change * c, pose[1] + change * s, pose[2])):
                return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting DriveOnHeading")
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(self._speed, 0.0))


class BackUp(DriveOnHeading):
    """Drive backwards `target_x` m at `speed` m/s."""

    reverse = True
