"""Nav2's layered costmap (nav2_costmap_2d, Humble): static, obstacle, voxel and inflation layers on a `CostGrid`.

One `Costmap` is one costmap node (`global_costmap` or `local_costmap`); `update` is one
`updateMap` cycle, called at `update_frequency`. What each layer does, as Nav2 does it:

- **Static layer**: the `/map` OccupancyGrid read as `StaticLayer::interpretValue` reads it:
  unknown (-1) is NO_INFORMATION when `track_unknown_space` (else free), a value at or above
  `lethal_cost_threshold` (100) is LETHAL, anything else FREE (trinary). A non-rolling costmap
  takes the map's size and origin; the static layer overwrites the master grid.
- **Obstacle layer** (`ObstacleLayer::updateBounds`): for each observation, first clearing
  (`raytraceFreespace`: nothing with the sensor off the grid; each point clipped to the grid, a ray
  whose clipped end is still off it skipped; Bresenham from the sensor's cell, at most
  `cellDistance(raytrace_max_range)` cells, setting FREE), then marking (with the sensor on the grid,
  a point within the layer's `min/max_obstacle_height` whose cell lies within
  `cellDistance(obstacle_max_range)` whole cells of the sensor's, `(unsigned) hypot`, and not below
  `cellDistance(obstacle_min_range)`, becomes LETHAL), then the robot's footprint is cleared as
  `setConvexPolygonCost` fills it. LaserScan ranges that are inf or outside [range_min, range_max)
  give no point (`inf_is_valid` false). The layer merges into the master by maximum, skipping its
  own unknown cells and overriding the master's unknown.
- **Voxel layer** (`VoxelLayer`, nav2_voxel_grid's uint32 columns: bit z and bit z + 16 of a voxel,
  both set marked, one unknown, none free; fresh columns all unknown): clearing pulls each point 2
  cells towards the sensor, clips it to the grid ((n - 0.5) cells, as `getSizeInMetersX`) and
  clears the voxels of a 3-D Bresenham from the sensor's fractional voxel, setting a cell FREE when
  its column's marked bits are within `mark_threshold` and its unknown bits within
  `unknown_threshold` + 16 - `z_voxels` (else unknown); marking takes points under
  `max_obstacle_height` closer than `obstacle_max_range` in metres (3-D) and sets LETHAL when the
  column's marked bits exceed `mark_threshold`. TB3's params run it beside an obstacle layer on the
  same scan; both are kept.
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
- **Rolling window** (local costmap): before each update the origin moves by the whole cells
  (truncated) from it to `robot - getSizeInMetersX() / 2`, where a grid of n cells measures
  (n - 0.5) cells; cells that come into view start at the default value (voxel columns unknown).

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
from twin.nav.params import CostmapParams, ObservationSource, ObstacleLayerParams

__all__ = ["Costmap", "Observation", "inflate", "inflation_cost_table", "scan_observation", "static_layer_costs"]

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

_NO_TABLE: U8 = np.zeros(2, dtype=np.uint8)  # the C kernel's table argument when nothing inflates
# the C kernel's addresses: static layer (or None), obstacle layers, cost table, master
_Addresses = tuple[int | None, "ctypes.Array[ctypes.c_void_p]", int, int]
# what Costmap._one_call passes per layer: doubles, longs, grid and voxel addresses, footprint clearing
_OneCall = tuple[
    F64, NDArray[np.int64], "ctypes.Array[ctypes.c_void_p]", "ctypes.Array[ctypes.c_void_p]", NDArray[np.int64]
]
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
    """One scan or point cloud as the obstacle layers see it: the sensor's origin and its points (costmap frame).

    Args:
        origin_x_m: The sensor's x in the costmap's frame.
        origin_y_m: The sensor's y.
        origin_z_m: The sensor's height (the voxel layer's rays run in 3-D; a planar lidar's points share it).
        points_xy_m: The points (n, 2), at the sensor's height, or (n, 3); None for a scan made by
            `scan_observation`, whose points are projected when first asked for (the C kernel projects the
            ranges itself, with the same roundings).
        scan: The scan the points come from.
        source: The observation source that made it: its name, or `<layer>.<source>` for one layer's
            alone (None: every source of every obstacle layer takes it).
    """

    __slots__ = ("_points", "origin_x_m", "origin_y_m", "origin_z_m", "scan", "source")

    def __init__(
        self,
        *,
        origin_x_m: float,
        origin_y_m: float,
        origin_z_m: float = 0.0,
        points_xy_m: F64 | None = None,
        scan: _Scan | None = None,
        source: str | None = None,
    ) -> None:
        if points_xy_m is None and scan is None:
            raise ValueError("an observation needs its points or its scan")
        self.origin_x_m = origin_x_m
        self.origin_y_m = origin_y_m
        self.origin_z_m = origin_z_m
        self._points: F64 | None = None
        if points_xy_m is not None:
            pts = np.asarray(points_xy_m, dtype=np.float64).reshape(len(points_xy_m), -1)
            if pts.shape[1] == 2:
                pts = np.column_stack([pts, np.full(len(pts), origin_z_m)])
            self._points = np.ascontiguousarray(pts[:, :3])
        self.scan = scan
        self.source = source

    @property
    def points_xy_m(self) -> F64:
        """The points (n, 2) in the costmap's frame."""
        return self.points_xyz_m[:, :2]

    @property
    def points_xyz_m(self) -> F64:
        """The points (n, 3): x, y and height in the costmap's frame (C-contiguous)."""
        if self._points is None:
            assert self.scan is not None
            r, cos_a, sin_a, lo, hi, c, s = self.scan
            index = np.flatnonzero((r >= lo) & (r < hi))  # false for nan and +-inf
            ca, sa, rk = cos_a[index], sin_a[index], r[index]
            points = np.empty((len(index), 3))
            points[:, 0] = self.origin_x_m + rk * (c * ca - s * sa)
            points[:, 1] = self.origin_y_m + rk * (s * ca + c * sa)
            points[:, 2] = self.origin_z_m
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
    sensor_z_m: float = 0.0,
    source: str | None = None,
) -> Observation:
    """Project a LaserScan into the costmap's frame (the sensor's pose given in that frame).

    Ranges that are not finite or lie outside [range_min, range_max) give no point, as
    laser_geometry's projection does for Nav2's obstacle layer (`inf_is_valid` false); every point
    is at the sensor's height. `source` names the observation source it is for (None: every one).
    """
    r = np.ascontiguousarray(ranges, dtype=np.float64)
    cos_a, sin_a = _beam_directions(angle_min_rad, angle_increment_rad, len(r))
    scan = _Scan(r, cos_a, sin_a, range_min_m, range_max_m, math.cos(sensor_yaw_rad), math.sin(sensor_yaw_rad))
    return Observation(origin_x_m=sensor_x_m, origin_y_m=sensor_y_m, origin_z_m=sensor_z_m, scan=scan, source=source)


@functools.lru_cache(maxsize=8)
def _beam_directions(angle_min_rad: float, angle_increment_rad: float, count: int) -> tuple[F64, F64]:
    """Return cos and sin of each beam's angle in the sensor frame."""
    angle = angle_min_rad + np.arange(count) * angle_increment_rad
    return np.cos(angle), np.sin(angle)


def static_layer_costs(data: NDArray[np.int8], params: CostmapParams) -> U8:
    """StaticLayer's costs for an OccupancyGrid's cells (`processMap` with `interpretValue`).

    Each value is read as an unsigned char (-1 is 255): the `unknown_cost_value` is NO_INFORMATION
    with `track_unknown_space` (else FREE); at or above `lethal_cost_threshold` LETHAL; anything else
    FREE when `trinary_costmap`, else `value / threshold * 254` truncated.
    """
    p = params
    raw = np.asarray(data).astype(np.int16) & 0xFF
    static = np.where(raw >= p.lethal_cost_threshold, LETHAL_OBSTACLE, FREE_SPACE).astype(np.uint8)
    if not p.trinary_costmap:
        scaled = np.floor(raw / p.lethal_cost_threshold * LETHAL_OBSTACLE).astype(np.uint8)
        static = np.where(raw >= p.lethal_cost_threshold, LETHAL_OBSTACLE, scaled).astype(np.uint8)
    static[raw == p.unknown_cost_value] = NO_INFORMATION if p.track_unknown_space else FREE_SPACE
    return static


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


_FRESH_COLUMN = 0xFFFF  # VoxelGrid::reset: every voxel of a column unknown


def _takes(layer: _ObstacleLayer, source: ObservationSource, tag: str | None) -> bool:
    """Whether an observation tagged `tag` is `source`'s: untagged, its name, or `<layer>.<source>`."""
    return tag is None or tag in (source.name, f"{layer.params.name}.{source.name}")


class _ObstacleLayer:
    """An ObstacleLayer's or VoxelLayer's own grid (and a VoxelLayer's voxel columns, uint32 as nav2_voxel_grid's)."""

    def __init__(self, params: ObstacleLayerParams, shape: tuple[int, int], default: int) -> None:
        self.params = params
        self.sources = params.sources
        self.footprint_clearing = params.footprint_clearing_enabled
        self.default = default
        self.cost: U8 = np.full(shape, default, dtype=np.uint8)
        self.voxels: NDArray[np.uint32] | None = (
            np.full(shape, _FRESH_COLUMN, dtype=np.uint32) if params.voxel else None
        )
        # VoxelLayer: origin_z, z_resolution, max_obstacle_height; z_voxels, unknown threshold, mark_threshold
        self.voxel_doubles = np.array([params.origin_z_m, params.z_resolution_m, params.max_obstacle_height_m])
        unknown = params.unknown_threshold + (16 - params.z_voxels)  # as VoxelLayer::onInitialize
        self.voxel_longs = np.array([params.z_voxels, unknown, params.mark_threshold], dtype=np.int64)

    def reset(self) -> None:
        """Every cell (and voxel) back to the layer's start."""
        self.cost.fill(self.default)
        if self.voxels is not None:
            self.voxels.fill(_FRESH_COLUMN)


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
        self._doubles = np.zeros(18)
        self._longs10 = np.zeros(10, dtype=np.int64)
        self._one_call_plan: tuple[tuple[str | None, float], _OneCall | None] | None = None
        self._longs = np.zeros(6, dtype=np.int64)
        self._doubles_address, self._longs_address = self._doubles.ctypes.data, self._longs.ctypes.data
        self._default = NO_INFORMATION if params.track_unknown_space else FREE_SPACE
        self._static: U8 | None = None
        self._obstacles: list[_ObstacleLayer] = []
        res = params.resolution_m
        cols = max(1, int(params.width_m / res))
        rows = max(1, int(params.height_m / res))
        ox, oy = params.origin_x_m, params.origin_y_m
        if params.rolling_window:
            ox, oy = self._snap(robot_xy_m[0], robot_xy_m[1], cols=cols, rows=rows, ox=ox, oy=oy)
        self.grid = CostGrid(
            frame_id=params.global_frame,
            resolution_m=res,
            origin_x_m=ox,
            origin_y_m=oy,
            cost=np.full((rows, cols), self._default, dtype=np.uint8),
        )
        seen: set[ObstacleLayerParams] = set()
        for layer in params.obstacle_layers:
            # Two layers of the same kind and parameters fed the same sources hold the same cells; their
            # maximum is either one, so keep one. An ObstacleLayer and a VoxelLayer (TB3's pair) differ:
            # the voxel layer clears 2 cells short of each point and marks by the 3-D distance in metres.
            key = ObstacleLayerParams(**{**{f: getattr(layer, f) for f in layer.__slots__}, "name": ""})
            if layer.enabled and key not in seen:
                seen.add(key)
                self._obstacles.append(_ObstacleLayer(layer, (rows, cols), self._default))
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
        static = static_layer_costs(occupancy.data, p)
        if not p.rolling_window:
            shape = static.shape
            self.grid.resolution_m = occupancy.resolution_m
            self.grid.origin_x_m = occupancy.origin_x_m
            self.grid.origin_y_m = occupancy.origin_y_m
            self.grid.cost = np.full(shape, self._default, dtype=np.uint8)
            for layer in self._obstacles:
                layer.cost = np.full(shape, layer.default, dtype=np.uint8)
                if layer.voxels is not None:
                    layer.voxels = np.full(shape, _FRESH_COLUMN, dtype=np.uint32)
            self._one_call_plan = None  # it holds the old grids' addresses
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
        if len(observations) == 1 and self._one_call(robot_x_m, robot_y_m, robot_yaw_rad, observations[0]):
            return
        bounds = self._apply_observations(robot_x_m, robot_y_m, robot_yaw_rad, observations)
        rows, cols = self.grid.cost.shape
        if self._full_update or self.params.rolling_window:
            bounds = (0, rows, 0, cols)
            self._full_update = False
        if bounds is not None:
            self._compose(bounds)

    @property
    def layer_grids(self) -> list[tuple[U8, NDArray[np.uint32] | None]]:
        """Each obstacle/voxel layer's own cells and a voxel layer's columns (None for an obstacle layer), writable."""
        return [(layer.cost, layer.voxels) for layer in self._obstacles]

    def update_layers(
        self, robot_x_m: float, robot_y_m: float, robot_yaw_rad: float, observations: Sequence[Observation] = ()
    ) -> None:
        """The obstacle layers' part of `update` only (rolling, clearing, marking, footprint clearing); no master."""
        if self.params.rolling_window:
            self._roll(robot_x_m, robot_y_m)
        self._apply_observations(robot_x_m, robot_y_m, robot_yaw_rad, observations)
        self._full_update = True

    # --- services -------------------------------------------------------------------------------

    def clear_entirely(self) -> None:
        """`clear_entirely_<name>`: reset every layer but the static one and rebuild the master."""
        for layer in self._obstacles:
            layer.reset()
        self.grid.cost.fill(self._default)
        self._full_update = True

    def clear_around_robot(self, robot_x_m: float, robot_y_m: float, reset_distance_m: float) -> None:
        """`clear_around_robot`: reset the obstacle layers in the square of side `reset_distance_m` around the robot."""
        r0, r1, c0, c1 = self._window(robot_x_m, robot_y_m, reset_distance_m)
        for layer in self._obstacles:
            layer.cost[r0:r1, c0:c1] = layer.default
            if layer.voxels is not None:
                layer.voxels[r0:r1, c0:c1] = _FRESH_COLUMN
        self._full_update = True

    def clear_except_region(self, robot_x_m: float, robot_y_m: float, reset_distance_m: float) -> None:
        """`clear_except_region`: reset the obstacle layers outside that square."""
        r0, r1, c0, c1 = self._window(robot_x_m, robot_y_m, reset_distance_m)
        for layer in self._obstacles:
            keep = layer.cost[r0:r1, c0:c1].copy()
            layer.cost.fill(layer.default)
            layer.cost[r0:r1, c0:c1] = keep
            if layer.voxels is not None:
                kept = layer.voxels[r0:r1, c0:c1].copy()
                layer.voxels.fill(_FRESH_COLUMN)
                layer.voxels[r0:r1, c0:c1] = kept
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

    def _snap(self, x: float, y: float, *, cols: int, rows: int, ox: float, oy: float) -> tuple[float, float]:
        """The origin Costmap2D::updateOrigin moves a rolling grid at (ox, oy) to for a robot at (x, y).

        Nav2 asks for `robot - getSizeInMetersX() / 2`, where a grid of n cells measures (n - 1 + 0.5)
        cells, and moves by the whole cells of the difference, truncated towards zero.
        """
        res = self.params.resolution_m
        cx = int((x - (cols - 1 + 0.5) * res / 2 - ox) / res)
        cy = int((y - (rows - 1 + 0.5) * res / 2 - oy) / res)
        return ox + cx * res, oy + cy * res

    def _roll(self, x: float, y: float) -> None:
        g = self.grid
        res = g.resolution_m
        cx = int((x - (g.cols - 1 + 0.5) * res / 2 - g.origin_x_m) / res)
        cy = int((y - (g.rows - 1 + 0.5) * res / 2 - g.origin_y_m) / res)
        if cx == 0 and cy == 0:
            return
        g.origin_x_m += cx * res
        g.origin_y_m += cy * res
        for layer in self._obstacles:
            _shift(layer.cost, cy, cx, layer.default)
            if layer.voxels is not None:
                _shift(layer.voxels, cy, cx, _FRESH_COLUMN)
        # the master needs no shift: a rolling window's update recomposes all of it

    def _one_call(self, x: float, y: float, yaw: float, obs: Observation) -> bool:
        """Run `update` in one C call (twin_costmap_scan_update); False when it needs the general path.

        It applies when every layer takes the scan through one source that clears and marks (TB3's costmaps).
        """
        scan = obs.scan
        if self._lib is None or scan is None or not self._obstacles:
            return False
        plan = self._one_call_plan
        if plan is None or plan[0] != (obs.source, self.grid.resolution_m):
            plan = self._one_call_plan = self._plan_one_call(obs.source)
        if plan[1] is None:
            return False
        layer_d, layer_k, pointers, voxel_pointers, fp_clear = plan[1]
        g = self.grid
        layer_d[:, :10] = (
            g.origin_x_m, g.origin_y_m, g.resolution_m, scan.range_min_m, scan.range_max_m,
            obs.origin_x_m, obs.origin_y_m, obs.origin_z_m, scan.cos_yaw, scan.sin_yaw,
        )  # fmt: skip
        layer_k[:, 0] = len(scan.ranges)
        rows, cols = g.cost.shape
        base, _, table, master = self._addresses()
        full = self._full_update or self.params.rolling_window
        self._full_update = False
        infl = self.params.inflation if self._inflate else None
        self._doubles[:4] = (x, y, math.cos(yaw), math.sin(yaw))
        self._longs10[:] = (
            rows, cols, len(self._footprint_xy), self._default, int(full), int(infl is not None), self._radius_cells,
            int(infl is not None and infl.inflate_unknown), int(infl is not None and infl.inflate_around_unknown),
            self._radius_cells + 1 if infl is not None else 0,
        )  # fmt: skip
        status = self._lib.twin_costmap_scan_update(
            pointers, voxel_pointers, len(self._obstacles), fp_clear.ctypes.data, layer_d.ctypes.data,
            layer_k.ctypes.data, base, master, table, scan.ranges.ctypes.data, scan.cos_a.ctypes.data,
            scan.sin_a.ctypes.data, self._footprint_address, self._doubles_address, self._longs10.ctypes.data,
            self._bounds_address,
        )  # fmt: skip
        if status != 0:
            raise MemoryError("costmap update: out of memory")
        return True

    def _plan_one_call(self, source_name: str | None) -> tuple[tuple[str | None, float], _OneCall | None]:
        """What `_one_call` passes for each layer (its constants filled once), or None when it does not apply."""
        key = (source_name, self.grid.resolution_m)
        n = len(self._obstacles)
        layer_d, layer_k = np.zeros((n, 18)), np.zeros((n, 6), dtype=np.int64)
        for i, layer in enumerate(self._obstacles):
            taking = [s for s in layer.sources if _takes(layer, s, source_name)]
            if len(taking) != 1 or not (taking[0].clearing and taking[0].marking):
                return key, None
            source, lp = taking[0], layer.params
            voxel = layer.voxels is not None
            layer_d[i, 10:] = (
                self._cells(source.raytrace_max_range_m), self._cells(source.raytrace_min_range_m),
                source.obstacle_max_range_m if voxel else self._cells(source.obstacle_max_range_m),
                source.obstacle_min_range_m if voxel else self._cells(source.obstacle_min_range_m),
                lp.min_obstacle_height_m, lp.max_obstacle_height_m, lp.origin_z_m, lp.z_resolution_m,
            )  # fmt: skip
            layer_k[i] = (0, 1, 1, *layer.voxel_longs.tolist())
        pointers = (ctypes.c_void_p * n)(*[layer.cost.ctypes.data for layer in self._obstacles])
        voxel_pointers = (ctypes.c_void_p * n)(
            *[None if layer.voxels is None else layer.voxels.ctypes.data for layer in self._obstacles]
        )
        fp_clear = np.array([int(layer.footprint_clearing) for layer in self._obstacles], dtype=np.int64)
        return key, (layer_d, layer_k, pointers, voxel_pointers, fp_clear)

    def _apply_observations(
        self, x: float, y: float, yaw: float, observations: Sequence[Observation]
    ) -> tuple[int, int, int, int] | None:
        """Each obstacle layer's updateBounds (and its footprint clearing); the cells written, or None."""
        bounds = self._bounds  # rows min, max, cols min, max (inclusive) of the cells written
        rows, cols = self.grid.cost.shape
        bounds[:] = (rows, -1, cols, -1)
        for layer in self._obstacles:
            # as ObstacleLayer::updateBounds: every clearing observation first, then every marking one
            pairs = [(src, obs) for src in layer.sources for obs in observations if _takes(layer, src, obs.source)]
            clearing = [(source, obs) for source, obs in pairs if source.clearing]
            marking = [(source, obs) for source, obs in pairs if source.marking]
            if self._lib is not None and len(clearing) == 1 and clearing == marking:
                source, obs = clearing[0]
                self._observe(layer, obs, source, clearing=True, marking=True)  # one call: clear, then mark
            else:
                for source, obs in clearing:
                    self._observe(layer, obs, source, clearing=True, marking=False)
                for source, obs in marking:
                    self._observe(layer, obs, source, clearing=False, marking=True)
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

    def _cells(self, range_m: float) -> float:
        """Costmap2D::cellDistance: whole cells, rounded up, never below 0."""
        return float(max(0.0, math.ceil(range_m / self.grid.resolution_m)))

    def _observe(
        self, layer: _ObstacleLayer, obs: Observation, source: ObservationSource, *, clearing: bool, marking: bool
    ) -> None:
        """Clear along one observation's rays, then mark their ends, as the layer does; grow the bounds."""
        if self._lib is None:
            if layer.voxels is not None:
                self._grow(*_voxel_update_py(self.grid, layer, obs, source, clearing=clearing, marking=marking))
                return
            if clearing:
                self._grow(*self._clear(layer.cost, obs, source))
            if marking:
                self._grow(*self._mark(layer, obs, source))
            return
        g = self.grid
        res = g.resolution_m
        rows, cols = layer.cost.shape
        lp = layer.params
        voxel = layer.voxels is not None
        # a voxel layer compares squared metres, an obstacle layer whole cells
        mark_max = source.obstacle_max_range_m if voxel else self._cells(source.obstacle_max_range_m)
        mark_min = source.obstacle_min_range_m if voxel else self._cells(source.obstacle_min_range_m)
        ray_max, ray_min = self._cells(source.raytrace_max_range_m), self._cells(source.raytrace_min_range_m)
        scan = obs.scan
        if scan is not None:  # the kernel projects the ranges
            self._doubles[:] = (
                g.origin_x_m, g.origin_y_m, res, scan.range_min_m, scan.range_max_m,
                obs.origin_x_m, obs.origin_y_m, obs.origin_z_m, scan.cos_yaw, scan.sin_yaw, ray_max, ray_min,
                mark_max, mark_min, lp.min_obstacle_height_m, lp.max_obstacle_height_m, lp.origin_z_m,
                lp.z_resolution_m,
            )  # fmt: skip
            self._longs[:] = (len(scan.ranges), int(clearing), int(marking), *layer.voxel_longs.tolist())
            status = self._lib.twin_scan_update(
                layer.cost.ctypes.data, None if layer.voxels is None else layer.voxels.ctypes.data, rows, cols,
                self._doubles_address, self._longs_address, scan.ranges.ctypes.data, scan.cos_a.ctypes.data,
                scan.sin_a.ctypes.data, self._bounds_address,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("costmap obstacle layer: out of memory")
            return
        pts = obs.points_xyz_m
        if layer.voxels is not None:
            self._lib.twin_voxel_update(
                layer.cost.ctypes.data, layer.voxels.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res,
                obs.origin_x_m, obs.origin_y_m, obs.origin_z_m, pts.ctypes.data, len(pts), int(clearing),
                int(marking), ray_max, ray_min, mark_max, mark_min, layer.voxel_doubles.ctypes.data,
                layer.voxel_longs.ctypes.data, self._bounds_address,
            )  # fmt: skip
            return
        self._lib.twin_obstacle_update(
            layer.cost.ctypes.data, rows, cols, g.origin_x_m, g.origin_y_m, res, obs.origin_x_m, obs.origin_y_m,
            pts.ctypes.data, len(pts), int(clearing), int(marking), ray_max, ray_min, mark_max, mark_min,
            lp.min_obstacle_height_m, lp.max_obstacle_height_m, self._bounds_address,
        )  # fmt: skip

    def _clear(
        self, cost: U8, obs: Observation, source: ObservationSource
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """ObstacleLayer::raytraceFreespace on the numpy path (twin_obstacle_update's clearing)."""
        g = self.grid
        res = g.resolution_m
        rows, cols = cost.shape
        ox, oy = obs.origin_x_m, obs.origin_y_m
        origin_cell = _world_to_map(np.array([ox]), np.array([oy]), g, rows, cols)
        if not origin_cell[2][0] or not len(obs.points_xy_m):
            return _NO_CELLS
        x0, y0 = int(origin_cell[0][0]), int(origin_cell[1][0])
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
        x1, y1, inside = _world_to_map(wx, wy, g, rows, cols)  # a ray whose clipped end is off the grid: none
        max_cells = self._cells(source.raytrace_max_range_m)
        min_cells = self._cells(source.raytrace_min_range_m)
        rr, cc = _bresenham(x0, y0, x1[inside], y1[inside], max_cells=max_cells, min_cells=min_cells)
        keep = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)
        rr, cc = rr[keep], cc[keep]
        cost[rr, cc] = FREE_SPACE
        return rr, cc

    def _mark(
        self, layer: _ObstacleLayer, obs: Observation, source: ObservationSource
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """ObstacleLayer::updateBounds' marking on the numpy path (twin_obstacle_update's marking)."""
        g = self.grid
        rows, cols = layer.cost.shape
        pts = obs.points_xyz_m
        origin_cell = _world_to_map(np.array([obs.origin_x_m]), np.array([obs.origin_y_m]), g, rows, cols)
        if not len(pts) or not origin_cell[2][0]:
            return _NO_CELLS
        lp = layer.params
        mx, my, inside = _world_to_map(pts[:, 0], pts[:, 1], g, rows, cols)
        inside &= (pts[:, 2] >= lp.min_obstacle_height_m) & (pts[:, 2] <= lp.max_obstacle_height_m)
        mx, my = mx[inside], my[inside]
        # the distance in whole cells from the sensor's cell, as the clearing's ray tracing counts it
        dist = np.hypot((mx - origin_cell[0][0]).astype(np.float64), (my - origin_cell[1][0]).astype(np.float64))
        dist = np.floor(dist)
        keep = (dist <= self._cells(source.obstacle_max_range_m)) & (dist >= self._cells(source.obstacle_min_range_m))
        rr, cc = my[keep].astype(np.intp), mx[keep].astype(np.intp)
        layer.cost[rr, cc] = LETHAL_OBSTACLE
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
        wx, wy = x + (fx * c - fy * s), y + (fx * s + fy * c)  # transformFootprint
        mx, my, inside = _world_to_map(wx, wy, g, rows, cols)
        if not inside.all():
            return  # setConvexPolygonCost fills nothing when a corner is off the grid
        cells = _convex_fill_cells([(int(a), int(b)) for a, b in zip(mx.tolist(), my.tolist(), strict=True)])
        if cells:
            cc, rr = (np.array(v, dtype=np.intp) for v in zip(*cells, strict=True))
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


def _shift(cost: NDArray[np.uint8] | NDArray[np.uint32], dr: int, dc: int, fill: int) -> None:
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


def _world_to_map(
    wx: F64, wy: F64, g: CostGrid, rows: int, cols: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Costmap2D::worldToMap for arrays of points: cell x, cell y (truncated), and which lie on the grid."""
    with np.errstate(invalid="ignore"):
        fx = (wx - g.origin_x_m) / g.resolution_m
        fy = (wy - g.origin_y_m) / g.resolution_m
        inside = (wx >= g.origin_x_m) & (wy >= g.origin_y_m) & (fx < cols) & (fy < rows)
    mx = np.where(inside, fx, 0.0).astype(np.int64)
    my = np.where(inside, fy, 0.0).astype(np.int64)
    return mx, my, inside


def _outline(x0: int, y0: int, x1: int, y1: int) -> list[tuple[int, int]]:
    """The cells Costmap2D::raytraceLine visits from (x0, y0) to (x1, y1) at full length (x, y)."""
    dx, dy = x1 - x0, y1 - y0
    sx, sy = (1 if dx > 0 else -1), (1 if dy > 0 else -1)
    x_major = abs(dx) >= abs(dy)
    da, db = (abs(dx), abs(dy)) if x_major else (abs(dy), abs(dx))
    error, x, y = da // 2, x0, y0
    cells = []
    for _ in range(da):
        cells.append((x, y))
        if x_major:
            x += sx
        else:
            y += sy
        error += db
        if error >= da:
            if x_major:
                y += sy
            else:
                x += sx
            error -= da
    cells.append((x, y))
    return cells


def _convex_fill_cells(polygon: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Costmap2D::convexFillCells: the outline's cells and the columns between them (twin_fill_footprint)."""
    if len(polygon) < 3:
        return []
    cells: list[tuple[int, int]] = []
    for i, (x0, y0) in enumerate(polygon):
        x1, y1 = polygon[(i + 1) % len(polygon)]
        cells.extend(_outline(x0, y0, x1, y1))
    i = 0
    while i < len(cells) - 1:  # Nav2's exchange sort by x
        if cells[i][0] > cells[i + 1][0]:
            cells[i], cells[i + 1] = cells[i + 1], cells[i]
            i = i - 1 if i > 0 else 0
        else:
            i += 1
    i = 0
    for x in range(cells[0][0], cells[-1][0] + 1):
        if i >= len(cells) - 1:
            break
        lo, hi = sorted((cells[i][1], cells[i + 1][1]))
        i += 2
        while i < len(cells) and cells[i][0] == x:
            if cells[i][1] < lo:
                lo = cells[i][1]
            elif cells[i][1] > hi:
                hi = cells[i][1]
            i += 1
        cells.extend((x, y) for y in range(lo, hi + 1))
    return cells


def _bits(n: int) -> int:
    return bin(n).count("1")


def _voxel_clear_ray(
    vox: NDArray[np.uint32],
    cost: U8,
    cols: int,
    start: tuple[float, float, float],
    end_cell: tuple[float, float, float],
    *,
    max_length: int,
    min_length: int,
    thresholds: tuple[int, int],
    written: list[int],
) -> None:
    """VoxelGrid::raytraceLine with ClearVoxelInMap from one fractional voxel to another (twin_voxel_update)."""
    sx, sy, sz = start
    px, py, pz = end_cell
    unknown_thr, mark_thr = thresholds
    dist = math.sqrt((sx - px) * (sx - px) + (sy - py) * (sy - py) + (sz - pz) * (sz - pz))
    if int(dist) < min_length:
        return
    scale, mx0, my0, mz0 = 1.0, sx, sy, sz
    if dist > 0.0:
        scale = min(1.0, max_length / dist)
        mx0 = sx + (px - sx) / dist * min_length
        my0 = sy + (py - sy) / dist * min_length
        mz0 = sz + (pz - sz) / dist * min_length
    d = (int(px) - int(mx0), int(py) - int(my0), int(pz) - int(mz0))
    ad = [abs(v) for v in d]
    steps = [1 if d[0] > 0 else -1, (1 if d[1] > 0 else -1) * cols, 1 if d[2] > 0 else -1]
    order = [0, 1, 2] if ad[0] >= max(ad[1], ad[2]) else ([1, 0, 2] if ad[1] >= ad[2] else [2, 0, 1])
    da, db, dc = (ad[k] for k in order)
    offset = int(my0) * cols + int(mx0)
    z_mask = ((1 << 16) | 1) << int(mz0)
    errors = [da // 2, da // 2]
    end = min(int(scale * da), da)

    def step(axis: int) -> None:
        nonlocal offset, z_mask
        if axis == 2:
            z_mask = (z_mask << 1) & 0xFFFFFFFF if steps[2] > 0 else z_mask >> 1
        else:
            offset += steps[axis]

    i = 0
    while True:
        col = int(vox[offset]) & ~z_mask & 0xFFFFFFFF
        vox[offset] = col
        unknown_bits = ((col >> 16) & 0xFFFF) ^ (col & 0xFFFF)
        if _bits(col >> 16) <= mark_thr:
            cost[offset] = FREE_SPACE if _bits(unknown_bits) <= unknown_thr else NO_INFORMATION
            written.append(offset)
        if i >= end:
            return
        i += 1
        step(order[0])
        for k, delta in ((0, db), (1, dc)):
            errors[k] += delta
            if errors[k] >= da:
                step(order[k + 1])
                errors[k] -= da


def _voxel_update_py(
    g: CostGrid, layer: _ObstacleLayer, obs: Observation, source: ObservationSource, *, clearing: bool, marking: bool
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """VoxelLayer::raytraceFreespace then its marking, in Python (the reference of twin_voxel_update)."""
    assert layer.voxels is not None
    cost, vox = layer.cost.reshape(-1), layer.voxels.reshape(-1)
    rows, cols = layer.cost.shape
    res, gx, gy = g.resolution_m, g.origin_x_m, g.origin_y_m
    z0, zr, max_h = (float(v) for v in layer.voxel_doubles)
    size_z, unknown_thr, mark_thr = (int(v) for v in layer.voxel_longs)
    ox, oy, oz = obs.origin_x_m, obs.origin_y_m, obs.origin_z_m
    pts = obs.points_xyz_m.tolist()
    written: list[int] = []
    sx, sy, sz = (ox - gx) / res, (oy - gy) / res, (oz - z0) / zr
    sensor_inside = not (ox < gx or oy < gy or oz < z0) and sx < cols and sy < rows and sz < size_z
    if clearing and pts and sensor_inside:
        end_x, end_y = gx + (cols - 1 + 0.5) * res, gy + (rows - 1 + 0.5) * res
        end_z = z0 + (size_z - 1 + 0.5) * zr
        max_length = int(max(0.0, math.ceil(source.raytrace_max_range_m / res)))
        min_length = int(max(0.0, math.ceil(source.raytrace_min_range_m / res)))
        for point in pts:
            wpx, wpy, wpz = point
            distance = math.sqrt((wpx - ox) * (wpx - ox) + (wpy - oy) * (wpy - oy) + (wpz - oz) * (wpz - oz))
            ratio = (distance - 2 * res) / distance if distance != 0.0 else math.nan
            scaling = ratio if ratio < 1.0 else 1.0  # std::min(1.0, ratio): a NaN keeps 1.0
            scaling = scaling if scaling > 0.0 else 0.0
            wpx, wpy, wpz = scaling * (wpx - ox) + ox, scaling * (wpy - oy) + oy, scaling * (wpz - oz) + oz
            a, b, c, t = wpx - ox, wpy - oy, wpz - oz, 1.0
            if wpz > end_z:
                t = max(0.0, min(t, (end_z - 0.01 - oz) / c))
            elif wpz < z0:
                t = min(t, (z0 - oz) / c)
            if wpx < gx:
                t = min(t, (gx - ox) / a)
            if wpy < gy:
                t = min(t, (gy - oy) / b)
            if wpx > end_x:
                t = min(t, (end_x - ox) / a)
            if wpy > end_y:
                t = min(t, (end_y - oy) / b)
            wpx, wpy, wpz = ox + a * t, oy + b * t, oz + c * t
            if wpx < gx or wpy < gy or wpz < z0:
                continue
            px, py, pz = (wpx - gx) / res, (wpy - gy) / res, (wpz - z0) / zr
            if px < cols and py < rows and pz < size_z:
                _voxel_clear_ray(
                    vox, cost, cols, (sx, sy, sz), (px, py, pz), max_length=max_length, min_length=min_length,
                    thresholds=(unknown_thr, mark_thr), written=written,
                )  # fmt: skip
    if marking:
        sq_max, sq_min = source.obstacle_max_range_m**2, source.obstacle_min_range_m**2
        for x, y, z in pts:
            if z > max_h:
                continue
            sq = (x - ox) * (x - ox) + (y - oy) * (y - oy) + (z - oz) * (z - oz)
            if sq >= sq_max or sq < sq_min:
                continue
            wz = z0 if z < z0 else z
            if x < gx or y < gy:
                continue
            mx, my, mz = int((x - gx) / res), int((y - gy) / res), int((wz - z0) / zr)
            if not (mx < cols and my < rows and mz < size_z):
                continue
            index = my * cols + mx
            col = int(vox[index]) | (1 << mz << 16) | (1 << mz)
            vox[index] = col
            if _bits(col >> 16) > mark_thr:
                cost[index] = LETHAL_OBSTACLE
                written.append(index)
    cells = np.array(written, dtype=np.intp)
    return cells // cols, cells % cols


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
