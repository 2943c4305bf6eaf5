"""The robot's footprint on a costmap, as nav2_costmap_2d's footprint helpers and collision checker.

`footprint_radii` gives the padded footprint and its inscribed and circumscribed radii (what
LayeredCostmap computes when the footprint is set); `footprint_cost` is FootprintCollisionChecker's
footprintCost: the highest cost along the footprint's edges at a pose, each edge a Bresenham line
(nav2_util's LineIterator), a point off the costmap counting as lethal. It runs in C when the
kernels are built (`costmap_kernels.c`), else in Python (`footprint_cost_py`, the reference).
"""

from __future__ import annotations

import functools
import itertools
import math
from typing import Any

import numpy as np

from twin.nav.costmap_2d._native import load_kernel
from twin.nav.costmap_2d.costmap_2d import LETHAL_OBSTACLE, CostGrid
from twin.nav.params import CostmapParams

__all__ = ["footprint_cost", "footprint_cost_py", "footprint_radii"]

Pose = tuple[float, float, float]


def _radius_footprint(radius_m: float) -> list[tuple[float, float]]:
    return [
        (math.cos(i * 2.0 * math.pi / 16) * radius_m, math.sin(i * 2.0 * math.pi / 16) * radius_m) for i in range(16)
    ]


def _sign0(v: float) -> float:
    return 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)


def _segment_distance(ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from the origin to segment ab."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0.0 else max(0.0, min(1.0, -(ax * dx + ay * dy) / length2))
    return math.hypot(ax + t * dx, ay + t * dy)


def footprint_radii(params: CostmapParams) -> tuple[float, float, tuple[tuple[float, float], ...]]:
    """Return (inscribed radius, circumscribed radius, padded footprint) as Nav2's LayeredCostmap computes them."""
    points = list(params.footprint) if params.footprint else _radius_footprint(params.robot_radius_m)
    pad = params.footprint_padding_m
    padded = [(x + _sign0(x) * pad, y + _sign0(y) * pad) for x, y in points]
    inscribed = min(_segment_distance(*padded[i], *padded[(i + 1) % len(padded)]) for i in range(len(padded)))
    circumscribed = max(math.hypot(x, y) for x, y in padded)
    return inscribed, circumscribed, tuple(padded)


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
        wx, wy = pose[0] + (px * c - py * s), pose[1] + (px * s + py * c)  # footprintCostAtPose's rounding
        if wx < costmap.origin_x_m or wy < costmap.origin_y_m:
            return LETHAL_OBSTACLE
        mx = int((wx - costmap.origin_x_m) / costmap.resolution_m)
        my = int((wy - costmap.origin_y_m) / costmap.resolution_m)
        if mx >= costmap.cols or my >= costmap.rows:
            return LETHAL_OBSTACLE
        cells.append((mx, my))
    worst = 0
    cost = costmap.cost
    # edges 0-1, 1-2, ..., then the closing one walked from the first point to the last (as Nav2 walks it)
    edges = [*itertools.pairwise(cells), (cells[0], cells[-1])]
    for (x0, y0), (x1, y1) in edges:
        worst = max(worst, _line_cost(cost, x0, y0, x1, y1))
        if worst == LETHAL_OBSTACLE:
            break
    return worst
