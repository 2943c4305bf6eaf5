"""Costmaps for the navigation tests: Nav2's inflation over an occupancy array, and the house."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from twin.nav.costmap_2d.costmap_2d import CostGrid

if TYPE_CHECKING:
    from twin.world.scene import Scene

REPO = Path(__file__).resolve().parents[3]


def inflate(
    occupied: NDArray[np.bool_], resolution_m: float, *, inscribed_m: float, inflation_m: float, scaling: float = 3.0
) -> NDArray[np.uint8]:
    """Nav2's inflation: 254 on obstacles, 253 inside the inscribed radius, 252 exp(-k (d - r)) out to the radius."""
    distance_m = distance_transform_edt(~occupied) * resolution_m
    cost = np.zeros(occupied.shape, dtype=np.uint8)
    ring = (distance_m > inscribed_m) & (distance_m <= inflation_m)
    cost[ring] = (252 * np.exp(-scaling * (distance_m[ring] - inscribed_m))).astype(np.uint8)
    cost[distance_m <= inscribed_m] = 253
    cost[occupied] = 254
    return cost


def grid(
    cost: NDArray[np.uint8], *, resolution_m: float = 0.05, origin_m: tuple[float, float] = (0.0, 0.0)
) -> CostGrid:
    """A CostGrid in frame `map` over `cost`."""
    return CostGrid(
        frame_id="map", resolution_m=resolution_m, origin_x_m=origin_m[0], origin_y_m=origin_m[1], cost=cost
    )


def _walls(scene: Scene, heights_m: tuple[float, ...], resolution_m: float, padding_m: float) -> tuple[Any, ...]:
    """The world's obstacle outlines at `heights_m` marked on a grid over their bounds plus `padding_m`."""
    (x0, y0, _), (x1, y1, _) = scene.bounds
    x0, y0, x1, y1 = x0 - padding_m, y0 - padding_m, x1 + padding_m, y1 + padding_m
    cols, rows = math.ceil((x1 - x0) / resolution_m), math.ceil((y1 - y0) / resolution_m)
    occupied = np.zeros((rows, cols), dtype=bool)
    origin = np.array([x0, y0])

    def mark(points: NDArray[np.float64]) -> None:
        cells = np.floor((points - origin) / resolution_m).astype(np.int64)
        keep = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
        occupied[cells[keep, 1], cells[keep, 0]] = True

    for height in heights_m:
        caster = scene.ray_caster(height)
        for sx, sy, ex, ey in np.asarray(caster.segments, dtype=np.float64).reshape(-1, 4):
            n = max(2, math.ceil(math.hypot(ex - sx, ey - sy) / (0.25 * resolution_m)) + 1)
            t = np.linspace(0.0, 1.0, n)[:, None]
            mark(np.array([sx, sy]) + t * np.array([ex - sx, ey - sy]))
        for cx, cy, r in np.asarray(caster.circles, dtype=np.float64).reshape(-1, 3):
            xs = x0 + (np.arange(cols) + 0.5) * resolution_m
            ys = y0 + (np.arange(rows) + 0.5) * resolution_m
            occupied |= (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2 <= (r + 0.5 * resolution_m) ** 2
    return occupied, (float(x0), float(y0))


@cache
def house_costmap(inscribed_m: float = 0.22, inflation_m: float = 0.55) -> CostGrid:
    """The house world's global costmap (walls at two heights through the robot, inflated as TB3's waffle global costmap)."""
    from twin.world import build_scene, load_world

    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf", model_path=[REPO / "sdf" / "models"]))
    occupied, origin = _walls(scene, (0.05, 0.15), 0.05, 1.0)
    cost = inflate(occupied, 0.05, inscribed_m=inscribed_m, inflation_m=inflation_m)
    return grid(cost, resolution_m=0.05, origin_m=origin)
