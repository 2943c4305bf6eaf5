"""Triangle meshes for geometry: mesh files read as triangles only, primitives tessellated.

Mesh files are read as Gazebo reads them: COLLADA's `<unit meter=...>` scales the vertices (its
`<up_axis>` is ignored, as Gazebo ignores it), `<submesh>` selects the geometry under the named
COLLADA node (or the named OBJ/STL object) and may centre it, and `<scale>` applies last. Collision
needs no materials or textures: COLLADA is read into arrays with lxml, other formats through trimesh
with materials skipped, and trimesh's own log records stay off the console.

Boxes, cones and polylines (most of an indoor world) are tessellated with numpy; trimesh, which takes
about half a second to import, loads only for non-COLLADA mesh files, curved primitives and callers
that ask for `trimesh.Trimesh` objects.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import logging
import os
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import WorldError
from twin.core.native import cache_dir
from twin.world.types import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Ellipsoid,
    Geometry,
    Mesh,
    Polyline,
    Sphere,
)

if TYPE_CHECKING:
    import trimesh

__all__ = ["MeshArrays", "MeshCache", "geometry_arrays", "geometry_mesh"]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

# Tessellation of curved primitives where an exact shape is not needed (bounds, viewers, slices of
# tilted shapes). Ray casting and collision use the exact shapes where they can.
_SECTIONS = 48


class MeshArrays(NamedTuple):
    """A triangle mesh as plain arrays (no trimesh needed to hold one)."""

    vertices: NDArray[np.float64]
    """(N, 3) vertex positions, m."""
    faces: NDArray[np.int64]
    """(M, 3) vertex indices of each triangle, counter-clockwise seen from outside."""

    def bounds(self) -> NDArray[np.float64]:
        """Return the (2, 3) min and max corners of the vertices the faces use (as `trimesh.Trimesh.bounds`)."""
        used = self.vertices
        if len(self.faces):
            referenced = np.zeros(len(used), dtype=bool)
            referenced[self.faces.ravel()] = True
            if not referenced.all():
                used = used[referenced]
        return np.array([used.min(axis=0), used.max(axis=0)])

    def to_trimesh(self) -> trimesh.Trimesh:
        """Return the mesh as a new `trimesh.Trimesh` (arrays copied, nothing merged or reordered)."""
        import trimesh

        return trimesh.Trimesh(vertices=self.vertices.copy(), faces=self.faces.copy(), process=False)


def _unit_box() -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Return the corners of a unit cube centred on the origin and its 12 outward-facing triangles.

    Corner `i` is at (-0.5 or +0.5) per axis from the bits of `i` (x the highest), the order trimesh
    uses too; each face's quad is split along one diagonal.
    """
    corners = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=np.float64) - 0.5
    faces: list[tuple[int, int, int]] = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, 1):
            # The quad's corners in order round the face: (u, v) = (0, 0), (1, 0), (1, 1), (0, 1).
            quad = [
                (side << (2 - axis)) | (bu << (2 - u)) | (bv << (2 - v)) for bu, bv in ((0, 0), (1, 0), (1, 1), (0, 1))
            ]
            for tri in ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3])):
                a, b, c = corners[list(tri)]
                outward = np.cross(b - a, c - a)[axis] * (1 if side else -1)
                faces.append(tri if outward > 0 else (tri[0], tri[2], tri[1]))
    return corners, np.array(faces, dtype=np.int64)


_UNIT_BOX_VERTICES, _UNIT_BOX_FACES = _unit_box()


def box_arrays(size_m: tuple[float, float, float]) -> MeshArrays:
    """Return a box of the given edge lengths centred on the origin: 8 corners, 12 triangles."""
    return MeshArrays(_UNIT_BOX_VERTICES * np.asarray(size_m, dtype=np.float64), _UNIT_BOX_FACES.copy())


def cone_arrays(radius_m: float, length_m: float, sections: int = _SECTIONS) -> MeshArrays:
    """Return a cone as SDF places it: base circle of `radius_m` at z = -length/2, apex at +length/2.

    The base is a regular polygon of `sections` corners on the circle, closed by a fan from its centre.
    """
    angles = np.arange(sections) * (2.0 * np.pi / sections)
    half = length_m / 2.0
    ring = np.column_stack([radius_m * np.cos(angles), radius_m * np.sin(angles), np.full(sections, -half)])
    apex, centre = sections, sections + 1
    vertices = np.vstack([ring, [[0.0, 0.0, half], [0.0, 0.0, -half]]])
    k = np.arange(sections)
    after = (k + 1) % sections
    # Counter-clockwise seen from outside: up the side towards the apex, and the base seen from below.
    sides = np.column_stack([k, after, np.full(sections, apex)])
    base = np.column_stack([np.full(sections, centre), after, k])
    return MeshArrays(vertices, np.vstack([sides, base]).astype(np.int64))


class _Part(NamedTuple):
    """The triangles of one mesh instance in a file, in the file's frame with its unit applied."""

    labels: frozenset[str]
    """Names a `<submesh>` may use to select it: its COLLADA geometry id and enclosing node names and
    ids, or the node and geometry names of other formats."""
    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]


# The mesh formats read: COLLADA by `twin.world._collada`, the others by trimesh (Gazebo reads
# COLLADA, STL and OBJ; glTF, PLY and OFF meshes occur in converted models).
_MESH_FORMATS = frozenset({".dae", ".stl", ".obj", ".glb", ".gltf", ".ply", ".off"})


class MeshCache:
    """Loads each mesh file once per world (the same file is often used by many collisions).

    Only triangles are read: collision needs no materials, textures or normals, so COLLADA files are
    read straight into arrays (`twin.world._collada`; trimesh would load and pack every texture the
    file names) and other formats through trimesh without their materials.
    """

    def __init__(self) -> None:
        self._files: dict[Path, tuple[_Part, ...]] = {}
        # Primitive shapes by value: a world of 10,000 equal boxes builds one box mesh (callers copy
        # before they transform, never change a mesh they are given).
        self.primitives: dict[object, MeshArrays] = {}

    def _parts(self, path: Path, where: str) -> tuple[_Part, ...]:
        """Return the file's mesh instances (read on first use).

        Raises:
            WorldError: If the file cannot be read as a mesh or holds no triangles.
        """
        parts = self._files.get(path)
        if parts is not None:
            return parts
        suffix = path.suffix.lower()
        if suffix not in _MESH_FORMATS:
            what = f"its format {path.suffix!r}" if suffix else "a file without an extension"
            msg = (
                f"{where}: cannot read mesh {path}: {what} is no mesh format twin reads "
                f"({', '.join(sorted(_MESH_FORMATS))}); export the mesh as one of them and name the file after it"
            )
            raise WorldError(msg)
        if suffix == ".stl":
            _check_stl(path, where)
        try:
            parts = _collada_parts(path) if suffix == ".dae" else _trimesh_parts(path)
        except Exception as err:  # the readers raise many kinds; all mean "not a mesh we can read"
            msg = (
                f"{where}: cannot read mesh {path}: it is damaged or not valid {suffix[1:].upper()} "
                f"({type(err).__name__}: {err}); export it again"
            )
            raise WorldError(msg) from None
        if not any(len(part.faces) for part in parts):
            msg = f"{where}: mesh {path} holds no triangles"
            raise WorldError(msg)
        self._files[path] = parts
        return parts

    def arrays(self, geometry: Mesh, where: str) -> MeshArrays:
        """Return the mesh of a `<mesh>` geometry in its own frame (unit, submesh and scale applied).

        Raises:
            WorldError: If the file is missing or unreadable, or the submesh does not exist.
        """
        if geometry.path is None:
            msg = f"{where}: mesh {geometry.uri!r} was not found"
            raise WorldError(msg)
        parts = self._parts(geometry.path, where)
        if geometry.submesh:
            chosen = [part for part in parts if geometry.submesh in part.labels]
            if not chosen:
                names = sorted({label for part in parts for label in part.labels})
                msg = f"{where}: submesh {geometry.submesh!r} not found in {geometry.path} (it has: {', '.join(names)})"
                raise WorldError(msg)
            parts = tuple(chosen)
        vertices, faces = _joined(parts)
        if geometry.submesh and geometry.center_submesh and len(faces):
            used = vertices[np.unique(faces)]
            vertices = vertices - (used.min(axis=0) + used.max(axis=0)) / 2.0
        if geometry.scale != (1.0, 1.0, 1.0):
            vertices = vertices * np.asarray(geometry.scale, dtype=np.float64)
        return MeshArrays(vertices, faces)

    def mesh(self, geometry: Mesh, where: str) -> trimesh.Trimesh:
        """Return the mesh of a `<mesh>` geometry as a new `trimesh.Trimesh` (see `arrays`).

        Raises:
            WorldError: If the file is missing or unreadable, or the submesh does not exist.
        """
        return self.arrays(geometry, where).to_trimesh()


def _joined(parts: Sequence[_Part]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Return one or more parts as one vertex array and one face array (faces renumbered)."""
    if len(parts) == 1:
        return parts[0].vertices, parts[0].faces
    offsets = np.cumsum([0, *(len(part.vertices) for part in parts[:-1])])
    vertices = np.concatenate([part.vertices for part in parts])
    faces = np.concatenate([part.faces + offset for part, offset in zip(parts, offsets, strict=True)])
    return vertices, faces


def _placed(vertices: NDArray[Any], faces: NDArray[Any], T: NDArray[Any]) -> tuple[F64, NDArray[np.int64]]:
    """Return the vertices the faces use, moved by the 4x4 transform T, and the faces renumbered to them."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    used, renumbered = np.unique(faces, return_inverse=True)
    points = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)[used]
    T = np.asarray(T, dtype=np.float64)
    return points @ T[:3, :3].T + T[:3, 3], renumbered.reshape(-1, 3).astype(np.int64)


def _collada_parts(path: Path) -> tuple[_Part, ...]:
    from twin.world._collada import read_collada  # only worlds with COLLADA meshes need it

    return tuple(_Part(part.labels, part.vertices, part.faces) for part in read_collada(path))


def _trimesh_parts(path: Path) -> tuple[_Part, ...]:
    """Read the triangles of a mesh file through trimesh (materials skipped where it allows)."""
    import trimesh

    options: dict[str, Any] = {"skip_materials": True} if path.suffix.lower() == ".obj" else {}
    with _trimesh_log_kept(path):
        loaded = trimesh.load(str(path), force="scene", process=False, **options)
    if not isinstance(loaded, trimesh.Scene):
        return ()
    parts: list[_Part] = []
    for node in loaded.graph.nodes_geometry:
        transform, name = loaded.graph[node]
        geometry = loaded.geometry[name]
        if isinstance(geometry, trimesh.Trimesh) and len(geometry.faces):
            vertices, faces = _placed(geometry.vertices, geometry.faces, transform)
            parts.append(_Part(frozenset({str(node), str(name)}), vertices, faces))
    return tuple(parts)


@contextlib.contextmanager
def _trimesh_log_kept(path: Path) -> Iterator[None]:
    """Keep trimesh's log records (texture and material complaints) off the user's console.

    While a file loads, trimesh's logger hands its records to a list instead of the application's
    handlers; they are then logged here once, at debug level, as one line.
    """
    logger = logging.getLogger("trimesh")
    kept: list[str] = []

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            kept.append(record.getMessage())

    handler = _Keep()
    propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
        if kept:
            _log.debug("%s: trimesh said: %s", path, "; ".join(dict.fromkeys(kept)))


def _check_stl(path: Path, where: str) -> None:
    """Refuse a file that is neither a binary STL (its size matches its triangle count) nor ASCII STL.

    trimesh would otherwise guess the text encoding of any non-binary file, and fail on that.

    Raises:
        WorldError: Naming the file and what it is not.
    """
    try:
        with path.open("rb") as stream:
            head = stream.read(84)
            size = path.stat().st_size
            if len(head) == 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little"):
                return  # binary STL
            text = head + stream.read(4096)
    except OSError as err:
        msg = f"{where}: cannot read mesh {path}: {err.strerror}"
        raise WorldError(msg) from None
    if text.lstrip().lower().startswith(b"solid"):
        try:
            text.decode("ascii")
            return
        except UnicodeDecodeError:
            pass
    msg = (
        f"{where}: mesh {path} is not an STL file: neither binary STL (its {size} bytes do not match the "
        "triangle count in its header) nor ASCII STL (text starting with 'solid'); re-export it"
    )
    raise WorldError(msg)


def _primitive_arrays(geometry: Box | Cone | Cylinder | Sphere | Capsule | Ellipsoid) -> MeshArrays:
    if isinstance(geometry, Box):
        return box_arrays(geometry.size_m)
    if isinstance(geometry, Cone):
        return cone_arrays(geometry.radius_m, geometry.length_m)
    path = _tessellation_path(geometry)
    if path is not None:
        try:
            with path.open("rb") as stream:
                vertices, faces = np.load(stream, allow_pickle=False), np.load(stream, allow_pickle=False)
            return MeshArrays(vertices, faces)
        except (OSError, ValueError, EOFError):
            pass  # not there yet (or cut short): tessellate and store it
    out = _arrays_of(_tessellate(geometry))
    if path is not None:
        _store(path, out)
    return out


def _tessellation_path(geometry: Cylinder | Sphere | Capsule | Ellipsoid) -> Path | None:
    """Return where the tessellation of a curved primitive is cached, keyed by shape and trimesh's files.

    trimesh tessellates curved shapes (and takes half a second to import); the same shape from the
    same trimesh gives the same triangles, so they are kept in the cache folder as `.npy` arrays.
    None when trimesh is not installed (tessellating then raises the ImportError).
    """
    spec = importlib.util.find_spec("trimesh")  # finds the package without importing it
    if spec is None or spec.origin is None:
        return None
    creation = Path(spec.origin).with_name("creation.py")
    try:
        stat = creation.stat()
    except OSError:
        return None
    key = f"{_SECTIONS}\0{geometry!r}\0{creation}\0{stat.st_mtime_ns}\0{stat.st_size}"
    digest = hashlib.sha256(key.encode()).hexdigest()[:20]
    return cache_dir() / "tessellations" / f"{type(geometry).__name__.lower()}-{digest}.npy"


def _store(path: Path, mesh: MeshArrays) -> None:
    """Write a tessellation into the cache in one step (a concurrent reader sees all of it or nothing)."""
    staged: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".tmp-", delete=False) as stream:
            staged = stream.name
            np.save(stream, mesh.vertices, allow_pickle=False)
            np.save(stream, mesh.faces, allow_pickle=False)
        os.replace(staged, path)
    except OSError as err:
        _log.debug("cannot cache a tessellation in %s (%s)", path, err)
        if staged is not None:
            with contextlib.suppress(OSError):
                os.unlink(staged)


def _tessellate(geometry: Cylinder | Sphere | Capsule | Ellipsoid) -> trimesh.Trimesh:
    import trimesh

    out: Any
    match geometry:
        case Cylinder(radius_m=r, length_m=length):
            out = trimesh.creation.cylinder(radius=r, height=length, sections=_SECTIONS)
        case Sphere(radius_m=r):
            out = trimesh.creation.icosphere(subdivisions=3, radius=r)
        case Capsule(radius_m=r, length_m=length):
            out = trimesh.creation.capsule(height=length, radius=r, count=[_SECTIONS, _SECTIONS // 2])
        case Ellipsoid(radii_m=radii):
            out = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
            out.apply_scale(np.asarray(radii))
    mesh: trimesh.Trimesh = out
    return mesh


def _arrays_of(mesh: trimesh.Trimesh) -> MeshArrays:
    return MeshArrays(np.array(mesh.vertices, dtype=np.float64), np.array(mesh.faces, dtype=np.int64))


def geometry_arrays(geometry: Geometry, cache: MeshCache, where: str = "") -> MeshArrays | None:
    """Return a triangle mesh of a geometry in its own frame as arrays (None for infinite planes).

    The arrays of a primitive are shared by every equal primitive of the cache, those of a mesh file
    by the collisions that use it unscaled: copy before changing.

    Raises:
        WorldError: If a mesh file cannot be used.
    """
    if isinstance(geometry, Box | Cone | Cylinder | Sphere | Capsule | Ellipsoid):
        cached = cache.primitives.get(geometry)
        if cached is None:
            cached = _primitive_arrays(geometry)
            cache.primitives[geometry] = cached
        return cached
    match geometry:
        case Polyline():
            return polyline_arrays(geometry)
        case Mesh():
            return cache.arrays(geometry, where)
    return None


def geometry_mesh(geometry: Geometry, cache: MeshCache, where: str = "") -> trimesh.Trimesh | None:
    """Return a triangle mesh of a geometry in its own frame as a new `trimesh.Trimesh` (None for planes).

    Raises:
        WorldError: If a mesh file cannot be used.
    """
    arrays = geometry_arrays(geometry, cache, where)
    return arrays.to_trimesh() if arrays is not None else None


def polyline_arrays(geometry: Polyline) -> MeshArrays:
    """Return the extruded polygons of a polyline as a closed triangle mesh (ear-clipped caps)."""
    vertices: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []
    h = geometry.height_m
    for polygon in geometry.polygons:
        pts = _ccw(polygon)
        n = len(pts)
        base = len(vertices)
        vertices.extend((x, y, 0.0) for x, y in pts)
        vertices.extend((x, y, h) for x, y in pts)
        for i in range(n):
            j = (i + 1) % n
            faces.append((base + i, base + j, base + n + j))
            faces.append((base + i, base + n + j, base + n + i))
        for a, b, c in _ear_clip(pts):
            faces.append((base + a, base + c, base + b))
            faces.append((base + n + a, base + n + b, base + n + c))
    return MeshArrays(
        np.array(vertices, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64).reshape(-1, 3)
    )


def _ccw(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    area = sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(points, [*points[1:], points[0]], strict=True))
    return list(points) if area >= 0 else list(reversed(points))


def _ear_clip(points: Sequence[tuple[float, float]]) -> list[tuple[int, int, int]]:
    """Triangulate a simple counter-clockwise polygon by ear clipping (O(n^2); polygons are small)."""
    index = list(range(len(points)))
    out: list[tuple[int, int, int]] = []

    def cross(o: int, a: int, b: int) -> float:
        (ox, oy), (ax, ay), (bx, by) = points[o], points[a], points[b]
        return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)

    def inside(p: int, a: int, b: int, c: int) -> bool:
        return cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0

    guard = 0
    while len(index) > 3 and guard < 10_000:
        guard += 1
        for k in range(len(index)):
            a, b, c = index[k - 1], index[k], index[(k + 1) % len(index)]
            if cross(a, b, c) <= 0:
                continue
            if any(inside(p, a, b, c) for p in index if p not in (a, b, c)):
                continue
            out.append((a, b, c))
            index.pop(k)
            break
        else:  # degenerate (self-intersecting) polygon: fan the rest
            break
    out.extend((index[0], index[i], index[i + 1]) for i in range(1, len(index) - 1))
    return out
