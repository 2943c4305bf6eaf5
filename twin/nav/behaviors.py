"""Nav2 Humble's behavior_server behaviours as state machines stepped at cycle_frequency (10 Hz).

Spin, BackUp, DriveOnHeading and Wait with Humble's code defaults (TB3_FACTS §4.6): spin speed
sqrt(2 * rotational_acc_lim * remaining angle) clamped to [min_rotational_vel 0.4, max 1.0] rad/s,
the angle turned summed signed as Nav2 sums it; back up / drive on heading at the requested speed
until the distance from the start is covered. Each cycle first fails a behaviour that has run
longer than its `time_allowance` (Humble's TimedBehavior), then checks for success, then simulates
the command ahead in cycle steps (`simulate_ahead_time_s` 2 s, or what remains of the motion) and
fails with "Collision Ahead" when the robot's footprint at one of those poses touches a lethal or
unknown cell of the local costmap (Nav2's FootprintCollisionChecker: the cells along the
footprint's edges, a Bresenham line each; a footprint point off the costmap counts as lethal).

`start(request, pose, t_ns)` with the action's request fields (as the BT leaves send them), then
`step(t_ns, pose, costmap)` per cycle returns the command and the status.
"""

from __future__ import annotations

import enum
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.nav.costmap_grid import LETHAL_OBSTACLE, CostGrid

__all__ = [
    "BackUp",
    "BehaviorParams",
    "BehaviorStatus",
    "BehaviorStep",
    "DriveOnHeading",
    "Spin",
    "Wait",
    "footprint_cost",
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
    #: The robot's footprint (x, y) m in its base frame: the local costmap's (TB3: a circle of 0.22 m).
    footprint: tuple[tuple[float, float], ...] = tuple(
        (math.cos(i * math.pi / 8) * 0.22, math.sin(i * math.pi / 8) * 0.22) for i in range(16)
    )


def _line_cost(cost: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> int:
    """The highest cost along a Bresenham line (nav2_util's LineIterator), LETHAL as soon as one is."""
    dx, dy = abs(x1 - x0), abs(y1 - y0)
    sx, sy = (1 if x1 >= x0 else -1), (1 if y1 >= y0 else -1)
    if dx >= dy:
        den, num, add, pixels, straight = dx, dx // 2, dy, dx, True
    else:
        den, num, add, pixels, straight = dy, dy // 2, dx, dy, False
    x, y, worst = x0, y0, 0
    for _ in range(pixels + 1):
        c = int(cost[y, x])
        if c == LETHAL_OBSTACLE:
            return c
        worst = max(worst, c)
        num += add
        if num >= den:
            num -= den
            if straight:
                y += sy
            else:
                x += sx
        if straight:
            x += sx
        else:
            y += sy
    return worst


@functools.cache
def _footprint_arrays(footprint: tuple[tuple[float, float], ...]) -> tuple[Any, Any] | None:
    """The footprint's x and y as float64 arrays for the kernel (and the kernel), or None without it."""
    from twin.nav._native import load_kernel

    lib = load_kernel()
    if lib is None or not 0 < len(footprint) <= 64:
        return None
    xs = np.ascontiguousarray([p[0] for p in footprint], dtype=np.float64)
    ys = np.ascontiguousarray([p[1] for p in footprint], dtype=np.float64)
    return (lib.twin_footprint_cost, (xs, ys, xs.ctypes.data, ys.ctypes.data))


def footprint_cost(costmap: CostGrid, footprint: tuple[tuple[float, float], ...], pose: Pose) -> int:
    """Nav2's FootprintCollisionChecker::footprintCost: the highest cost on the footprint's edges at `pose`.

    A footprint point off the costmap gives LETHAL (254). In C when the kernels are built (the same
    arithmetic, the same cells: tested), else in Python.
    """
    kernel = _footprint_arrays(footprint)
    cost = costmap.cost
    if kernel is not None and cost.dtype == np.uint8 and cost.flags.c_contiguous:
        fn, (_, _, xs, ys) = kernel
        rows, cols = cost.shape
        return int(
            fn(cost.ctypes.data, rows, cols, costmap.origin_x_m, costmap.origin_y_m, costmap.resolution_m,
               xs, ys, len(footprint), pose[0], pose[1], pose[2])
        )  # fmt: skip
    return footprint_cost_py(costmap, footprint, pose)


def footprint_cost_py(costmap: CostGrid, footprint: tuple[tuple[float, float], ...], pose: Pose) -> int:
    """`footprint_cost` in Python (the reference the kernel is tested against)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    cells = []
    for px, py in footprint:
        wx, wy = pose[0] + c * px - s * py, pose[1] + s * px + c * py
        if wx < costmap.origin_x_m or wy < costmap.origin_y_m:
            return LETHAL_OBSTACLE
        mx = int((wx - costmap.origin_x_m) / costmap.resolution_m)
        my = int((wy - costmap.origin_y_m) / costmap.resolution_m)
        if mx >= costmap.cols or my >= costmap.rows:
            return LETHAL_OBSTACLE
        cells.append((mx, my))
    worst = 0
    cost = costmap.cost
    for i, (x0, y0) in enumerate(cells):
        x1, y1 = cells[(i + 1) % len(cells)]
        worst = max(worst, _line_cost(cost, x0, y0, x1, y1))
        if worst == LETHAL_OBSTACLE:
            break
    return worst


def _collision_free(costmap: CostGrid, footprint: tuple[tuple[float, float], ...], pose: Pose) -> bool:
    """CostmapTopicCollisionChecker::isCollisionFree: the footprint on no lethal or unknown cell."""
    return footprint_cost(costmap, footprint, pose) < LETHAL_OBSTACLE


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
        self._relative = 0.0
        self._prev_yaw = pose[2]

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
            if not _collision_free(costmap, p.footprint, (pose[0], pose[1], pose[2] + change)):
                return BehaviorStep(status=BehaviorStatus.FAILED, reason="Collision Ahead - Exiting Spin")
        return BehaviorStep(status=BehaviorStatus.RUNNING, cmd=(0.0, w))


class DriveOnHeading(_Timed):
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
            if not _collision_free(costmap, p.footprint, (pose[0] + change * c, pose[1] + change * s, pose[2])):
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
