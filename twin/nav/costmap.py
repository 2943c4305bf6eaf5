"""Nav2's layered costmap (nav2_costmap_2d, Humble): static, obstacle and inflation layers on a `CostGrid`.

One `Costmap` is one costmap node (`global_costmap` or `local_costmap`); `update` is one
`updateMap` cycle, called at `update_frequency`. What each layer does, as Nav2 does it:

- **Static layer**: the `/map` OccupancyGrid read as `StaticLayer::interpretValue` reads it:
  unknown (-1) is NO_INFORMATION when `track_unknown_space` (else free), a value at or above
  `lethal_cost_threshold` (100) is LETHAL, anything else FREE (trinary). A non-rolling costmap
  takes the map's size and origin; the static layer overwrites the master grid.
- **Obstacle layer** (and VoxelLayer, which a planar lidar makes a 2D obstacle layer): for each
  observation, first clearing (Bresenham ray tracing from the sensor cell towards every endpoint,
  clipped to the grid and to `raytrace_max_range`, setting FREE), then marking (endpoints closer
  than `obstacle_max_range` and not closer than `obstacle_min_range` become LETHAL), then the
  robot's footprint is cleared. LaserScan ranges that are inf or outside [range_min, range_max)
  give no point (`inf_is_valid` false). The layer merges into the master by maximum, skipping its
  own unknown cells and overriding the master's unknown.
- **Inflation layer**: every LETHAL cell spreads cost to cells within `inflation_radius`
  (`ceil(inflation_radius / resolution)` cells): distance 0 is 254, distance <= inscribed radius
  253, else `int(252 * exp(-cost_scaling_factor * (d - inscribed_radius)))`, merged by maximum
  (an unknown master cell takes only 253 or more). Distances are exact Euclidean distances between
  cell centres. The inscribed radius is that of the padded footprint: `footprint` if given, else
  Nav2's 16-point circle of `robot_radius`, each point pushed out by `footprint_padding` along x and y.
- **Rolling window** (local costmap): the grid is recentred on the robot before each update,
  its origin moving in whole cells; cells that come into view start at the default value.

`clear_entirely`, `clear_around_robot` and `clear_except_region` are the ClearCostmap services.
The grid's Nav2 0..100 publication values come from `CostGrid.occupancy_values()`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.nav._native import load_kernel
from twin.nav.costmap_grid import (
    FREE_SPACE,
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    CostGrid,
)
from twin.nav.map_server import OccupancyMap
from twin.nav.params import CostmapParams, ObservationSource

__all__ = ["Costmap", "Observation", "footprint_radii", "inflation_costs", "scan_observation"]

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Observation:
    """One scan as the obstacle layer sees it: the sensor's origin and the hit points, in the costmap's frame."""

    origin_x_m: float
    origin_y_m: float
    points_xy_m: F64  # (n, 2)


def scan_observation(
    ranges: NDArray[np.floating],
    *,
    angle_min_rad: float,
    angle_increment_rad: float,
    range_min_m: float,
    range_max_m: float,
    sensor_x_m: float,
    sensor_y_m: float,
    sensor_yaw_rad: float,
) -> Observation:
    """Project a LaserScan into the costmap's frame (the sensor's pose given in that frame).

    Ranges that are not finite or lie outside [range_min, range_max) give no point, as
    laser_geometry's projection does for Nav2's obstacle layer (`inf_is_valid` false).
    """
    r = np.asarray(ranges, dtype=np.float64)
    keep = np.isfinite(r) & (r >= range_min_m) & (r < range_max_m)
    index = np.nonzero(keep)[0]
    angle = sensor_yaw_rad + angle_min_rad + index * angle_increment_rad
    points = np.column_stack([sensor_x_m + r[index] * np.cos(angle), sensor_y_m + r[index] * np.sin(angle)])
    return Observation(origin_x_m=sensor_x_m, origin_y_m=sensor_y_m, points_xy_m=points)


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


def inflation_costs(
    distance_cells: F64,
    *,
    resolution_m: float,
    inscribed_radius_m: float,
    cost_scaling_factor: float,
    radius_cells: int,
) -> U8:
    """Nav2's InflationLayer::computeCost for distances in cells (0 beyond `radius_cells`)."""
    d = np.asarray(distance_cells, dtype=np.float64)
    metres = d * resolution_m
    with np.errstate(over="ignore"):
        factor = np.exp(-cost_scaling_factor * (metres - inscribed_radius_m))
    cost = np.floor((INSCRIBED_INFLATED_OBSTACLE - 1) * factor).astype(np.int64)
    cost = np.where(metres <= inscribed_radius_m, INSCRIBED_INFLATED_OBSTACLE, cost)
    cost = np.where(d == 0.0, LETHAL_OBSTACLE, cost)
    cost = np.where(d > radius_cells, 0, cost)
    return cost.astype(np.uint8)


class _ObstacleLayer:
    def __init__(
        self, sources: tuple[ObservationSource, ...], footprint_clearing: bool, shape: tuple[int, int], default: int
    ) -> None:
        self.sources = sources
        self.footprint_clearing = footprint_clearing
        self.default = default
        self.cost: U8 = np.full(shape, default, dtype=np.uint8)


class Costmap:
    """One Nav2 costmap (global or local): its layers and the master `grid` they write.

    Args:
        params: The costmap node's parameters (`Nav2Params.global_costmap` or `.local_costmap`).
        static_map: The `/map` for the static layer (a costmap without one may receive it later
            through `set_static_map`).
        robot_xy_m: Where a rolling window starts centred.
        native: Ray-trace with the C kernel when it can be built (else numpy; the same cells).
    """

    def __init__(
        self,
        params: CostmapParams,
        *,
        static_map: OccupancyMap | None = None,
        robot_xy_m: tuple[float, float] = (0.0, 0.0),
        native: bool = True,
    ) -> None:
        self.params = params
        self._lib = load_kernel() if native else None
        self.inscribed_radius_m, self.circumscribed_radius_m, self.footprint = footprint_radii(params)
        self._default = NO_INFORMATION if params.track_unknown_space else FREE_SPACE
        self._static: U8 | None = None
        self._obstacles: list[_ObstacleLayer] = []
        res = params.resolution_m
        cols = max(1, int(params.width_m / res))
        rows = max(1, int(params.height_m / res))
        ox, oy = params.origin_x_m, params.origin_y_m
        if params.rolling_window:
            ox, oy = self._snap(robot_xy_m[0] - cols * res / 2.0, robot_xy_m[1] - rows * res / 2.0, ox=0.0, oy=0.0)
        self.grid = CostGrid(
            frame_id=params.global_frame,
            resolution_m=res,
            origin_x_m=ox,
            origin_y_m=oy,
            cost=np.full((rows, cols), self._default, dtype=np.uint8),
        )
        seen: set[tuple[tuple[ObservationSource, ...], bool]] = set()
        for layer in params.obstacle_layers:
            key = (layer.sources, layer.footprint_clearing_enabled)
            # Two layers fed the same sources hold the same cells (TB3's obstacle_layer and
            # voxel_layer, for a planar lidar); their maximum is either one, so keep one.
            if layer.enabled and key not in seen:
                seen.add(key)
                self._obstacles.append(
                    _ObstacleLayer(layer.sources, layer.footprint_clearing_enabled, (rows, cols), self._default)
                )
        inflation = params.inflation
        self._inflate = inflation is not None and inflation.enabled
        self._radius_cells = math.ceil(inflation.inflation_radius_m / res) if inflation is not None else 0
        self._full_update = True
        self._table_cache: tuple[tuple[int, float], U8] | None = None
        if static_map is not None and params.static_layer is not None and params.static_layer.enabled:
            self.set_static_map(static_map)

    # --- inputs ---------------------------------------------------------------------------------

    def set_static_map(self, occupancy: OccupancyMap) -> None:
        """Take a new `/map`: the static layer's costs; a non-rolling costmap takes its size and origin."""
        p = self.params
        raw = occupancy.data.astype(np.int16) & 0xFF  # int8 -1 reads as 255, as the layer's unsigned cast does
        unknown = raw == p.unknown_cost_value
        static = np.where(raw >= p.lethal_cost_threshold, LETHAL_OBSTACLE, FREE_SPACE).astype(np.uint8)
        if not p.trinary_costmap:
            scaled = np.floor(raw / p.lethal_cost_threshold * LETHAL_OBSTACLE).astype(np.uint8)
            static = np.where(raw >= p.lethal_cost_threshold, LETHAL_OBSTACLE, scaled).astype(np.uint8)
        static[unknown] = NO_INFORMATION if p.track_unknown_space else FREE_SPACE
        if not p.rolling_window:
            shape = static.shape
            self.grid.resolution_m = occupancy.resolution_m
            self.grid.origin_x_m = occupancy.origin_x_m
            self.grid.origin_y_m = occupancy.origin_y_m
            self.grid.cost = np.full(shape, self._default, dtype=np.uint8)
            for layer in self._obstacles:
                layer.cost = np.full(shape, layer.default, dtype=np.uint8)
            self._radius_cells = (
                math.ceil(p.inflation.inflation_radius_m / occupancy.resolution_m) if p.inflation is not None else 0
            )
        self._static = static
        self._static_map = occupancy
        self._full_update = True

    def update(
        self, robot_x_m: float, robot_y_m: float, robot_yaw_rad: float, observations: Sequence[Observation] = ()
    ) -> None:
        """Run one update cycle with the robot's pose and the observations since the last one (costmap frame)."""
        if self.params.rolling_window:
            self._roll(robot_x_m, robot_y_m)
        bounds = self._apply_observations(robot_x_m, robot_y_m, robot_yaw_rad, observations)
        rows, cols = self.grid.cost.shape
        if self._full_update or self.params.rolling_window:
            bounds = (0, rows, 0, cols)
            self._full_update = False
        if bounds is not None:
            self._compose(bounds)

    # --- services -------------------------------------------------------------------------------

    def clear_entirely(self) -> None:
        """`clear_entirely_<name>`: reset every layer but the static one and rebuild the master."""
        for layer in self._obstacles:
            layer.cost.fill(layer.default)
        self.grid.cost.fill(self._default)
        self._full_update = True

    def clear_around_robot(self, robot_x_m: float, robot_y_m: float, reset_distance_m: float) -> None:
        """`clear_around_robot`: reset the obstacle layers in the square of side `reset_distance_m` around the robot."""
        r0, r1, c0, c1 = self._window(robot_x_m, robot_y_m, reset_distance_m)
        for layer in self._obstacles:
            layer.cost[r0:r1, c0:c1] = layer.default
        self._full_update = True

    def clear_except_region(self, robot_x_m: float, robot_y_m: float, reset_distance_m: float) -> None:
        """`clear_except_region`: reset the obstacle layers outside that square."""
        r0, r1, c0, c1 = self._window(robot_x_m, robot_y_m, reset_distance_m)
        for layer in self._obstacles:
            keep = layer.cost[r0:r1, c0:c1].copy()
            layer.cost.fill(layer.default)
            layer.cost[r0:r1, c0:c1] = keep
        self._full_update = True

    # --- internals ------------------------------------------------------------------------------

    def _window(self, x: float, y: float, side_m: float) -> tuple[int, int, int, int]:
        g = self.grid
        res = g.resolution_m
        c0 = max(0, int((x - side_m / 2.0 - g.origin_x_m) / res))
        c1 = min(g.cols, int((x + side_m / 2.0 - g.origin_x_m) / res) + 1)
        r0 = max(0, int((y - side_m / 2.0 - g.origin_y_m) / res))
        r1 = min(g.rows, int((y + side_m / 2.0 - g.origin_y_m) / res) + 1)
        return r0, max(r0, r1), c0, max(c0, c1)

    def _snap(self, new_x: float, new_y: float, *, ox: float, oy: float) -> tuple[float, float]:
        res = self.params.resolution_m
        cx, cy = int((new_x - ox) / res), int((new_y - oy) / res)
        return ox + cx * res, oy + cy * res

    def _roll(self, x: float, y: float) -> None:
        g = self.grid
        res = g.resolution_m
        cx = int((x - g.cols * res / 2.0 - g.origin_x_m) / res)
        cy = int((y - g.rows * res / 2.0 - g.origin_y_m) / res)
        if cx == 0 and cy == 0:
            return
        g.origin_x_m += cx * res
        g.origin_y_m += cy * res
        for layer in self._obstacles:
            layer.cost = _shift(layer.cost, cy, cx, layer.default)
        g.cost = _shift(g.cost, cy, cx, self._default)

    def _apply_observations(
        self, x: float, y: float, yaw: float, observations: Sequence[Observation]
    ) -> tuple[int, int, int, int] | None:
        rows, cols = self.grid.cost.shape
        touched: list[NDArray[np.intp]] = []
        for layer in self._obstacles:
            # as ObstacleLayer::updateBounds: every clearing observation first, then every marking one
            for source in layer.sources:
                for obs in observations:
                    if source.clearing:
                        touched.extend(self._observe(layer.cost, obs, source, clearing=True))
            for source in layer.sources:
                for obs in observations:
                    if source.marking:
                        touched.extend(self._observe(layer.cost, obs, source, clearing=False))
            if layer.footprint_clearing:
                touched.extend(self._clear_footprint(layer.cost, x, y, yaw))
        rr = np.concatenate(touched[0::2]) if touched else np.zeros(0, np.intp)
        cc = np.concatenate(touched[1::2]) if touched else np.zeros(0, np.intp)
        if not len(rr):
            return None
        return int(rr.min()), min(rows, int(rr.max()) + 1), int(cc.min()), min(cols, int(cc.max()) + 1)

    def _observe(
        self, cost: U8, obs: Observation, source: ObservationSource, *, clearing: bool
    ) -> list[NDArray[np.intp]]:
        """Clear along (or mark the ends of) one observation's rays; return the touched bounds or cells."""
        if self._lib is None:
            return self._clear(cost, obs, source) if clearing else self._mark(cost, obs, source)
        g = self.grid
        res = g.resolution_m
        rows, cols = cost.shape
        pts = np.ascontiguousarray(obs.points_xy_m, dtype=np.float64)
        bounds = np.array([rows, -1, cols, -1], dtype=np.int64)
        self._lib.twin_obstacle_update(
            cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res, obs.origin_x_m, obs.origin_y_m,
            pts.ctypes.data, len(pts), int(clearing), int(not clearing),
            float(max(0.0, math.ceil(source.raytrace_max_range_m / res))),
            float(max(0.0, math.ceil(source.raytrace_min_range_m / res))),
            source.obstacle_max_range_m, source.obstacle_min_range_m, bounds.ctypes.data,
        )  # fmt: skip
        if bounds[1] < 0:
            return []
        return [np.array([bounds[0], bounds[1]], dtype=np.intp), np.array([bounds[2], bounds[3]], dtype=np.intp)]

    def _clear(self, cost: U8, obs: Observation, source: ObservationSource) -> list[NDArray[np.intp]]:
        g = self.grid
        res = g.resolution_m
        rows, cols = cost.shape
        ox, oy = obs.origin_x_m, obs.origin_y_m
        x0f, y0f = (ox - g.origin_x_m) / res, (oy - g.origin_y_m) / res
        if not (0.0 <= x0f < cols and 0.0 <= y0f < rows) or not len(obs.points_xy_m):
            return []
        x0, y0 = int(x0f), int(y0f)
        map_end_x = g.origin_x_m + cols * res
        map_end_y = g.origin_y_m + rows * res
        wx = obs.points_xy_m[:, 0].copy()
        wy = obs.points_xy_m[:, 1].copy()
        a, b = wx - ox, wy - oy
        with np.errstate(divide="ignore", invalid="ignore"):
            m = wx < g.origin_x_m
            t = (g.origin_x_m - ox) / a[m]
            wx[m], wy[m] = g.origin_x_m, oy + b[m] * t
            m = wy < g.origin_y_m
            t = (g.origin_y_m - oy) / b[m]
            wx[m], wy[m] = ox + a[m] * t, g.origin_y_m
            m = wx > map_end_x
            t = (map_end_x - ox) / a[m]
            wx[m], wy[m] = map_end_x - 0.001, oy + b[m] * t
            m = wy > map_end_y
            t = (map_end_y - oy) / b[m]
            wx[m], wy[m] = ox + a[m] * t, map_end_y - 0.001
        x1 = np.clip(((wx - g.origin_x_m) / res).astype(np.int64), 0, cols - 1)
        y1 = np.clip(((wy - g.origin_y_m) / res).astype(np.int64), 0, rows - 1)
        max_cells = max(0.0, math.ceil(source.raytrace_max_range_m / res))
        min_cells = max(0.0, math.ceil(source.raytrace_min_range_m / res))
        rr, cc = _bresenham(x0, y0, x1, y1, max_cells=max_cells, min_cells=min_cells)
        keep = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)
        rr, cc = rr[keep], cc[keep]
        cost[rr, cc] = FREE_SPACE
        return [rr, cc]

    def _mark(self, cost: U8, obs: Observation, source: ObservationSource) -> list[NDArray[np.intp]]:
        g = self.grid
        pts = obs.points_xy_m
        if not len(pts):
            return []
        d2 = (pts[:, 0] - obs.origin_x_m) ** 2 + (pts[:, 1] - obs.origin_y_m) ** 2
        keep = (d2 < source.obstacle_max_range_m**2) & (d2 >= source.obstacle_min_range_m**2)
        pts = pts[keep]
        fx = (pts[:, 0] - g.origin_x_m) / g.resolution_m
        fy = (pts[:, 1] - g.origin_y_m) / g.resolution_m
        rows, cols = cost.shape
        inside = (fx >= 0) & (fy >= 0) & (fx < cols) & (fy < rows)
        cc, rr = fx[inside].astype(np.intp), fy[inside].astype(np.intp)
        cost[rr, cc] = LETHAL_OBSTACLE
        return [rr, cc]

    def _clear_footprint(self, cost: U8, x: float, y: float, yaw: float) -> list[NDArray[np.intp]]:
        g = self.grid
        c, s = math.cos(yaw), math.sin(yaw)
        poly = np.array([(x + c * px - s * py, y + s * px + c * py) for px, py in self.footprint])
        res = g.resolution_m
        rows, cols = cost.shape
        if self._lib is not None:
            bounds = np.array([rows, -1, cols, -1], dtype=np.int64)
            self._lib.twin_fill_polygon(
                cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res,
                poly.ctypes.data, len(poly), FREE_SPACE, bounds.ctypes.data,
            )  # fmt: skip
            if bounds[1] < 0:
                return []
            return [np.array([bounds[0], bounds[1]], dtype=np.intp), np.array([bounds[2], bounds[3]], dtype=np.intp)]
        c0 = max(0, int((poly[:, 0].min() - g.origin_x_m) / res))
        c1 = min(cols, int((poly[:, 0].max() - g.origin_x_m) / res) + 1)
        r0 = max(0, int((poly[:, 1].min() - g.origin_y_m) / res))
        r1 = min(rows, int((poly[:, 1].max() - g.origin_y_m) / res) + 1)
        if c0 >= c1 or r0 >= r1:
            return []
        xs = g.origin_x_m + (np.arange(c0, c1) + 0.5) * res
        ys = g.origin_y_m + (np.arange(r0, r1) + 0.5) * res
        inside = _in_polygon(xs[None, :], ys[:, None], poly)
        rr, cc = np.nonzero(inside)
        rr, cc = rr + r0, cc + c0
        cost[rr, cc] = FREE_SPACE
        return [rr, cc]

    def _compose(self, bounds: tuple[int, int, int, int]) -> None:
        from scipy import ndimage

        r0, r1, c0, c1 = bounds
        rows, cols = self.grid.cost.shape
        pad = self._radius_cells + 1 if self._inflate else 0
        # the window whose costs may change: the changed cells grown by the inflation radius
        w0, w1, v0, v1 = max(0, r0 - pad), min(rows, r1 + pad), max(0, c0 - pad), min(cols, c1 + pad)
        # the obstacles that reach into that window lie within another inflation radius of it
        e0, e1, f0, f1 = max(0, w0 - pad), min(rows, w1 + pad), max(0, v0 - pad), min(cols, v1 + pad)
        master = self._layers(e0, e1, f0, f1)
        if self._inflate and self.params.inflation is not None:
            infl = self.params.inflation
            seeds = master == LETHAL_OBSTACLE
            if infl.inflate_around_unknown:
                seeds |= master == NO_INFORMATION
            if seeds.any():
                if self._lib is not None:
                    cost = np.empty(master.shape, dtype=np.uint8)
                    table = self._cost_table()
                    seed_cells = np.ascontiguousarray(seeds, dtype=np.uint8)  # kept alive across the call
                    status = self._lib.twin_inflate(
                        seed_cells.ctypes.data, master.shape[0], master.shape[1],
                        table.ctypes.data, len(table) - 1, cost.ctypes.data,
                    )  # fmt: skip
                    if status != 0:
                        raise MemoryError("costmap inflation: out of memory")
                else:
                    distance = np.asarray(ndimage.distance_transform_edt(~seeds), dtype=np.float64)
                    cost = self._costs(distance)
                unknown = master == NO_INFORMATION
                take = (cost > FREE_SPACE) if infl.inflate_unknown else (cost >= INSCRIBED_INFLATED_OBSTACLE)
                master = np.where(unknown, np.where(take, cost, master), np.maximum(master, cost)).astype(np.uint8)
        self.grid.cost[w0:w1, v0:v1] = master[w0 - e0 : w1 - e0, v0 - f0 : v1 - f0]

    def _costs(self, distance_cells: F64) -> U8:
        infl = self.params.inflation
        assert infl is not None
        return inflation_costs(
            distance_cells,
            resolution_m=self.grid.resolution_m,
            inscribed_radius_m=self.inscribed_radius_m,
            cost_scaling_factor=infl.cost_scaling_factor,
            radius_cells=self._radius_cells,
        )

    def _cost_table(self) -> U8:
        """The inflation cost for every squared cell distance 0..R^2."""
        key = (self._radius_cells, self.grid.resolution_m)
        if self._table_cache is None or self._table_cache[0] != key:
            d2 = np.arange(self._radius_cells**2 + 1, dtype=np.float64)
            self._table_cache = (key, np.ascontiguousarray(self._costs(np.sqrt(d2))))
        return self._table_cache[1]

    def _layers(self, r0: int, r1: int, c0: int, c1: int) -> U8:
        """Static (overwrite) then obstacle layers (maximum) over a window; the master before inflation."""
        if self._static is not None and self.params.static_layer is not None and not self.params.rolling_window:
            master = self._static[r0:r1, c0:c1].copy()
        else:
            master = np.full((r1 - r0, c1 - c0), self._default, dtype=np.uint8)
        for layer in self._obstacles:
            obs = layer.cost[r0:r1, c0:c1]
            known = obs != NO_INFORMATION
            take = known & ((master == NO_INFORMATION) | (master < obs))
            master[take] = obs[take]
        return master


def _shift(cost: U8, dr: int, dc: int, fill: int) -> U8:
    """Move a grid's window by (dr, dc) cells: the overlap is kept, new cells are `fill`."""
    rows, cols = cost.shape
    out = np.full_like(cost, fill)
    if abs(dr) < rows and abs(dc) < cols:
        src_r = slice(max(0, dr), rows + min(0, dr))
        dst_r = slice(max(0, -dr), rows + min(0, -dr))
        src_c = slice(max(0, dc), cols + min(0, dc))
        dst_c = slice(max(0, -dc), cols + min(0, -dc))
        out[dst_r, dst_c] = cost[src_r, src_c]
    return out


def _in_polygon(x: F64, y: F64, poly: F64) -> NDArray[np.bool_]:
    """Even-odd test of points (x a row, y a column, broadcast) against a polygon (n, 2)."""
    x1, y1 = poly[:, 0, None, None], poly[:, 1, None, None]
    nxt = np.roll(poly, -1, axis=0)
    x2, y2 = nxt[:, 0, None, None], nxt[:, 1, None, None]
    crosses = (y1 > y[None]) != (y2 > y[None])
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x1 + (y[None] - y1) * (x2 - x1) / (y2 - y1)
    return np.asarray(np.logical_xor.reduce(crosses & (x[None] < xc), axis=0), dtype=bool)


def _bresenham(
    x0: int, y0: int, x1: NDArray[np.int64], y1: NDArray[np.int64], *, max_cells: float, min_cells: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Cells Costmap2D::raytraceLine visits from (x0, y0) towards each (x1, y1), all rays at once.

    As Nav2: rays shorter than `min_cells` are skipped; the start moves `min_cells` along the ray;
    the major axis runs `min(int(scale * |d_major|), |d_major|)` steps with `scale = min(1,
    max_cells / length)`, the minor axis steps when the error (starting at `|d_major| // 2`)
    reaches `|d_major|`; the last cell reached is visited too.
    """
    dxf = (x1 - x0).astype(np.float64)
    dyf = (y1 - y0).astype(np.float64)
    dist = np.hypot(dxf, dyf)
    keep = dist >= min_cells
    x1, y1, dxf, dyf, dist = x1[keep], y1[keep], dxf[keep], dyf[keep], dist[keep]
    with np.errstate(divide="ignore", invalid="ignore"):
        sx0 = np.where(dist > 0, (x0 + dxf / dist * min_cells).astype(np.int64), x0)
        sy0 = np.where(dist > 0, (y0 + dyf / dist * min_cells).astype(np.int64), y0)
        scale = np.where(dist == 0.0, 1.0, np.minimum(1.0, max_cells / np.where(dist == 0.0, 1.0, dist)))
    dx, dy = x1 - sx0, y1 - sy0
    adx, ady = np.abs(dx), np.abs(dy)
    x_major = adx >= ady
    da = np.where(x_major, adx, ady)
    db = np.where(x_major, ady, adx)
    end = np.minimum((scale * da).astype(np.int64), da)
    steps = int(end.max(initial=0)) + 1
    i = np.arange(steps)[None, :]
    valid = i <= end[:, None]
    minor = (da[:, None] // 2 + i * db[:, None]) // np.maximum(da[:, None], 1)
    sa = np.where(x_major, np.sign(dx), np.sign(dy))[:, None]
    sb = np.where(x_major, np.sign(dy), np.sign(dx))[:, None]
    major_off = i * sa
    minor_off = minor * sb
    cx = np.where(x_major[:, None], sx0[:, None] + major_off, sx0[:, None] + minor_off)
    cy = np.where(x_major[:, None], sy0[:, None] + minor_off, sy0[:, None] + major_off)
    return cy[valid].astype(np.intp), cx[valid].astype(np.intp)
