"""A global planner on the navigation grid: Dijkstra over free cells, then the path straightened.

Like Nav2's NavFn (Dijkstra, `use_astar: false`, `tolerance: 0.5`): the robot (a disc of
`robot_radius_m`) may enter a cell whose distance to every obstacle is at least its radius; cells
near obstacles cost more (an exponential decay, Nav2's inflation with `cost_scaling_factor`), so
paths keep off walls where there is room. A start or goal the robot cannot stand on is moved to
the nearest free cell within `tolerance_m`. The cell path is then cut into straight legs that stay
in free cells.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from twin.nav.grid import NavGrid

__all__ = ["GridPlanner"]

_NEIGHBOURS = ((0, 1), (1, 0), (1, 1), (1, -1))  # the other four are the same edges reversed


class GridPlanner:
    """Plans collision-free paths for a disc robot on one grid (the graph is built once).

    Args:
        grid: The navigation grid.
        robot_radius_m: The robot's radius (its footprint's circumscribed circle keeps every yaw safe).
        inflation_radius_m: Beyond this distance from obstacles, cells cost no extra.
        cost_scaling_factor: Decay rate of the extra cost with distance, 1/m.
        tolerance_m: How far a start or goal may be moved to a free cell.
    """

    def __init__(
        self,
        grid: NavGrid,
        *,
        robot_radius_m: float,
        inflation_radius_m: float = 0.55,
        cost_scaling_factor: float = 3.0,
        tolerance_m: float = 0.5,
    ) -> None:
        from scipy.sparse import coo_matrix

        self.grid = grid
        self.robot_radius_m = robot_radius_m
        self.tolerance_m = tolerance_m
        rows, cols = grid.shape
        d = grid.distance_m
        self.free = d >= robot_radius_m
        near = np.clip(inflation_radius_m - d, 0.0, None) > 0.0
        penalty = np.where(near, 10.0 * np.exp(-cost_scaling_factor * np.maximum(d - robot_radius_m, 0.0)), 0.0)
        index = np.arange(rows * cols).reshape(rows, cols)
        src: list[NDArray[np.int64]] = []
        dst: list[NDArray[np.int64]] = []
        weight: list[NDArray[np.float64]] = []
        res = grid.resolution_m
        for dr, dc in _NEIGHBOURS:
            r0, r1 = max(0, -dr), rows - max(0, dr)
            c0, c1 = max(0, -dc), cols - max(0, dc)
            a = (slice(r0, r1), slice(c0, c1))
            b = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
            both = self.free[a] & self.free[b]
            length = res * math.hypot(dr, dc)
            w = length * (1.0 + 0.5 * (penalty[a] + penalty[b]))
            src.append(index[a][both])
            dst.append(index[b][both])
            weight.append(w[both])
        s, t, w = np.concatenate(src), np.concatenate(dst), np.concatenate(weight)
        n = rows * cols
        self._graph = coo_matrix(
            (np.concatenate((w, w)), (np.concatenate((s, t)), np.concatenate((t, s)))), shape=(n, n)
        ).tocsr()

    def _snap(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        """The free cell nearest to a point, within the tolerance (None if there is none)."""
        grid = self.grid
        cell = grid.cell(x_m, y_m)
        if cell is not None and self.free[cell]:
            return cell
        reach = max(1, math.ceil(self.tolerance_m / grid.resolution_m))
        rows, cols = grid.shape
        r, c = (
            cell
            if cell is not None
            else (
                math.floor((y_m - grid.origin_xy_m[1]) / grid.resolution_m),
                math.floor((x_m - grid.origin_xy_m[0]) / grid.resolution_m),
            )
        )
        r0, r1, c0, c1 = max(0, r - reach), min(rows, r + reach + 1), max(0, c - reach), min(cols, c + reach + 1)
        if r0 >= r1 or c0 >= c1:
            return None
        window = self.free[r0:r1, c0:c1]
        if not window.any():
            return None
        rr, cc = np.nonzero(window)
        dist2 = (rr + r0 - r) ** 2 + (cc + c0 - c) ** 2
        k = int(np.argmin(dist2))
        if math.sqrt(float(dist2[k])) * grid.resolution_m > self.tolerance_m:
            return None
        return int(rr[k] + r0), int(cc[k] + c0)

    def plan(self, start_xy_m: tuple[float, float], goal_xy_m: tuple[float, float]) -> list[tuple[float, float]] | None:
        """Return waypoints from start to goal (the goal last, as given), or None if there is no path."""
        from scipy.sparse.csgraph import dijkstra

        start, goal = self._snap(*start_xy_m), self._snap(*goal_xy_m)
        if start is None or goal is None:
            return None
        cols = self.grid.shape[1]
        s, g = start[0] * cols + start[1], goal[0] * cols + goal[1]
        if s == g:
            return [goal_xy_m]
        dist, pred = dijkstra(self._graph, indices=s, return_predecessors=True, min_only=False)
        if not math.isfinite(float(dist[g])):
            return None
        cells = [g]
        while cells[-1] != s:
            cells.append(int(pred[cells[-1]]))
        cells.reverse()
        points = [self.grid.centre(c // cols, c % cols) for c in cells]
        points[0] = start_xy_m if self.free[start] and self.grid.cell(*start_xy_m) == start else points[0]
        legs = self._straighten(points)
        if self.grid.cell(*goal_xy_m) == goal:
            legs[-1] = goal_xy_m
        else:
            legs.append(goal_xy_m)  # the goal itself lies inside the inflation: the last leg reaches in
        return legs[1:]

    def _clear(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """True if the straight line a-b stays on free cells."""
        grid = self.grid
        n = max(2, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / (0.5 * grid.resolution_m)) + 1)
        xs, ys = np.linspace(a[0], b[0], n), np.linspace(a[1], b[1], n)
        cols = np.floor((xs - grid.origin_xy_m[0]) / grid.resolution_m).astype(np.int64)
        rows = np.floor((ys - grid.origin_xy_m[1]) / grid.resolution_m).astype(np.int64)
        r_max, c_max = grid.shape
        if rows.min() < 0 or cols.min() < 0 or rows.max() >= r_max or cols.max() >= c_max:
            return False
        return bool(self.free[rows, cols].all())

    def _straighten(self, points: list[tuple[float, float]]) -> list[tuple[float, float]]:
        """Keep the path points where a straight leg from the last kept one would leave free cells."""
        out = [points[0]]
        i, n = 0, len(points)
        while i < n - 1:
            j = i + 1
            while j + 1 < n and self._clear(points[i], points[j + 1]):
                j += 1
            out.append(points[j])
            i = j
        return out
