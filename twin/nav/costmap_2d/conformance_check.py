"""The inflation layer's check against a case recorded from Nav2 Humble's `InflationLayer::updateCosts`.

A case (`tests/unit/nav/costmap_2d/inflation_cases/README.md`) holds the master grid before the call
(`master`), the layer's parameters, the update window and Nav2's master grid after it (`expected`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray


def check_inflation(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """The ways the twin's inflation of `master` differs from Nav2's `expected` (empty: every cell equal)."""
    from twin.nav.costmap_2d._native import load_kernel
    from twin.nav.costmap_2d.layered_costmap import inflate, inflation_cost_table

    if native and load_kernel() is None:
        return ["the C kernel is not available (no C compiler?): only the Python path can be checked"]
    radius = int(meta["cell_inflation_radius"])
    table = inflation_cost_table(
        resolution_m=meta["resolution"],
        inscribed_radius_m=meta["inscribed_radius"],
        cost_scaling_factor=meta["cost_scaling_factor"],
        radius_cells=radius,
    )
    w = meta["window"]
    grid = np.array(arrays["master"], dtype=np.uint8, order="C")
    inflate(
        grid,
        window=(w["min_j"], w["max_j"], w["min_i"], w["max_i"]),
        radius_cells=radius,
        table=table,
        inflate_unknown=meta["inflate_unknown"],
        inflate_around_unknown=meta["inflate_around_unknown"],
        native=native,
    )
    expected = arrays["expected"]
    differing = np.argwhere(grid != expected)
    if not len(differing):
        return []
    row, col = (int(v) for v in differing[0])
    return [
        f"cost: {len(differing)} cells differ, first at (row {row}, column {col}): "
        f"twin {int(grid[row, col])}, Nav2 {int(expected[row, col])}"
    ]
