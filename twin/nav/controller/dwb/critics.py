"""dwb_critics: the state the critics keep between cycles, and the map-grid critics' cell distances.

`CriticState` holds RotateToGoal's latches and Oscillation's command trends (reset by a new plan);
`walk_plan` and `manhattan_distances` are MapGridCritic's seeding and propagation. The scores
themselves are computed in one pass over all trajectories (`DwbController`, in C in `dwb_kernel.c`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.nav.controller.dwb.dwb_params import DwbParams
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = [
    "CommandTrend",
    "CriticState",
    "adjusted_plan",
    "manhattan_distances",
    "shortest_angle",
    "trajectory_cells",
    "walk_plan",
    "world_to_map",
]

F64 = NDArray[np.float64]
Pose = tuple[float, float, float]


@dataclass(slots=True)
class CommandTrend:
    """Oscillation's CommandTrend for one velocity component."""

    sign: int = 0
    positive_only: bool = False
    negative_only: bool = False

    def update(self, v: float) -> bool:
        """Record a command's sign; True when it flipped."""
        flipped = False
        if v < 0.0:
            if self.sign > 0:
                self.negative_only = flipped = True
            self.sign = -1
        elif v > 0.0:
            if self.sign < 0:
                self.positive_only = flipped = True
            self.sign = 1
        return flipped

    def oscillating(self, v: F64) -> NDArray[np.bool_]:
        """Which of the values `v` would flip the sign again after a flip."""
        return np.asarray((self.positive_only & (v < 0.0)) | (self.negative_only & (v > 0.0)), dtype=bool)


class CriticState:
    """RotateToGoal's latches and Oscillation's trends; reset by a new plan."""

    def __init__(self) -> None:
        self.in_window = False
        self.rotating = False
        self.x = CommandTrend()
        self.theta = CommandTrend()
        self.stationary: Pose = (0.0, 0.0, 0.0)  # Oscillation's prev_stationary_pose_: kept across resets

    def reset(self) -> None:
        """Forget the latches and trends (a new plan)."""
        self.in_window = self.rotating = False
        self.x, self.theta = CommandTrend(), CommandTrend()

    def debrief(self, cmd: tuple[float, float], pose: Pose, p: DwbParams) -> None:
        """Oscillation's debrief: record the command's signs, forget them after enough motion since a flip."""
        flipped = self.x.update(cmd[0])
        if p.x_only_threshold < 0.0 or abs(cmd[0]) <= p.x_only_threshold:
            flipped = self.theta.update(cmd[1]) or flipped
        if flipped:
            self.stationary = pose
        if self.x.positive_only or self.x.negative_only or self.theta.positive_only or self.theta.negative_only:
            dx, dy = pose[0] - self.stationary[0], pose[1] - self.stationary[1]
            moved = p.oscillation_reset_dist_m >= 0.0 and dx * dx + dy * dy > p.oscillation_reset_dist_m**2
            turned = p.oscillation_reset_angle_rad >= 0.0 and abs(pose[2] - self.stationary[2]) > (
                p.oscillation_reset_angle_rad
            )
            if moved or turned:
                self.x, self.theta = CommandTrend(), CommandTrend()


def adjusted_plan(points: F64, resolution_m: float) -> list[tuple[float, float]]:
    """nav_2d_utils::adjustPlanResolution (x, y only): points added where two are more than 2 cells apart."""
    if len(points) == 0:
        return []
    out = [(float(points[0, 0]), float(points[0, 1]))]
    min_sq = resolution_m * resolution_m * 4.0
    lx, ly = out[0]
    for x, y in points[1:].tolist():
        sq = (x - lx) * (x - lx) + (y - ly) * (y - ly)
        if sq > min_sq:
            steps = int((math.sqrt(sq) - math.sqrt(min_sq)) / resolution_m) - 1
            if steps > 1:
                dx, dy = (x - lx) / steps, (y - ly) / steps
                out += [(lx + j * dx, ly + j * dy) for j in range(1, steps)]
        out.append((x, y))
        lx, ly = x, y
    return out


def world_to_map(costmap: CostGrid, x: float, y: float) -> tuple[int, int] | None:
    """Costmap2D::worldToMap: (row, col), or None left of or below the origin or past the far edges."""
    if x < costmap.origin_x_m or y < costmap.origin_y_m:
        return None
    col = int((x - costmap.origin_x_m) / costmap.resolution_m)
    row = int((y - costmap.origin_y_m) / costmap.resolution_m)
    return (row, col) if row < costmap.rows and col < costmap.cols else None


def walk_plan(points: F64, costmap: CostGrid, *, last_only: bool) -> list[tuple[int, int]]:
    """The map-grid critics' seeds: every adjusted plan pose on a known cell (or the last), up to the first off it."""
    seeds: list[tuple[int, int]] = []
    for x, y in adjusted_plan(points, costmap.resolution_m):
        cell = world_to_map(costmap, x, y)
        if cell is not None and costmap.cost[cell] != 255:
            if last_only:
                seeds[:] = [cell]
            else:
                seeds.append(cell)
        elif seeds:
            break
    return seeds


def manhattan_distances(costmap: CostGrid, seeds: list[tuple[int, int]]) -> F64:
    """Manhattan cell distance of every cell to the nearest seed (Humble's MapGridCritic propagation)."""
    from scipy.ndimage import distance_transform_cdt

    free = np.ones(costmap.cost.shape, dtype=bool)
    rows, cols = zip(*seeds, strict=True)
    free[list(rows), list(cols)] = False
    return np.asarray(distance_transform_cdt(free, metric="taxicab"), dtype=np.float64)


def trajectory_cells(
    costmap: CostGrid, x: F64, y: F64
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Cells as worldToMap finds them: (row, col, on the costmap)."""
    fx = (x - costmap.origin_x_m) / costmap.resolution_m
    fy = (y - costmap.origin_y_m) / costmap.resolution_m
    inside = (x >= costmap.origin_x_m) & (y >= costmap.origin_y_m) & (fx < costmap.cols) & (fy < costmap.rows)
    col = np.where(inside, fx, 0).astype(np.int64)
    row = np.where(inside, fy, 0).astype(np.int64)
    inside &= (col < costmap.cols) & (row < costmap.rows)
    return row, col, inside


def shortest_angle(from_rad: F64, to_rad: float) -> F64:
    """angles::shortest_angular_distance as Humble's angles 1.15 computes it: normalize_angle(to - from).

    That is fmod(a + pi, 2 pi), then minus pi (plus pi when not positive); the older double-fmod form
    rounds differently in the last bits.
    """
    r = np.fmod((to_rad - from_rad) + math.pi, 2.0 * math.pi)
    return np.asarray(np.where(r <= 0.0, r + math.pi, r - math.pi))
