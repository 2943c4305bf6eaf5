"""Costmaps for the navigation tests: Nav2's inflation over an occupancy array, and the house."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from twin.nav.costmap_grid import CostGrid

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


@cache
def house_costmap(inscribed_m: float = 0.22, inflation_m: float = 0.55) -> CostGrid:
    """The house world's global costmap (walls at lidar height, inflated as TB3's waffle global costmap)."""
    from twin.nav import build_grid
    from twin.world import build_scene, load_world

    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf", model_path=[REPO / "sdf" / "models"]))
    nav = build_grid(scene, heights_m=(0.05, 0.15))
    cost = inflate(nav.occupied, nav.resolution_m, inscribed_m=inscribed_m, inflation_m=inflation_m)
    return grid(cost, resolution_m=nav.resolution_m, origin_m=nav.origin_xy_m)
