"""The camera renderer: the world's visuals drawn into an RGB image and a depth image, on a CPU.

What Gazebo Classic's camera draws: the `<visual>` elements (never the collisions) with their
`<material>` colours (diffuse, else ambient, else a named Gazebo script material; a visual without
one is Gazebo's default white), the world's directional lights and its `<scene>` ambient and
background. Shading is flat Lambert per face: `ambient * scene_ambient + diffuse * sum(light_diffuse
* max(0, n . -direction))`, clamped to [0, 1]. Textures are not read (a textured script material is
its texture's mean colour). Back faces are culled and geometry is cut at the near and far clip
planes, as OGRE does.

Why a z-buffer rasteriser of our own: the worlds are a few hundred to a few thousand triangles, so
per frame the cost is the pixels, not the triangles; a scan-line rasteriser in C fills 640x480
RGB + depth in about a millisecond on one core, with nothing to install beyond the C compiler the
other kernels use. A ray caster (Embree) pays per pixel for a traversal and an OpenGL context on a
CPU (Mesa llvmpipe) needs system packages and threads the 2-core machine does not have to spare.
The kernel is C (`twin.world._render_native`); the numpy path below does the same arithmetic.

Depth is the distance along the optical axis (z in the optical frame) to the nearest visual,
perspective-correct (1/z interpolated across each triangle), +inf where nothing is nearer than
the far clip (REP 117, as gazebo_ros's depth camera gives it).
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.geometry import Mat4
from twin.world._render_native import load_render_kernel
from twin.world.meshes import MeshArrays, MeshCache, box_arrays, geometry_arrays
from twin.world.types import Box, Cylinder, Link, Plane, World

__all__ = [
    "Body",
    "CameraModel",
    "ColouredMesh",
    "Frame",
    "Lighting",
    "Renderer",
    "body_of",
    "box_mesh",
    "join_meshes",
    "lighting_of",
    "prepare_noise",
    "shapes_mesh",
    "world_visuals",
]

F64 = NDArray[np.float64]
_DEFAULT_RGB = (1.0, 1.0, 1.0)  # a visual without a material: OGRE's default white
_PLANE_SIZE_M = 100.0  # a <plane> without <size>: Gazebo draws a finite one
# The optical frame (x right, y down, z forward) from the sensor frame Gazebo's camera looks along
# (x forward, y left, z up).
_OPTICAL_FROM_SENSOR = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True, kw_only=True, slots=True)
class CameraModel:
    """A pinhole camera as Gazebo's: square pixels, the vertical field of view from the aspect ratio."""

    width: int
    height: int
    hfov_rad: float
    near_m: float
    far_m: float

    @property
    def f_px(self) -> float:
        """Focal length in pixels, fx = fy = (width / 2) / tan(hfov / 2)."""
        return (self.width / 2.0) / math.tan(self.hfov_rad / 2.0)

    def K(self) -> tuple[float, ...]:
        """The 3x3 camera matrix of `camera_info`, row-major, as gazebo_ros_camera fills it.

        cx = (width + 1) / 2 and cy = (height + 1) / 2 are gazebo_ros_camera's own values.
        """
        f = self.f_px
        return (f, 0.0, (self.width + 1) / 2.0, 0.0, f, (self.height + 1) / 2.0, 0.0, 0.0, 1.0)

    def P(self) -> tuple[float, ...]:
        """The 3x4 projection matrix of `camera_info` (a monocular camera: K with a zero column)."""
        k = self.K()
        return (k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0)


class ColouredMesh(NamedTuple):
    """Triangles in the world frame with one shaded colour each."""

    vertices: F64
    """(N, 3) m."""
    faces: NDArray[np.int32]
    """(M, 3), counter-clockwise seen from outside."""
    colours: F64
    """(M, 3) RGB in [0, 1], lit."""


@dataclass(frozen=True, kw_only=True, slots=True)
class Lighting:
    """The world's lights as the renderer uses them."""

    ambient_rgb: tuple[float, float, float] = (0.4, 0.4, 0.4)
    background_rgb: tuple[float, float, float] = (0.7, 0.7, 0.7)
    directional: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = ()
    """(direction in the world frame, unit; diffuse RGB) per directional light."""

    def shade(self, vertices: F64, faces: NDArray[np.int32], rgb: F64) -> F64:
        """Return each face's lit colour: flat Lambert with the material colour as ambient and diffuse."""
        if len(faces) == 0:
            return np.zeros((0, 3))
        a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
        normals = np.cross(b - a, c - a)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
        light = np.tile(np.asarray(self.ambient_rgb, dtype=np.float64), (len(faces), 1))
        for direction, diffuse in self.directional:
            lambert = np.clip(normals @ -np.asarray(direction, dtype=np.float64), 0.0, None)
            light = light + lambert[:, None] * np.asarray(diffuse, dtype=np.float64)
        return np.clip(rgb * light, 0.0, 1.0)


class Frame(NamedTuple):
    """One rendered frame."""

    rgb: NDArray[np.uint8]
    """(height, width, 3)."""
    depth_m: NDArray[np.float32]
    """(height, width) distance along the optical axis, +inf where nothing is within the far clip."""


def lighting_of(world: World) -> Lighting:
    """The world's scene ambient, background and directional lights (directions in the world frame)."""
    directional = []
    for light in world.lights:
        if light.type != "directional":
            continue
        d = np.asarray(light.T_world)[:3, :3] @ np.asarray(light.direction, dtype=np.float64)
        norm = float(np.linalg.norm(d))
        if norm == 0.0:
            continue
        d = d / norm
        directional.append(((float(d[0]), float(d[1]), float(d[2])), tuple(float(v) for v in light.diffuse_rgba[:3])))
    return Lighting(
        ambient_rgb=(world.ambient_rgba[0], world.ambient_rgba[1], world.ambient_rgba[2]),
        background_rgb=(world.background_rgba[0], world.background_rgba[1], world.background_rgba[2]),
        directional=tuple(directional),  # type: ignore[arg-type]
    )


def _plane_arrays(plane: Plane) -> MeshArrays:
    """A <plane> as two triangles of its <size> (100 m square when it has none), facing its normal."""
    sx, sy = plane.size_m if plane.size_m[0] > 0 and plane.size_m[1] > 0 else (_PLANE_SIZE_M, _PLANE_SIZE_M)
    n = np.asarray(plane.normal, dtype=np.float64)
    n = n / (np.linalg.norm(n) or 1.0)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    corners = [u * (su * sx / 2) + v * (sv * sy / 2) for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    vertices = np.array(corners)
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    # Counter-clockwise about n: flip if the corner order runs the other way.
    if float(np.dot(np.cross(vertices[1] - vertices[0], vertices[2] - vertices[0]), n)) < 0:
        faces = faces[:, ::-1]
    return MeshArrays(vertices, faces)


def _join(parts: Sequence[tuple[F64, NDArray[np.int64], F64]], lighting: Lighting) -> ColouredMesh:
    if not parts:
        return ColouredMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32), np.zeros((0, 3)))
    vertices, faces, rgb = [], [], []
    offset = 0
    for v, f, c in parts:
        vertices.append(v)
        faces.append(f + offset)
        rgb.append(np.broadcast_to(c, (len(f), 3)))
        offset += len(v)
    all_v = np.concatenate(vertices)
    all_f = np.concatenate(faces).astype(np.int32)
    return ColouredMesh(all_v, all_f, lighting.shade(all_v, all_f, np.concatenate(rgb)))


class Body(NamedTuple):
    """A robot's visuals in its base frame, unlit: placed and lit per frame (`Body.placed`)."""

    vertices: F64
    faces: NDArray[np.int32]
    rgb: F64
    """(M, 3) material colour per face."""

    def placed(self, T_world_base: Mat4, lighting: Lighting) -> ColouredMesh:
        """The body at a pose in the world, lit as the world is."""
        T = np.asarray(T_world_base)
        vertices = self.vertices @ T[:3, :3].T + T[:3, 3]
        return ColouredMesh(vertices, self.faces, lighting.shade(vertices, self.faces, self.rgb))


def body_of(links: Iterable[Link], T_base_model: Mat4) -> Body:
    """The visuals of a robot's links (their joints at zero) in its base frame.

    Raises:
        WorldError: If a visual's mesh cannot be read.
    """
    cache = MeshCache()
    vertices, faces, rgb = [], [], []
    offset = 0
    for link in links:
        for visual in link.visuals:
            if isinstance(visual.geometry, Plane):
                continue
            local = geometry_arrays(visual.geometry, cache, f"{link.scoped_name}::{visual.name}")
            if local is None or len(local.faces) == 0:
                continue
            T = np.asarray(T_base_model) @ np.asarray(link.T_model) @ np.asarray(visual.T_link)
            vertices.append(local.vertices @ T[:3, :3].T + T[:3, 3])
            faces.append(local.faces + offset)
            colour = visual.color_rgba[:3] if visual.color_rgba is not None else _DEFAULT_RGB
            rgb.append(np.broadcast_to(np.asarray(colour, dtype=np.float64), (len(local.faces), 3)))
            offset += len(local.vertices)
    if not faces:
        return Body(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32), np.zeros((0, 3)))
    return Body(np.concatenate(vertices), np.concatenate(faces).astype(np.int32), np.concatenate(rgb))


def join_meshes(meshes: Sequence[ColouredMesh]) -> ColouredMesh | None:
    """One mesh of several (None for none)."""
    present = [m for m in meshes if len(m.faces)]
    if not present:
        return None
    if len(present) == 1:
        return present[0]
    offsets = np.cumsum([0] + [len(m.vertices) for m in present[:-1]])
    return ColouredMesh(
        np.concatenate([m.vertices for m in present]),
        np.concatenate([m.faces + o for m, o in zip(present, offsets, strict=True)]).astype(np.int32),
        np.concatenate([m.colours for m in present]),
    )


def world_visuals(world: World, lighting: Lighting, *, exclude_models: Iterable[str] = ()) -> ColouredMesh:
    """Every visual of the world's models (but `exclude_models`), placed, lit, as one mesh.

    Raises:
        WorldError: If a visual's mesh file cannot be read.
    """
    excluded = set(exclude_models)
    cache = MeshCache()
    parts: list[tuple[F64, NDArray[np.int64], F64]] = []
    for model in world.all_models():
        if excluded and (
            model.name in excluded
            or model.scoped_name in excluded
            or any(model.scoped_name.startswith(f"{name}::") for name in excluded)
        ):
            continue
        for link in model.links:
            for visual in link.visuals:
                geometry = visual.geometry
                local = (
                    _plane_arrays(geometry)
                    if isinstance(geometry, Plane)
                    else geometry_arrays(geometry, cache, f"{link.scoped_name}::{visual.name}")
                )
                if local is None or len(local.faces) == 0:
                    continue
                T = np.asarray(link.T_world) @ np.asarray(visual.T_link)
                vertices = local.vertices @ T[:3, :3].T + T[:3, 3]
                rgb = np.asarray(visual.color_rgba[:3] if visual.color_rgba is not None else _DEFAULT_RGB)
                parts.append((vertices, local.faces, rgb))
    return _join(parts, lighting)


def shapes_mesh(
    shapes: Sequence[tuple[Box | Cylinder, Mat4, tuple[float, float, float]]], lighting: Lighting, cache: MeshCache
) -> ColouredMesh:
    """Boxes and cylinders (pose in the world frame, RGB) as one lit mesh: a scenario's obstacles and blocks."""
    parts = []
    for geometry, pose, rgb in shapes:
        local = geometry_arrays(geometry, cache)
        assert local is not None
        T = np.asarray(pose)
        parts.append((local.vertices @ T[:3, :3].T + T[:3, 3], local.faces, np.asarray(rgb, dtype=np.float64)))
    return _join(parts, lighting)


def box_mesh(
    boxes: Sequence[tuple[tuple[float, float, float], Mat4, tuple[float, float, float]]], lighting: Lighting
) -> ColouredMesh:
    """Boxes (size m, pose in the world frame, RGB) as one lit mesh."""
    parts = []
    for size, pose, rgb in boxes:
        local = box_arrays(size)
        T = np.asarray(pose)
        parts.append((local.vertices @ T[:3, :3].T + T[:3, 3], local.faces, np.asarray(rgb, dtype=np.float64)))
    return _join(parts, lighting)


class Renderer:
    """Draws a fixed mesh (the world) plus per-frame meshes (obstacles) from a camera pose.

    Args:
        camera: Image size, field of view and clip planes.
        static: The world's visuals (`world_visuals`).
        lighting: Background colour (the other fields are baked into the meshes' colours).
        native: Use the C kernel when it can be built (the numpy path gives the same images).
    """

    def __init__(self, camera: CameraModel, static: ColouredMesh, lighting: Lighting, *, native: bool = True) -> None:
        self.camera = camera
        self._static = static
        self._background = np.asarray(lighting.background_rgb, dtype=np.float64)
        self._lib = load_render_kernel() if native else None
        n = camera.width * camera.height
        self._ids = np.empty(n, dtype=np.int32)

    @property
    def native(self) -> bool:
        """True when frames are drawn by the C kernel."""
        return self._lib is not None

    def render(
        self,
        T_world_sensor: Mat4,
        extra: ColouredMesh | None = None,
        *,
        noise_mean: float = 0.0,
        noise_std: float = 0.0,
        seed: int = 0,
    ) -> Frame:
        """Draw one frame from a sensor pose (x forward, y left, z up, as Gazebo's camera frame).

        Args:
            T_world_sensor: The sensor frame in the world frame.
            extra: More triangles for this frame only (moving obstacles).
            noise_mean: Mean of the Gaussian noise added to each pixel's channels, in [0, 1] units.
            noise_std: Its standard deviation (0: no noise).
            seed: The noise's seed for this frame (same seed, same image).
        """
        cam = self.camera
        mesh = self._static
        if extra is not None and len(extra.faces):
            mesh = ColouredMesh(
                np.concatenate([mesh.vertices, extra.vertices]),
                np.concatenate([mesh.faces, extra.faces + len(mesh.vertices)]).astype(np.int32),
                np.concatenate([mesh.colours, extra.colours]),
            )
        T = np.asarray(T_world_sensor, dtype=np.float64)
        R = _OPTICAL_FROM_SENSOR @ T[:3, :3].T
        view = np.ascontiguousarray((mesh.vertices - T[:3, 3]) @ R.T)
        faces = np.ascontiguousarray(mesh.faces, dtype=np.int32)
        # Row 0 is the background, row id + 1 face id's colour.
        colours = np.ascontiguousarray(np.vstack([self._background[None, :], mesh.colours]))
        levels = np.ascontiguousarray(_levels(colours))
        noisy = noise_std > 0.0 or noise_mean != 0.0
        fixed = np.ascontiguousarray(np.floor(colours * 65280.0 + 0.5).astype(np.int32) + 128)
        table = _noise_table(noise_mean, noise_std) if noisy else None
        w, h = cam.width, cam.height
        depth = np.empty(w * h, dtype=np.float32)
        rgb = np.empty(w * h * 3, dtype=np.uint8)
        ids = self._ids
        seed64 = seed & 0xFFFFFFFFFFFFFFFF
        if self._lib is not None:
            ptr = ctypes.c_void_p
            self._lib.twin_render(
                view.ctypes.data_as(ptr), faces.ctypes.data_as(ptr), len(faces),
                cam.f_px, w / 2.0, h / 2.0, cam.near_m, cam.far_m, w, h,
                depth.ctypes.data_as(ptr), ids.ctypes.data_as(ptr),
            )  # fmt: skip
            self._lib.twin_resolve(
                ids.ctypes.data_as(ptr), levels.ctypes.data_as(ptr), fixed.ctypes.data_as(ptr), w * h,
                table.ctypes.data_as(ptr) if table is not None else None, seed64, rgb.ctypes.data_as(ptr),
            )  # fmt: skip
        else:
            _render_numpy(view, faces, cam, depth, ids)
            _resolve_numpy(ids, levels, fixed, table, seed64, rgb)
        return Frame(rgb.reshape(h, w, 3), depth.reshape(h, w))


def _levels(colours: F64) -> NDArray[np.uint8]:
    """Colours in [0, 1] to 8-bit levels, rounded as the kernel rounds (clamped to 0 and 255)."""
    scaled = np.floor(np.clip(colours, 0.0, 1.0) * 255.0 + 0.5)
    return scaled.astype(np.uint8)


_QUANTILES: list[F64] = []


def prepare_noise() -> None:
    """Compute the normal quantiles noisy frames draw from (importing scipy.special: a few hundred ms, once).

    A run calls it while it sets up: a run's first noisy frame taking that long would let the
    recorder's wall-clock flush cut a chunk where another run of the same seed does not.
    """
    if not _QUANTILES:
        from scipy.special import ndtri

        _QUANTILES.append(ndtri((np.arange(4096) + 0.5) / 4096.0))


def _noise_table(mean: float, std: float) -> NDArray[np.int32]:
    """The noise's 4096 samples in 1/256ths of a level: N(mean, std) quantiles at (i + 0.5) / 4096."""
    prepare_noise()
    return np.ascontiguousarray(np.floor((mean + std * _QUANTILES[0]) * 65280.0 + 0.5).astype(np.int32))


# --- the numpy path: the C kernel's arithmetic, vectorised over each triangle's pixels ----------------


def _raster_numpy(  # noqa: PLR0917 - the kernel's argument list
    a: F64, b: F64, c: F64, face: int, w: int, h: int, far: float, depth: NDArray[np.float32], ids: NDArray[np.int32]
) -> None:
    area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    if not area < 0.0:
        return
    b, c, area = c, b, -area
    lo_x = max(min(a[0], b[0], c[0]), -1.0)
    hi_x = min(max(a[0], b[0], c[0]), w + 1.0)
    lo_y = max(min(a[1], b[1], c[1]), -1.0)
    hi_y = min(max(a[1], b[1], c[1]), h + 1.0)
    x0, x1 = max(math.ceil(lo_x - 0.5), 0), min(math.floor(hi_x - 0.5), w - 1)
    y0, y1 = max(math.ceil(lo_y - 0.5), 0), min(math.floor(hi_y - 0.5), h - 1)
    if x0 > x1 or y0 > y1:
        return
    px = np.arange(x0, x1 + 1, dtype=np.float64)[None, :] + 0.5
    py = np.arange(y0, y1 + 1, dtype=np.float64)[:, None] + 0.5
    w0 = (c[0] - b[0]) * (py - b[1]) - (c[1] - b[1]) * (px - b[0])
    w1 = (a[0] - c[0]) * (py - c[1]) - (a[1] - c[1]) * (px - c[0])
    w2 = (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = area / (w0 * a[2] + w1 * b[2] + w2 * c[2])
    rows = np.arange(y0, y1 + 1)[:, None] * w + np.arange(x0, x1 + 1)[None, :]
    current = depth[rows].astype(np.float64)
    hit = (w0 >= 0.0) & (w1 >= 0.0) & (w2 >= 0.0) & (z <= far) & (z < current)
    k = rows[hit]
    depth[k] = z[hit].astype(np.float32)
    ids[k] = face


def _render_numpy(
    view: F64, faces: NDArray[np.int32], cam: CameraModel, depth: NDArray[np.float32], ids: NDArray[np.int32]
) -> None:
    w, h, near, far, f = cam.width, cam.height, cam.near_m, cam.far_m, cam.f_px
    cx, cy = w / 2.0, h / 2.0
    depth.fill(np.inf)
    ids.fill(-1)
    for i, face in enumerate(faces):
        p = [view[int(j)] for j in face]
        if not any(q[2] >= near for q in p):
            continue
        if all(q[2] > far for q in p):
            continue
        poly = []
        for j in range(3):
            s, e = p[j], p[(j + 1) % 3]
            s_in, e_in = s[2] >= near, e[2] >= near
            if s_in:
                poly.append((float(s[0]), float(s[1]), float(s[2])))
            if s_in != e_in:
                t = (near - s[2]) / (e[2] - s[2])
                poly.append((s[0] + t * (e[0] - s[0]), s[1] + t * (e[1] - s[1]), near))
        q = [np.array([cx + f * x / z, cy + f * y / z, 1.0 / z]) for x, y, z in poly]
        for j in range(1, len(q) - 1):
            _raster_numpy(q[0], q[j], q[j + 1], i, w, h, far, depth, ids)


def _splitmix64(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    with np.errstate(over="ignore"):
        x = x + np.uint64(0x9E3779B97F4A7C15)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _resolve_numpy(  # noqa: PLR0917 - the kernel's argument list
    ids: NDArray[np.int32],
    levels: NDArray[np.uint8],
    fixed: NDArray[np.int32],
    table: NDArray[np.int32] | None,
    seed: int,
    rgb: NDArray[np.uint8],
) -> None:
    n = len(ids)
    rows = ids.astype(np.int64) + 1
    if table is None:
        rgb[:] = levels[rows].reshape(-1)
        return
    quads = np.arange(0, (n + 3) // 4, dtype=np.uint64)
    with np.errstate(over="ignore"):
        bits = _splitmix64(np.uint64(seed) + quads)
    picks = np.stack([(bits >> np.uint64(16 * j)) & np.uint64(0xFFF) for j in range(4)], axis=1).reshape(-1)[:n]
    pixel = (fixed[rows] + table[picks.astype(np.int64)][:, None]) >> 8
    rgb[:] = np.clip(pixel, 0, 255).astype(np.uint8).reshape(-1)
