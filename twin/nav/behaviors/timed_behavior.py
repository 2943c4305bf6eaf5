"""Nav2 Humble's behaviours (nav2_behaviors) as state machines stepped at cycle_frequency (10 Hz).

Spin, BackUp, DriveOnHeading and Wait with Humble's code defaults (TB3_FACTS §4.6): spin speed
sqrt(2 * rotational_acc_lim * remaining angle) clamped to [min_rotational_vel 0.4, max 1.0] rad/s,
the angle turned summed signed as Nav2 sums it; back up / drive on heading at the requested speed
(with `<behaviour>.acceleration_limit`, `.deceleration_limit` and `.minimum_speed` when set) until
the distance from the start is covered. Each cycle first fails a behaviour that has run longer than
a positive `time_allowance` (Humble's TimedBehavior; 0 means no limit), then checks for success,
then simulates the command ahead in cycle steps (`simulate_ahead_time_s` 2 s, or what remains of
the motion) and fails with "Collision Ahead" when the robot's centre is off the local costmap or its
footprint at one of those poses touches a lethal or unknown cell (CostmapTopicCollisionChecker over
Nav2's FootprintCollisionChecker: the cells along the footprint's edges, a Bresenham line each; a
footprint point off the costmap counts as lethal). Held to Nav2 Humble's code by recorded cases
(`tests/unit/nav/behaviors/behavior_cases/`).

`start(request, pose, t_ns)` with the action's request fields (as the BT leaves send them) returns
why Nav2's `onRun` refuses the goal ("" when it accepts it), then `step(t_ns, pose, costmap)` per
cycle returns the command and the status. This module holds what
they share (`TimedBehavior`, the footprint check); each behaviour has its module (`spin`,
`drive_on_heading` with BackUp, `wait`), and `behavior_server` runs them.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from twin.nav.costmap_2d.costmap_2d import LETHAL_OBSTACLE, CostGrid
from twin.nav.costmap_2d.footprint import footprint_cost

__all__ = ["BehaviorParams", "BehaviorStatus", "BehaviorStep", "TimedBehavior", "collision_free"]

Pose = tuple[float, float, float]


class BehaviorStatus(enum.Enum):
    """A behaviour's state after a cycle."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True, kw_only=True, slots=True)
class BehaviorStep:
    """One cycle: the status, the command for `/cmd_vel` (Humble's behavior_server sends it straight), a reason."""

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
    #: BackUp's `backup.acceleration_limit`, `.deceleration_limit`, `.minimum_speed` (0: unlimited / none).
    backup_limits: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: DriveOnHeading's `drive_on_heading.acceleration_limit`, `.deceleration_limit`, `.minimum_speed`.
    drive_on_heading_limits: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: The robot's footprint (x, y) m in its base frame: the local costmap's (TB3: a circle of 0.22 m).
    footprint: tuple[tuple[float, float], ...] = tuple(
        (math.cos(i * math.pi / 8) * 0.22, math.sin(i * math.pi / 8) * 0.22) for i in range(16)
    )


def collision_free(costmap: CostGrid, footprint: tuple[tuple[float, float], ...], pose: Pose) -> bool:
    """CostmapTopicCollisionChecker::isCollisionFree: centre on the costmap, footprint on no lethal/unknown cell."""
    if costmap.world_to_cell(pose[0], pose[1]) is None:
        return False  # scorePose: "Pose Goes Off Grid."
    return footprint_cost(costmap, footprint, pose) < LETHAL_OBSTACLE


class TimedBehavior:
    """Humble's TimedBehavior: a behaviour fails once it has run longer than its `time_allowance`."""

    def __init__(self, params: BehaviorParams | None = None) -> None:
        self.params = params or BehaviorParams()
        self._start_ns = 0
        self._allowance_ns = 0
        self._start_pose: Pose = (0.0, 0.0, 0.0)

    def start(self, request: Mapping[str, Any], pose: Pose, t_ns: int) -> str:
        """Begin a behaviour goal at `pose`; return why it is refused ("": accepted)."""
        self._start_ns = t_ns
        self._allowance_ns = round(float(request.get("time_allowance", 10.0)) * 1e9)
        self._start_pose = pose
        return ""

    def _timed_out(self, t_ns: int) -> bool:
        """Past a positive time allowance (Humble: `time_remaining < 0 && time_allowance > 0`)."""
        return self._allowance_ns > 0 and self._start_ns + self._allowance_ns - t_ns < 0
