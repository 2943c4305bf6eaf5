"""The costmap's checks against cases recorded from Nav2 Humble's nav2_costmap_2d.

- `check_inflation`: one `InflationLayer::updateCosts` (`tests/unit/nav/costmap_2d/inflation_cases/`):
  the master grid before the call (`master`), the layer's parameters, the window, Nav2's grid after it.
- `check_static`, `check_publish`, `check_footprint`, `check_layer`: the static layer's costs from an
  OccupancyGrid, the published 0..100 values, FootprintCollisionChecker's cost at poses, and an
  obstacle or voxel layer's own grid after update cycles (`costmap_<part>_cases/`, each with a README).
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


def _cells_differ(what: str, got: NDArray[Any], want: NDArray[Any]) -> list[str]:
    if got.shape != want.shape:
        return [f"{what}: shape {got.shape}, Nav2 {want.shape}"]
    differing = np.argwhere(got != want)
    if not len(differing):
        return []
    index = tuple(int(v) for v in differing[0])
    return [f"{what}: {len(differing)} cells differ, first at {index}: twin {got[index]!r}, Nav2 {want[index]!r}"]


def layers_fields(meta: Mapping[str, Any]) -> dict[str, Any]:
    """The costmap-wide parameters a static case names."""
    return {
        "track_unknown_space": bool(meta["track_unknown_space"]),
        "unknown_cost_value": int(meta["unknown_cost_value"]),
        "lethal_cost_threshold": int(meta["lethal_cost_threshold"]),
        "trinary_costmap": bool(meta["trinary_costmap"]),
    }


def check_static(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """StaticLayer's costs for the case's OccupancyGrid (`data`) against Nav2's (`expected`)."""
    from twin.nav.costmap_2d.layered_costmap import static_layer_costs
    from twin.nav.params import CostmapParams

    params = CostmapParams(name="global_costmap", **layers_fields(meta))
    return _cells_differ("static layer", static_layer_costs(arrays["data"], params), arrays["expected"])


def check_publish(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """The published 0..100 values of a grid (`costs`): both of the twin's tables against Costmap2DPublisher's."""
    from twin.nav.costmap_2d.costmap_2d import CostGrid
    from twin.nav.costmap_2d.costmap_node import costmap_translation

    costs = np.ascontiguousarray(arrays["costs"], dtype=np.uint8)
    grid = CostGrid(frame_id="map", resolution_m=0.05, origin_x_m=0.0, origin_y_m=0.0, cost=costs.reshape(-1, 1))
    published = grid.occupancy_values().reshape(costs.shape)
    node_table = costmap_translation()[costs]
    return _cells_differ("CostGrid.occupancy_values", published, arrays["expected"]) + _cells_differ(
        "costmap node's table", node_table, arrays["expected"]
    )


def check_footprint(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """FootprintCollisionChecker::footprintCostAtPose at each of the case's poses: the twin's `footprint_cost`."""
    from twin.nav.costmap_2d._native import load_kernel
    from twin.nav.costmap_2d.costmap_2d import CostGrid
    from twin.nav.costmap_2d.footprint import footprint_cost, footprint_cost_py

    if native and load_kernel() is None:
        return ["the C kernel is not available (no C compiler?): only the Python path can be checked"]
    grid = CostGrid(
        frame_id="map",
        resolution_m=float(meta["resolution"]),
        origin_x_m=float(meta["origin_x"]),
        origin_y_m=float(meta["origin_y"]),
        cost=np.ascontiguousarray(arrays["grid"], dtype=np.uint8),
    )
    footprint = tuple((float(x), float(y)) for x, y in meta["footprint"])
    cost = footprint_cost if native else footprint_cost_py
    got = np.array([cost(grid, footprint, (float(x), float(y), float(t))) for x, y, t in arrays["poses"]])
    return _cells_differ("footprint cost", got.astype(np.float64), arrays["expected"])


def check_layer(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """An ObstacleLayer's or VoxelLayer's grid (and voxels) after the case's update cycles, and its origin."""
    from twin.nav.costmap_2d._native import load_kernel
    from twin.nav.costmap_2d.layered_costmap import Costmap, Observation
    from twin.nav.params import CostmapParams, ObservationSource, ObstacleLayerParams

    if native and load_kernel() is None:
        return ["the C kernel is not available (no C compiler?): only the Python path can be checked"]
    res = float(meta["resolution"])
    cols, rows = int(meta["size_x"]), int(meta["size_y"])
    width = max((len(c["observations"]) for c in meta["cycles"]), default=0)
    sources = []
    for j in range(width):
        o = next(c["observations"][j] for c in meta["cycles"] if len(c["observations"]) > j)
        sources.append(
            ObservationSource(
                name=f"source{j}",
                clearing=bool(o["clearing"]),
                marking=bool(o["marking"]),
                obstacle_max_range_m=float(o["obstacle_max_range"]),
                obstacle_min_range_m=float(o["obstacle_min_range"]),
                raytrace_max_range_m=float(o["raytrace_max_range"]),
                raytrace_min_range_m=float(o["raytrace_min_range"]),
            )
        )
    layer = ObstacleLayerParams(
        name=f"{meta['kind']}_layer",
        plugin="nav2_costmap_2d::VoxelLayer" if meta["kind"] == "voxel" else "nav2_costmap_2d::ObstacleLayer",
        footprint_clearing_enabled=bool(meta["footprint_clearing_enabled"]),
        min_obstacle_height_m=float(meta["min_obstacle_height"]),
        max_obstacle_height_m=float(meta["max_obstacle_height"]),
        origin_z_m=float(meta["origin_z"]),
        z_resolution_m=float(meta["z_resolution"]),
        z_voxels=int(meta["z_voxels"]),
        unknown_threshold=int(meta["unknown_threshold"]),
        mark_threshold=int(meta["mark_threshold"]),
        sources=tuple(sources),
    )
    params = CostmapParams(
        name="costmap",
        rolling_window=bool(meta["rolling_window"]),
        width_m=(cols + 0.5) * res,
        height_m=(rows + 0.5) * res,
        resolution_m=res,
        origin_x_m=float(meta["origin_x"]),
        origin_y_m=float(meta["origin_y"]),
        footprint=tuple((float(x), float(y)) for x, y in meta["footprint"]),
        footprint_padding_m=0.0,
        track_unknown_space=int(meta["default_value"]) == 255,
        plugins=(layer.name,),
        obstacle_layers=(layer,),
    )
    costmap = Costmap(params, native=native)
    costmap.grid.origin_x_m, costmap.grid.origin_y_m = float(meta["origin_x"]), float(meta["origin_y"])
    (cost, voxels), *_ = costmap.layer_grids
    cost[...] = arrays["layer"]
    if voxels is not None:
        voxels[...] = arrays["voxel"]
    for i, cycle in enumerate(meta["cycles"]):
        observations = []
        for j, o in enumerate(cycle["observations"]):
            x, y, z = (float(v) for v in o["origin"])
            points = np.asarray(arrays[f"points_{i}_{j}"], dtype=np.float64).reshape(-1, 3)
            observations.append(
                Observation(origin_x_m=x, origin_y_m=y, origin_z_m=z, points_xy_m=points, source=f"source{j}")
            )
        x, y, yaw = (float(v) for v in cycle["robot"])
        costmap.update_layers(x, y, yaw, observations)
    (cost, voxels), *_ = costmap.layer_grids
    out = _cells_differ("layer", cost, arrays["expected_layer"])
    if voxels is not None:
        out += _cells_differ("voxels", voxels, arrays["expected_voxel"])
    origin = np.array([costmap.grid.origin_x_m, costmap.grid.origin_y_m])
    if not np.array_equal(origin, arrays["expected_origin"]):
        out.append(f"origin: twin {origin.tolist()}, Nav2 {arrays['expected_origin'].tolist()}")
    return out
