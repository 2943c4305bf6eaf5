"""Reading SDF documents: elements into raw models (includes followed), geometry and values, warnings.

`SdfReader` reads a file's `<sdf>` root and its `<model>` elements into `RawModel`s: their links,
joints, frames and nested models as XML still, with every `<include>` resolved
(`twin.world.paths.resolve_include`) and read in turn. Where things are placed is worked out after
(`twin.world.sdf_frames`). Unknown elements and plugins the twin does not run are warned about once.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from twin.core.errors import WorldError
from twin.world._xml import XmlNode, parse_file, parse_string
from twin.world.paths import (
    MAX_SDF_VERSION,
    fallback_search,
    fuel_model_name,
    missing_mesh_message,
    resolve_include,
    resolve_resource,
    resolve_resource_ignoring_case,
    sdf_version,
)
from twin.world.types import (
    Box,
    Capsule,
    Cone,
    Cylinder,
    Ellipsoid,
    Geometry,
    Mesh,
    Plane,
    Plugin,
    Polyline,
    Sphere,
)

__all__ = [
    "GAZEBO_MATERIALS",
    "UNSUPPORTED_WORLD",
    "MissingIncludes",
    "RawModel",
    "SdfReader",
    "material_color",
    "second_model_message",
]

MissingIncludes = Literal["error", "warn"]
"""What a `model://` include that is not on the model path does: fail, or warn and skip it."""

_log = logging.getLogger(__name__)

# Children each element may have that this loader reads or knowingly ignores. Anything else is
# an unknown element: kept as data in `World.unknown`, warned once per tag.
_KNOWN: dict[str, frozenset[str]] = {
    "world": frozenset(
        {
            "model",
            "include",
            "frame",
            "state",
            "physics",
            "gravity",
            "plugin",
            "light",
            "audio",
            "wind",
            "atmosphere",
            "gui",
            "scene",
            "magnetic_field",
            "spherical_coordinates",
            "road",
            "population",
            "actor",
            "joint",
            "enable_wind",
        }
    ),
    "model": frozenset(
        {
            "static",
            "pose",
            "link",
            "joint",
            "frame",
            "model",
            "include",
            "plugin",
            "self_collide",
            "allow_auto_disable",
            "enable_wind",
            "gripper",
        }
    ),
    "link": frozenset(
        {
            "pose",
            "inertial",
            "collision",
            "visual",
            "sensor",
            "gravity",
            "self_collide",
            "kinematic",
            "must_be_base_link",
            "velocity_decay",
            "projector",
            "audio_sink",
            "audio_source",
            "battery",
            "light",
            "particle_emitter",
            "enable_wind",
        }
    ),
    # `density` and `auto_inertia_params` (SDF 1.11) feed Gazebo's automatic inertia, not collision.
    "collision": frozenset(
        {"pose", "geometry", "surface", "laser_retro", "max_contacts", "density", "auto_inertia_params"}
    ),
    "visual": frozenset(
        {
            "pose",
            "geometry",
            "material",
            "cast_shadows",
            "transparency",
            "laser_retro",
            "meta",
            "plugin",
            "visibility_flags",
        }
    ),
    "joint": frozenset(
        {
            "parent",
            "child",
            "pose",
            "axis",
            "axis2",
            "physics",
            "sensor",
            "gearbox_ratio",
            "gearbox_reference_body",
            "thread_pitch",
            "screw_thread_pitch",
        }
    ),
    "include": frozenset({"uri", "name", "pose", "static", "placement_frame", "plugin"}),
}
UNSUPPORTED_WORLD = {
    "population": "model populations are not expanded",
    "actor": "animated actors are not simulated",
    "road": "roads are not simulated",
}
_GEOMETRY_TAGS = (
    "box",
    "cylinder",
    "cone",
    "sphere",
    "plane",
    "capsule",
    "ellipsoid",
    "polyline",
    "mesh",
    "heightmap",
    "image",
)

# Fuel or Gazebo-installed models that the twin stands in for when they cannot be resolved.
_GROUND_PLANE_NAMES = {"ground_plane", "groundplane"}
_SUN_NAMES = {"sun"}

# Plugins whose effect the twin reproduces itself (diff drive, joint states, sensors) or that only
# matter to Gazebo's own machinery; any other plugin is warned about once.
_UNDERSTOOD_PLUGINS = frozenset(  # by `plugin_kind`: any spelling of each library
    {
        "gazebo_ros_diff_drive",
        "DiffDrivePlugin",
        "SkidSteerDrivePlugin",
        "gazebo_ros_joint_state_publisher",
        "gazebo_ros_ray_sensor",
        "gazebo_ros_imu_sensor",
        "gazebo_ros_camera",
        "gazebo_ros_init",
        "gazebo_ros_factory",
        "gazebo_ros_state",
        "gz-sim-diff-drive-system",
        "gz-sim-joint-state-publisher-system",
        "gz-sim-physics-system",
        "gz-sim-sensors-system",
        "gz-sim-imu-system",
        "gz-sim-scene-broadcaster-system",
        "gz-sim-user-commands-system",
        "gz-sim-contact-system",
    }
)


def _norm_model_name(text: str) -> str:
    name = fuel_model_name(text) or text.strip().rstrip("/").rsplit("/", 1)[-1]
    return name.lower().replace(" ", "_").replace("-", "_")


@dataclass(kw_only=True, eq=False)
class RawModel:
    """A model as read: its elements still XML, its includes read, nothing placed yet."""

    name: str
    node: XmlNode
    version: tuple[int, int]
    file: Path
    static: bool
    pose: XmlNode | None
    placement_frame: str = ""
    pose_override: XmlNode | None = None
    merged: bool = False
    links: list[XmlNode] = field(default_factory=list)
    joints: list[XmlNode] = field(default_factory=list)
    frames: list[XmlNode] = field(default_factory=list)
    models: list[RawModel] = field(default_factory=list)
    plugins: list[Plugin] = field(default_factory=list)
    #: Names of the nested includes that could not be resolved and were skipped with a warning.
    skipped: set[str] = field(default_factory=set)
    #: The `<include>` that brought this model in (None for a `<model>` written in place).
    include: XmlNode | None = None

    @property
    def pose_node(self) -> XmlNode | None:
        """The `<pose>` that places the model: its `<include>`'s, else its own."""
        return self.pose_override if self.pose_override is not None else self.pose


class SdfReader:
    """Reads SDF files into `RawModel`s, following includes; collects the warnings and unknown elements."""

    def __init__(self, search: Sequence[Path], missing_includes: MissingIncludes = "error") -> None:
        self.search = tuple(search)
        self.missing_includes = missing_includes
        self.warnings: list[str] = []
        self.unknown: list[XmlNode] = []
        self._warned: set[str] = set()
        self.include_stack: list[Path] = []

    def warn(self, key: str, message: str) -> None:
        """Record a warning once per `key`."""
        if key in self._warned:
            return
        self._warned.add(key)
        self.warnings.append(message)
        _log.debug("%s", message)

    # -- documents --

    def read_sdf(self, path: Path) -> tuple[XmlNode, tuple[int, int]]:
        """Read an SDF file: its `<sdf>` root and its version (warned about when missing or too new)."""
        root = parse_file(path)
        if root.tag != "sdf":
            raise WorldError(_not_sdf_message(path, root))
        version_text = root.get("version")
        version = sdf_version(version_text)
        if version is None:
            self.warn(f"version:{path}", f"{path}:{root.line}: <sdf> has no valid version attribute; read as SDF 1.11")
            version = MAX_SDF_VERSION
        elif version > MAX_SDF_VERSION:
            self.warn(
                f"version:{path}",
                f"{path}:{root.line}: SDF {version_text} is newer than 1.11; read with 1.11 rules",
            )
        return root, version

    # -- models --

    def parse_model(self, node: XmlNode, version: tuple[int, int], file: Path, *, parent_static: bool) -> RawModel:
        """Read a `<model>` into a `RawModel`, following its includes."""
        name = node.get("name")
        if not name:
            msg = f"{node.where}: <model> needs a name attribute"
            raise WorldError(msg)
        static = parent_static or node.bool_at("static", False)
        raw = RawModel(
            name=name,
            node=node,
            version=version,
            file=file,
            static=static,
            pose=node.find("pose"),
            placement_frame=node.get("placement_frame") or "",
        )
        for child in node.children:
            tag = child.tag
            if tag == "link":
                raw.links.append(child)
            elif tag == "joint":
                raw.joints.append(child)
            elif tag == "frame":
                raw.frames.append(child)
            elif tag == "model":
                raw.models.append(self.parse_model(child, version, file, parent_static=static))
            elif tag == "include":
                included = self.include(child, file, parent_static=static)
                if included is not None:
                    raw.models.append(included)
                else:
                    uri = child.text_at("uri") or ""
                    raw.skipped.add(child.text_at("name") or fuel_model_name(uri) or uri.rstrip("/").rsplit("/", 1)[-1])
            elif tag == "plugin":
                raw.plugins.append(self.plugin(child))
            else:
                self.check_known("model", child)
        self.check_unique(raw)
        self.frames_named_apart(raw)
        nested: dict[str, RawModel] = {}
        for model in raw.models:
            if model.name in nested and not model.merged:
                raise WorldError(second_model_message(model, nested[model.name], f"model {raw.name!r}"))
            nested.setdefault(model.name, model)
        return raw

    def check_unique(self, raw: RawModel) -> None:
        """Refuse a second link, joint or frame of the same name in a model."""
        seen: dict[str, str] = {}
        for node in (*raw.links, *raw.joints, *raw.frames):
            name = node.get("name") or ""
            if not name:
                msg = f"{node.where}: <{node.tag}> needs a name attribute"
                raise WorldError(msg)
            if name in seen and seen[name] == node.tag:
                msg = f"{node.where}: a second <{node.tag}> named {name!r} in model {raw.name!r}; names must be unique"
                raise WorldError(msg)
            seen[name] = node.tag

    def frames_named_apart(self, raw: RawModel) -> None:
        """Give a `<frame>` named like a sibling link, joint or model a name of its own, as libsdformat does.

        Before SDF 1.7 such a frame is renamed `<name>_frame` (libsdformat's conversion of older
        files); from 1.7 on, sibling names must be unique and the file is refused (its DUPLICATE_NAME).

        Raises:
            WorldError: From SDF 1.7, naming the frame, the sibling and the fix.
        """
        taken: dict[str, XmlNode] = {}
        for node in (*raw.links, *raw.joints):
            taken.setdefault(node.get("name") or "", node)
        for model in raw.models:
            if not model.merged:
                taken.setdefault(model.name, model.node)
        frames = []
        names = {node.get("name") or "" for node in raw.frames}
        for node in raw.frames:
            name = node.get("name") or ""
            sibling = taken.get(name)
            if sibling is not None:
                scope = "the world" if raw.node.tag == "world" else f"model {raw.name!r}"
                if raw.version >= (1, 7):
                    msg = (
                        f"{node.where}: <frame name={name!r}> has the name of the <{sibling.tag}> at "
                        f"{sibling.where} in {scope}; from SDF 1.7 the names of a scope's links, joints, models "
                        "and frames must be unique: rename one"
                    )
                    raise WorldError(msg)
                renamed, k = f"{name}_frame", 0
                while renamed in taken or renamed in names:  # as libsdformat: a name no sibling has
                    renamed, k = f"{name}_frame{k}", k + 1
                names.add(renamed)
                self.warn(
                    f"frame-renamed:{node.where}",
                    f"{node.where}: <frame name={name!r}> shares its name with a <{sibling.tag}> in {scope}; "
                    f"read as {renamed!r}, as libsdformat reads SDF {raw.version[0]}.{raw.version[1]}",
                )
                attrib = tuple((k, renamed if k == "name" else v) for k, v in node.attrib)
                frames.append(dataclasses.replace(node, attrib=attrib))
                continue
            frames.append(node)
        raw.frames = frames

    def check_known(self, parent: str, child: XmlNode) -> None:
        """Keep and warn about (once per tag) a child element `parent` does not have in SDF."""
        known = _KNOWN.get(parent)
        if known is None or child.tag in known:
            return
        self.unknown.append(child)
        # `prefix:name` is SDF's custom element (a simulator's own extension), not a typo.
        what = "custom element" if ":" in child.tag else "unknown element"
        self.warn(
            f"unknown:{parent}/{child.tag}",
            f"{child.where}: {what} <{child.tag}> in <{parent}>; kept as data and ignored",
        )

    def plugin(self, node: XmlNode) -> Plugin:
        """Read a `<plugin>`, warned about when the twin does not run it."""
        filename = node.get("filename") or ""
        plugin = Plugin(name=node.get("name") or "", filename=filename, element=node, where=node.where)
        if filename and plugin.kind not in _UNDERSTOOD_PLUGINS:
            self.warn(
                f"plugin:{filename}",
                f"{node.where}: plugin {filename!r} is not run by the twin; kept as data",
            )
        return plugin

    def include(self, node: XmlNode, file: Path, *, parent_static: bool) -> RawModel | None:
        """Read the model an `<include>` names (None when it is skipped)."""
        uri = node.text_at("uri")
        if not uri:
            msg = f"{node.where}: <include> needs a <uri>"
            raise WorldError(msg)
        for child in node.children:
            self.check_known("include", child)
        target = resolve_include(uri, file, self.search)
        if target is None:
            builtin = _norm_model_name(uri)
            if builtin in _GROUND_PLANE_NAMES:
                return self.builtin_ground_plane(node, file, parent_static=parent_static)
            if builtin in _SUN_NAMES:
                return None
            if uri.startswith(("http://", "https://")):
                self.warn(
                    f"include:{uri}",
                    f"{node.where}: cannot fetch <include> {uri!r} offline and it is in no local Fuel cache; "
                    "skipped (`gz fuel download -u URI` caches it, or put the model on the model path)",
                )
                return None
            missing = (
                f"{node.where}: <include> {uri!r} not found in the model path "
                f"[{', '.join(str(p) for p in self.search) or 'empty'}]"
            )
            where = "(--model-path, a scenario's world.model_path, or TWIN_MODEL_PATH)"
            if self.missing_includes == "error":
                msg = (
                    f"{missing}; put its parent folder on the model path {where}, or skip missing includes "
                    "(map save --skip-missing, world.missing_includes: warn)"
                )
                raise WorldError(msg)
            self.warn(f"include:{uri}", f"{missing}; skipped (its parent folder on the model path {where} adds it)")
            return None
        if target in self.include_stack:
            msg = f"{node.where}: <include> {uri!r} includes itself (through {target})"
            raise WorldError(msg)
        self.include_stack.append(target)
        try:
            root, version = self.read_sdf(target)
            model_node = root.find("model")
            if model_node is None:
                if root.find("light") is not None:
                    return None
                actor = root.find("actor")
                if actor is not None:  # as an inline <actor>
                    self.warn(
                        f"unsupported:actor:{target}",
                        f"{node.where}: <include> {uri!r} is an <actor>: animated actors are not simulated; skipped",
                    )
                    return None
                what = "a world" if root.find("world") is not None else "no <model>"
                msg = f"{node.where}: <include> {uri!r} resolves to {target}, which holds {what}; expected a <model>"
                raise WorldError(msg)
            static = parent_static or node.bool_at("static", False)
            raw = self.parse_model(model_node, version, target, parent_static=static)
        finally:
            self.include_stack.pop()
        raw.include = node
        name = node.text_at("name")
        if name:
            raw.name = name
        if node.find("pose") is not None:
            raw.pose_override = node.find("pose")
        if node.find("static") is not None:
            raw.static = parent_static or node.bool_at("static", False)
        raw.placement_frame = node.text_at("placement_frame") or raw.placement_frame
        raw.merged = (node.get("merge") or "").lower() in ("true", "1")
        raw.plugins.extend(self.plugin(p) for p in node.findall("plugin"))
        return raw

    def builtin_ground_plane(self, node: XmlNode, file: Path, *, parent_static: bool) -> RawModel:
        """Stand in for Gazebo's `ground_plane` model: a static infinite plane at z = 0."""
        text = (
            '<model name="ground_plane"><static>true</static><link name="link">'
            '<collision name="collision"><geometry><plane><normal>0 0 1</normal><size>100 100</size></plane>'
            "</geometry></collision></link></model>"
        )
        model_node = parse_string(text, file)
        raw = self.parse_model(model_node, MAX_SDF_VERSION, file, parent_static=True)
        name = node.text_at("name")
        if name:
            raw.name = name
        if node.find("pose") is not None:
            raw.pose_override = node.find("pose")
        return raw

    def check_children(self, parent: str, node: XmlNode) -> None:
        """Check every child of `node` against what `parent` may hold."""
        for child in node.children:
            self.check_known(parent, child)

    def _check_dimensions(self, shape: XmlNode, label: str) -> None:
        """Refuse a shape extent that is not a finite number; warn of a negative or zero one.

        A NaN box passed every check before (its bounds were NaN, the map save failed deep inside).
        """
        for child in shape.children:
            if child.tag not in _DIMENSIONS or not child.text:
                continue
            values = child.as_floats()
            if not all(math.isfinite(v) for v in values):
                text = child.text.strip()
                msg = f"{child.where}: <{shape.tag}><{child.tag}> of {label} is {text!r}; give finite numbers"
                raise WorldError(msg)
            if any(v < 0.0 for v in values):
                self.warn(
                    f"negative:{child.where}",
                    f"{child.where}: <{shape.tag}><{child.tag}> of {label} is {child.text.strip()!r}; "
                    "a negative extent is taken as its size",
                )
            elif any(v == 0.0 for v in values) and shape.tag != "plane":
                self.warn(
                    f"zero:{child.where}",
                    f"{child.where}: <{shape.tag}><{child.tag}> of {label} is {child.text.strip()!r}; a shape without "
                    "extent along an axis may be neither seen nor touched",
                )

    def geometry(self, node: XmlNode, base_dir: Path, model: str, link: str, *, collision: bool) -> Geometry | None:
        """Read a collision's or visual's `<geometry>`, its mesh resolved (None when it is skipped)."""
        what = "collision" if collision else "visual"
        geom = node.find("geometry")
        label = f"{what} {node.get('name')!r} of link {link!r} in model {model!r}"
        if geom is None:
            if not collision:
                self.warn(f"visual-geometry:{node.where}", f"{node.where}: {label} has no <geometry>; skipped")
                return None
            msg = f"{node.where}: {label} has no <geometry>"
            raise WorldError(msg)
        shapes = [c for c in geom.children if c.tag in _GEOMETRY_TAGS]
        for child in geom.children:
            if child.tag not in _GEOMETRY_TAGS and child.tag != "empty":
                self.unknown.append(child)
                self.warn(
                    f"unknown:geometry/{child.tag}",
                    f"{child.where}: unknown geometry <{child.tag}>; kept as data and ignored",
                )
        if not shapes:
            return None
        shape = shapes[0]
        tag = shape.tag
        self._check_dimensions(shape, label)
        if tag == "box":
            size = _vector(shape, "size", (1.0, 1.0, 1.0))
            return Box(size_m=(size[0], size[1], size[2]))
        if tag == "cylinder":
            return Cylinder(radius_m=shape.float_at("radius", 1.0), length_m=shape.float_at("length", 1.0))
        if tag == "cone":
            return Cone(radius_m=shape.float_at("radius", 1.0), length_m=shape.float_at("length", 1.0))
        if tag == "sphere":
            return Sphere(radius_m=shape.float_at("radius", 1.0))
        if tag == "capsule":
            return Capsule(radius_m=shape.float_at("radius", 0.5), length_m=shape.float_at("length", 1.0))
        if tag == "ellipsoid":
            radii = _vector(shape, "radii", (1.0, 1.0, 1.0))
            return Ellipsoid(radii_m=(radii[0], radii[1], radii[2]))
        if tag == "plane":
            normal = _vector(shape, "normal", (0.0, 0.0, 1.0))
            size_node = shape.find("size")
            size_m = size_node.as_floats(2) if size_node is not None and size_node.text else (1.0, 1.0)
            return Plane(normal=(normal[0], normal[1], normal[2]), size_m=(size_m[0], size_m[1]))
        if tag == "polyline":
            return _polyline([s for s in geom.children if s.tag == "polyline"])
        if tag == "mesh":
            uri = shape.text_at("uri") or ""
            if not uri:
                msg = f"{shape.where}: <mesh> of {label} needs a <uri>"
                raise WorldError(msg)
            path = resolve_resource(uri, base_dir=base_dir, search=fallback_search(self.search, base_dir))
            if (path is None or not path.is_file()) and uri.startswith(("http://", "https://")):
                # A Fuel mesh that is in no local Fuel cache: like a web <include>, never fetched.
                self.warn(
                    f"mesh:{uri}",
                    f"{shape.where}: cannot fetch {what} mesh {uri!r} offline and it is in no local Fuel cache; "
                    f"that {what} of link {link!r} in model {model!r} is skipped (`gz fuel download` caches it)",
                )
                return None
            if path is None or not path.is_file():
                path = resolve_resource_ignoring_case(
                    uri, base_dir=base_dir, search=fallback_search(self.search, base_dir)
                )
                if path is not None:
                    self.warn(
                        f"mesh-case:{uri}",
                        f"{shape.where}: mesh {uri!r} not found; using {path}, whose name differs only in letter "
                        "case (as Gazebo on a case-insensitive file system does); rename one to match the other",
                    )
            if path is None or not path.is_file():
                if collision:
                    owner = f"of link {link!r} in model {model!r}"
                    raise WorldError(missing_mesh_message(shape.where, uri, base_dir, owner))
                self.warn(f"mesh:{uri}", f"{shape.where}: visual mesh {uri!r} not found; the visual is kept without it")
                path = None
            scale = _vector(shape, "scale", (1.0, 1.0, 1.0))
            submesh = shape.find("submesh")
            return Mesh(
                uri=uri,
                path=path,
                scale=(scale[0], scale[1], scale[2]),
                submesh=submesh.text_at("name") if submesh is not None else None,
                center_submesh=submesh.bool_at("center", False) if submesh is not None else False,
            )
        self.warn(
            f"geometry:{tag}",
            f"{shape.where}: <{tag}> geometry is not supported by the twin; that {what} is skipped",
        )
        return None


_DIMENSIONS = ("size", "radius", "length", "radii", "scale", "height")  # a shape's numbers that are extents


def _vector(node: XmlNode, tag: str, default: tuple[float, ...]) -> tuple[float, ...]:
    child = node.find(tag)
    if child is None or not child.text:
        return default
    return child.as_floats(len(default))


def _polyline(nodes: list[XmlNode]) -> Polyline:
    polygons: list[tuple[tuple[float, float], ...]] = []
    height = nodes[0].float_at("height", 1.0)
    for node in nodes:
        points = []
        for point in node.findall("point"):
            x, y = point.as_floats(2)
            points.append((x, y))
        if len(points) >= 2 and points[0] == points[-1]:
            points.pop()
        if len(points) < 3:
            msg = f"{node.where}: <polyline> needs at least 3 distinct <point>s, got {len(points)}"
            raise WorldError(msg)
        polygons.append(tuple(points))
    return Polyline(polygons=tuple(polygons), height_m=height)


# Gazebo Classic's named materials (media/materials/scripts/gazebo.material): their diffuse colour;
# a textured one (Gazebo/Wood) as its texture's mean colour.
GAZEBO_MATERIALS: dict[str, tuple[float, float, float, float]] = {
    "Gazebo/White": (1.0, 1.0, 1.0, 1.0),
    "Gazebo/Grey": (0.7, 0.7, 0.7, 1.0),
    "Gazebo/Gray": (0.7, 0.7, 0.7, 1.0),
    "Gazebo/DarkGrey": (0.175, 0.175, 0.175, 1.0),
    "Gazebo/Black": (0.0, 0.0, 0.0, 1.0),
    "Gazebo/FlatBlack": (0.1, 0.1, 0.1, 1.0),
    "Gazebo/Red": (1.0, 0.0, 0.0, 1.0),
    "Gazebo/Green": (0.0, 1.0, 0.0, 1.0),
    "Gazebo/Blue": (0.0, 0.0, 1.0, 1.0),
    "Gazebo/Yellow": (1.0, 1.0, 0.0, 1.0),
    "Gazebo/Orange": (1.0, 0.5088, 0.0468, 1.0),
    "Gazebo/Purple": (1.0, 0.0, 1.0, 1.0),
    "Gazebo/Turquoise": (0.0, 1.0, 1.0, 1.0),
    "Gazebo/Indigo": (0.33, 0.0, 0.5, 1.0),
    "Gazebo/Wood": (0.55, 0.38, 0.22, 1.0),
}


def material_color(node: XmlNode) -> tuple[float, float, float, float] | None:
    """A visual's diffuse (else ambient) colour as RGBA, else its Gazebo script material's, or None."""
    material = node.find("material")
    if material is None:
        return None
    for tag in ("diffuse", "ambient"):
        child = material.find(tag)
        if child is not None and child.text:
            values = child.as_floats()
            if len(values) == 4:
                return (values[0], values[1], values[2], values[3])
            if len(values) == 3:
                return (values[0], values[1], values[2], 1.0)
    script = material.text_at("script/name")
    if script:
        return GAZEBO_MATERIALS.get(script.strip())
    return None


def second_model_message(raw: RawModel, first: RawModel, where: str) -> str:
    """Say that `raw` repeats the name of `first`, at the line to change: its <include> or its <model>."""
    first_at = (first.include or first.node).where
    if raw.include is not None:
        uri = raw.include.text_at("uri") or ""
        fix = "give it another <name>" if raw.include.text_at("name") else "give it a <name>"
        return (
            f"{raw.include.where}: <include> {uri!r} is a second model named {raw.name!r} in {where} "
            f"(the first is at {first_at}); {fix}"
        )
    return (
        f"{raw.node.where}: a second model named {raw.name!r} in {where} (the first is at {first_at}); "
        "model names must be unique: rename it"
    )


def _not_sdf_message(path: Path, root: XmlNode) -> str:
    tag = root.tag
    if tag == "robot":
        return (
            f"{path}: this is a URDF robot description (<robot>), not SDF; twin reads SDF "
            f"(convert it with `gz sdf -p {path} > model.sdf`)"
        )
    if tag == "model" and root.find("sdf") is not None:
        return f"{path}: this is a model.config; pass its model folder or the model.sdf it names"
    if tag == "gazebo":
        return f"{path}: this is a pre-1.0 Gazebo world (<gazebo>); convert it to SDF 1.4 or newer"
    return f"{path}: not an SDF file: the root element is <{tag}>, expected <sdf version=...>"
