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
- **Inflation layer**: `InflationLayer::updateCosts`'s wavefront (`inflate`). Every LETHAL cell (and
  NO_INFORMATION with `inflate_around_unknown`) of the update window grown by the radius
  (`ceil(inflation_radius / resolution)` cells) is a source; cells are settled by increasing squared
  distance to the source they were reached from through 4-neighbours, which is not always the
  nearest obstacle. A cell's cost for distance d cells (`hypot`): 254 at 0, 253 while
  `d * resolution <= inscribed_radius`, else `int(252 * exp(-cost_scaling_factor * (d * resolution -
  inscribed_radius)))`; merged by maximum (an unknown master cell takes only 253 or more, or any
  positive cost with `inflate_unknown`). The inscribed radius is that of the padded footprint:
  `footprint` if given, else Nav2's 16-point circle of `robot_radius`, each point pushed out by
  `footprint_padding` along x and y.
- **Rolling window** (local costmap): the grid is recentred on the robot before each update,
  its origin moving in whole cells; cells that come into view start at the default value.

`clear_entirely`, `clear_around_robot` and `clear_except_region` are the ClearCostmap services.
The grid's Nav2 0..100 publication values come from `CostGrid.occupancy_values()`.
"""

from __future__ import annotations

import ctypes
import functools
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.nav.costmap_2d._native import load_kernel
from twin.nav.costmap_2d.costmap_2d import (
    FREE_SPACE,
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
    CostGrid,
)
from twin.nav.costmap_2d.footprint import footprint_radii
from twin.nav.map_server.map_io import OccupancyMap
from twin.nav.params import CostmapParams, ObservationSource

__all__ = ["Costmap", "Observation", "inflate", "inflation_cost_table", "scan_observation"]

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

_NO_TABLE: U8 = np.zeros(2, dtype=np.uint8)  # the C kernel's table argument when nothing inflates
# the C kernel's addresses: static layer (or None), obstacle layers, cost table, master
_Addresses = tuple[int | None, "ctypes.Array[ctypes.c_void_p]", int, int]
_NO_CELLS: tuple[NDArray[np.intp], NDArray[np.intp]] = (np.zeros(0, np.intp), np.zeros(0, np.intp))


class _Scan(NamedTuple):
    """A LaserScan's ranges with what projects them: beam directions in the sensor frame, range limits, heading."""

    ranges: F64
    cos_a: F64
    sin_a: F64
    range_min_m: float
    range_max_m: float
    cos_yaw: float
    sin_yaw: float


class Observation:
    """One scan as the obstacle layer sees it: the sensor's origin and the hit points, in the costmap's frame.

    Args:
        origin_x_m: The sensor's x in the costmap's frame.
        origin_y_m: The sensor's y.
        points_xy_m: The hit points (n, 2); None for a scan made by `scan_observation`, whose points are
            projected when first asked for (the C kernel projects the ranges itself, with the same roundings).
        scan: The scan the points come from.
    """

    __slots__ = ("_points", "origin_x_m", "origin_y_m", "scan")

    def __init__(
        self, *, origin_x_m: float, origin_y_m: float, points_xy_m: F64 | None = None, scan: _Scan | None = None
    ) -> None:
        if points_xy_m is None and scan is None:
            raise ValueError("an observation needs its points or its scan")
        self.origin_x_m = origin_x_m
        self.origin_y_m = origin_y_m
        self._points = points_xy_m
        self.scan = scan

    @property
    def points_xy_m(self) -> F64:
        """The hit points (n, 2) in the costmap's frame."""
        if self._points is None:
            assert self.scan is not None
            r, cos_a, sin_a, lo, hi, c, s = self.scan
            index = np.flatnonzero((r >= lo) & (r < hi))  # false for nan and +-inf
            ca, sa, rk = cos_a[index], sin_a[index], r[index]
            points = np.empty((len(index), 2))
            points[:, 0] = self.origin_x_m + rk * (c * ca - s * sa)
            points[:, 1] = self.origin_y_m + rk * (s * ca + c * sa)
            self._points = points
        return self._points


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
    r = np.ascontiguousarray(ranges, dtype=np.float64)
    cos_a, sin_a = _beam_directions(angle_min_rad, angle_increment_rad, len(r))
    scan = _Scan(r, cos_a, sin_a, range_min_m, range_max_m, math.cos(sensor_yaw_rad), math.sin(sensor_yaw_rad))
    return Observation(origin_x_m=sensor_x_m, origin_y_m=sensor_y_m, scan=scan)


@functools.lru_cache(maxsize=8)
def _beam_directions(angle_min_rad: float, angle_increment_rad: float, count: int) -> tuple[F64, F64]:
    """Return cos and sin of each beam's angle in the sensor frame."""
    angle = angle_min_rad + np.arange(count) * angle_increment_rad
    return np.cos(angle), np.sin(angle)


def inflation_cost_table(
    *, resolution_m: float, inscribed_radius_m: float, cost_scaling_factor: float, radius_cells: int
) -> U8:
    """InflationLayer's cached costs: entry [|dx|, |dy|] (cells, dx along x) for 0 <= dx, dy <= `radius_cells`.

    As `computeCaches` fills them: the distance is libm's `hypot(dx, dy)` (numpy's hypot calls it; a
    square root of dx^2 + dy^2 differs from it in the last bit for some cells), the factor libm's
    `exp` (`math.exp`), the product with 252 truncated as the cast to unsigned char does.
    """
    n = radius_cells + 1
    ij = np.arange(n, dtype=np.float64)
    distance = np.hypot(ij[:, None], ij[None, :])
    table = np.empty((n, n), dtype=np.uint8)
    for index, value in np.ndenumerate(distance):
        d = float(value)
        if d == 0.0:
            cost = LETHAL_OBSTACLE
        elif d * resolution_m <= inscribed_radius_m:
            cost = INSCRIBED_INFLATED_OBSTACLE
        else:
            factor = math.exp(-1.0 * cost_scaling_factor * (d * resolution_m - inscribed_radius_m))
            cost = int((INSCRIBED_INFLATED_OBSTACLE - 1) * factor)
        table[index] = cost
    return table


def inflate(
    master: U8,
    *,
    window: tuple[int, int, int, int],
    radius_cells: int,
    table: U8,
    inflate_unknown: bool = False,
    inflate_around_unknown: bool = False,
    native: bool = True,
) -> None:
    """Run InflationLayer::updateCosts on a master grid in place, writing only inside `window`.

    Args:
        master: The master grid (rows, cols), uint8, C-contiguous; its costs before inflation.
        window: (row min, row max, col min, col max), maxima exclusive: Nav2's (min_j, max_j, min_i, max_i).
        radius_cells: `cell_inflation_radius_`; 0 inflates nothing.
        table: `inflation_cost_table` for that radius.
        inflate_unknown: An unknown cell takes any positive cost (else only 253 and 254).
        inflate_around_unknown: Unknown cells are sources too.
        native: Use the C kernel when it can be built (else the numpy path; the same cells).

    Raises:
        ValueError: `master` is not a C-contiguous uint8 grid.
    """
    if master.dtype != np.uint8 or master.ndim != 2 or not master.flags.c_contiguous:
        raise ValueError("inflate: the master grid must be a C-contiguous 2-D uint8 array")
    rows, cols = master.shape
    r0, r1, c0, c1 = (int(v) for v in window)
    r0, r1, c0, c1 = max(0, r0), min(rows, r1), max(0, c0), min(cols, c1)
    if radius_cells <= 0 or r1 <= r0 or c1 <= c0:
        return
    pre = master.copy()
    lib = load_kernel() if native else None
    if lib is not None:
        status = lib.twin_inflate(
            pre.ctypes.data, 0, 0, rows, cols, rows, cols, r0, r1, c0, c1, radius_cells,
            np.ascontiguousarray(table, dtype=np.uint8).ctypes.data, int(inflate_unknown),
            int(inflate_around_unknown), master.ctypes.data,
        )  # fmt: skip
        if status != 0:
            raise MemoryError("costmap inflation: out of memory")
        return
    _inflate_py(
        pre, pre_origin=(0, 0), window=(r0, r1, c0, c1), radius=radius_cells, table=table,
        inflate_unknown=inflate_unknown, around_unknown=inflate_around_unknown, master=master,
    )  # fmt: skip


def _inflate_py(
    pre: U8,
    *,
    pre_origin: tuple[int, int],
    window: tuple[int, int, int, int],
    radius: int,
    table: U8,
    inflate_unknown: bool,
    around_unknown: bool,
    master: U8,
) -> None:
    """The numpy path of `twin_inflate` (costmap_kernels.c): the same wavefront, one distance at a time.

    `pre` holds the costs before inflation over a box from `pre_origin` (row, col) that covers the
    window grown by `radius`; `master` is the whole grid, written inside the window.

    Nav2 takes its queues entry by entry; here a queue is taken whole. That settles the same cells
    from the same sources in the same order: a step to a 4-neighbour changes the squared distance to
    the source by an odd number, so no entry joins the queue being taken; within it the first entry
    of a cell not yet settled wins, as it would one by one; and an entry queued for a cell that is
    settled by the time its queue comes would only be skipped.
    """
    rows, cols = master.shape
    p0, q0 = pre_origin
    w0, w1, v0, v1 = window
    e0, e1, f0, f1 = max(0, w0 - radius), min(rows, w1 + radius), max(0, v0 - radius), min(cols, v1 + radius)
    box = pre[e0 - p0 : e1 - p0, f0 - q0 : f1 - q0]
    is_source = box == LETHAL_OBSTACLE
    if around_unknown:
        is_source |= box == NO_INFORMATION
    y, x = np.nonzero(is_source)  # row-major: Nav2's seeding order
    if not len(y):
        return
    r2 = radius * radius
    # queues[d2]: chunks of entries (x, y, source x, source y) in the order Nav2 appends them
    queues: list[list[tuple[NDArray[np.int64], ...]]] = [[] for _ in range(r2 + 1)]
    x, y = (x + f0).astype(np.int64), (y + e0).astype(np.int64)
    queues[0].append((x, y, x, y))
    settled = np.zeros(rows * cols, dtype=bool)
    out = master.reshape(-1)
    step_x, step_y = np.array([-1, 0, 1, 0]), np.array([0, -1, 0, 1])  # left, down, right, up
    for d2 in range(r2 + 1):
        if not queues[d2]:
            continue
        x, y, sx, sy = (np.concatenate(parts) for parts in zip(*queues[d2], strict=True))
        queues[d2] = []
        cell = y * cols + x
        fresh = ~settled[cell]
        x, y, sx, sy, cell = x[fresh], y[fresh], sx[fresh], sy[fresh], cell[fresh]
        first = np.sort(np.unique(cell, return_index=True)[1])  # a cell's first entry settles it
        x, y, sx, sy, cell = x[first], y[first], sx[first], sy[first], cell[first]
        settled[cell] = True
        inside = (y >= w0) & (y < w1) & (x >= v0) & (x < v1)
        if inside.any():
            c, xi, yi = cell[inside], x[inside], y[inside]
            cost = table[np.abs(xi - sx[inside]), np.abs(yi - sy[inside])]
            old = pre[yi - p0, xi - q0]
            take = (cost > FREE_SPACE) if inflate_unknown else (cost >= INSCRIBED_INFLATED_OBSTACLE)
            out[c] = np.where((old == NO_INFORMATION) & take, cost, np.maximum(old, cost))
        # each settled cell queues its neighbours in Nav2's order, with its source, when within the radius
        nx = (x[:, None] + step_x[None, :]).ravel()
        ny = (y[:, None] + step_y[None, :]).ravel()
        nsx, nsy = np.repeat(sx, 4), np.repeat(sy, 4)
        nd2 = (nx - nsx) ** 2 + (ny - nsy) ** 2
        # within E (see twin_inflate: nothing settled outside it reaches the window) and the radius;
        # not below this distance (Nav2 would queue it where its loop has passed)
        keep = (nx >= f0) & (ny >= e0) & (nx < f1) & (ny < e1) & (nd2 <= r2) & (nd2 > d2)
        keep[keep] = ~settled[ny[keep] * cols + nx[keep]]
        nx, ny, nsx, nsy, nd2 = nx[keep], ny[keep], nsx[keep], nsy[keep], nd2[keep]
        if not len(nd2):
            continue
        order = np.argsort(nd2, kind="stable")
        nx, ny, nsx, nsy, nd2 = nx[order], ny[order], nsx[order], nsy[order], nd2[order]
        values, starts = np.unique(nd2, return_index=True)
        ends = [*starts[1:].tolist(), len(nd2)]
        for value, a, b in zip(values.tolist(), starts.tolist(), ends, strict=True):
            queues[value].append((nx[a:b], ny[a:b], nsx[a:b], nsy[a:b]))


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
        self._footprint_xy = np.array(self.footprint, dtype=np.float64).reshape(-1, 2)
        self._footprint_address = self._footprint_xy.ctypes.data
        self._bounds = np.zeros(4, dtype=np.int64)
        self._bounds_address = self._bounds.ctypes.data
        self._address_cache: tuple[tuple[U8 | None, ...], _Addresses] | None = None
        self._doubles = np.zeros(17)
        self._longs = np.zeros(11, dtype=np.int64)
        self._doubles_address, self._longs_address = self._doubles.ctypes.data, self._longs.ctypes.data
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
        # the one-call update: one obstacle layer fed one source that clears and marks (TB3's costmaps)
        self._single_source: ObservationSource | None = None
        if self._lib is not None and len(self._obstacles) == 1 and len(self._obstacles[0].sources) == 1:
            only = self._obstacles[0].sources[0]
            self._single_source = only if only.clearing and only.marking else None
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
        source = self._single_source
        if source is not None and len(observations) == 1 and observations[0].scan is not None:
            self._scan_update(robot_x_m, robot_y_m, robot_yaw_rad, observations[0], source)
            return
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
            _shift(layer.cost, cy, cx, layer.default)
        # the master needs no shift: a rolling window's update recomposes all of it

    def _scan_update(self, x: float, y: float, yaw: float, obs: Observation, source: ObservationSource) -> None:
        """The whole update in one C call: one layer, one scan source that clears and marks (TB3's costmaps)."""
        assert self._lib is not None and obs.scan is not None
        g = self.grid
        res = g.resolution_m
        rows, cols = g.cost.shape
        scan = obs.scan
        layer = self._obstacles[0]
        base, pointers, table, master = self._addresses()
        full = self._full_update or self.params.rolling_window
        self._full_update = False
        infl = self.params.inflation if self._inflate else None
        self._doubles[:] = (
            g.origin_x_m, g.origin_y_m, res, scan.range_min_m, scan.range_max_m,
            obs.origin_x_m, obs.origin_y_m, scan.cos_yaw, scan.sin_yaw,
            float(max(0.0, math.ceil(source.raytrace_max_range_m / res))),
            float(max(0.0, math.ceil(source.raytrace_min_range_m / res))),
            source.obstacle_max_range_m, source.obstacle_min_range_m, x, y, math.cos(yaw), math.sin(yaw),
        )  # fmt: skip
        self._longs[:] = (
            rows, cols, len(scan.ranges), len(self._footprint_xy) if layer.footprint_clearing else 0,
            self._default, int(full), int(infl is not None), self._radius_cells,
            int(infl is not None and infl.inflate_unknown), int(infl is not None and infl.inflate_around_unknown),
            self._radius_cells + 1 if infl is not None else 0,
        )  # fmt: skip
        status = self._lib.twin_costmap_scan_update(
            pointers[0], base, master, table, scan.ranges.ctypes.data, scan.cos_a.ctypes.data,
            scan.sin_a.ctypes.data, self._footprint_address, self._doubles_address, self._longs_address,
            self._bounds_address,
        )  # fmt: skip
        if status != 0:
            raise MemoryError("costmap update: out of memory")

    def _apply_observations(
        self, x: float, y: float, yaw: float, observations: Sequence[Observation]
    ) -> tuple[int, int, int, int] | None:
        bounds = self._bounds  # rows min, max, cols min, max (inclusive) of the cells written
        rows, cols = self.grid.cost.shape
        bounds[:] = (rows, -1, cols, -1)
        for layer in self._obstacles:
            # as ObstacleLayer::updateBounds: every clearing observation first, then every marking one
            clearing = [(source, obs) for source in layer.sources if source.clearing for obs in observations]
            marking = [(source, obs) for source in layer.sources if source.marking for obs in observations]
            if self._lib is not None and len(clearing) == 1 and clearing == marking:
                source, obs = clearing[0]
                self._observe(layer.cost, obs, source, clearing=True, marking=True)  # one call: clear, then mark
            else:
                for source, obs in clearing:
                    self._observe(layer.cost, obs, source, clearing=True, marking=False)
                for source, obs in marking:
                    self._observe(layer.cost, obs, source, clearing=False, marking=True)
            if layer.footprint_clearing:
                self._clear_footprint(layer.cost, x, y, yaw)
        r0, r1, c0, c1 = (int(v) for v in bounds)
        return None if r1 < 0 else (r0, min(rows, r1 + 1), c0, min(cols, c1 + 1))

    def _grow(self, rr: NDArray[np.intp], cc: NDArray[np.intp]) -> None:
        """Grow the update's bounds by cells written on the numpy path."""
        if len(rr):
            b = self._bounds
            b[0], b[1] = min(b[0], int(rr.min())), max(b[1], int(rr.max()))
            b[2], b[3] = min(b[2], int(cc.min())), max(b[3], int(cc.max()))

    def _observe(self, cost: U8, obs: Observation, source: ObservationSource, *, clearing: bool, marking: bool) -> None:
        """Clear along one observation's rays, then mark their ends, as the source does; grow the bounds."""
        if self._lib is None:
            if clearing:
                self._grow(*self._clear(cost, obs, source))
            if marking:
                self._grow(*self._mark(cost, obs, source))
            return
        g = self.grid
        res = g.resolution_m
        rows, cols = cost.shape
        ray_max = float(max(0.0, math.ceil(source.raytrace_max_range_m / res)))
        ray_min = float(max(0.0, math.ceil(source.raytrace_min_range_m / res)))
        scan = obs.scan
        if scan is not None:  # the kernel projects the ranges
            status = self._lib.twin_scan_update(
                cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res,
                scan.ranges.ctypes.data, len(scan.ranges), scan.cos_a.ctypes.data, scan.sin_a.ctypes.data,
                scan.range_min_m, scan.range_max_m, obs.origin_x_m, obs.origin_y_m, scan.cos_yaw, scan.sin_yaw,
                int(clearing), int(marking), ray_max, ray_min,
                source.obstacle_max_range_m, source.obstacle_min_range_m, self._bounds_address,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("costmap obstacle layer: out of memory")
            return
        pts = obs.points_xy_m
        if not pts.flags.c_contiguous or pts.dtype != np.float64:
            pts = np.ascontiguousarray(pts, dtype=np.float64)
        self._lib.twin_obstacle_update(
            cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res, obs.origin_x_m, obs.origin_y_m,
            pts.ctypes.data, len(pts), int(clearing), int(marking), ray_max, ray_min,
            source.obstacle_max_range_m, source.obstacle_min_range_m, self._bounds_address,
        )  # fmt: skip

    def _clear(
        self, cost: U8, obs: Observation, source: ObservationSource
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        g = self.grid
        res = g.resolution_m
        rows, cols = cost.shape
        ox, oy = obs.origin_x_m, obs.origin_y_m
        x0f, y0f = (ox - g.origin_x_m) / res, (oy - g.origin_y_m) / res
        if not (0.0 <= x0f < cols and 0.0 <= y0f < rows) or not len(obs.points_xy_m):
            return _NO_CELLS
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
        return rr, cc

    def _mark(self, cost: U8, obs: Observation, source: ObservationSource) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        g = self.grid
        pts = obs.points_xy_m
        if not len(pts):
            return _NO_CELLS
        d2 = (pts[:, 0] - obs.origin_x_m) ** 2 + (pts[:, 1] - obs.origin_y_m) ** 2
        keep = (d2 < source.obstacle_max_range_m**2) & (d2 >= source.obstacle_min_range_m**2)
        pts = pts[keep]
        fx = (pts[:, 0] - g.origin_x_m) / g.resolution_m
        fy = (pts[:, 1] - g.origin_y_m) / g.resolution_m
        rows, cols = cost.shape
        inside = (fx >= 0) & (fy >= 0) & (fx < cols) & (fy < rows)
        cc, rr = fx[inside].astype(np.intp), fy[inside].astype(np.intp)
        cost[rr, cc] = LETHAL_OBSTACLE
        return rr, cc

    def _clear_footprint(self, cost: U8, x: float, y: float, yaw: float) -> None:
        g = self.grid
        c, s = math.cos(yaw), math.sin(yaw)
        res = g.resolution_m
        rows, cols = cost.shape
        if self._lib is not None:
            status = self._lib.twin_fill_footprint(
                cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res,
                self._footprint_address, len(self._footprint_xy), x, y, c, s, FREE_SPACE, self._bounds_address,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("costmap footprint clearing: out of memory")
            return
        fx, fy = self._footprint_xy[:, 0], self._footprint_xy[:, 1]
        poly = np.empty((len(fx), 2))
        poly[:, 0] = x + c * fx - s * fy
        poly[:, 1] = y + s * fx + c * fy
        c0 = max(0, int((poly[:, 0].min() - g.origin_x_m) / res))
        c1 = min(cols, int((poly[:, 0].max() - g.origin_x_m) / res) + 1)
        r0 = max(0, int((poly[:, 1].min() - g.origin_y_m) / res))
        r1 = min(rows, int((poly[:, 1].max() - g.origin_y_m) / res) + 1)
        if c0 >= c1 or r0 >= r1:
            return
        xs = g.origin_x_m + (np.arange(c0, c1) + 0.5) * res
        ys = g.origin_y_m + (np.arange(r0, r1) + 0.5) * res
        inside = _in_polygon(xs[None, :], ys[:, None], poly)
        rr, cc = np.nonzero(inside)
        rr, cc = rr + r0, cc + c0
        cost[rr, cc] = FREE_SPACE
        self._grow(rr, cc)

    def _compose(self, bounds: tuple[int, int, int, int]) -> None:
        r0, r1, c0, c1 = bounds
        rows, cols = self.grid.cost.shape
        pad = self._radius_cells + 1 if self._inflate else 0
        reach = self._radius_cells if self._inflate else 0
        # the window whose costs may change: the changed cells grown by the inflation radius
        w0, w1, v0, v1 = max(0, r0 - pad), min(rows, r1 + pad), max(0, c0 - pad), min(cols, c1 + pad)
        # the sources of the inflation: as InflationLayer::updateCosts, the window grown by the radius
        e0, e1, f0, f1 = max(0, w0 - reach), min(rows, w1 + reach), max(0, v0 - reach), min(cols, v1 + reach)
        infl = self.params.inflation if self._inflate else None
        if self._lib is not None:
            base, pointers, table_address, master_address = self._addresses()
            status = self._lib.twin_costmap_compose(
                base, self._default, pointers, len(self._obstacles),
                rows, cols, w0, w1, v0, v1, e0, e1, f0, f1, int(infl is not None), self._radius_cells,
                table_address, int(infl is not None and infl.inflate_unknown),
                int(infl is not None and infl.inflate_around_unknown), master_address,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("costmap update: out of memory")
            return
        pre = self._layers(e0, e1, f0, f1)
        self.grid.cost[w0:w1, v0:v1] = pre[w0 - e0 : w1 - e0, v0 - f0 : v1 - f0]
        if infl is not None and self._radius_cells > 0:
            _inflate_py(
                pre, pre_origin=(e0, f0), window=(w0, w1, v0, v1), radius=self._radius_cells,
                table=self._cost_table(), inflate_unknown=infl.inflate_unknown,
                around_unknown=infl.inflate_around_unknown, master=self.grid.cost,
            )  # fmt: skip

    def _addresses(self) -> _Addresses:
        """Addresses for the C kernel: static layer (or None), obstacle layers, cost table, master (cached)."""
        static = self._static if self._uses_static() else None
        table = self._cost_table() if self._inflate and self.params.inflation is not None else _NO_TABLE
        key = (static, table, self.grid.cost, *(layer.cost for layer in self._obstacles))
        cache = self._address_cache
        if cache is None or len(cache[0]) != len(key) or any(a is not b for a, b in zip(cache[0], key, strict=True)):
            layers = [layer.cost for layer in self._obstacles]
            pointers = (ctypes.c_void_p * max(1, len(layers)))(*[layer.ctypes.data for layer in layers])
            values = (
                None if static is None else int(static.ctypes.data),
                pointers,
                int(table.ctypes.data),
                int(self.grid.cost.ctypes.data),
            )
            cache = self._address_cache = (key, values)
        return cache[1]

    def _uses_static(self) -> bool:
        p = self.params
        return self._static is not None and p.static_layer is not None and not p.rolling_window

    def _cost_table(self) -> U8:
        """InflationLayer's cost cache for the current radius and resolution (`inflation_cost_table`)."""
        infl = self.params.inflation
        assert infl is not None
        key = (self._radius_cells, self.grid.resolution_m)
        if self._table_cache is None or self._table_cache[0] != key:
            table = inflation_cost_table(
                resolution_m=self.grid.resolution_m,
                inscribed_radius_m=self.inscribed_radius_m,
                cost_scaling_factor=infl.cost_scaling_factor,
                radius_cells=self._radius_cells,
            )
            self._table_cache = (key, np.ascontiguousarray(table))
        return self._table_cache[1]

    def _layers(self, r0: int, r1: int, c0: int, c1: int) -> U8:
        """Static (overwrite) then obstacle layers (maximum) over a window; the master before inflation."""
        if self._static is not None and self._uses_static():
            master = self._static[r0:r1, c0:c1].copy()
        else:
            master = np.full((r1 - r0, c1 - c0), self._default, dtype=np.uint8)
        for layer in self._obstacles:
            obs = layer.cost[r0:r1, c0:c1]
            known = obs != NO_INFORMATION
            take = known & ((master == NO_INFORMATION) | (master < obs))
            master[take] = obs[take]
        return master


def _shift(cost: U8, dr: int, dc: int, fill: int) -> None:
    """Move a grid's window by (dr, dc) cells in place: the overlap is kept, new cells are `fill`."""
    rows, cols = cost.shape
    if abs(dr) >= rows or abs(dc) >= cols:
        cost.fill(fill)
        return
    src_r = slice(max(0, dr), rows + min(0, dr))
    dst_r = slice(max(0, -dr), rows + min(0, -dr))
    src_c = slice(max(0, dc), cols + min(0, dc))
    dst_c = slice(max(0, -dc), cols + min(0, -dc))
    cost[dst_r, dst_c] = cost[src_r, src_c].copy()
    if dr > 0:
        cost[rows - dr :, :] = fill
    elif dr < 0:
        cost[:-dr, :] = fill
    if dc > 0:
        cost[:, cols - dc :] = fill
    elif dc < 0:
        cost[:, :-dc] = fill


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
