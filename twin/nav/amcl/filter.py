"""AMCL as Nav2 Humble runs it: a particle filter on the map, fed odometry and laser scans.

What it does, step for step as `nav2_amcl` (amcl_node, pf, DifferentialMotionModel,
LikelihoodFieldModel), vectorised over particles and beams:

- **Gating.** Scans are ignored until an initial pose is set. The first scan after one only
  weighs the particles; later scans update the filter only once odometry has moved more than
  `update_min_d` along x or along y, or turned more than `update_min_a` since the last update.
- **Motion** (differential model, alpha1..alpha4): the odometry change is split into rotate,
  translate, rotate; each particle gets that change with Gaussian noise of standard deviation
  `sqrt(alpha1 rot^2 + alpha2 trans^2)` on the rotations and `sqrt(alpha3 trans^2 + alpha4 (rot1^2
  + rot2^2))` on the translation (rotations folded to the nearer of forward and backward motion).
  Particle yaws are never folded into [-pi, pi), as in Nav2's filter: a cloud heading west stays
  one histogram cluster instead of splitting at the seam.
- **Laser** (likelihood field): `max_beams` beams, every `(n - 1) // (max_beams - 1)`-th; ranges
  at or below range_min count as range_max, and range_max readings are skipped. Each endpoint's
  distance `z` to the nearest occupied map cell (capped at `laser_likelihood_max_dist`; off the
  map it is the cap) gives `pz = z_hit exp(-z^2 / (2 sigma_hit^2)) + z_rand / range_max`, and a
  particle's weight is multiplied by `1 + sum(pz^3)`. Map cells are looked up as AMCL does,
  rounding (not flooring) world / resolution.
- **Resampling** every `resample_interval` updates, KLD-sampling: particles are drawn by weight
  (or, with recovery alphas, uniformly in free space with probability `1 - w_fast / w_slow`) until
  their count exceeds the KLD bound for the number of occupied (0.5 m, 0.5 m, 10 deg) histogram
  bins, `ceil((k - 1) / (2 pf_err) (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) pf_z)^3)`, within
  [min_particles, max_particles]. `pf_z` is used as given (0.99), as Nav2 does.
- **Estimate**: particles are clustered by connected histogram bins; the pose is the mean of the
  heaviest cluster (yaw a circular mean); the covariance is the whole set's (x, y block and
  the circular variance `-2 ln R` of yaw), as `amcl_pose` carries them. As Nav2's
  pf_cluster_stats, they are taken when the set is drawn (initial pose, resampling) and published
  when the filter resampled or on the first update after an initial pose.
- **The map** is taken as the OccupancyGrid carries it: its resolution a float32 (`as_received`).
- **map -> odom** is the estimate composed with the inverse of the odometry pose of the scan that
  produced it; Nav2 re-sends it on every scan stamped scan time + transform_tolerance.

Random numbers come from the draw source passed in: a `numpy.random.Generator` seeded by the
caller, or anything with its `standard_normal`, `random`, `integers` and `uniform` (a test replays
recorded draws through one). The motion model takes one (n, 3) block of standard normal draws per
update, in Nav2's order: per particle, rot1, trans, rot2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import ConfigError
from twin.nav.amcl._native import load_kernel
from twin.nav.frames import LaserGeometry
from twin.nav.map_server.map_io import OccupancyMap
from twin.nav.params import AmclParams

__all__ = [
    "Amcl",
    "AmclEstimate",
    "Beams",
    "DrawSource",
    "LaserGeometry",
    "LikelihoodField",
    "Pz",
    "as_received",
    "beam_endpoints",
    "cluster_estimate",
    "kld_limits",
    "kld_resample",
    "laser_likelihood",
    "nav2_bearings",
    "nav2_distances",
    "odometry_update",
    "weight_total",
]

F64 = NDArray[np.float64]

_BIN_SIZE = np.array([0.5, 0.5, math.radians(10.0)])  # pf_kdtree's histogram: x m, y m, yaw rad


class DrawSource(Protocol):
    """Where the filter's random numbers come from: `numpy.random.Generator`'s methods the filter calls."""

    def standard_normal(self, size: Any) -> Any:
        """Standard normal draws of the given shape."""
        ...

    def random(self, size: Any) -> Any:
        """Uniform draws in [0, 1) of the given shape."""
        ...

    def integers(self, low: Any, high: Any, size: Any) -> Any:
        """Integers in [low, high)."""
        ...

    def uniform(self, low: Any, high: Any, size: Any) -> Any:
        """Uniform draws in [low, high)."""
        ...


def _angle_diff(a: float, b: float) -> float:
    """Nav2's angle_diff: a - b folded into [-pi, pi]."""
    d = math.atan2(math.sin(a), math.cos(a)) - math.atan2(math.sin(b), math.cos(b))
    d1 = d
    d2 = 2.0 * math.pi - abs(d1)
    if d1 > 0.0:
        d2 *= -1.0
    return d1 if abs(d1) < abs(d2) else d2


def _angle_diffs(a: float, b: F64) -> F64:
    """`_angle_diff(a, b)` for each b."""
    d1 = math.atan2(math.sin(a), math.cos(a)) - np.arctan2(np.sin(b), np.cos(b))
    d2 = 2.0 * math.pi - np.abs(d1)
    d2 = np.where(d1 > 0.0, -d2, d2)
    return np.where(np.abs(d1) < np.abs(d2), d1, d2)


def odometry_update(
    poses: F64,
    pose: tuple[float, float, float],
    delta: tuple[float, float, float],
    alphas: tuple[float, float, float, float],
    draws: DrawSource,
    *,
    native: bool = True,
) -> F64:
    """Move every particle by the odometry change as Nav2's DifferentialMotionModel::odometryUpdate does.

    The change is split into rotate, translate, rotate (no first rotation below 1 cm of travel); each
    particle's rotations are `angle_diff(rot, sd * z)` (folded into [-pi, pi], so a sampled rotation
    near +-pi can come out a turn lower or higher) and its translation `trans - sd * z`, z the standard
    normal draws (one (n, 3) block from `draws`: per particle rot1, trans, rot2). Products and sums
    are taken in Nav2's order.

    Args:
        poses: (n, 3) particles (x m, y m, yaw rad), updated in place.
        pose: The odometry pose now (odom frame).
        delta: Its change since the last update: (dx, dy, angle_diff(yaw, old yaw)).
        alphas: alpha1..alpha4.
        draws: The random numbers.
        native: Use the C kernel when it can be built.

    Returns:
        `poses`, moved (a new contiguous array when `poses` was not one).
    """
    a1, a2, a3, a4 = alphas
    dx, dy, dyaw = delta
    old_yaw = pose[2] - dyaw  # pf_vector_sub(pose, delta)
    trans = math.sqrt(dx * dx + dy * dy)
    rot1 = 0.0 if math.sqrt(dy * dy + dx * dx) < 0.01 else _angle_diff(math.atan2(dy, dx), old_yaw)
    rot2 = _angle_diff(dyaw, rot1)
    n1 = min(abs(_angle_diff(rot1, 0.0)), abs(_angle_diff(rot1, math.pi)))
    n2 = min(abs(_angle_diff(rot2, 0.0)), abs(_angle_diff(rot2, math.pi)))
    sd_rot1 = math.sqrt(a1 * n1 * n1 + a2 * trans * trans)
    sd_trans = math.sqrt(a3 * trans * trans + a4 * n1 * n1 + a4 * n2 * n2)
    sd_rot2 = math.sqrt(a1 * n2 * n2 + a2 * trans * trans)
    n = len(poses)
    noise = np.ascontiguousarray(draws.standard_normal((n, 3)), dtype=np.float64)
    lib = load_kernel() if native else None
    if lib is not None:
        out = np.ascontiguousarray(poses, dtype=np.float64)
        lib.twin_amcl_motion(out.ctypes.data, n, noise.ctypes.data, rot1, trans, rot2, sd_rot1, sd_trans, sd_rot2)
        return out
    rot1_hat = _angle_diffs(rot1, sd_rot1 * noise[:, 0])
    trans_hat = trans - sd_trans * noise[:, 1]
    rot2_hat = _angle_diffs(rot2, sd_rot2 * noise[:, 2])
    heading = poses[:, 2] + rot1_hat
    poses[:, 0] += trans_hat * np.cos(heading)
    poses[:, 1] += trans_hat * np.sin(heading)
    poses[:, 2] += rot1_hat + rot2_hat
    return poses


@dataclass(frozen=True, kw_only=True, slots=True)
class AmclEstimate:
    """AMCL's pose in the map frame with its covariance (x, y, yaw; 3x3), and the map->odom it implies."""

    x_m: float
    y_m: float
    yaw_rad: float
    covariance: F64
    map_odom: tuple[float, float, float]
    particles: int

    def covariance_6x6(self) -> list[float]:
        """Return the 36 values of PoseWithCovariance.covariance as amcl_pose fills them."""
        out = [0.0] * 36
        c = self.covariance
        for i in range(2):
            for j in range(2):
                out[6 * i + j] = float(c[i, j])
        out[35] = float(c[2, 2])
        return out


def _bin_keys(bins: NDArray[np.int64]) -> NDArray[np.int64]:
    """One integer per (x, y, yaw) histogram bin."""
    local = bins - bins.min(axis=0)
    span = local.max(axis=0) + 1
    return np.asarray((local[:, 0] * span[1] + local[:, 1]) * span[2] + local[:, 2], dtype=np.int64)


def nav2_distances(occupied: NDArray[np.bool_], resolution_m: float, max_dist_m: float, *, native: bool = True) -> F64:
    """Distances (m) from each cell to an occupied one, spread as Nav2's `map_update_cspace` spreads them.

    Every occupied cell enters a priority queue at 0 (column by column, each column bottom to top);
    while the queue holds cells, the top cell's neighbours at x - 1, y - 1, x + 1, y + 1 that no cell
    has reached take the distance to the top cell's source, if it is at most `int(max_dist /
    resolution)` cells, and join the queue; then the top is popped, whichever cell is on top by then.
    The queue is a binary heap kept as libstdc++'s `std::priority_queue` keeps it, so cells of equal
    distance leave it in Nav2's order. Cells never reached are `max_dist_m` away.

    Args:
        occupied: (rows, cols) obstacle cells, row = y.
        resolution_m: Cell size.
        max_dist_m: `laser_likelihood_max_dist`.
        native: Use the C kernel when it can be built.
    """
    rows, cols = occupied.shape
    out = np.empty((rows, cols))
    lib = load_kernel() if native else None
    if lib is not None:
        cells = np.ascontiguousarray(occupied, dtype=np.uint8)
        if lib.twin_amcl_distances(cells.ctypes.data, cols, rows, resolution_m, max_dist_m, out.ctypes.data):
            raise MemoryError("amcl likelihood field: out of memory")
        return out
    radius = int(max_dist_m / resolution_m)
    table = np.sqrt(np.add.outer(np.arange(radius + 2) ** 2, np.arange(radius + 2) ** 2).astype(np.float64))
    dist = np.full(rows * cols, max_dist_m)
    marked = occupied.reshape(-1).copy()
    dist[marked] = 0.0
    heap: list[tuple[float, int, int, int, int]] = []  # (distance, x, y, source x, source y)
    for i, j in zip(*np.nonzero(occupied.T), strict=True):  # x outer, y inner, as Nav2 pushes them
        _heap_push(heap, (0.0, int(i), int(j), int(i), int(j)))
    while heap:
        _, i, j, si, sj = heap[0]
        for x, y in ((i - 1, j), (i, j - 1), (i + 1, j), (i, j + 1)):
            if x < 0 or y < 0 or x >= cols or y >= rows or marked[y * cols + x]:
                continue
            d = float(table[abs(x - si), abs(y - sj)])
            if d > radius:
                continue
            dist[y * cols + x] = d * resolution_m
            _heap_push(heap, (d * resolution_m, x, y, si, sj))
            marked[y * cols + x] = True
        _heap_pop(heap)
    return dist.reshape(rows, cols)


_Cell = tuple[float, int, int, int, int]


def _heap_push(heap: list[_Cell], value: _Cell) -> None:
    """std::push_heap with the smallest distance on top."""
    heap.append(value)
    _sift_up(heap, len(heap) - 1, value)


def _sift_up(heap: list[_Cell], hole: int, value: _Cell) -> None:
    parent = (hole - 1) // 2
    while hole > 0 and heap[parent][0] > value[0]:
        heap[hole] = heap[parent]
        hole = parent
        parent = (hole - 1) // 2
    heap[hole] = value


def _heap_pop(heap: list[_Cell]) -> None:
    """std::pop_heap (libstdc++'s __adjust_heap: the hole goes down to a leaf, then the last value up)."""
    n = len(heap) - 1
    if n < 1:
        heap.pop()
        return
    value = heap[n]
    heap[n] = heap[0]
    hole = child = 0
    while child < (n - 1) // 2:
        child = 2 * (child + 1)
        if heap[child][0] > heap[child - 1][0]:
            child -= 1
        heap[hole] = heap[child]
        hole = child
    if n % 2 == 0 and child == (n - 2) // 2:
        child = 2 * (child + 1)
        heap[hole] = heap[child - 1]
        hole = child - 1
    _sift_up(heap, hole, value)
    heap.pop()


def _rpy_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """tf2::Quaternion::setRPY: (x, y, z, w), its products in its order."""
    cy, sy = math.cos(yaw * 0.5), math.sin(yaw * 0.5)
    cp, sp = math.cos(pitch * 0.5), math.sin(pitch * 0.5)
    cr, sr = math.cos(roll * 0.5), math.sin(roll * 0.5)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def _base_yaw(mount_yaw_rad: float, angle_rad: float) -> float:
    """A scan angle's yaw in the base frame as amcl_node gets it: a quaternion about z, turned by the mount, getYaw."""
    tx, ty, tz, tw = _rpy_quaternion(0.0, 0.0, mount_yaw_rad)
    ax, ay, az, aw = _rpy_quaternion(0.0, 0.0, angle_rad)
    x = tw * ax + tx * aw + ty * az - tz * ay
    y = tw * ay + ty * aw + tz * ax - tx * az
    z = tw * az + tz * aw + tx * ay - ty * ax
    w = tw * aw - tx * ax - ty * ay - tz * az
    sqx, sqy, sqz, sqw = x * x, y * y, z * z, w * w
    sarg = -2.0 * (x * z - w * y) / (sqx + sqy + sqz + sqw)
    if sarg <= -0.99999:
        return -2.0 * math.atan2(y, x)
    if sarg >= 0.99999:
        return 2.0 * math.atan2(y, x)
    return math.atan2(2.0 * (x * y + w * z), sqw + sqx - sqy - sqz)


def nav2_bearings(laser: LaserGeometry, count: int) -> F64:
    """Each beam's angle in the base frame as Nav2's amcl_node computes it (updateFilter).

    The LaserScan carries `angle_min` and `angle_increment` as float32; AMCL turns `angle_min` and
    `angle_min + angle_increment` (a float32 sum) into quaternions about z, into the base frame and
    back to yaws (tf2), takes the increment as their difference wrapped by `fmod(d + 5 pi, 2 pi) - pi`,
    and beam i's bearing as `angle_min + i * increment`. With the double increment instead, beam
    359's bearing is 2e-7 rad off. The mount's rotation is taken as a yaw (`setRPY(0, 0, yaw)`,
    the identity for TurtleBot3; a lidar mounted upside down has its angles mirrored in `laser`).
    """
    angle_min = np.float32(laser.angle_min_rad)
    second = float(angle_min + np.float32(laser.angle_increment_rad))  # float + float in C++: a float
    a_min = _base_yaw(laser.mount_yaw_rad, float(angle_min))
    increment = _base_yaw(laser.mount_yaw_rad, second) - a_min
    increment = math.fmod(increment + 5 * math.pi, 2 * math.pi) - math.pi
    return a_min + np.arange(count, dtype=np.float64) * increment


def as_received(occupancy: OccupancyMap) -> OccupancyMap:
    """The map as AMCL receives it on `/map`: an OccupancyGrid, whose resolution is a float32.

    Nav2's AMCL keeps that float32 as its map scale (`convertMap`): 0.05 m arrives as
    0.05000000074505806 m, which moves the cell an endpoint falls in by up to a few 1e-8 m and the
    likelihood field's distances in their last bits, and caps them at int(2.0 / scale) = 39 cells,
    not 40 (`map_update_cspace`). The origin is a float64 in the message and stays as it is.
    """
    res = float(np.float32(occupancy.resolution_m))
    return occupancy if res == occupancy.resolution_m else replace(occupancy, resolution_m=res)


class LikelihoodField:
    """The map's distance to the nearest occupied cell as Nav2's AMCL computes it, and per-cell likelihood cubes.

    Nav2 (`map_update_cspace`) does not take the exact distance transform: it spreads distances from
    the occupied cells through a priority queue, each cell taking the distance to the source of the
    first neighbour that reaches it (up to `int(max_dist / resolution)` cells). About one cell in ten
    then lies up to a few centimetres further from the wall than it is; the filter's statistics
    follow, so the twin spreads them the same way, in the same order (`nav2_distances`).

    Args:
        occupancy: The map (cells equal to 100 are obstacles, as AMCL reads them).
        max_dist_m: `laser_likelihood_max_dist`: distances are capped here (and off the map).
        native: Use the C kernel when it can be built (else the same steps in Python, much slower).
    """

    def __init__(self, occupancy: OccupancyMap, max_dist_m: float, *, native: bool = True) -> None:
        res = occupancy.resolution_m
        self.max_dist_m = float(max_dist_m)
        self.distance_m: F64 = nav2_distances(occupancy.data == 100, res, self.max_dist_m, native=native)
        self.resolution_m = res
        self.origin_x_m = occupancy.origin_x_m
        self.origin_y_m = occupancy.origin_y_m
        self.free_cells = np.argwhere(occupancy.data == 0)  # (row, col) for uniform pose draws
        self._pz: dict[tuple[float, float, float, float], Pz] = {}

    def pz(self, z_hit: float, z_rand: float, sigma_hit_m: float, range_max_m: float) -> Pz:
        """Return pz per map cell and pz of an endpoint off the map as the likelihood-field model computes them.

        `pz = z_hit exp(-(z z) / (2 sigma sigma)) + z_rand (1 / range_max)`, z the cell's distance,
        with libm's exp (`math.exp`) over the few distinct distances, so each value is Nav2's to the bit;
        with each cell's `pz * pz * pz` (what a beam ending there adds, the same bits as taken per beam).
        """
        key = (z_hit, z_rand, sigma_hit_m, range_max_m)
        if key not in self._pz:
            denominator = 2 * sigma_hit_m * sigma_hit_m
            rand = z_rand * (1.0 / range_max_m)
            values, index = np.unique(self.distance_m, return_inverse=True)
            table = np.array([z_hit * math.exp(-(z * z) / denominator) + rand for z in values.tolist()])
            off = z_hit * math.exp(-(self.max_dist_m * self.max_dist_m) / denominator) + rand
            per_cell = np.ascontiguousarray(table[index.reshape(self.distance_m.shape)])
            cubes = np.ascontiguousarray(np.append((table * table * table)[index.ravel()], off * off * off))
            self._pz[key] = Pz(per_cell, off, cubes)
        return self._pz[key]


class Pz(NamedTuple):
    """The likelihood field's pz for one set of model parameters."""

    table: F64
    """pz per map cell (rows, cols)."""
    off_map: float
    """pz of an endpoint off the map (at `laser_likelihood_max_dist`)."""
    cubes: F64
    """`pz * pz * pz` per cell, row-major, then the off-map one: rows * cols + 1 values (the C kernel's table)."""


class Beams(NamedTuple):
    """The beams the likelihood-field model uses: endpoints in the base frame, and each beam's reading."""

    x_m: F64
    y_m: F64
    range_m: F64
    bearing_rad: F64
    laser_xy_m: tuple[float, float]


def beam_endpoints(
    ranges_m: F64, bearings_rad: F64, laser_xy_m: tuple[float, float], range_max_m: float, max_beams: int
) -> Beams:
    """The beams the likelihood-field model uses, with their endpoints in the base frame (x, y; m).

    Every `(n - 1) // (max_beams - 1)`-th beam (at least every one) from the first; readings at or
    beyond `range_max_m`, and NaN, are skipped (LikelihoodFieldModel::sensorFunction).

    Args:
        ranges_m: The scan's ranges as amcl_node hands them over (those at or below range_min
            already set to range_max).
        bearings_rad: Each beam's angle in the base frame.
        laser_xy_m: The laser's position in the base frame (Nav2 keeps its yaw in the bearings).
        range_max_m: The laser's range_max (capped by `laser_max_range`).
        max_beams: `max_beams` (at least 2; Nav2 does not weigh with fewer).
    """
    count = len(ranges_m)
    step = max(1, (count - 1) // (max_beams - 1)) if max_beams > 1 else max(1, count)
    index = np.arange(0, count, step)
    r = ranges_m[index]
    keep = (r < range_max_m) & ~np.isnan(r)
    r, angle = r[keep], bearings_rad[index][keep]
    x: F64 = laser_xy_m[0] + r * np.cos(angle)
    y: F64 = laser_xy_m[1] + r * np.sin(angle)
    return Beams(x, y, np.ascontiguousarray(r), np.ascontiguousarray(angle), laser_xy_m)


def laser_likelihood(poses: F64, beams: Beams, field: LikelihoodField, pz: Pz, *, native: bool = True) -> F64:
    """Each particle's likelihood-field factor `1 + pz^3 + ...` over the beams (its weight is multiplied by it).

    As LikelihoodFieldModel::sensorFunction: each cube is `pz * pz * pz`, added to 1 beam by beam.
    The endpoint's cell is found from the particle's grid position and the endpoint in the base frame
    (cheaper than Nav2's per-beam sin and cos); where that lands within 1e-6 of a cell edge, where the
    two ways of computing it could round to different cells, the cell is taken Nav2's way (`_nav2_cells`).

    Args:
        poses: (n, 3) particles (x m, y m, yaw rad) in the map frame.
        beams: The beams used, from `beam_endpoints`.
        field: The map's likelihood field.
        pz: The field's pz for the model's parameters (`field.pz`).
        native: Use the C kernel when it can be built.
    """
    table, off_map = pz.table, pz.off_map
    n = len(poses)
    if not len(beams.x_m):
        return np.ones(n)
    inv_res = 1.0 / field.resolution_m
    ex = np.ascontiguousarray(beams.x_m * inv_res)  # each beam's endpoint in the base frame, in cells
    ey = np.ascontiguousarray(beams.y_m * inv_res)
    rows, cols = table.shape
    lx, ly = beams.laser_xy_m
    lib = load_kernel() if native else None
    if lib is not None:
        poses = np.ascontiguousarray(poses, dtype=np.float64)
        out = np.empty(n)
        status = lib.twin_amcl_likelihood(
            poses.ctypes.data, n, field.origin_x_m, field.origin_y_m, inv_res,
            ex.ctypes.data, ey.ctypes.data, beams.range_m.ctypes.data, beams.bearing_rad.ctypes.data, len(ex),
            lx, ly, field.resolution_m, pz.cubes.ctypes.data, rows, cols, out.ctypes.data,
        )  # fmt: skip
        if status != 0:
            raise MemoryError("amcl likelihood: out of memory")
        return out
    # grid coordinates of each particle (AMCL rounds: +0.5 then floor), its heading
    gx = (poses[:, 0] - field.origin_x_m) * inv_res + 0.5
    gy = (poses[:, 1] - field.origin_y_m) * inv_res + 0.5
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    fc = gx[:, None] + c[:, None] * ex - s[:, None] * ey
    fr = gy[:, None] + s[:, None] * ex + c[:, None] * ey
    col, row = np.floor(fc), np.floor(fr)
    edge = (fc - col < 1e-6) | (fc - col > 1.0 - 1e-6) | (fr - row < 1e-6) | (fr - row > 1.0 - 1e-6)
    col_i, row_i = col.astype(np.intp), row.astype(np.intp)
    if edge.any():
        j, i = np.nonzero(edge)
        col_i[j, i], row_i[j, i] = _nav2_cells(poses[j], beams, i, field, (rows, cols))
    inside = (col_i >= 0) & (col_i < cols) & (row_i >= 0) & (row_i < rows)
    values = np.where(inside, table[np.clip(row_i, 0, rows - 1), np.clip(col_i, 0, cols - 1)], off_map)
    terms = np.empty((n, len(ex) + 1))
    terms[:, 0] = 1.0
    np.multiply(values * values, values, out=terms[:, 1:])
    # cumsum adds left to right (np.sum would pair them up): 1 + pz^3 + ... beam by beam, as Nav2 adds them
    likelihood: F64 = np.cumsum(terms, axis=1)[:, -1]
    return likelihood


def _nav2_cells(
    poses: F64, beams: Beams, index: NDArray[np.intp], field: LikelihoodField, shape: tuple[int, int]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The map cells of beams `index` from particles `poses` computed as Nav2 does (see the C kernel's nav2_cell)."""
    rows, cols = shape
    lx, ly = beams.laser_xy_m
    scale = field.resolution_m
    yaw = poses[:, 2]
    px = poses[:, 0] + lx * np.cos(yaw) - ly * np.sin(yaw)
    py = poses[:, 1] + lx * np.sin(yaw) + ly * np.cos(yaw)
    lyaw = np.arctan2(np.sin(yaw + 0.0), np.cos(yaw + 0.0))
    r, b = beams.range_m[index], beams.bearing_rad[index]
    hx = px + r * np.cos(lyaw + b)
    hy = py + r * np.sin(lyaw + b)
    cx = field.origin_x_m + (cols // 2) * scale
    cy = field.origin_y_m + (rows // 2) * scale
    col = np.floor((hx - cx) / scale + 0.5) + cols // 2
    row = np.floor((hy - cy) / scale + 0.5) + rows // 2
    return col.astype(np.intp), row.astype(np.intp)


def weight_total(weights: F64) -> float:
    """The particles' total weight as the likelihood-field model sums it: in particle order (not pairwise)."""
    return float(np.cumsum(weights)[-1]) if len(weights) else 0.0


def kld_limits(min_particles: int, max_particles: int, pf_err: float, pf_z: float) -> F64:
    """KLD-sampling's particle bound for k = 0 .. max_particles occupied bins, as pf_resample_limit computes it.

    `ceil((k - 1) / (2 pf_err) * x * x * x)` with `x = 1 - b + sqrt(b) pf_z`, `b = 2 / (9 (k - 1))`,
    in Nav2's order of operations, within [min_particles, max_particles]; max_particles for k <= 1.
    """
    k = np.arange(max_particles + 1)
    kk = np.maximum(k - 1, 1).astype(np.float64)
    b = 2 / (9 * kk)
    x = 1 - b + np.sqrt(2 / (9 * kk)) * pf_z
    n = np.ceil(kk / (2 * pf_err) * x * x * x)
    n = np.clip(n, min_particles, max_particles)
    return np.ascontiguousarray(np.where(k <= 1, float(max_particles), n))


def _kld_count(bins: NDArray[np.int64], limits: F64, lib: Any) -> int:
    """How many of the drawn particles KLD-sampling keeps: the first n with n > limit(bins among them)."""
    m = len(bins)
    if lib is not None:
        bins = np.ascontiguousarray(bins, dtype=np.int64)
        n = int(lib.twin_kld_count(bins.ctypes.data, m, limits.ctypes.data))
        if n < 0:
            raise MemoryError("amcl resampling: out of memory")
        return n
    _, first = np.unique(_bin_keys(bins), return_index=True)
    is_first = np.zeros(m, dtype=bool)
    is_first[first] = True
    leaves = np.cumsum(is_first)
    stop = np.nonzero(np.arange(1, m + 1) > limits[leaves])[0]
    return int(stop[0]) + 1 if len(stop) else m


def kld_resample(poses: F64, weights: F64, picks: F64, limits: F64, *, native: bool = True) -> F64:
    """Draw a new particle set as Nav2's pf_update_resample does without recovery draws.

    Sample j is the particle i with `c[i] <= picks[j] < c[i + 1]`, c the running sum of the weights
    from 0 in particle order (not renormalised; a draw at or past the last sum takes the last particle,
    where Nav2 reads past its set); each sample is counted into its (0.5 m, 0.5 m, 10 degree) bin and
    drawing stops at the first count above `limits[bins]`, or at `len(picks)`.

    Nav2 draws two uniforms per sample, the first to decide on a random pose (never, without
    recovery), the second the pick: `picks` are the second ones.

    Args:
        poses: (n, 3) particles.
        weights: Their normalised weights.
        picks: Uniform draws in [0, 1), one per sample at most (max_particles).
        limits: `kld_limits(...)`.
        native: Use the C kernel when it can be built.

    Returns:
        The drawn particles (count, 3).
    """
    cumulative = np.ascontiguousarray(np.cumsum(weights))
    picks = np.ascontiguousarray(picks, dtype=np.float64)
    m = len(picks)
    lib = load_kernel() if native else None
    if lib is not None:  # draw, histogram and stop in one pass
        poses = np.ascontiguousarray(poses, dtype=np.float64)
        out = np.empty((m, 3))
        n = int(
            lib.twin_pf_resample(
                poses.ctypes.data, len(poses), cumulative.ctypes.data, picks.ctypes.data, m,
                _BIN_SIZE.ctypes.data, limits.ctypes.data, out.ctypes.data,
            )
        )  # fmt: skip
        if n < 0:
            raise MemoryError("amcl resampling: out of memory")
        return out[:n]
    pick = np.minimum(np.searchsorted(cumulative, picks, side="right"), len(cumulative) - 1)
    new = poses[pick]
    keys: NDArray[np.int64] = np.floor(new / _BIN_SIZE).astype(np.int64)
    return new[: _kld_count(keys, limits, None)]


def _clusters(bins: NDArray[np.int64], lib: Any) -> tuple[NDArray[np.int64], int]:
    """Each particle's cluster (bins that touch, 26-neighbourhood), numbered from 1 in raster order of the bins."""
    if lib is not None:
        bins = np.ascontiguousarray(bins, dtype=np.int64)
        labels = np.empty(len(bins), dtype=np.int64)
        count = int(lib.twin_pf_clusters(bins.ctypes.data, len(bins), labels.ctypes.data))
        if count < 0:
            raise MemoryError("amcl clustering: out of memory")
        return labels, count
    from scipy import ndimage  # the numpy path only: scipy is slow to import

    lo = bins.min(axis=0)
    shape = tuple(int(v) for v in bins.max(axis=0) - lo + 1)
    grid = np.zeros(shape, dtype=bool)
    local = bins - lo
    grid[local[:, 0], local[:, 1], local[:, 2]] = True
    labels, count = ndimage.label(grid, structure=np.ones((3, 3, 3), dtype=bool))
    return np.asarray(labels[local[:, 0], local[:, 1], local[:, 2]], dtype=np.int64), int(count)


def _running(values: F64) -> float:
    """A sum taken in order (Nav2 adds sample by sample; numpy's sum pairs them up)."""
    return float(np.cumsum(values)[-1]) if len(values) else 0.0


def cluster_estimate(poses: F64, weights: F64, *, native: bool = True) -> tuple[tuple[float, float, float], F64]:
    """The pose AMCL publishes and the covariance `amcl_pose` carries, as pf_cluster_stats and amcl_node give them.

    Particles are clustered by touching (0.5 m, 0.5 m, 10 degree) bins; the pose is the weighted mean
    of the heaviest cluster (yaw the atan2 of its weighted sines and cosines); the covariance is the
    whole set's: x, y from the weighted second moments, yaw `-2 ln sqrt(C^2 + S^2)` of the weighted
    sums of cosines and sines. Sums run in particle order, as Nav2's.

    Args:
        poses: (n, 3) particles.
        weights: Their (normalised) weights.
        native: Use the C kernel when it can be built.

    Returns:
        ((x, y, yaw) of the published cluster, the 3x3 covariance: [0, 1] = sum (w x) y based,
        [1, 0] = sum (w y) x based, as Nav2 keeps both).
    """
    lib = load_kernel() if native else None
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    w = np.ascontiguousarray(weights, dtype=np.float64)
    keys: NDArray[np.int64]
    if lib is not None:
        keys = np.empty((len(poses), 3), dtype=np.int64)
        lib.twin_pf_keys(poses.ctypes.data, len(poses), _BIN_SIZE.ctypes.data, keys.ctypes.data)
    else:
        keys = np.floor(poses / _BIN_SIZE).astype(np.int64)
    cluster, count = _clusters(keys, lib)
    cov = np.zeros((3, 3))
    if lib is not None:
        out = np.empty(8)
        if lib.twin_pf_estimate(poses.ctypes.data, w.ctypes.data, len(w), cluster.ctypes.data, count, out.ctypes.data):
            raise MemoryError("amcl estimate: out of memory")
        cov[0, 0], cov[1, 1], cov[0, 1], cov[2, 2], cov[1, 0] = out[3], out[4], out[5], out[6], out[7]
        return (float(out[0]), float(out[1]), float(out[2])), cov
    x, y = poses[:, 0], poses[:, 1]
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    cw = np.array([_running(w[cluster == label]) for label in range(count + 1)])
    mask = cluster == int(np.argmax(cw))
    wc = w[mask]
    total = _running(wc)
    mean = (
        _running(wc * x[mask]) / total,
        _running(wc * y[mask]) / total,
        math.atan2(_running(wc * s[mask]), _running(wc * c[mask])),
    )
    wt = _running(w)
    sx, sy = _running(w * x) / wt, _running(w * y) / wt
    cov[0, 0] = _running(w * x * x) / wt - sx * sx
    cov[1, 1] = _running(w * y * y) / wt - sy * sy
    cov[0, 1] = _running(w * x * y) / wt - sx * sy
    cov[1, 0] = _running(w * y * x) / wt - sy * sx
    sc, ss = _running(w * c), _running(w * s)
    cov[2, 2] = -2 * math.log(math.sqrt(sc * sc + ss * ss))
    return mean, cov


class Amcl:
    """Nav2's AMCL filter: set an initial pose, then feed every scan with the odometry pose at its time.

    Args:
        params: The `amcl` node's parameters.
        occupancy: The map it localises against (`/map`).
        laser: The scan's geometry and the laser's mount in the base frame.
        rng: The filter's random numbers: a `numpy.random.Generator` seeded from the scenario seed, or
            any `DrawSource` (a test replays recorded draws through one).
        native: Use the C kernel for the laser model when it can be built (else numpy).
    """

    def __init__(
        self,
        params: AmclParams,
        occupancy: OccupancyMap,
        laser: LaserGeometry,
        rng: DrawSource,
        *,
        native: bool = True,
    ) -> None:
        self._lib = load_kernel() if native else None
        self.params = params
        self.map = occupancy
        self.laser = laser
        self._rng = rng
        self.field = LikelihoodField(as_received(occupancy), params.laser_likelihood_max_dist_m, native=native)
        range_max = laser.range_max_m
        if params.laser_max_range_m > 0.0:
            range_max = min(range_max, params.laser_max_range_m)
        self._range_max = range_max
        self._range_min = max(laser.range_min_m, params.laser_min_range_m)
        self._pz = self.field.pz(params.z_hit, params.z_rand, params.sigma_hit_m, range_max)
        # KLD-sampling's particle bound for k occupied bins, k = 0 .. max_particles (one table, both paths)
        self._kld_limits = kld_limits(params.min_particles, params.max_particles, params.pf_err, params.pf_z)
        self.poses: F64 = np.zeros((0, 3))
        self.weights: F64 = np.zeros(0)
        self._w_slow = 0.0
        self._w_fast = 0.0
        self._initialised = False  # an initial pose was given
        self._pf_init = False  # the first scan after it was taken (odometry reference set)
        self._odom_ref = (0.0, 0.0, 0.0)
        self._resample_count = 0
        self._stats: tuple[tuple[float, float, float], F64] = ((0.0, 0.0, 0.0), np.zeros((3, 3)))
        self.estimate: AmclEstimate | None = None
        self.updated = False  # the last scan updated the filter
        self._bearings: F64 = np.zeros(0)  # each beam's angle in the base frame, as updateFilter computes it

    # --- inputs -------------------------------------------------------------------------------

    def set_initial_pose(self, x_m: float, y_m: float, yaw_rad: float, covariance: F64) -> None:
        """Spread `max_particles` particles from a Gaussian around a map pose (/initialpose).

        Args:
            x_m: Map x.
            y_m: Map y.
            yaw_rad: Map yaw.
            covariance: 3x3 covariance of (x, y, yaw), or the message's 36 values (6x6 row-major).

        Raises:
            ConfigError: If the pose lies outside the map or the covariance is not symmetric positive semi-definite.
        """
        if self.map.world_to_cell(x_m, y_m) is None:
            msg = (
                f"initial pose ({x_m:.3f}, {y_m:.3f}) lies outside the map (x from {self.map.origin_x_m:.2f}, "
                f"y from {self.map.origin_y_m:.2f}, {self.map.width} x {self.map.height} cells of "
                f"{self.map.resolution_m} m); give a pose on the map"
            )
            raise ConfigError(msg)
        cov = np.asarray(covariance, dtype=np.float64)
        if cov.size == 36:
            full = cov.reshape(6, 6)
            cov = np.array([[full[0, 0], full[0, 1], 0.0], [full[1, 0], full[1, 1], 0.0], [0.0, 0.0, full[5, 5]]])
        cov = cov.reshape(3, 3)
        values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
        if not np.all(np.isfinite(values)) or values.min() < -1e-12:
            msg = f"initial pose covariance {cov.tolist()} is not positive semi-definite; fix the covariance"
            raise ConfigError(msg)
        n = self.params.max_particles
        draws = self._rng.standard_normal((n, 3)) * np.sqrt(np.maximum(values, 0.0))
        self.set_particles(np.array([x_m, y_m, yaw_rad]) + draws @ vectors.T)

    def set_particles(self, poses: F64) -> None:
        """Start the filter from these particles (n, 3) of equal weight, as pf_init leaves it after drawing them.

        The next scan only weighs them (no motion), as after an initial pose.
        """
        n = len(poses)
        self.poses = np.array(poses, dtype=np.float64).reshape(n, 3)
        self.weights = np.full(n, 1.0 / n)
        self._w_slow = self._w_fast = 0.0
        self._initialised = True
        self._pf_init = False
        self._resample_count = 0
        self._clusters_now()  # pf_init's cluster statistics

    def process_scan(self, odom_pose: tuple[float, float, float], ranges: NDArray[np.floating]) -> AmclEstimate | None:
        """Take one scan with the odometry pose (odom frame, base) at its stamp.

        Returns:
            The estimate AMCL publishes on `amcl_pose` with this scan, else None. As Nav2's
            laserReceived, a pose is published when the filter resampled, and on the first update
            after an initial pose (then from the clusters of the initial set unless it resampled):
            with `resample_interval` above 1, updates in between publish none. `updated` tells
            whether the filter updated with this scan (then `particle_cloud` is published). Before an
            initial pose every scan is ignored. `map_odom()` holds the transform to broadcast on every
            scan once an estimate exists.
        """
        self.updated = False
        if not self._initialised:
            return None
        p = self.params
        x, y, yaw = odom_pose
        first = not self._pf_init
        if first:
            self._odom_ref = (x, y, yaw)
            self._pf_init = True
            self._resample_count = 0
        else:
            rx, ry, ryaw = self._odom_ref
            dx, dy, dyaw = x - rx, y - ry, _angle_diff(yaw, ryaw)
            if not (abs(dx) > p.update_min_d_m or abs(dy) > p.update_min_d_m or abs(dyaw) > p.update_min_a_rad):
                return None
            self._motion((x, y, yaw), (dx, dy, dyaw))
        if p.max_beams >= 2:  # Nav2's likelihood model refuses fewer than two beams (no weighting)
            self._sensor(np.asarray(ranges, dtype=np.float64))
        self._odom_ref = (x, y, yaw)
        self.updated = True
        self._resample_count += 1
        resampled = self._resample_count % p.resample_interval == 0
        if resampled:
            self._resample()
            self._clusters_now()
        if not (resampled or first):
            return None
        self.estimate = self._estimate(odom_pose)
        return self.estimate

    @property
    def w_slow(self) -> float:
        """The slow running average of the weights' mean (pf's w_slow; 0 until the first weighing)."""
        return self._w_slow

    @property
    def w_fast(self) -> float:
        """The fast running average of the weights' mean (pf's w_fast)."""
        return self._w_fast

    @property
    def has_initial_pose(self) -> bool:
        """True once an initial pose was set (before it, scans are ignored)."""
        return self._initialised

    def map_odom(self) -> tuple[float, float, float] | None:
        """Return the latest map->odom (x, y, yaw), or None before the first estimate."""
        return None if self.estimate is None else self.estimate.map_odom

    # --- the filter ---------------------------------------------------------------------------

    def _motion(self, pose: tuple[float, float, float], delta: tuple[float, float, float]) -> None:
        p = self.params
        alphas = (p.alpha1, p.alpha2, p.alpha3, p.alpha4)
        self.poses = odometry_update(self.poses, pose, delta, alphas, self._rng, native=self._lib is not None)

    def _sensor(self, ranges: F64) -> None:
        laser = self.laser
        r: F64 = ranges.copy()
        r[r <= self._range_min] = self._range_max  # as amcl_node fills LaserData
        if len(self._bearings) != len(r):
            self._bearings = nav2_bearings(laser, len(r))
        bearings = self._bearings
        beams = beam_endpoints(r, bearings, (laser.mount_x_m, laser.mount_y_m), self._range_max, self.params.max_beams)
        likelihood = laser_likelihood(self.poses, beams, self.field, self._pz, native=self._lib is not None)
        weights = self.weights * likelihood
        total = weight_total(weights)
        p = self.params
        if total > 0.0 and math.isfinite(total):
            self.weights = weights / total
            w_avg = total / len(weights)
            self._w_slow = (
                w_avg if self._w_slow == 0.0 else self._w_slow + p.recovery_alpha_slow * (w_avg - self._w_slow)
            )
            self._w_fast = (
                w_avg if self._w_fast == 0.0 else self._w_fast + p.recovery_alpha_fast * (w_avg - self._w_fast)
            )
        else:
            self.weights = np.full(len(weights), 1.0 / len(weights))

    def _bins(self, poses: F64) -> NDArray[np.int64]:
        """Each particle's (x, y, yaw) histogram bin, as pf_kdtree keys them (floor of pose / bin size)."""
        keys: NDArray[np.int64] = np.floor(poses / _BIN_SIZE).astype(np.int64)
        return keys

    def _resample(self) -> None:
        p = self.params
        rng = self._rng
        m = p.max_particles
        w_diff = 0.0
        if self._w_slow > 0.0:
            w_diff = max(0.0, 1.0 - self._w_fast / self._w_slow)
        draws = rng.random(m)
        recovering = w_diff > 0.0 and len(self.field.free_cells) > 0
        if not recovering:
            self.poses = kld_resample(self.poses, self.weights, draws, self._kld_limits, native=self._lib is not None)
            n = len(self.poses)
            self.weights = np.full(n, 1.0 / n)
            return
        cumulative = np.cumsum(self.weights)  # Nav2's c[i + 1] = c[i] + w[i], not renormalised
        pick = np.minimum(np.searchsorted(cumulative, draws, side="right"), len(cumulative) - 1)
        new = self.poses[pick]
        if recovering:
            random = rng.random(m) < w_diff
            count = int(random.sum())
            if count:
                cells = self.field.free_cells[rng.integers(0, len(self.field.free_cells), count)]
                res = self.field.resolution_m
                new[random, 0] = self.field.origin_x_m + cells[:, 1] * res
                new[random, 1] = self.field.origin_y_m + cells[:, 0] * res
                new[random, 2] = rng.uniform(-math.pi, math.pi, count)
            self._w_slow = self._w_fast = 0.0
        n = self._kld_count(self._bins(new))
        self.poses = new[:n]
        self.weights = np.full(n, 1.0 / n)

    def _kld_count(self, bins: NDArray[np.int64]) -> int:
        """How many of the drawn particles KLD-sampling keeps: the first n with n > limit(bins among them)."""
        return _kld_count(bins, self._kld_limits, self._lib)

    def _clusters(self, bins: NDArray[np.int64]) -> tuple[NDArray[np.int64], int]:
        """Each particle's cluster (bins that touch), numbered from 1 in raster order of the bins."""
        return _clusters(bins, self._lib)

    def _clusters_now(self) -> None:
        """pf_cluster_stats: the published cluster's mean and the set's covariance, kept until the next resampling."""
        self._stats = cluster_estimate(self.poses, self.weights, native=self._lib is not None)

    def _estimate(self, odom_pose: tuple[float, float, float]) -> AmclEstimate:
        poses = self.poses
        (mx, my, myaw), cov = self._stats
        ox, oy, oyaw = odom_pose
        # map->odom = map->base * (odom->base)^-1
        tyaw = myaw - oyaw
        c, s = math.cos(tyaw), math.sin(tyaw)
        tx = mx - (c * ox - s * oy)
        ty = my - (s * ox + c * oy)
        return AmclEstimate(
            x_m=mx,
            y_m=my,
            yaw_rad=myaw,
            covariance=cov,
            map_odom=(tx, ty, math.atan2(math.sin(tyaw), math.cos(tyaw))),
            particles=len(poses),
        )
