"""nav2_behaviors' Wait: publish nothing for a while, then succeed."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from twin.nav.behaviors.timed_behavior import BehaviorStatus, BehaviorStep, TimedBehavior
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["Wait"]

Pose = tuple[float, float, float]


class Wait(TimedBehavior):
    """Publish nothing for `time_s` seconds, then succeed."""

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> str:
        """Begin waiting."""
        super().start({"time_allowance": 0.0}, pose, t_ns)
        self._duration_ns = round(float(request["time_s"]) * 1e9)
        return ""

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        if t_ns - self._start_ns >= self._duration_ns:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        return BehaviorStep(status=BehaviorStatus.RUNNING)
