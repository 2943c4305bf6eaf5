"""The navigation grid: the world's obstacles rasterised at the robot's heights, with distances to them.

Each cell (5 cm by default) is occupied when an obstacle's outline at any of a few heights through
the robot's body crosses it; `distance_m` holds every cell's distance to the nearest occupied
cell, from which the planner takes what a robot of a given radius may enter and how close to walls
it likes to go (Nav2's inflation, in spirit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.world.scene import Scene

__all__ = ["NavGrid", "build_grid"]


@dataclass(frozen=True, slots=True, eq=False)
class NavGrid:
    """A 2D grid over the world: `occupied[row, col]` and `distance_m`, row = y, col = x."""

    origin_xy_m: tuple[float, float]  # world position of cell (0, 0)'s lower-left corner
    resolution_m: float
    occupied: NDArray[np.bool_]
    distance_m: NDArray[np.float64]

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        rows, cols = self.occupied.shape
        return rows, cols

    def cell(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        """Return (row, col) of the cell holding a world point, or None outside the grid."""
        col = math.floor((x_m - self.origin_xy_m[0]) / self.resolution_m)
        row = math.floor((y_m - self.origin_xy_m[1]) / self.resolution_m)
        rows, cols = self.shape
        return (row, col) if 0 <= row < rows and 0 <= col < cols else None

    def centre(self, row: int, col: int) -> tuple[float, float]:
        """World position of a cell's centre."""
        res = self.resolution_m
        return self.origin_xy_m[0] + (col + 0.5) * res, self.origin_xy_m[1] + (row + 0.5) * res


def _mark_segments(
    occupied: NDArray[np.bool_], segments: NDArray[np.float64], origin: NDArray[np.float64], res: float
) -> None:
    if not len(segments):
        return
    starts, ends = segments[:, :2], segments[:, 2:]
    counts = np.maximum(2, np.ceil(np.hypot(*(ends - starts).T) / (0.25 * res)).astype(int) + 1)
    # One row of sample points per segment, flattened: t in [0, 1] along each.
    seg_index = np.repeat(np.arange(len(segments)), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t = offsets / np.repeat(counts - 1, counts)
    points = starts[seg_index] + (ends - starts)[seg_index] * t[:, None]
    _mark_points(occupied, points, origin, res)


def _mark_points(
    occupied: NDArray[np.bool_], points: NDArray[np.float64], origin: NDArray[np.float64], res: float
) -> None:
    cells = np.floor((points - origin) / res).astype(np.int64)
    rows, cols = occupied.shape
    keep = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
    occupied[cells[keep, 1], cells[keep, 0]] = True


def _mark_circles(
    occupied: NDArray[np.bool_], circles: NDArray[np.float64], origin: NDArray[np.float64], res: float
) -> None:
    rows, cols = occupied.shape
    for cx, cy, r in circles:
        c0, c1 = int((cx - r - origin[0]) // res), int((cx + r - origin[0]) // res) + 1
        r0, r1 = int((cy - r - origin[1]) // res), int((cy + r - origin[1]) // res) + 1
        c0, c1, r0, r1 = max(c0, 0), min(c1, cols - 1), max(r0, 0), min(r1, rows - 1)
        if c0 > c1 or r0 > r1:
            continue
        xs = origin[0] + (np.arange(c0, c1 + 1) + 0.5) * res
        ys = origin[1] + (np.arange(r0, r1 + 1) + 0.5) * res
        inside = (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2 <= (r + 0.5 * res) ** 2
        occupied[r0 : r1 + 1, c0 : c1 + 1] |= inside


def build_grid(
    scene: Scene,
    *,
    heights_m: tuple[float, ...],
    resolution_m: float = 0.05,
    bounds_xy_m: tuple[float, float, float, float] | None = None,
    padding_m: float = 1.0,
) -> NavGrid:
    """Rasterise the scene's obstacles at `heights_m` into a grid with distances to them.

    Args:
        scene: The world's obstacles.
        heights_m: Heights above the floor at which obstacles block the robot (e.g. a few through its body).
        resolution_m: Cell size.
        bounds_xy_m: (x_min, y_min, x_max, y_max) to cover; default the obstacles' bounds plus `padding_m`.
        padding_m: Margin around the obstacles' bounds.
    """
    from scipy import ndimage

    if bounds_xy_m is None:
        box = scene.bounds
        if box is None:
            bounds_xy_m = (-10.0, -10.0, 10.0, 10.0)
        else:
            (x0, y0, _), (x1, y1, _) = box
            bounds_xy_m = (x0 - padding_m, y0 - padding_m, x1 + padding_m, y1 + padding_m)
    x_min, y_min, x_max, y_max = bounds_xy_m
    cols = max(1, math.ceil((x_max - x_min) / resolution_m))
    rows = max(1, math.ceil((y_max - y_min) / resolution_m))
    occupied = np.zeros((rows, cols), dtype=bool)
    origin = np.array([x_min, y_min])
    for height in heights_m:
        caster = scene.ray_caster(height)
        _mark_segments(occupied, np.asarray(caster.segments, dtype=np.float64), origin, resolution_m)
        _mark_circles(occupied, np.asarray(caster.circles, dtype=np.float64), origin, resolution_m)
    if occupied.any():
        distance = ndimage.distance_transform_edt(~occupied) * resolution_m
    else:
        distance = np.full(occupied.shape, np.inf)
    return NavGrid(
        origin_xy_m=(x_min, y_min), resolution_m=resolution_m, occupied=occupied, distance_m=np.asarray(distance)
    )
