"""The grid every Nav2 part shares: a costmap's cells in Nav2's cost units, and its geometry.

Cell (row, col) covers world x in [origin_x + col * res, origin_x + (col + 1) * res) and likewise y
with row, as nav2_costmap_2d lays out a Costmap2D (row-major, row = y). Costs are Nav2's:
0 free, 1..252 inflated, 253 inscribed, 254 lethal, 255 unknown (NO_INFORMATION).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["FREE_SPACE", "INSCRIBED_INFLATED_OBSTACLE", "LETHAL_OBSTACLE", "NO_INFORMATION", "CostGrid"]

FREE_SPACE = 0
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255


@dataclass(slots=True, eq=False)
class CostGrid:
    """A costmap's cells (`cost[row, col]`, uint8, Nav2 cost units) over an axis-aligned window of a frame.

    The array is owned and may be rewritten in place by the layer that owns the grid (a rolling
    local costmap moves `origin_*_m`); readers take what is there at the time they read.
    """

    frame_id: str
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    cost: NDArray[np.uint8]

    @property
    def rows(self) -> int:
        """Cells along y."""
        return int(self.cost.shape[0])

    @property
    def cols(self) -> int:
        """Cells along x."""
        return int(self.cost.shape[1])

    def world_to_cell(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        """Return (row, col) of the cell holding a point, or None outside the grid."""
        col = math.floor((x_m - self.origin_x_m) / self.resolution_m)
        row = math.floor((y_m - self.origin_y_m) / self.resolution_m)
        return (row, col) if 0 <= row < self.rows and 0 <= col < self.cols else None

    def cell_centre(self, row: int, col: int) -> tuple[float, float]:
        """World (x, y) of a cell's centre, m."""
        res = self.resolution_m
        return self.origin_x_m + (col + 0.5) * res, self.origin_y_m + (row + 0.5) * res

    def cost_at(self, x_m: float, y_m: float) -> int:
        """Return the cost of the cell holding a point (NO_INFORMATION outside the grid)."""
        cell = self.world_to_cell(x_m, y_m)
        return NO_INFORMATION if cell is None else int(self.cost[cell])

    def occupancy_values(self) -> NDArray[np.int8]:
        """Return the cells as nav_msgs/OccupancyGrid data: Nav2's 0..100 scaling, -1 unknown (row-major).

        nav2_costmap_2d's publisher maps 0 to 0, costs 1..252 to 1 + 97 * (c - 1) // 251 (so 1..98),
        inscribed to 99, lethal to 100 and unknown to -1.
        """
        table = np.empty(256, dtype=np.int8)
        table[0] = 0
        table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
        table[INSCRIBED_INFLATED_OBSTACLE] = 99
        table[LETHAL_OBSTACLE] = 100
        table[NO_INFORMATION] = -1
        return table[self.cost]
