"""The Scene: the world's obstacles as triangle meshes, FCL objects and 2D slices for ray casting.

Built once from a `World` at start-up:

- every collision except infinite planes and floor-level slabs becomes an obstacle, with a
  triangle mesh in the world frame (`Scene.meshes()` gives them as trimesh meshes) and a
  python-fcl collision object (primitives stay primitives);
- `ray_caster(height_m)` cuts the obstacles with a horizontal plane into 2D segments and circles,
  analytic where the shape allows (upright boxes, cylinders, spheres, capsules, polylines; any mesh
  by exact plane intersection), and answers vectorised ray casts over all beams at once;
- `robot_body(...)`, `clearance(...)`, `collides(...)` and `CollisionMonitor` give the simulation
  loop a contact check whose per-step cost is a few arithmetic operations while the robot is
  far from obstacles.

Models that are not static are obstacles too: nothing in the world file moves in the twin. A
scenario's obstacles that appear, vanish and walk live beside the Scene (`twin.world.obstacles`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import fcl
import numpy as np
from numpy.typing import NDArray

from twin.core.errors import WorldError
from twin.core.geometry import Mat4
from twin.world._native import load_kernel
from twin.world.meshes import MeshArrays, MeshCache, geometry_arrays
from twin.world.types import (
    Box,
    Capsule,
    Collision,
    Cylinder,
    Ellipsoid,
    Geometry,
    Plane,
    Polyline,
    Sphere,
    World,
    geometry_kind,
)

if TYPE_CHECKING:
    import trimesh

__all__ = ["CollisionMonitor", "Contact", "RayCaster", "RobotBody", "Scene", "build_scene", "obstacle_extent"]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
_TWO_PI = 2.0 * math.pi
_UPRIGHT_TOL = 1e-9


class Contact(NamedTuple):
    """One contact between the robot and an obstacle.

    `normal` is a unit vector in the world frame pointing from the obstacle towards the robot
    (the direction that separates them); `depth_m` is the penetration depth (>= 0).
    """

    model: str
    link: str
    collision: str
    robot_link: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    depth_m: float


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class _Obstacle:
    collision: Collision
    mesh: MeshArrays  # in the world frame
    bounds: F64  # (2, 3): the mesh's min and max corners
    fcl_object: fcl.CollisionObject
    fcl_geometry: fcl.CollisionGeometry


# --- construction helpers -------------------------------------------------------------------------


def _fcl_transform(mat: Mat4) -> fcl.Transform:
    return fcl.Transform(np.ascontiguousarray(mat[:3, :3]), np.ascontiguousarray(mat[:3, 3]))


def _fcl_geometry(geometry: Geometry, mesh: MeshArrays | None) -> fcl.CollisionGeometry | None:
    match geometry:
        case Box(size_m=size):
            return fcl.Box(*size)
        case Cylinder(radius_m=r, length_m=length):
            return fcl.Cylinder(r, length)
        case Sphere(radius_m=r):
            return fcl.Sphere(r)
        case Capsule(radius_m=r, length_m=length):
            return fcl.Capsule(r, length)
        case Ellipsoid(radii_m=radii):
            return fcl.Ellipsoid(*radii)
        case Plane():
            return None
    if mesh is None:
        return None
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


_PRIMITIVES = (Box, Cylinder, Sphere, Capsule, Ellipsoid, Plane)
"""Geometries FCL holds as shapes; any other is a triangle mesh."""


def _is_upright(T: Mat4) -> bool:
    """True when the shape's local z axis is the world's (so horizontal slices are analytic)."""
    return abs(abs(float(T[2, 2])) - 1.0) < _UPRIGHT_TOL


class _Block(NamedTuple):
    seg_idx: NDArray[np.int64]
    circ_idx: NDArray[np.int64]
    seg_ptr: int
    circ_ptr: int


class _Slice(NamedTuple):
    segments: F64  # (M, 4): x0, y0, x1, y1
    circles: F64  # (K, 3): cx, cy, r
    segment_owner: NDArray[np.int64]
    circle_owner: NDArray[np.int64]


def _box_section(T: Mat4, size: tuple[float, float, float], z: float) -> list[tuple[float, float, float, float]]:
    half = np.asarray(size) / 2.0
    if _is_upright(T):
        if abs(z - T[2, 3]) > half[2]:
            return []
        corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
        pts = [T[:2, 3] + T[:2, 0] * sx * half[0] + T[:2, 1] * sy * half[1] for sx, sy in corners]
        return [(*pts[i], *pts[(i + 1) % 4]) for i in range(4)]
    # Tilted box: intersect the plane with the 12 edges; the section is a convex polygon.
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    verts = (T[:3, :3] @ (signs * half).T).T + T[:3, 3]
    points = []
    for i in range(8):
        for j in range(i + 1, 8):
            if np.count_nonzero(signs[i] != signs[j]) != 1:
                continue
            za, zb = verts[i, 2], verts[j, 2]
            if (za - z) * (zb - z) > 0 or za == zb:
                continue
            s = (z - za) / (zb - za)
            points.append(verts[i, :2] + s * (verts[j, :2] - verts[i, :2]))
    if len(points) < 3:
        return []
    arr = np.array(points)
    centre = arr.mean(axis=0)
    order = np.argsort(np.arctan2(arr[:, 1] - centre[1], arr[:, 0] - centre[0]))
    arr = arr[order]
    keep = [arr[0]]
    for p in arr[1:]:
        if np.hypot(*(p - keep[-1])) > 1e-12:
            keep.append(p)
    return [(*keep[i], *keep[(i + 1) % len(keep)]) for i in range(len(keep))] if len(keep) >= 3 else []


def _section(
    obstacle: _Obstacle, z: float
) -> tuple[list[tuple[float, float, float, float]], list[tuple[float, float, float]]]:
    """Return the segments and circles where the plane at height z cuts one obstacle."""
    geometry, T = obstacle.collision.geometry, obstacle.collision.T_world
    bounds = obstacle.bounds
    if not (bounds[0, 2] - 1e-9 <= z <= bounds[1, 2] + 1e-9) and not isinstance(geometry, (Sphere, Capsule, Cylinder)):
        return [], []
    dz = z - float(T[2, 3])
    upright = _is_upright(T)
    match geometry:
        case Box(size_m=size):
            return _box_section(T, size, z), []
        case Cylinder(radius_m=r, length_m=length) if upright:
            return ([], [(float(T[0, 3]), float(T[1, 3]), r)]) if abs(dz) <= length / 2 else ([], [])
        case Sphere(radius_m=r):
            return ([], [(float(T[0, 3]), float(T[1, 3]), math.sqrt(r * r - dz * dz))]) if abs(dz) < r else ([], [])
        case Capsule(radius_m=r, length_m=length) if upright:
            reach = abs(dz) - length / 2
            if reach <= 0:
                return [], [(float(T[0, 3]), float(T[1, 3]), r)]
            return ([], [(float(T[0, 3]), float(T[1, 3]), math.sqrt(r * r - reach * reach))]) if reach < r else ([], [])
        case Ellipsoid(radii_m=(rx, ry, rz)) if upright and rx == ry:
            frac = 1.0 - (dz / rz) ** 2
            return ([], [(float(T[0, 3]), float(T[1, 3]), rx * math.sqrt(frac))]) if frac > 0 else ([], [])
        case Polyline(polygons=polygons, height_m=h) if upright:
            # Extruded from the frame's z = 0 along its z axis (which may point down).
            lo, hi = sorted((float(T[2, 3]), float(T[2, 3] + T[2, 2] * h)))
            if not lo <= z <= hi:
                return [], []
            segs: list[tuple[float, float, float, float]] = []
            for polygon in polygons:
                pts = [T[:2, :2] @ np.array(p) + T[:2, 3] for p in polygon]
                segs.extend((*pts[i], *pts[(i + 1) % len(pts)]) for i in range(len(pts)))
            return segs, []
    import trimesh

    lines = trimesh.intersections.mesh_plane(obstacle.mesh.to_trimesh(), [0.0, 0.0, 1.0], [0.0, 0.0, z])  # type: ignore[no-untyped-call]
    return [(float(a[0]), float(a[1]), float(b[0]), float(b[1])) for a, b in lines], []


# --- ray casting ---------------------------------------------------------------------------------


class RayCaster:
    """Casts horizontal rays against the scene's cross-section at one height.

    Rays start at `origin_xy` and report the distance to the first surface they cross at or beyond
    `min_range_m` (a ray that starts inside a shape reports where it leaves it, as Gazebo's ODE
    rays do), or `inf` when nothing is crossed within `max_range_m`. All beams are handled in one
    vectorised pass: for each nearby segment and circle the beams inside its angular extent are
    paired with it, and only those pairs are intersected.

    A uniform grid indexes the segments and circles; a cast looks only at the cells within
    `max_range_m` of the origin (the union for each cell is computed once and memoised).
    """

    def __init__(
        self, section: _Slice, height_m: float, labels: Sequence[str], cell_m: float = 1.0, *, native: bool = True
    ) -> None:
        self.height_m = height_m
        self._lib = load_kernel() if native else None
        self._labels = tuple(labels)
        seg = np.ascontiguousarray(section.segments, dtype=np.float64).reshape(-1, 4)
        keep = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 1e-12
        self._seg = seg[keep]
        self._seg_owner = section.segment_owner[keep]
        self._ex = self._seg[:, 2] - self._seg[:, 0]
        self._ey = self._seg[:, 3] - self._seg[:, 1]
        self._circ = np.ascontiguousarray(section.circles, dtype=np.float64).reshape(-1, 3)
        self._circ_owner = section.circle_owner
        self._cell_m = float(cell_m)
        self._blocks: dict[tuple[int, int, int], _Block] = {}
        self._seg_ptr = self._seg.ctypes.data
        self._circ_ptr = self._circ.ctypes.data
        if len(self._seg) or len(self._circ):
            lo_seg = np.minimum(self._seg[:, :2], self._seg[:, 2:])
            hi_seg = np.maximum(self._seg[:, :2], self._seg[:, 2:])
            lo_c = self._circ[:, :2] - self._circ[:, 2:3]
            hi_c = self._circ[:, :2] + self._circ[:, 2:3]
            self._seg_cells = (
                np.floor(lo_seg / self._cell_m).astype(np.int64),
                np.floor(hi_seg / self._cell_m).astype(np.int64),
            )
            self._circ_cells = (
                np.floor(lo_c / self._cell_m).astype(np.int64),
                np.floor(hi_c / self._cell_m).astype(np.int64),
            )

    @property
    def native(self) -> bool:
        """Whether the compiled kernel casts (else the numpy implementation, same ranges)."""
        return self._lib is not None

    @property
    def segments(self) -> F64:
        """The slice's segments, shape (M, 4): x0, y0, x1, y1 in the world frame (read-only view)."""
        view = self._seg.view()
        view.flags.writeable = False
        return view

    @property
    def circles(self) -> F64:
        """The slice's circles, shape (K, 3): centre x, y and radius (read-only view)."""
        view = self._circ.view()
        view.flags.writeable = False
        return view

    def _candidates(self, x: float, y: float, max_range_m: float) -> _Block:
        reach = max(1, math.ceil(max_range_m / self._cell_m))
        key = (math.floor(x / self._cell_m), math.floor(y / self._cell_m), reach)
        found = self._blocks.get(key)
        if found is None:
            cx, cy, _ = key
            lo = np.array([cx - reach, cy - reach])
            hi = np.array([cx + reach, cy + reach])
            if len(self._seg) or len(self._circ):
                seg_idx = _overlapping(self._seg_cells, lo, hi)
                circ_idx = _overlapping(self._circ_cells, lo, hi)
            else:
                seg_idx = circ_idx = np.empty(0, dtype=np.int64)
            found = _Block(seg_idx, circ_idx, seg_idx.ctypes.data, circ_idx.ctypes.data)
            if len(self._blocks) > 100_000:
                self._blocks.clear()
            self._blocks[key] = found
        return found

    def cast_rays(
        self, origin_xy: tuple[float, float], angles_rad: F64, max_range_m: float, *, min_range_m: float = 0.0
    ) -> F64:
        """Return the range along each beam (world-frame angles), `inf` where nothing is hit.

        Args:
            origin_xy: Ray origin in the world frame (m).
            angles_rad: Beam directions in the world frame, any order, shape (N,).
            max_range_m: Hits beyond this are not reported.
            min_range_m: Rays start this far from the origin; nearer surfaces are not seen.
        """
        angles = np.ascontiguousarray(angles_rad, dtype=np.float64)
        if self._lib is not None:
            block = self._candidates(float(origin_xy[0]), float(origin_xy[1]), max_range_m)
            out = np.empty(len(angles))
            self._lib.twin_cast_rays(
                self._seg_ptr, block.seg_ptr, len(block.seg_idx), self._circ_ptr, block.circ_ptr, len(block.circ_idx),
                float(origin_xy[0]), float(origin_xy[1]), len(angles), angles.ctypes.data,
                min_range_m, max_range_m, out.ctypes.data,
            )  # fmt: skip
            return out
        wrapped = np.mod(angles, _TWO_PI)
        order = np.argsort(wrapped, kind="stable")
        sorted_angles = wrapped[order]
        ranges_sorted = self._cast(origin_xy, sorted_angles, None, max_range_m, min_range_m)
        out = np.empty_like(ranges_sorted)
        out[order] = ranges_sorted
        return out

    def cast_fan(
        self,
        origin_xy: tuple[float, float],
        start_rad: float,
        increment_rad: float,
        count: int,
        max_range_m: float,
        *,
        min_range_m: float = 0.0,
    ) -> F64:
        """Return ranges for `count` beams at `start_rad + i * increment_rad` (world frame).

        The same ranges as `cast_rays` on those angles, faster: each shape is paired only with the
        beams inside its angular extent.
        """
        if increment_rad <= 0.0 or count < 1:
            angles = start_rad + increment_rad * np.arange(count, dtype=np.float64)
            return self.cast_rays(origin_xy, angles, max_range_m, min_range_m=min_range_m)
        ox, oy = float(origin_xy[0]), float(origin_xy[1])
        if self._lib is not None:
            block = self._candidates(ox, oy, max_range_m)
            out = np.empty(count)
            status = self._lib.twin_cast_fan(
                self._seg_ptr, block.seg_ptr, len(block.seg_idx), self._circ_ptr, block.circ_ptr, len(block.circ_idx),
                ox, oy, float(start_rad), float(increment_rad), int(count), min_range_m, max_range_m, out.ctypes.data,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("ray caster kernel could not allocate its beam buffer")
            return out
        beam = start_rad + increment_rad * np.arange(count)
        return self._cast(
            (ox, oy), None, (start_rad, increment_rad, count, (np.cos(beam), np.sin(beam))), max_range_m, min_range_m
        )

    def cast_scan(
        self,
        origin_xy: tuple[float, float],
        start_rad: float,
        increment_rad: float,
        count: int,
        *,
        range_min_m: float,
        range_max_m: float,
        noise_m: F64 | None = None,
        also: tuple[F64, F64] | None = None,
    ) -> NDArray[np.float32]:
        """Return a lidar scan: `cast_fan` ranges masked as REP 117 says, optionally noisy.

        `also` (the compiled kernel only: see `native`) adds shapes outside the slice, as contiguous
        float64 arrays of segments (M, 4) and circles (K, 3), each cast against every beam.

        A range at or beyond `range_max_m` (nothing hit) is `+inf`, one at or below `range_min_m`
        is `-inf`; `noise_m` (shape (count,)) is added to the others, which are then clamped to
        [`range_min_m`, `range_max_m`]. float32, as LaserScan carries ranges. One compiled call
        when the kernel is available.
        """
        if also is not None and self._lib is None:
            raise ValueError("cast_scan(also=...) needs the compiled kernel; check RayCaster.native first")
        if self._lib is not None and increment_rad > 0.0 and count >= 1:
            ox, oy = float(origin_xy[0]), float(origin_xy[1])
            block = self._candidates(ox, oy, range_max_m)
            out = np.empty(count, dtype=np.float32)
            noise_ptr = None
            if noise_m is not None:
                noise_m = np.ascontiguousarray(noise_m, dtype=np.float64)
                noise_ptr = noise_m.ctypes.data
            if also is not None:
                seg2, circ2 = also
                status = self._lib.twin_scan_with(
                    self._seg_ptr, block.seg_ptr, len(block.seg_idx), self._circ_ptr, block.circ_ptr,
                    len(block.circ_idx), seg2.ctypes.data, len(seg2), circ2.ctypes.data, len(circ2),
                    ox, oy, float(start_rad), float(increment_rad), int(count), range_min_m, range_max_m,
                    noise_ptr, out.ctypes.data,
                )  # fmt: skip
                if status != 0:
                    raise MemoryError("ray caster kernel could not allocate its beam buffer")
                return out
            status = self._lib.twin_scan(
                self._seg_ptr, block.seg_ptr, len(block.seg_idx), self._circ_ptr, block.circ_ptr, len(block.circ_idx),
                ox, oy, float(start_rad), float(increment_rad), int(count), range_min_m, range_max_m,
                noise_ptr, out.ctypes.data,
            )  # fmt: skip
            if status != 0:
                raise MemoryError("ray caster kernel could not allocate its beam buffer")
            return out
        ranges = self.cast_fan(origin_xy, start_rad, increment_rad, count, range_max_m, min_range_m=range_min_m)
        return mask_ranges(ranges, range_min_m, range_max_m, noise_m)

    def _cast(
        self,
        origin_xy: tuple[float, float],
        sorted_angles: F64 | None,
        fan: tuple[float, float, int, tuple[F64, F64]] | None,
        max_range_m: float,
        min_range_m: float,
    ) -> F64:
        ox, oy = float(origin_xy[0]), float(origin_xy[1])
        if fan is not None:
            n, (cos_b, sin_b) = fan[2], fan[3]
        else:
            assert sorted_angles is not None
            n = len(sorted_angles)
            cos_b, sin_b = np.cos(sorted_angles), np.sin(sorted_angles)
        ranges = np.full(n, np.inf)
        if n == 0 or (not len(self._seg) and not len(self._circ)):
            return ranges
        block = self._candidates(ox, oy, max_range_m)
        seg_idx, circ_idx = block.seg_idx, block.circ_idx

        if len(seg_idx):
            seg = self._seg[seg_idx]
            wx0 = seg[:, 0] - ox
            wy0 = seg[:, 1] - oy
            ex = self._ex[seg_idx]
            ey = self._ey[seg_idx]
            a0 = np.arctan2(wy0, wx0)
            a1 = np.arctan2(wy0 + ey, wx0 + ex)
            span = np.mod(a1 - a0, _TWO_PI)
            flip = span > math.pi
            lo_angle = np.where(flip, a1, a0) - 1e-9
            span = np.where(flip, _TWO_PI - span, span) + 2e-9
            beams, owners = _pairs(lo_angle, span, sorted_angles, fan)
            if len(beams):
                c = cos_b[beams]
                s = sin_b[beams]
                pex = ex[owners]
                pey = ey[owners]
                pwx = wx0[owners]
                pwy = wy0[owners]
                denom = c * pey - s * pex
                with np.errstate(divide="ignore", invalid="ignore"):
                    inv = 1.0 / denom
                    t = (pwx * pey - pwy * pex) * inv
                    u = (pwx * s - pwy * c) * inv
                ok = (u >= -1e-12) & (u <= 1.0 + 1e-12) & (t >= min_range_m) & (t <= max_range_m)
                np.minimum.at(ranges, beams[ok], t[ok])

        if len(circ_idx):
            circ = self._circ[circ_idx]
            qx = circ[:, 0] - ox
            qy = circ[:, 1] - oy
            r = circ[:, 2]
            dist = np.hypot(qx, qy)
            inside = dist <= r
            centre = np.arctan2(qy, qx)
            with np.errstate(invalid="ignore"):
                half = np.where(inside, math.pi, np.arcsin(np.minimum(1.0, r / np.maximum(dist, 1e-300))))
            beams, owners = _pairs(centre - half - 1e-9, 2.0 * half + 2e-9, sorted_angles, fan)
            if len(beams):
                b = cos_b[beams] * qx[owners] + sin_b[beams] * qy[owners]
                cc = (dist * dist - r * r)[owners]
                disc = b * b - cc
                with np.errstate(invalid="ignore"):
                    root = np.sqrt(disc)
                t1 = b - root
                t = np.where(t1 >= min_range_m, t1, b + root)
                ok = (disc >= 0.0) & (t >= min_range_m) & (t <= max_range_m)
                np.minimum.at(ranges, beams[ok], t[ok])
        return ranges


def mask_ranges(ranges: F64, range_min_m: float, range_max_m: float, noise_m: F64 | None = None) -> NDArray[np.float32]:
    """Mask raw ranges as REP 117 says and add clamped noise to the in-range ones (float32 out)."""
    out = np.array(ranges, dtype=np.float64)
    out[out >= range_max_m] = np.inf
    out[out <= range_min_m] = -np.inf
    if noise_m is not None:
        noisy = np.clip(out + noise_m, range_min_m, range_max_m)
        out = np.where(np.isfinite(out), noisy, out)
    return out.astype(np.float32)


def _overlapping(
    cells: tuple[NDArray[np.int64], NDArray[np.int64]], lo: NDArray[np.int64], hi: NDArray[np.int64]
) -> NDArray[np.int64]:
    cmin, cmax = cells
    mask = (cmax[:, 0] >= lo[0]) & (cmin[:, 0] <= hi[0]) & (cmax[:, 1] >= lo[1]) & (cmin[:, 1] <= hi[1])
    return np.ascontiguousarray(np.flatnonzero(mask), dtype=np.int64)


def _pairs(
    lo_angle: F64, span: F64, sorted_angles: F64 | None, fan: tuple[float, float, int, tuple[F64, F64]] | None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pair each shape with the beams inside its angular interval [lo, lo + span].

    Returns (beam index, shape index) arrays. Intervals are tried at three turns (-1, 0, +1)
    so wrap-around at 2*pi and fans wider than a full turn are covered.
    """
    k = len(lo_angle)
    starts = []
    stops = []
    if fan is not None:
        start, inc, n, _ = fan
        u = np.mod(lo_angle - start, _TWO_PI)
        for turn in (-_TWO_PI, 0.0, _TWO_PI):
            first = np.ceil((u + turn) / inc)
            last = np.floor((u + span + turn) / inc)
            starts.append(np.clip(first, 0, n))
            stops.append(np.clip(last + 1, 0, n))
    else:
        assert sorted_angles is not None
        n = len(sorted_angles)
        u = np.mod(lo_angle, _TWO_PI)
        for turn in (-_TWO_PI, 0.0):
            starts.append(np.searchsorted(sorted_angles, u + turn, side="left"))
            stops.append(np.searchsorted(sorted_angles, u + span + turn, side="right"))
    first_all = np.concatenate(starts).astype(np.intp)
    last_all = np.concatenate(stops).astype(np.intp)
    counts = np.maximum(last_all - first_all, 0)
    total = int(counts.sum())
    if total == 0:
        empty = np.empty(0, dtype=np.intp)
        return empty, empty
    owners = np.repeat(np.tile(np.arange(k, dtype=np.intp), len(starts)), counts)
    offsets = np.repeat(np.cumsum(counts) - counts - first_all, counts)
    beams = np.arange(total, dtype=np.intp) - offsets
    return beams, owners


# --- the robot against the scene ------------------------------------------------------------------

# A shape's bounding circle is measured on its mesh, whose curved faces are polygons inside the true
# surface; circles this much apart may still hold touching shapes, m (a 32-gon of 5 cm: 0.25 mm).
_CIRCLE_PAD_M = 1e-3


class RobotBody:
    """The robot's collision shapes as FCL objects, posed by a planar (x, y, yaw).

    Args:
        collisions: The robot's collision shapes; each `T_world` is its pose in the robot's
            base frame (`base_footprint`).
        base_height_m: Height of the base frame above the floor (the robot stands on z = 0).
    """

    def __init__(self, collisions: Iterable[Collision], *, base_height_m: float = 0.0) -> None:
        cache = MeshCache()
        self._local: list[Mat4] = []
        self._objects: list[fcl.CollisionObject] = []
        self._owner: dict[int, Collision] = {}
        self._parts: list[_Obstacle] = []
        self._sections: dict[float, tuple[F64, F64]] = {}
        radius = 0.0
        z_lo, z_hi = math.inf, -math.inf
        self.base_height_m = base_height_m
        for collision in collisions:
            mesh = geometry_arrays(collision.geometry, cache, collision.where)
            geometry = _fcl_geometry(collision.geometry, mesh)
            if geometry is None or mesh is None:
                continue
            T = np.array(collision.T_world)
            T[2, 3] += base_height_m
            pts = mesh.vertices @ T[:3, :3].T + T[:3, 3]
            radius = max(radius, float(np.max(np.hypot(pts[:, 0], pts[:, 1]))))
            z_lo, z_hi = min(z_lo, float(pts[:, 2].min())), max(z_hi, float(pts[:, 2].max()))
            obj = fcl.CollisionObject(geometry, _fcl_transform(T))
            self._local.append(T)
            self._objects.append(obj)
            self._owner[id(geometry)] = collision
            # The shape in the base frame, for its section at a lidar's height (`section`).
            placed = MeshArrays(pts, mesh.faces)
            self._parts.append(
                _Obstacle(
                    collision=dataclasses.replace(collision, T_world=T),
                    mesh=placed,
                    bounds=placed.bounds(),
                    fcl_object=obj,
                    fcl_geometry=geometry,
                )
            )
        if not self._objects:
            msg = "the robot has no collision shapes to check against the world"
            raise WorldError(msg)
        self.radius_m = radius
        """Largest horizontal distance of any collision point from the base frame's z axis."""
        self.z_range_m = (z_lo, z_hi)
        # Every shape's rotation and translation in the base frame, stacked: `_place` turns them all at once.
        self._rotations = np.array([T[:3, :3] for T in self._local])
        self._translations = np.array([T[:3, 3:4] for T in self._local])
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        self._manager.registerObjects(self._objects)
        self._manager.setup()
        height = max(z_hi - z_lo, 1e-6)
        self._bound_geometry = fcl.Cylinder(radius, height)
        self._bound = fcl.CollisionObject(
            self._bound_geometry, fcl.Transform(np.eye(3), np.array([0.0, 0.0, (z_lo + z_hi) / 2]))
        )
        self._bound_z = (z_lo + z_hi) / 2
        # Each shape's bounding circle in the base frame's xy plane (cx, cy, r): a query between two
        # robots places and asks FCL about only the shapes whose circles reach the other robot.
        circles = []
        for part in self._parts:
            xy = part.mesh.vertices[:, :2]
            centre = (xy.min(axis=0) + xy.max(axis=0)) / 2.0
            circles.append((float(centre[0]), float(centre[1]), float(np.max(np.hypot(*(xy - centre).T)))))
        self._circles: tuple[tuple[float, float, float], ...] = tuple(circles)
        self._placed_at: tuple[float, float, float] | None = None  # every shape placed there, the tree updated
        self._part_at: list[tuple[float, float, float] | None] = [None] * len(self._objects)
        self._turned: tuple[float, F64, F64] | None = None  # a heading and the shapes turned by it
        self._circles_at: tuple[tuple[float, float, float], list[tuple[float, float, float]]] | None = None
        # `touches`' request: `contacts_with`'s own (the same narrow phase decides), one contact enough.
        self._touch_request = fcl.CollisionRequest(num_max_contacts=1, enable_contact=True)

    def _placements(self, x: float, y: float, yaw: float) -> tuple[F64, F64]:
        """Every shape's rotation and translation in the world with the base frame at this pose."""
        turned = self._turned
        if turned is None or turned[0] != yaw:  # a robot pressed against another often keeps its heading
            c, s = math.cos(yaw), math.sin(yaw)
            rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            # each shape's rot @ R and rot @ t, as one product each
            turned = self._turned = (yaw, rot @ self._rotations, (rot @ self._translations)[:, :, 0])
        return turned[1], turned[2] + np.array([x, y, 0.0])

    def _place(self, x: float, y: float, yaw: float) -> None:
        """Place every shape at this pose and update the broad phase's tree (for a whole-body query)."""
        pose = (x, y, yaw)
        if pose == self._placed_at:  # e.g. a robot stalled against another: asked again at one pose
            return
        self._placed_at = pose
        rotations, translations = self._placements(x, y, yaw)
        part_at = self._part_at
        for i, obj in enumerate(self._objects):
            if part_at[i] != pose:
                obj.setTransform(fcl.Transform(rotations[i], translations[i]))
                part_at[i] = pose
        self._manager.update()

    def _place_parts(self, pose: tuple[float, float, float], parts: Iterable[int]) -> None:
        """Place only these shapes at this pose (the tree is left stale: the next `_place` updates it)."""
        part_at = self._part_at
        todo = [i for i in parts if part_at[i] != pose]
        if not todo:
            return
        self._placed_at = None
        rotations, translations = self._placements(*pose)  # the same numbers `_place` sets
        objects = self._objects
        for i in todo:
            objects[i].setTransform(fcl.Transform(rotations[i], translations[i]))
            part_at[i] = pose

    def _placed_circles(self, pose: tuple[float, float, float]) -> list[tuple[float, float, float]]:
        """Every shape's bounding circle (cx, cy, r) in the world with the base frame at `pose`."""
        known = self._circles_at
        if known is not None and known[0] == pose:
            return known[1]
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        circles = [(x + c * cx - s * cy, y + s * cx + c * cy, r) for cx, cy, r in self._circles]
        self._circles_at = (pose, circles)
        return circles

    def _near_pairs(
        self, pose: tuple[float, float, float], other: RobotBody, other_pose: tuple[float, float, float], reach_m: float
    ) -> list[tuple[float, int, int]]:
        """The pairs of shapes (mine, theirs) whose bounding circles are within `reach_m`, with that gap.

        Two shapes whose circles are farther apart than a distance cannot be nearer than it, so a
        query between two robots need ask FCL about these pairs only.
        """
        hypot = math.hypot
        mine = [
            (i, c)
            for i, c in enumerate(self._placed_circles(pose))
            if hypot(c[0] - other_pose[0], c[1] - other_pose[1]) - c[2] - other.radius_m <= reach_m
        ]
        if not mine:
            return []
        theirs = [
            (j, c)
            for j, c in enumerate(other._placed_circles(other_pose))
            if hypot(c[0] - pose[0], c[1] - pose[1]) - c[2] - self.radius_m <= reach_m
        ]
        pairs = []
        for i, (ax, ay, ar) in mine:
            for j, (bx, by, br) in theirs:
                gap = hypot(ax - bx, ay - by) - ar - br
                if gap <= reach_m:
                    pairs.append((gap, i, j))
        return pairs

    def _place_bound(self, x: float, y: float) -> None:
        self._bound.setTranslation(np.array([x, y, self._bound_z]))

    def owner(self, geometry: object) -> Collision | None:
        """Return the robot collision an FCL geometry belongs to."""
        return self._owner.get(id(geometry))

    def section(self, height_m: float) -> tuple[F64, F64]:
        """Return where the plane at `height_m` above the floor cuts the robot's shapes, in its base frame.

        Returns:
            Segments (M, 4: x0, y0, x1, y1) and circles (K, 3: cx, cy, r), m; what another robot's
            lidar at that height sees of this one.
        """
        key = round(float(height_m), 9)
        cached = self._sections.get(key)
        if cached is None:
            segments: list[tuple[float, float, float, float]] = []
            circles: list[tuple[float, float, float]] = []
            for part in self._parts:
                if not part.bounds[0, 2] - 1e-9 <= key <= part.bounds[1, 2] + 1e-9:
                    continue  # below or above the plane (a wheel under a lidar): nothing to cut
                segs, circs = _section(part, key)
                segments += segs
                circles += circs
            cached = (
                np.array(segments, dtype=np.float64).reshape(-1, 4),
                np.array(circles, dtype=np.float64).reshape(-1, 3),
            )
            self._sections[key] = cached
        return cached

    def distance_to(
        self, pose: tuple[float, float, float], other: RobotBody, other_pose: tuple[float, float, float]
    ) -> float:
        """Return the distance between this robot's shapes at `pose` and another's at `other_pose` (0: touching)."""
        # FCL's distance between the shapes, pair by pair as its broad phase would ask, nearest
        # circles first; a pair whose circles are farther apart than the distance found so far
        # cannot lower it.
        pairs = self._near_pairs(pose, other, other_pose, math.inf)
        pairs.sort()
        request, result = fcl.DistanceRequest(), fcl.DistanceResult()
        own, others = self._objects, other._objects
        for gap, i, j in pairs:
            if gap - _CIRCLE_PAD_M >= result.min_distance:
                break
            self._place_parts(pose, (i,))  # each shape placed once, when first needed
            other._place_parts(other_pose, (j,))
            fcl.distance(own[i], others[j], request, result)
            if result.min_distance <= 0.0:
                break
        return max(0.0, float(result.min_distance))

    def touches(
        self, pose: tuple[float, float, float], other: RobotBody, other_pose: tuple[float, float, float]
    ) -> bool:
        """Whether this robot's shapes at `pose` touch another's at `other_pose`: `contacts_with` as a yes or no.

        The same pairs and the same FCL request as `contacts_with` (its answer is non-empty exactly
        when this is true), stopping at the first pair that collides and building no contacts.
        """
        request = self._touch_request
        own, others = self._objects, other._objects
        for _, i, j in self._near_pairs(pose, other, other_pose, _CIRCLE_PAD_M):
            self._place_parts(pose, (i,))  # each shape placed once, when first needed
            other._place_parts(other_pose, (j,))
            if fcl.collide(own[i], others[j], request, fcl.CollisionResult()):
                return True
        return False

    def contacts_with(
        self,
        pose: tuple[float, float, float],
        other: RobotBody,
        other_pose: tuple[float, float, float],
        *,
        max_contacts: int = 8,
    ) -> list[tuple[Collision, Collision, tuple[float, float, float], tuple[float, float, float], float]]:
        """Return the contacts of this robot at `pose` with another at `other_pose`, deepest first.

        Returns:
            (own collision, other's collision, point, normal pointing from the other into this robot, depth m).
        """
        request = fcl.CollisionRequest(num_max_contacts=max_contacts, enable_contact=True)
        result = fcl.CollisionResult()
        own, others = self._objects, other._objects
        # FCL's narrow phase on the pairs of shapes whose bounding circles touch (no other pair can),
        # as its broad phase would ask them, until it has `max_contacts`.
        pairs = self._near_pairs(pose, other, other_pose, _CIRCLE_PAD_M)
        if pairs:
            self._place_parts(pose, {i for _, i, _ in pairs})
            other._place_parts(other_pose, {j for _, _, j in pairs})
        for _, i, j in pairs:
            fcl.collide(own[i], others[j], request, result)
            if len(result.contacts) > max_contacts:  # where FCL's own callback stops
                break
        out = []
        for contact in result.contacts:
            mine, theirs = self.owner(contact.o1), other.owner(contact.o2)
            normal = -np.asarray(contact.normal, dtype=float)
            if mine is None:
                mine, theirs = self.owner(contact.o2), other.owner(contact.o1)
                normal = -normal
            if mine is None or theirs is None:
                continue
            point = (float(contact.pos[0]), float(contact.pos[1]), float(contact.pos[2]))
            out.append(
                (
                    mine,
                    theirs,
                    point,
                    (float(normal[0]), float(normal[1]), float(normal[2])),
                    max(0.0, float(contact.penetration_depth)),
                )
            )
        out.sort(key=lambda c: -c[4])
        return out


class Scene:
    """The world's obstacles, ready for ray casting and collision checks. Build with `build_scene`."""

    def __init__(self, obstacles: Sequence[_Obstacle], *, world_name: str = "") -> None:
        self.world_name = world_name
        self._obstacles = tuple(obstacles)
        self._owner = {id(o.fcl_geometry): o.collision for o in self._obstacles}
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        if self._obstacles:
            self._manager.registerObjects([o.fcl_object for o in self._obstacles])
        self._manager.setup()
        self._casters: dict[float, RayCaster] = {}

    @property
    def obstacles(self) -> tuple[Collision, ...]:
        """The collisions the robot and the lidar can meet, in the world frame."""
        return tuple(o.collision for o in self._obstacles)

    def meshes(self) -> tuple[trimesh.Trimesh, ...]:
        """The obstacles as triangle meshes in the world frame (copies)."""
        return tuple(o.mesh.to_trimesh() for o in self._obstacles)

    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """Axis-aligned bounds of all obstacles ((xmin, ymin, zmin), (xmax, ymax, zmax)), or None."""
        if not self._obstacles:
            return None
        lo = np.min([o.bounds[0] for o in self._obstacles], axis=0)
        hi = np.max([o.bounds[1] for o in self._obstacles], axis=0)
        return (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))

    def ray_caster(self, height_m: float, *, cell_m: float = 1.0, native: bool = True) -> RayCaster:
        """Return a ray caster for the horizontal plane at `height_m` (built once per height).

        `native=False` forces the numpy implementation (the compiled kernel is used otherwise
        when a C compiler is available).
        """
        key = round(float(height_m), 9)
        caster = self._casters.get(key) if native else None
        if caster is None:
            segments: list[tuple[float, float, float, float]] = []
            circles: list[tuple[float, float, float]] = []
            seg_owner: list[int] = []
            circ_owner: list[int] = []
            for index, obstacle in enumerate(self._obstacles):
                segs, circs = _section(obstacle, key)
                segments.extend(segs)
                circles.extend(circs)
                seg_owner.extend([index] * len(segs))
                circ_owner.extend([index] * len(circs))
            section = _Slice(
                segments=np.array(segments, dtype=np.float64).reshape(-1, 4),
                circles=np.array(circles, dtype=np.float64).reshape(-1, 3),
                segment_owner=np.array(seg_owner, dtype=np.int64),
                circle_owner=np.array(circ_owner, dtype=np.int64),
            )
            labels = [f"{o.collision.link}::{o.collision.name}" for o in self._obstacles]
            caster = RayCaster(section, key, labels, cell_m=cell_m, native=native)
            if native:
                self._casters[key] = caster
        return caster

    def clearance(self, body: RobotBody, x_m: float, y_m: float, yaw_rad: float = 0.0) -> float:
        """Return a lower bound on the distance between the robot and every obstacle (m).

        Uses one upright cylinder bounding all of the robot's shapes, so it is cheap (one FCL
        distance query) and never larger than the true distance; 0 when the bound touches
        something. `yaw_rad` does not matter to the bound and is accepted for symmetry.
        """
        if not self._obstacles:
            return math.inf
        body._place_bound(x_m, y_m)
        data = fcl.DistanceData()
        self._manager.distance(body._bound, data, fcl.defaultDistanceCallback)
        return max(0.0, float(data.result.min_distance))

    def distance(self, body: RobotBody, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return the distance between the robot's own shapes at (x, y, yaw) and the nearest obstacle (m).

        Exact where `clearance` is a bound (its cylinder touches long before the robot does, beside a
        wall); costs one FCL distance query per shape pair near each other. 0 when they touch.
        """
        if not self._obstacles:
            return math.inf
        body._place(x_m, y_m, yaw_rad)
        data = fcl.DistanceData()
        self._manager.distance(body._manager, data, fcl.defaultDistanceCallback)
        return max(0.0, float(data.result.min_distance))

    def collides(
        self, body: RobotBody, x_m: float, y_m: float, yaw_rad: float, *, max_contacts: int = 8
    ) -> tuple[Contact, ...]:
        """Return the contacts of the robot at (x, y, yaw) with the obstacles, deepest first (empty if none)."""
        if not self._obstacles:
            return ()
        body._place_bound(x_m, y_m)
        quick = fcl.CollisionData(request=fcl.CollisionRequest())
        self._manager.collide(body._bound, quick, fcl.defaultCollisionCallback)
        if not quick.result.is_collision:
            return ()
        body._place(x_m, y_m, yaw_rad)
        request = fcl.CollisionRequest(num_max_contacts=max_contacts, enable_contact=True)
        data = fcl.CollisionData(request=request)
        self._manager.collide(body._manager, data, fcl.defaultCollisionCallback)
        contacts = []
        for contact in data.result.contacts:
            robot_part = body.owner(contact.o1)
            obstacle = self._owner.get(id(contact.o2))
            normal = np.asarray(contact.normal, dtype=float)
            if robot_part is None:  # o1 is the obstacle: FCL's normal points from o1 to o2 (the robot)
                robot_part = body.owner(contact.o2)
                obstacle = self._owner.get(id(contact.o1))
            else:
                normal = -normal
            if robot_part is None or obstacle is None:
                continue
            contacts.append(
                Contact(
                    model=obstacle.model,
                    link=obstacle.link,
                    collision=obstacle.name,
                    robot_link=robot_part.link,
                    point=(float(contact.pos[0]), float(contact.pos[1]), float(contact.pos[2])),
                    normal=(float(normal[0]), float(normal[1]), float(normal[2])),
                    depth_m=max(0.0, float(contact.penetration_depth)),
                )
            )
        contacts.sort(key=lambda c: -c.depth_m)
        return tuple(contacts)

    def top_m(self, contact: Contact) -> float | None:
        """Height of the top of the obstacle `contact` is with (m), or None if it is not in the scene."""
        for o in self._obstacles:
            c = o.collision
            if (c.model, c.link, c.name) == (contact.model, contact.link, contact.collision):
                return float(o.bounds[1, 2])
        return None

    def robot_body(self, collisions: Iterable[Collision], *, base_height_m: float = 0.0) -> RobotBody:
        """Return the robot's collision body (see `RobotBody`)."""
        return RobotBody(collisions, base_height_m=base_height_m)


# What an FCL distance between the robot's primitives and the world may be off by, m.
_DISTANCE_TOLERANCE_M = 1e-4


class CollisionMonitor:
    """Checks the robot against the scene every step, paying for FCL only near obstacles.

    After each clearance query the monitor knows a distance `d` the robot can move before it may
    touch anything; while the motion since then (translation plus the body radius times the
    rotation) stays below `d`, `check` returns no contacts after a few float operations.

    A robot pressed against a wall asks about the same refused pose step after step (the drive
    stays where it was and tries the same step again). The scene does not move, so the answers of
    the last few queried poses are kept and a pose asked again is answered from them: the same
    contacts and the same free distance as a new query, without FCL.
    """

    RECENT_POSES = 8
    """How many queried poses' answers are kept."""
    static = True
    """The scene it checks against does not move (a free distance, less the robot's motion, stays true)."""

    def __init__(self, scene: Scene, body: RobotBody, *, margin_m: float = 0.005) -> None:
        self.scene = scene
        self.body = body
        self.margin_m = margin_m
        self._x = math.nan
        self._y = math.nan
        self._yaw = 0.0
        self._free_m = -1.0
        self._recent: dict[tuple[float, float, float], tuple[tuple[Contact, ...], float]] = {}
        self.queries = 0
        """How many FCL queries were made (for benchmarks)."""
        self.repeats = 0
        """How many checks were answered from the poses asked before."""

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return how far the robot may still move from this pose with no contact possible (0 if unknown)."""
        moved = math.hypot(x_m - self._x, y_m - self._y) + self.body.radius_m * abs(yaw_rad - self._yaw)
        free = self._free_m - moved
        return free if free > 0.0 else 0.0

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the contacts at this pose (empty tuple when free)."""
        moved = math.hypot(x_m - self._x, y_m - self._y) + self.body.radius_m * abs(yaw_rad - self._yaw)
        if moved < self._free_m:
            return ()
        pose = (x_m, y_m, yaw_rad)
        known = self._recent.get(pose)
        if known is not None:
            self.repeats += 1
            self._x, self._y, self._yaw = pose
            contacts, self._free_m = known
        else:
            contacts = self._query(x_m, y_m, yaw_rad)
            recent = self._recent
            if len(recent) >= self.RECENT_POSES:
                del recent[next(iter(recent))]  # the oldest
            recent[pose] = (contacts, self._free_m)
        return contacts

    def _query(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Ask FCL about this pose; set the free distance from it."""
        self.queries += 1
        scene, body = self.scene, self.body
        clearance = scene.clearance(body, x_m, y_m, yaw_rad)  # the bounding cylinder: one cheap query
        self._x, self._y, self._yaw = x_m, y_m, yaw_rad
        if clearance <= self.margin_m:
            self.queries += 1
            clearance = scene.distance(body, x_m, y_m, yaw_rad)  # the robot's own shapes
        if clearance > self.margin_m:
            self._free_m = clearance - self.margin_m
            return ()
        if clearance > _DISTANCE_TOLERANCE_M:
            # Inside the margin, the exact distance of the robot's own shapes is still free (less
            # FCL's tolerance): an approach or a graze along a wall costs a few queries, not every step.
            self._free_m = clearance - _DISTANCE_TOLERANCE_M
            return ()
        self.queries += 1
        self._free_m = -1.0
        return scene.collides(body, x_m, y_m, yaw_rad)


def _placed_obstacles(
    world: World, exclude_models: Iterable[str], floor_height_m: float, cache: MeshCache
) -> Iterator[tuple[Collision, MeshArrays, F64]]:
    """Yield (collision, mesh in its own frame, its world-frame vertices) of every obstacle of `world`.

    Planes, shapes with no mesh and floor-level shapes (top at or below `floor_height_m`) are left out,
    and so are a mesh's floor-level triangles: a floor modelled as one mesh with a step or a kerb in it
    keeps the step, not the ground the robot stands on.
    """
    excluded = set(exclude_models)
    skipped_floor = 0
    trimmed = 0
    for model in world.all_models():
        if excluded and (
            model.name in excluded
            or model.scoped_name in excluded
            or any(model.scoped_name.startswith(f"{name}::") for name in excluded)
        ):
            continue
        for link in model.links:
            for collision in link.collisions:
                if isinstance(collision.geometry, Plane):
                    _warn_if_tilted(collision)
                    continue
                local = geometry_arrays(collision.geometry, cache, collision.where)
                if local is None:
                    continue
                T = np.asarray(collision.T_world)
                vertices = local.vertices @ T[:3, :3].T + T[:3, 3]
                if vertices[:, 2].max() <= floor_height_m:
                    skipped_floor += 1
                    continue
                if not isinstance(collision.geometry, _PRIMITIVES) and len(local.faces):
                    above = vertices[:, 2][local.faces].max(axis=1) > floor_height_m
                    if not above.all():
                        local = MeshArrays(local.vertices, local.faces[above])
                        trimmed += 1
                yield collision, local, vertices
    if skipped_floor or trimmed:
        _log.debug(
            "%d floor-level collisions left out of the scene, %d meshes without their floor-level triangles",
            skipped_floor,
            trimmed,
        )


_TILTED_PLANES: set[str] = set()  # the tilted planes warned of (once a process, however often a world is read)


def _warn_if_tilted(collision: Collision) -> None:
    """Warn once that a `<plane>` which is not the ground (its normal not vertical) is no obstacle here."""
    normal = np.asarray(collision.T_world)[:3, :3] @ np.asarray(collision.geometry.normal, dtype=float)  # type: ignore[union-attr]
    length = float(np.linalg.norm(normal))
    if length == 0.0 or abs(normal[2]) >= 0.999 * length or collision.where in _TILTED_PLANES:
        return
    _TILTED_PLANES.add(collision.where)
    _log.warning(
        "%s: <plane> %r has a normal of (%.3g, %.3g, %.3g) in the world: the twin takes planes as the ground only, "
        "so this one is no obstacle; make the wall a <box>",
        collision.where,
        collision.name,
        *(normal / length),
    )


def obstacle_extent(
    world: World, *, exclude_models: Iterable[str] = (), floor_height_m: float = 0.01
) -> tuple[int, tuple[tuple[float, float, float], tuple[float, float, float]] | None]:
    """Return how many obstacles `build_scene` would make of `world`, and their bounds (`Scene.bounds`).

    Cheap: no collision objects are built, so `twin world info` on a big world need not build them.

    Raises:
        WorldError: If a collision mesh cannot be read.
    """
    placed = [
        MeshArrays(vertices, local.faces).bounds()  # the vertices its faces use, as the Scene's bounds
        for _, local, vertices in _placed_obstacles(world, exclude_models, floor_height_m, MeshCache())
    ]
    if not placed:
        return 0, None
    every = np.concatenate(placed)
    lo, hi = every.min(axis=0), every.max(axis=0)
    return len(placed), ((float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2])))


def build_scene(world: World, *, exclude_models: Iterable[str] = (), floor_height_m: float = 0.01) -> Scene:
    """Build the Scene of a world.

    Args:
        world: The loaded world.
        exclude_models: Model names (or scoped names) left out, e.g. a robot the world already
            holds.
        floor_height_m: Obstacles whose top is at or below this height are part of the floor
            (a ground slab, a road marking) and are left out, like infinite planes.

    Raises:
        WorldError: If a collision mesh cannot be read.
    """
    obstacles: list[_Obstacle] = []
    for collision, local, vertices in _placed_obstacles(world, exclude_models, floor_height_m, MeshCache()):
        geometry = _fcl_geometry(collision.geometry, local)
        if geometry is None:
            continue
        mesh = MeshArrays(vertices, local.faces)
        obstacles.append(
            _Obstacle(
                collision=collision,
                mesh=mesh,
                bounds=mesh.bounds(),
                fcl_object=fcl.CollisionObject(geometry, _fcl_transform(collision.T_world)),
                fcl_geometry=geometry,
            )
        )
    _log.debug(
        "scene of %s: %d obstacles (%s)",
        world.name,
        len(obstacles),
        ", ".join(sorted({geometry_kind(o.collision.geometry) for o in obstacles})),
    )
    return Scene(obstacles, world_name=world.name)
