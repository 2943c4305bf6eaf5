"""Nav2 Humble's behavior_server behaviours as state machines stepped at cycle_frequency (10 Hz).

Spin, BackUp, DriveOnHeading and Wait with Humble's code defaults (TB3_FACTS §4.6): spin speed
sqrt(2 * rotational_acc_lim * remaining angle) clamped to [min_rotational_vel 0.4, max 1.0] rad/s;
back up / drive on heading at the requested speed until the distance is covered. Before each
motion command the motion is simulated ahead (`simulate_ahead_time_s` 2 s, or what remains of the
motion) on the local costmap; a lethal or inscribed cell on the way aborts the behaviour with
"Collision Ahead". Exceeding `time_allowance` fails it (Humble's TIMEOUT).

`start(request, pose, t_ns)` with the action's request fields (as the BT leaves send them), then
`step(t_ns, pose, costmap)` per cycle returns the command and the status.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.nav.costmap_grid import INSCRIBED_INFLATED_OBSTACLE, CostGrid

__all__ = [
    "BackUp",
    "BehaviorParams",
    "BehaviorStatus",
    "BehaviorStep",
    "DriveOnHeading",
    "Spin",
    "Wait",
    "make_behavior",
]

Pose = tuple[float, float, float]


class BehaviorStatus(enum.Enum):
    """A behaviour's state after a cycle."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True, kw_only=True, slots=True)
class BehaviorStep:
    """One cycle: the status, the command for cmd_vel (behavior_server publishes to the smoother's input), a reason."""

    status: BehaviorStatus
    cmd: tuple[float, float] = (0.0, 0.0)
    reason: str = ""


@dataclass(frozen=True, kw_only=True, slots=True)
class BehaviorParams:
    """behavior_server parameters (Humble code defaults)."""

    cycle_frequency_hz: float = 10.0
    simulate_ahead_time_s: float = 2.0
    max_rotational_vel: float = 1.0
    min_rotational_vel: float = 0.4
    rotational_acc_lim: float = 3.2


def _blocked(costmap: CostGrid, xs: np.ndarray, ys: np.ndarray) -> bool:
    col = np.floor((xs - costmap.origin_x_m) / costmap.resolution_m).astype(np.int64)
    row = np.floor((ys - costmap.origin_y_m) / costmap.resolution_m).astype(np.int64)
    inside = (row >= 0) & (row < costmap.rows) & (col >= 0) & (col < costmap.cols)
    return bool((costmap.cost[row[inside], col[inside]] >= INSCRIBED_INFLATED_OBSTACLE).any())


class _Timed:
    def __init__(self, params: BehaviorParams | None = None) -> None:
        self.params = params or BehaviorParams()
        self._start_ns = 0
        self._allowance_ns = 0
        self._start_pose: Pose = (0.0, 0.0, 0.0)

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> None:
        """Begin a behaviour goal at `pose`."""
        self._start_ns = t_ns
        self._allowance_ns = round(float(request.get("time_allowance", 10.0)) * 1e9)
        self._start_pose = pose

    def _timed_out(self, t_ns: int) -> bool:
        return t_ns - self._start_ns > self._allowance_ns


class Spin(_Timed):
    """Turn in place by `target_yaw` rad (sign gives the direction)."""

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> None:
        """Begin a spin."""
        super().start(request, pose, t_ns)
        self._target = float(request["target_yaw"])
        self._turned = 0.0
        self._prev_yaw = pose[2]

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        p = self.params
        self._turned += abs((pose[2] - self._prev_yaw + math.pi) % (2 * math.pi) - math.pi)
        self._prev_yaw = pose[2]
        remaining = abs(self._target) - self._turned
        if remaining <= 0.0:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        if self._timed_out(t_ns):
            return BehaviorStep(status=BehaviorStatus.FAILED, reason="Spin exceeded time allowance")
        vel = min(max(math.sqrt(2.0 * p.rotational_acc_lim * remaining), p.min_rotational_vel), p.max_rotational_vel)
        if _blocked(costmap, np.array([pose[0]]), np.array([pose[1]])):
            return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting Spin")
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(0.0, math.copysign(vel, self._target)))


class DriveOnHeading(_Timed):
    """Drive straight `target_x` m at `speed` m/s (negative speed for BackUp)."""

    reverse = False

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> None:
        """Begin driving."""
        super().start(request, pose, t_ns)
        self._distance = abs(float(request["target_x"]))
        speed = abs(float(request["speed"]))
        self._speed = -speed if self.reverse else speed

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        travelled = math.hypot(pose[0] - self._start_pose[0], pose[1] - self._start_pose[1])
        remaining = self._distance - travelled
        if remaining <= 0.0:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        if self._timed_out(t_ns):
            return BehaviorStep(status=BehaviorStatus.FAILED, reason="exceeded time allowance")
        ahead = min(remaining, abs(self._speed) * self.params.simulate_ahead_time_s)
        s = np.linspace(0.0, ahead, max(2, int(ahead / costmap.resolution_m) + 2)) * math.copysign(1.0, self._speed)
        if _blocked(costmap, pose[0] + s * math.cos(pose[2]), pose[1] + s * math.sin(pose[2])):
            return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting DriveOnHeading")
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(self._speed, 0.0))


class BackUp(DriveOnHeading):
    """Drive backwards `target_x` m at `speed` m/s."""

    reverse = True


class Wait(_Timed):
    """Publish nothing for `time_s` seconds, then succeed."""

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> None:
        """Begin waiting."""
        super().start({"time_allowance": 1e9}, pose, t_ns)
        self._duration_ns = round(float(request["time_s"]) * 1e9)

    def step(self, t_ns: int, pose: Pose, costmap: CostGrid) -> BehaviorStep:
        """One cycle."""
        if t_ns - self._start_ns >= self._duration_ns:
            return BehaviorStep(status=BehaviorStatus.SUCCEEDED)
        return BehaviorStep(status=BehaviorStatus.RUNNING)


def make_behavior(server: str, params: BehaviorParams | None = None) -> Spin | DriveOnHeading | Wait:
    """The behaviour for an action server name: spin, backup, drive_on_heading, wait."""
    kinds: dict[str, type[Spin] | type[DriveOnHeading] | type[Wait]] = {
        "spin": Spin,
        "backup": BackUp,
        "drive_on_heading": DriveOnHeading,
        "wait": Wait,
    }
    return kinds[server](params)
