"""The triangles of a COLLADA (.dae) file, read with lxml: geometry only, as collision needs.

Gazebo's COLLADA loader reads a file's scene graph and the meshes it instances and looks at materials
only to draw them. This reader does the same for collision: it never opens an effect, material or
image, so a texture the file cannot find or a material it names but lacks does not matter (pycollada
drops a geometry instance whose material is missing; trimesh then loads and packs every texture).

What is read: `<asset><unit meter>`; the visual scene `<scene>` instances (else the first one);
nested `<node>`s with `<matrix>`, `<translate>`, `<rotate>`, `<scale>` and `<lookat>` in document
order; `<instance_node>` and `<instance_geometry>` (URLs inside the file); and the primitives
Gazebo Classic and gz-common read, `<triangles>` and `<polylist>` (polygons split into fans).
`<polygons>`, `<trifans>` and `<tristrips>`, which Gazebo does not read, are skipped like lines,
`<skew>`, controllers and URLs into other files.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from lxml import etree
from numpy.typing import NDArray

__all__ = ["ColladaPart", "read_collada"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

# An <instance_node> may name a node that instances it again; deeper than this is a cycle.
_MAX_DEPTH = 64


class ColladaPart(NamedTuple):
    """One instanced geometry's triangles in the file's frame, in metres."""

    labels: frozenset[str]
    """The geometry's id and name and the names and ids of the nodes above it."""
    vertices: F64
    faces: I64


class _Document:
    """One parsed file: its elements by id and its namespace-qualified tag names."""

    def __init__(self, root: etree._Element) -> None:
        self.root = root
        tag = root.tag if isinstance(root.tag, str) else ""
        self.ns = tag[: tag.index("}") + 1] if tag.startswith("{") else ""
        # Ids by element kind: exporters reuse one id for a visual scene and a node in it.
        self.by_id: dict[tuple[str, str], etree._Element] = {}
        for element in root.iter():
            ident = element.get("id")
            if ident is not None:
                self.by_id.setdefault((self.local(element), ident), element)
        self.geometry_cache: dict[str, list[tuple[F64, I64]]] = {}

    def tag(self, name: str) -> str:
        return self.ns + name

    def local(self, element: etree._Element) -> str:
        tag = element.tag
        return tag[len(self.ns) :] if isinstance(tag, str) and tag.startswith(self.ns) else str(tag)

    def ref(self, url: str | None, *kinds: str) -> etree._Element | None:
        """Return the element of one of these kinds that an in-file URL (`#id`) names, or None."""
        if not url or not url.startswith("#"):
            return None
        for kind in kinds:
            found = self.by_id.get((kind, url[1:]))
            if found is not None:
                return found
        return None

    def floats(self, element: etree._Element | None) -> F64:
        return _numbers(element.text if element is not None else None, np.float64)

    def ints(self, element: etree._Element | None) -> I64:
        return _numbers(element.text if element is not None else None, np.int64)


def _numbers(text: str | None, dtype: type[np.float64] | type[np.int64]) -> NDArray[Any]:
    """Return whitespace-separated numbers (numpy's text reader: several times faster than split()).

    Raises:
        ValueError: If the text holds something that is not a number of that type.
    """
    if not text:
        return np.zeros(0, dtype=dtype)
    with warnings.catch_warnings():
        # Older numpy stops at the first bad token with only a DeprecationWarning; newer raises.
        warnings.simplefilter("error", DeprecationWarning)
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (DeprecationWarning, ValueError):
            msg = f"not a list of numbers: {text[:40]!r}..."
            raise ValueError(msg) from None


def read_collada(path: Path) -> tuple[ColladaPart, ...]:
    """Return the triangles of every geometry instanced in the file's scene.

    Raises:
        OSError: If the file cannot be read.
        lxml.etree.XMLSyntaxError: If it is not well-formed XML.
        ValueError: If numbers or indices in it are malformed.
    """
    parser = etree.XMLParser(huge_tree=True, remove_comments=True, resolve_entities=False)
    doc = _Document(etree.parse(str(path), parser).getroot())
    unit_el = doc.root.find(f"{doc.tag('asset')}/{doc.tag('unit')}")
    unit = float(unit_el.get("meter") or 1.0) if unit_el is not None else 1.0
    scene = _visual_scene(doc)
    if scene is None:
        return ()
    T_root = np.diag([unit, unit, unit, 1.0])
    parts = [
        ColladaPart(labels, vertices @ T[:3, :3].T + T[:3, 3], faces)
        for labels, T, vertices, faces in _instances(doc, scene, T_root, frozenset(), 0)
    ]
    return tuple(parts)


def _visual_scene(doc: _Document) -> etree._Element | None:
    instance = doc.root.find(f"{doc.tag('scene')}/{doc.tag('instance_visual_scene')}")
    scene = doc.ref(instance.get("url"), "visual_scene") if instance is not None else None
    if scene is None:
        scene = doc.root.find(f"{doc.tag('library_visual_scenes')}/{doc.tag('visual_scene')}")
    return scene


def _instances(
    doc: _Document, parent: etree._Element, T: F64, labels: frozenset[str], depth: int
) -> Iterator[tuple[frozenset[str], F64, F64, I64]]:
    """Yield (labels, T_file_geometry, vertices, faces) for each geometry under a node or scene."""
    if depth > _MAX_DEPTH:
        return
    for child in parent:
        kind = doc.local(child)
        if kind == "instance_geometry":
            geometry = doc.ref(child.get("url"), "geometry")
            if geometry is not None:
                names = {text for text in (geometry.get("id"), geometry.get("name")) if text}
                for vertices, faces in _geometry_triangles(doc, geometry):
                    yield labels | names, T, vertices, faces
            continue
        if kind == "node":
            node: etree._Element | None = child
        elif kind == "instance_node":
            node = doc.ref(child.get("url"), "node")
        else:
            continue
        if node is None:
            continue
        with np.errstate(invalid="ignore", over="ignore"):
            T_node = T @ _node_matrix(doc, node)
        if not np.isfinite(T_node).all():
            continue  # exporters write INF/NaN matrices for camera views: nothing to place there
        names = {text for text in (node.get("name"), node.get("id")) if text}
        yield from _instances(doc, node, T_node, labels | names, depth + 1)


def _node_matrix(doc: _Document, node: etree._Element) -> F64:
    """Return the product of a node's transform elements, in document order."""
    out = np.eye(4)
    for child in node:
        kind = doc.local(child)
        if kind not in ("matrix", "translate", "rotate", "scale", "lookat"):
            continue
        values = doc.floats(child)
        step = np.eye(4)
        if kind == "matrix" and len(values) == 16:
            step = values.reshape(4, 4)
        elif kind == "translate" and len(values) == 3:
            step[:3, 3] = values
        elif kind == "scale" and len(values) == 3:
            step[:3, :3] = np.diag(values)
        elif kind == "rotate" and len(values) == 4:
            step[:3, :3] = _axis_angle(values[:3], math.radians(values[3]))
        elif kind == "lookat" and len(values) == 9:
            step = _look_at(values[:3], values[3:6], values[6:])
        out = out @ step
    return out


def _axis_angle(axis: F64, angle_rad: float) -> F64:
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        return np.eye(3)
    x, y, z = axis / norm
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    k = 1.0 - c
    return np.array(
        [
            [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
        ]
    )


def _look_at(eye: F64, target: F64, up: F64) -> F64:
    """Return the frame at `eye` whose -z looks at `target` with y towards `up` (COLLADA's camera convention)."""
    out = np.eye(4)
    back = eye - target
    if np.linalg.norm(back) == 0.0 or np.linalg.norm(np.cross(up, back)) == 0.0:
        out[:3, 3] = eye
        return out
    z = back / np.linalg.norm(back)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, np.cross(z, x), z, eye
    return out


def _geometry_triangles(doc: _Document, geometry: etree._Element) -> list[tuple[F64, I64]]:
    """Return (vertices, faces) of each triangle-bearing primitive of a `<geometry>`'s `<mesh>`.

    Each primitive keeps only the vertices its faces use (a position array is often shared).
    """
    key = geometry.get("id") or str(id(geometry))
    cached = doc.geometry_cache.get(key)
    if cached is not None:
        return cached
    out: list[tuple[F64, I64]] = []
    mesh = geometry.find(doc.tag("mesh"))
    if mesh is not None:
        for primitive in mesh:
            corners = _primitive_corners(doc, primitive)
            if corners is None:
                continue
            positions, triangles = corners
            if not len(triangles):
                continue
            if triangles.min() < 0 or triangles.max() >= len(positions):
                msg = f"<{doc.local(primitive)}> of geometry {key!r} indexes a position it does not have"
                raise ValueError(msg)
            used, renumbered = np.unique(triangles, return_inverse=True)
            out.append((positions[used], renumbered.reshape(-1, 3).astype(np.int64)))
    doc.geometry_cache[key] = out
    return out


def _primitive_corners(doc: _Document, primitive: etree._Element) -> tuple[F64, I64] | None:
    """Return a primitive's positions and its triangles as (M, 3) indices into them, or None if it has none."""
    kind = doc.local(primitive)
    if kind not in ("triangles", "polylist"):
        return None
    inputs = primitive.findall(doc.tag("input"))
    if not inputs:
        return None
    stride = max(int(i.get("offset") or 0) for i in inputs) + 1
    position = next((i for i in inputs if i.get("semantic") in ("VERTEX", "POSITION")), None)
    if position is None:
        return None
    positions = _positions(doc, position.get("source"))
    if positions is None:
        return None
    offset = int(position.get("offset") or 0)

    def corners(p: etree._Element | None) -> I64:
        indices = doc.ints(p)
        usable = len(indices) - len(indices) % stride
        return indices[:usable].reshape(-1, stride)[:, offset]

    if kind == "triangles":
        flat = corners(primitive.find(doc.tag("p")))
        return positions, flat[: len(flat) - len(flat) % 3].reshape(-1, 3)
    counts = doc.ints(primitive.find(doc.tag("vcount")))
    return positions, _fans(corners(primitive.find(doc.tag("p"))), counts)


def _positions(doc: _Document, url: str | None) -> F64 | None:
    """Return the (N, 3) positions a VERTEX input (through `<vertices>`) or POSITION input names."""
    source = doc.ref(url, "vertices", "source")
    if source is not None and doc.local(source) == "vertices":
        inner = next((i for i in source.findall(doc.tag("input")) if i.get("semantic") == "POSITION"), None)
        source = doc.ref(inner.get("source"), "source") if inner is not None else None
    if source is None:
        return None
    values = doc.floats(source.find(doc.tag("float_array")))
    accessor = source.find(f"{doc.tag('technique_common')}/{doc.tag('accessor')}")
    stride, start = 3, 0
    count = len(values) // 3
    if accessor is not None:
        stride = int(accessor.get("stride") or 1)
        start = int(accessor.get("offset") or 0)
        count = int(accessor.get("count") or (len(values) - start) // max(stride, 1))
    if stride < 3 or start + count * stride > len(values):
        msg = f"source {source.get('id')!r} has {len(values)} numbers, too few for {count} positions"
        raise ValueError(msg)
    return values[start : start + count * stride].reshape(count, stride)[:, :3]


def _fans(flat: I64, counts: I64) -> I64:
    """Split polygons (corner lists of `counts` lengths, one after another in `flat`) into triangle fans."""
    counts = counts[: np.searchsorted(np.cumsum(counts), len(flat), side="right")]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    keep = counts >= 3
    starts, counts = starts[keep], counts[keep]
    if not len(counts):
        return np.zeros((0, 3), dtype=np.int64)
    per = counts - 2
    first = np.repeat(starts, per)
    # Within each polygon, triangle k uses corners 0, k + 1, k + 2.
    k = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
    return np.stack([flat[first], flat[first + k + 1], flat[first + k + 2]], axis=1)
