"""SDF loading as Gazebo reads SDFormat 1.3 to 1.11 (Classic and gz-sim).

What is understood:

- `<world>`, `<model>` (nested), `<include>` (`model://`, `package://`, `file://` and relative
  URIs; `<name>`, `<pose>`, `<static>`, `<placement_frame>`, `<plugin>`, `merge="true"`), with
  model.config's choice of SDF file;
- `<static>`, links, joints, `<frame>` elements and pose composition: defaults of every SDF version
  (link poses in the model frame, joint poses in the child link frame, collision/visual/sensor poses
  in the link frame) and SDF 1.7+ `relative_to` (any frame of the scope, `::` into nested models,
  `__model__`), `placement_frame` (1.8), `degrees` and `quat_xyzw` poses (1.9);
- joint axes expressed in the model frame (SDF 1.4, `use_parent_model_frame` in 1.5/1.6,
  `expressed_in` in 1.7+), converted to the joint frame;
- a world's `<state>` block: model and link poses (world frame), nested model states,
  `<insertions>` and `<deletions>`, as Gazebo Classic applies it when it loads a world;
- collision geometry: box, cylinder, cone, sphere, plane, capsule, ellipsoid, polyline, mesh.

A missing visual mesh, an include that cannot be resolved offline, a plugin the twin does not run
and an element it does not know are warnings (each once), collected in `World.warnings`. A
missing collision mesh, malformed XML, a file that is not SDF, a missing `model://` include and a
frame that does not exist are `WorldError`s naming file and line.
"""

from __future__ import annotations

import contextlib
import gc
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from twin.core.errors import WorldError
from twin.core.geometry import Mat4
from twin.world._xml import XmlNode, parse_file, parse_pose, parse_string
from twin.world.paths import (
    MAX_SDF_VERSION,
    find_model_dir,
    folder_to_add,
    fuel_model_dir,
    fuel_model_name,
    model_file,
    resolve_resource,
    resolve_resource_ignoring_case,
    sdf_version,
    search_path,
)
from twin.world.types import (
    Box,
    Capsule,
    Collision,
    Cone,
    Cylinder,
    Ellipsoid,
    Frame,
    Geometry,
    Inertial,
    Joint,
    JointType,
    Light,
    Link,
    Mesh,
    Model,
    Physics,
    Plane,
    Plugin,
    Polyline,
    Sensor,
    Sphere,
    Visual,
    World,
    frozen_matrix,
    inverse,
)

__all__ = ["MissingIncludes", "load_model", "load_world"]

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
_UNSUPPORTED_WORLD = {
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
_UNDERSTOOD_PLUGINS = (
    "libgazebo_ros_diff_drive.so",
    "libgazebo_ros_joint_state_publisher.so",
    "libgazebo_ros_ray_sensor.so",
    "libgazebo_ros_imu_sensor.so",
    "libgazebo_ros_camera.so",
    "libgazebo_ros_init.so",
    "libgazebo_ros_factory.so",
    "libgazebo_ros_state.so",
    "gz-sim-diff-drive-system",
    "gz-sim-joint-state-publisher-system",
    "gz-sim-physics-system",
    "gz-sim-sensors-system",
    "gz-sim-imu-system",
    "gz-sim-scene-broadcaster-system",
    "gz-sim-user-commands-system",
    "gz-sim-contact-system",
    "ignition-gazebo-diff-drive-system",
    "ignition-gazebo-joint-state-publisher-system",
    "ignition-gazebo-physics-system",
    "ignition-gazebo-sensors-system",
    "ignition-gazebo-imu-system",
    "ignition-gazebo-scene-broadcaster-system",
    "ignition-gazebo-user-commands-system",
)


def _norm_model_name(text: str) -> str:
    name = fuel_model_name(text) or text.strip().rstrip("/").rsplit("/", 1)[-1]
    return name.lower().replace(" ", "_").replace("-", "_")


_EYE4 = np.eye(4)  # copied: faster than np.eye for the many small matrices of a big world


# --- raw (unresolved) structures -----------------------------------------------------------------


@dataclass(kw_only=True, eq=False)
class _RawModel:
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
    models: list[_RawModel] = field(default_factory=list)
    plugins: list[Plugin] = field(default_factory=list)
    #: Names of the nested includes that could not be resolved and were skipped with a warning.
    skipped: set[str] = field(default_factory=set)
    #: The `<include>` that brought this model in (None for a `<model>` written in place).
    include: XmlNode | None = None

    @property
    def pose_node(self) -> XmlNode | None:
        return self.pose_override if self.pose_override is not None else self.pose


class _Scope:
    """Resolves frame names to poses in one model's frame (`T_model_X`), SDF 1.7 style."""

    def __init__(self, raw: _RawModel) -> None:
        self.raw = raw
        self._cache: dict[str, Mat4] = {"__model__": _EYE4.copy()}
        self._visiting: set[str] = set()
        self._nested: dict[str, _Scope] = {}
        self._entries: dict[str, tuple[str, XmlNode | _RawModel]] = {}
        for node in raw.links:
            self._entries.setdefault(node.get("name", "") or "", ("link", node))
        for node in raw.joints:
            self._entries.setdefault(node.get("name", "") or "", ("joint", node))
        for node in raw.frames:
            self._entries.setdefault(node.get("name", "") or "", ("frame", node))
        for model in raw.models:
            self._entries.setdefault(model.name, ("model", model))

    def nested(self, name: str) -> _Scope:
        if name not in self._nested:
            _, raw = self._entries[name]
            assert isinstance(raw, _RawModel)
            self._nested[name] = _Scope(raw)
        return self._nested[name]

    def names(self) -> list[str]:
        return ["__model__", *self._entries]

    def has(self, name: str) -> bool:
        return name in self._entries or name == "__model__"

    def T(self, name: str, where: str) -> Mat4:
        """Return the pose of frame `name` in this model's frame."""
        if name in self._cache:
            return self._cache[name]
        if "::" in name:
            head, rest = name.split("::", 1)
            if head in self._entries and self._entries[head][0] == "model":
                return self.T(head, where) @ self.nested(head).T(rest, where)
        if name not in self._entries and name == self.raw.name:
            # The model's own name for its frame: Gazebo accepts it where `__model__` is meant.
            return self._cache["__model__"]
        if name not in self._entries:
            for other, (kind, raw) in self._entries.items():
                if kind == "model" and isinstance(raw, _RawModel) and raw.merged and self.nested(other).has(name):
                    return self.T(other, where) @ self.nested(other).T(name, where)
            known = ", ".join(self.names())
            msg = f"{where}: no frame named {name!r} in model {self.raw.name!r} (frames here: {known})"
            raise WorldError(msg)
        if name in self._visiting:
            msg = f"{where}: the pose of {name!r} in model {self.raw.name!r} depends on itself (relative_to cycle)"
            raise WorldError(msg)
        self._visiting.add(name)
        kind, raw = self._entries[name]
        if isinstance(raw, _RawModel):
            pose_node = raw.pose_node
            relative_to = (pose_node.get("relative_to") if pose_node is not None else None) or "__model__"
            result = self.T(relative_to, where) @ parse_pose(pose_node)
            if raw.placement_frame:
                result = result @ inverse(self.nested(name).T(raw.placement_frame, raw.node.where))
        else:
            pose_node = raw.find("pose")
            relative_to = (pose_node.get("relative_to") if pose_node is not None else None) or ""
            if not relative_to:
                if kind == "joint":
                    relative_to = raw.text_at("child") or "__model__"
                elif kind == "frame":
                    relative_to = raw.get("attached_to") or "__model__"
                else:
                    relative_to = "__model__"
            result = self.T(relative_to, pose_node.where if pose_node is not None else raw.where) @ parse_pose(
                pose_node
            )
        self._visiting.discard(name)
        self._cache[name] = result
        return result


@dataclass(kw_only=True)
class _StateOverrides:
    models: dict[str, Mat4] = field(default_factory=dict)
    links: dict[str, Mat4] = field(default_factory=dict)


# --- the loader ----------------------------------------------------------------------------------


class _Loader:
    def __init__(self, search: Sequence[Path], missing_includes: MissingIncludes = "error") -> None:
        self.search = tuple(search)
        self.missing_includes = missing_includes
        self.warnings: list[str] = []
        self.unknown: list[XmlNode] = []
        self._warned: set[str] = set()
        self._include_stack: list[Path] = []

    def fallback_search(self, base_dir: Path) -> tuple[Path, ...]:
        """Return the model path plus the folder holding the current model folder.

        The extra entry, searched last, lets a model name itself or a sibling model
        (`model://mailbox/meshes/...` inside `.../mailbox/model.sdf`) when its parent folder is not
        on the model path, as happens with models nested inside another model's folder.
        """
        extra = base_dir.parent
        return self.search if extra in self.search else (*self.search, extra)

    def warn(self, key: str, message: str) -> None:
        if key in self._warned:
            return
        self._warned.add(key)
        self.warnings.append(message)
        _log.debug("%s", message)

    # -- documents --

    def read_sdf(self, path: Path) -> tuple[XmlNode, tuple[int, int]]:
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

    def parse_model(self, node: XmlNode, version: tuple[int, int], file: Path, *, parent_static: bool) -> _RawModel:
        name = node.get("name")
        if not name:
            msg = f"{node.where}: <model> needs a name attribute"
            raise WorldError(msg)
        static = parent_static or node.bool_at("static", False)
        raw = _RawModel(
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
        nested: dict[str, _RawModel] = {}
        for model in raw.models:
            if model.name in nested and not model.merged:
                raise WorldError(_second_model_message(model, nested[model.name], f"model {raw.name!r}"))
            nested.setdefault(model.name, model)
        return raw

    def check_unique(self, raw: _RawModel) -> None:
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

    def check_known(self, parent: str, child: XmlNode) -> None:
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
        filename = node.get("filename") or ""
        plugin = Plugin(name=node.get("name") or "", filename=filename, element=node, where=node.where)
        if filename and filename not in _UNDERSTOOD_PLUGINS:
            self.warn(
                f"plugin:{filename}",
                f"{node.where}: plugin {filename!r} is not run by the twin; kept as data",
            )
        return plugin

    def include(self, node: XmlNode, file: Path, *, parent_static: bool) -> _RawModel | None:
        uri = node.text_at("uri")
        if not uri:
            msg = f"{node.where}: <include> needs a <uri>"
            raise WorldError(msg)
        for child in node.children:
            self.check_known("include", child)
        target = self.resolve_include(uri, file)
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
            msg = (
                f"{node.where}: <include> {uri!r} not found in the model path "
                f"[{', '.join(str(p) for p in self.search) or 'empty'}]; "
                "add its parent folder with --model-path or TWIN_MODEL_PATH"
            )
            if self.missing_includes == "error":
                raise WorldError(msg)
            self.warn(f"include:{uri}", f"{msg}; skipped")
            return None
        if target in self._include_stack:
            msg = f"{node.where}: <include> {uri!r} includes itself (through {target})"
            raise WorldError(msg)
        self._include_stack.append(target)
        try:
            root, version = self.read_sdf(target)
            model_node = root.find("model")
            if model_node is None:
                if root.find("light") is not None:
                    return None
                what = "a world" if root.find("world") is not None else "no <model>"
                msg = f"{node.where}: <include> {uri!r} resolves to {target}, which holds {what}; expected a <model>"
                raise WorldError(msg)
            static = parent_static or node.bool_at("static", False)
            raw = self.parse_model(model_node, version, target, parent_static=static)
        finally:
            self._include_stack.pop()
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

    def resolve_include(self, uri: str, file: Path) -> Path | None:
        uri = uri.strip()
        path: Path | None
        search = self.fallback_search(file.parent)
        if uri.startswith(("model://", "package://")):
            name = uri.split("://", 1)[1]
            path = find_model_dir(name, search)
        elif uri.startswith(("http://", "https://")):
            # The local Fuel cache first, then a folder of the model's name on the model path.
            path = fuel_model_dir(uri) or find_model_dir(
                fuel_model_name(uri) or uri.rstrip("/").rsplit("/", 1)[-1], search
            )
        else:
            path = resolve_resource(uri, base_dir=file.parent, search=search)
        if path is None:
            return None
        return model_file(path) if path.is_dir() else path

    def builtin_ground_plane(self, node: XmlNode, file: Path, *, parent_static: bool) -> _RawModel:
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

    # -- building the final dataclasses --

    def build_model(
        self,
        raw: _RawModel,
        scope: _Scope,
        T_world_model: Mat4,
        prefix: str,
        state: _StateOverrides,
    ) -> Model:
        scoped = f"{prefix}::{raw.name}" if prefix else raw.name
        T_world_model = state.models.get(scoped, T_world_model)
        base_dir = raw.file.parent
        links: list[Link] = []
        link_world: dict[str, Mat4] = {}
        for node in raw.links:
            name = node.get("name") or ""
            T_model_link = scope.T(name, node.where)
            link_scoped = f"{scoped}::{name}"
            T_world_link = state.links.get(link_scoped, T_world_model @ T_model_link)
            T_model_link = inverse(T_world_model) @ T_world_link
            link_world[name] = T_world_link
            links.append(
                self.build_link(
                    node,
                    raw=raw,
                    scope=scope,
                    model_scoped=scoped,
                    name=name,
                    T_model_link=T_model_link,
                    T_world_link=T_world_link,
                    base_dir=base_dir,
                )
            )
        joints = [
            self.build_joint(node, raw, scope, T_world_model, link_world)
            for node in raw.joints
            if not self.on_skipped(raw, node, (node.text_at("parent") or "", node.text_at("child") or ""))
        ]
        frames = []
        for node in raw.frames:
            name = node.get("name") or ""
            attached = node.get("attached_to") or ""
            if self.on_skipped(raw, node, (attached,)):
                continue
            T_model_frame = scope.T(name, node.where)
            if attached in link_world:
                T_world = link_world[attached] @ inverse(scope.T(attached, node.where)) @ T_model_frame
            else:
                T_world = T_world_model @ T_model_frame
            frames.append(
                Frame(
                    name=name,
                    attached_to=attached or "__model__",
                    T_model=frozen_matrix(inverse(T_world_model) @ T_world),
                    T_world=frozen_matrix(T_world),
                )
            )
        models: list[Model] = []
        for nested in raw.models:
            nested_scope = scope.nested(nested.name)
            nested_prefix = prefix if nested.merged else scoped
            model = self.build_model(
                nested, nested_scope, T_world_model @ scope.T(nested.name, nested.node.where), nested_prefix, state
            )
            if nested.merged:
                links.extend(model.links)
                joints.extend(model.joints)
                frames.extend(model.frames)
                models.extend(model.models)
            else:
                models.append(model)
        return Model(
            name=raw.name,
            scoped_name=scoped,
            static=raw.static,
            T_world=frozen_matrix(T_world_model),
            links=tuple(links),
            joints=tuple(joints),
            frames=tuple(frames),
            models=tuple(models),
            plugins=tuple(raw.plugins),
            source=raw.file,
            sdf_version=f"{raw.version[0]}.{raw.version[1]}",
        )

    def on_skipped(self, raw: _RawModel, node: XmlNode, frames: tuple[str, ...]) -> bool:
        """Warn and return True if a joint or frame attaches to a model whose include was skipped."""
        for frame in frames:
            head = frame.split("::", 1)[0]
            if head in raw.skipped:
                self.warn(
                    f"on-skipped:{node.where}",
                    f"{node.where}: <{node.tag}> {node.get('name')!r} refers to {frame!r}, whose <include> "
                    "was skipped; it is skipped too",
                )
                return True
        return False

    def missing_mesh_message(self, shape: XmlNode, uri: str, base_dir: Path, owner: str) -> str:
        """Say which collision mesh is missing and which folder the model path needs for it."""
        head = f"{shape.where}: collision mesh {uri!r} {owner} not found (searched {base_dir} and the model path)"
        folder = folder_to_add(uri, base_dir)
        if folder is None:
            return f"{head}; add the folder holding it to the model path"
        relative = uri.strip().removeprefix("file://")
        if (folder / relative).is_file():
            return f"{head}; it is {folder / relative}: add {folder} to the model path"
        return f"{head}; {uri!r} is relative to a folder on the model path, such as {folder}, which lacks it"

    def element_pose(self, node: XmlNode, scope: _Scope, T_model_link: Mat4, link_name: str) -> Mat4:
        """Return the pose of a collision/visual/sensor/inertial in its link frame."""
        pose_node = node.find("pose")
        relative_to = pose_node.get("relative_to") if pose_node is not None else None
        if not relative_to or relative_to == link_name:
            return parse_pose(pose_node)
        assert pose_node is not None
        return inverse(T_model_link) @ scope.T(relative_to, pose_node.where) @ parse_pose(pose_node)

    def build_link(
        self,
        node: XmlNode,
        *,
        raw: _RawModel,
        scope: _Scope,
        model_scoped: str,
        name: str,
        T_model_link: Mat4,
        T_world_link: Mat4,
        base_dir: Path,
    ) -> Link:
        collisions: list[Collision] = []
        visuals: list[Visual] = []
        sensors: list[Sensor] = []
        inertial: Inertial | None = None
        for child in node.children:
            tag = child.tag
            if tag == "collision":
                geometry = self.geometry(child, base_dir, model_scoped, name, collision=True)
                if geometry is None:
                    continue
                T_link = self.element_pose(child, scope, T_model_link, name)
                collisions.append(
                    Collision(
                        name=child.get("name") or "",
                        model=model_scoped,
                        link=f"{model_scoped}::{name}",
                        geometry=geometry,
                        T_link=frozen_matrix(T_link),
                        T_world=frozen_matrix(T_world_link @ T_link),
                        where=child.where,
                    )
                )
                self.check_children("collision", child)
            elif tag == "visual":
                geometry = self.geometry(child, base_dir, model_scoped, name, collision=False)
                if geometry is None:
                    continue
                visuals.append(
                    Visual(
                        name=child.get("name") or "",
                        geometry=geometry,
                        T_link=frozen_matrix(self.element_pose(child, scope, T_model_link, name)),
                        color_rgba=_material_color(child),
                    )
                )
                self.check_children("visual", child)
            elif tag == "sensor":
                sensors.append(
                    Sensor(
                        name=child.get("name") or "",
                        type=child.get("type") or "",
                        T_link=frozen_matrix(self.element_pose(child, scope, T_model_link, name)),
                        update_rate_hz=child.float_at("update_rate", 0.0),
                        topic=child.text_at("topic"),
                        element=child,
                        where=child.where,
                    )
                )
            elif tag == "inertial":
                ixx = child.float_at("inertia/ixx", 1.0)
                iyy = child.float_at("inertia/iyy", 1.0)
                izz = child.float_at("inertia/izz", 1.0)
                ixy = child.float_at("inertia/ixy", 0.0)
                ixz = child.float_at("inertia/ixz", 0.0)
                iyz = child.float_at("inertia/iyz", 0.0)
                inertial = Inertial(
                    mass_kg=child.float_at("mass", 1.0),
                    T_link=frozen_matrix(self.element_pose(child, scope, T_model_link, name)),
                    inertia_kgm2=(ixx, iyy, izz, ixy, ixz, iyz),
                )
            else:
                self.check_known("link", child)
        return Link(
            name=name,
            scoped_name=f"{model_scoped}::{name}",
            T_model=frozen_matrix(T_model_link),
            T_world=frozen_matrix(T_world_link),
            collisions=tuple(collisions),
            visuals=tuple(visuals),
            sensors=tuple(sensors),
            inertial=inertial,
        )

    def check_children(self, parent: str, node: XmlNode) -> None:
        for child in node.children:
            self.check_known(parent, child)

    def build_joint(
        self,
        node: XmlNode,
        raw: _RawModel,
        scope: _Scope,
        T_world_model: Mat4,
        link_world: dict[str, Mat4],
    ) -> Joint:
        name = node.get("name") or ""
        type_text = (node.get("type") or "").lower()
        try:
            joint_type = JointType(type_text)
        except ValueError:
            valid = ", ".join(t.value for t in JointType)
            msg = f"{node.where}: joint {name!r} has unknown type {type_text!r}; valid: {valid}"
            raise WorldError(msg) from None
        parent = node.text_at("parent") or ""
        child = node.text_at("child") or ""
        if not parent or not child:
            msg = f"{node.where}: joint {name!r} needs <parent> and <child>"
            raise WorldError(msg)
        T_model_joint = scope.T(name, node.where)
        if child in link_world:
            T_world = link_world[child] @ inverse(scope.T(child, node.where)) @ T_model_joint
        else:
            T_world = T_world_model @ T_model_joint
        axis_node = node.find("axis")
        axis = (0.0, 0.0, 1.0)
        lower, upper, effort, velocity = -np.inf, np.inf, np.inf, np.inf
        if axis_node is not None:
            xyz_node = axis_node.find("xyz")
            if xyz_node is not None and xyz_node.text:
                vec = np.array(xyz_node.as_floats(3))
                norm = float(np.linalg.norm(vec))
                if norm == 0.0:
                    msg = f"{xyz_node.where}: joint {name!r} axis is the zero vector"
                    raise WorldError(msg)
                vec = vec / norm
                expressed_in = xyz_node.get("expressed_in") or ""
                if raw.version < (1, 5) or (
                    raw.version < (1, 7) and axis_node.bool_at("use_parent_model_frame", False)
                ):
                    expressed_in = "__model__"
                if expressed_in and expressed_in != name:
                    R_model_frame = scope.T(expressed_in, xyz_node.where)[:3, :3]
                    vec = T_model_joint[:3, :3].T @ (R_model_frame @ vec)
                axis = (float(vec[0]), float(vec[1]), float(vec[2]))
            lower = axis_node.float_at("limit/lower", -np.inf)
            upper = axis_node.float_at("limit/upper", np.inf)
            effort = axis_node.float_at("limit/effort", np.inf)
            velocity = axis_node.float_at("limit/velocity", np.inf)
        self.check_children("joint", node)
        return Joint(
            name=name,
            type=joint_type,
            parent=parent,
            child=child,
            T_model=frozen_matrix(inverse(T_world_model) @ T_world),
            T_world=frozen_matrix(T_world),
            axis_xyz=axis,
            lower=lower,
            upper=upper,
            effort=effort if effort >= 0 else np.inf,
            velocity=velocity if velocity >= 0 else np.inf,
        )

    def geometry(self, node: XmlNode, base_dir: Path, model: str, link: str, *, collision: bool) -> Geometry | None:
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
            path = resolve_resource(uri, base_dir=base_dir, search=self.fallback_search(base_dir))
            if (path is None or not path.is_file()) and uri.startswith(("http://", "https://")):
                # A Fuel mesh that is in no local Fuel cache: like a web <include>, never fetched.
                self.warn(
                    f"mesh:{uri}",
                    f"{shape.where}: cannot fetch {what} mesh {uri!r} offline and it is in no local Fuel cache; "
                    f"that {what} of link {link!r} in model {model!r} is skipped (`gz fuel download` caches it)",
                )
                return None
            if path is None or not path.is_file():
                path = resolve_resource_ignoring_case(uri, base_dir=base_dir, search=self.fallback_search(base_dir))
                if path is not None:
                    self.warn(
                        f"mesh-case:{uri}",
                        f"{shape.where}: mesh {uri!r} not found; using {path}, whose name differs only in letter "
                        "case (as Gazebo on a case-insensitive file system does); rename one to match the other",
                    )
            if path is None or not path.is_file():
                if collision:
                    owner = f"of link {link!r} in model {model!r}"
                    raise WorldError(self.missing_mesh_message(shape, uri, base_dir, owner))
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


def _material_color(node: XmlNode) -> tuple[float, float, float, float] | None:
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
    return None


def _second_model_message(raw: _RawModel, first: _RawModel, where: str) -> str:
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


# --- worlds --------------------------------------------------------------------------------------


def _physics(world: XmlNode) -> Physics:
    nodes = list(world.findall("physics"))
    chosen = next((n for n in nodes if (n.get("default") or "").lower() in ("1", "true")), nodes[0] if nodes else None)
    gravity_node = world.find("gravity")
    if gravity_node is None and chosen is not None:
        gravity_node = chosen.find("gravity")
    gravity = gravity_node.as_floats(3) if gravity_node is not None and gravity_node.text else (0.0, 0.0, -9.8)
    if chosen is None:
        return Physics(gravity_mps2=(gravity[0], gravity[1], gravity[2]))
    return Physics(
        max_step_size_s=chosen.float_at("max_step_size", 0.001),
        real_time_update_rate_hz=chosen.float_at("real_time_update_rate", 1000.0),
        real_time_factor=chosen.float_at("real_time_factor", 1.0),
        gravity_mps2=(gravity[0], gravity[1], gravity[2]),
    )


def _collect_state(loader: _Loader, state: XmlNode, known_models: dict[str, _RawModel]) -> _StateOverrides:
    out = _StateOverrides()

    def visit(node: XmlNode, prefix: str, raw: _RawModel | None) -> None:
        name = node.get("name") or ""
        scoped = f"{prefix}::{name}" if prefix else name
        if raw is None:
            loader.warn(
                f"state:{scoped}",
                f"{node.where}: <state> names model {scoped!r}, which the world does not have; ignored",
            )
            return
        if (pose := node.find("pose")) is not None:
            out.models[scoped] = parse_pose(pose)
        scale = node.find("scale")
        if scale is not None and scale.text and tuple(scale.as_floats(3)) != (1.0, 1.0, 1.0):
            loader.warn(f"state-scale:{scoped}", f"{scale.where}: <state> scales model {scoped!r}; scale is ignored")
        link_names = {n.get("name") for n in raw.links}
        for link in node.findall("link"):
            link_name = link.get("name") or ""
            if link_name not in link_names:
                loader.warn(
                    f"state:{scoped}::{link_name}",
                    f"{link.where}: <state> names link {link_name!r} that model {scoped!r} does not have; ignored",
                )
                continue
            if (pose := link.find("pose")) is not None:
                out.links[f"{scoped}::{link_name}"] = parse_pose(pose)
        nested = {m.name: m for m in raw.models}
        for child in node.findall("model"):
            visit(child, scoped, nested.get(child.get("name") or ""))

    for node in state.findall("model"):
        visit(node, "", known_models.get(node.get("name") or ""))
    return out


def _world_from_node(loader: _Loader, world_node: XmlNode, version: tuple[int, int], path: Path) -> World:
    raw_models: list[_RawModel] = []
    lights: list[Light] = []
    plugins: list[Plugin] = []
    frames: list[XmlNode] = []
    state_nodes: list[XmlNode] = []
    for child in world_node.children:
        tag = child.tag
        if tag == "model":
            raw_models.append(loader.parse_model(child, version, path, parent_static=False))
        elif tag == "include":
            included = loader.include(child, path, parent_static=False)
            if included is not None:
                raw_models.append(included)
        elif tag == "frame":
            frames.append(child)
        elif tag == "plugin":
            plugins.append(loader.plugin(child))
        elif tag == "light":
            lights.append(
                Light(
                    name=child.get("name") or "",
                    type=child.get("type") or "",
                    T_world=frozen_matrix(parse_pose(child.find("pose"))),
                )
            )
        elif tag == "state":
            state_nodes.append(child)
        elif tag in _UNSUPPORTED_WORLD:
            loader.unknown.append(child)
            loader.warn(f"unsupported:{tag}", f"{child.where}: <{tag}> is not supported: {_UNSUPPORTED_WORLD[tag]}")
        else:
            loader.check_known("world", child)

    # <state>: deletions and insertions change the model list; poses override placement.
    for state in state_nodes:
        deleted = {n.text for d in state.findall("deletions") for n in d.findall("name")}
        if deleted:
            raw_models = [m for m in raw_models if m.name not in deleted]
        for insertions in state.findall("insertions"):
            for model_node in insertions.findall("model"):
                raw_models.append(loader.parse_model(model_node, version, path, parent_static=False))
    names: dict[str, _RawModel] = {}
    for raw in raw_models:
        if raw.name in names:
            raise WorldError(_second_model_message(raw, names[raw.name], "the world"))
        names[raw.name] = raw
    overrides = _StateOverrides()
    for state in state_nodes:
        found = _collect_state(loader, state, names)
        overrides.models.update(found.models)
        overrides.links.update(found.links)

    # The world is a scope too: models and frames may be placed relative to each other (SDF 1.7+).
    world_raw = _RawModel(
        name=world_node.get("name") or "default", node=world_node, version=version, file=path, static=True, pose=None
    )
    world_raw.models = raw_models
    world_raw.frames = frames
    scope = _Scope(world_raw)
    # Inside the world scope "__model__" is the world frame; SDF spells it "world".
    scope._cache["world"] = np.eye(4)
    models = [
        loader.build_model(raw, scope.nested(raw.name), scope.T(raw.name, raw.node.where), "", overrides)
        for raw in raw_models
    ]
    return World(
        name=world_raw.name,
        models=tuple(models),
        lights=tuple(lights),
        plugins=tuple(plugins),
        physics=_physics(world_node),
        unknown=tuple(loader.unknown),
        warnings=tuple(loader.warnings),
        source=path,
        sdf_version=f"{version[0]}.{version[1]}",
    )


def load_world(
    path: Path | str,
    *,
    model_path: Sequence[Path | str] = (),
    missing_includes: MissingIncludes = "error",
    env: dict[str, str] | None = None,
) -> World:
    """Load an SDF world file (or a model file, as a world holding just that model).

    Args:
        path: A `.world`/`.sdf` file, or a model folder with a model.config.
        model_path: Folders holding model folders, searched for `model://NAME` after
            `TWIN_MODEL_PATH` and before `GAZEBO_MODEL_PATH` / `GZ_SIM_RESOURCE_PATH`.
        missing_includes: `"error"` (default) fails on a `model://` include that is not on the
            model path; `"warn"` skips it with a warning, as Gazebo Classic does. Web URIs
            (Fuel) never fail: Ground Plane and Sun have built-in stand-ins, others are skipped
            with a warning.
        env: Environment to read those variables from (defaults to `os.environ`).

    Raises:
        WorldError: On malformed XML (file:line:column), a file that is not SDF, an include that
            is not on the model path, a missing collision mesh, or an inconsistent frame graph.
    """
    # The loader makes a few hundred thousand small objects and no garbage cycles: the cyclic
    # collector, run thousands of times meanwhile over them all, would cost a third of the time.
    with _collector_paused():
        return _load_world(Path(path), model_path=model_path, missing_includes=missing_includes, env=env)


@contextlib.contextmanager
def _collector_paused() -> Iterator[None]:
    """Pause Python's cyclic garbage collector (reference counting still frees everything else)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _load_world(
    path: Path, *, model_path: Sequence[Path | str], missing_includes: MissingIncludes, env: dict[str, str] | None
) -> World:
    loader = _Loader(search_path(model_path, env), missing_includes)
    if path.is_dir():
        path = model_file(path)
    root, version = loader.read_sdf(path)
    world_node = root.find("world")
    if world_node is not None:
        return _world_from_node(loader, world_node, version, path)
    model_node = root.find("model")
    if model_node is None:
        children = ", ".join(f"<{c.tag}>" for c in root.children) or "nothing"
        msg = f"{path}:{root.line}: <sdf> holds {children}; expected a <world> or a <model>"
        raise WorldError(msg)
    loader._include_stack.append(path)
    raw = loader.parse_model(model_node, version, path, parent_static=False)
    holder = _RawModel(name="__world__", node=root, version=version, file=path, static=True, pose=None)
    holder.models = [raw]
    scope = _Scope(holder)
    model = loader.build_model(raw, scope.nested(raw.name), scope.T(raw.name, raw.node.where), "", _StateOverrides())
    return World(
        name=raw.name,
        models=(model,),
        unknown=tuple(loader.unknown),
        warnings=tuple(loader.warnings),
        source=path,
        sdf_version=f"{version[0]}.{version[1]}",
    )


def load_model(
    name_or_path: Path | str, *, model_path: Sequence[Path | str] = (), env: dict[str, str] | None = None
) -> Model:
    """Load one model by name (`turtlebot3_waffle`, `model://turtlebot3_waffle`) or path.

    The model's own `<pose>` is dropped: the model frame is the world frame, as when a robot is
    spawned at the origin. Problems that do not stop loading (a missing visual mesh, a plugin the
    twin does not run) are logged as warnings.

    Raises:
        WorldError: If the model cannot be found or loaded.
    """
    search = search_path(model_path, env)
    text = str(name_or_path)
    candidate = Path(text).expanduser()
    if candidate.exists():
        path = model_file(candidate) if candidate.is_dir() else candidate
    else:
        name = text.split("://", 1)[1] if "://" in text else text
        folder = find_model_dir(name, search)
        if folder is None:
            msg = (
                f"model {text!r} not found: it is not a file and no folder {name!r} is on the model path "
                f"[{', '.join(str(p) for p in search) or 'empty'}]; add the folder holding it to the model path "
                "(a scenario's world.model_path, --model-path or TWIN_MODEL_PATH)"
            )
            raise WorldError(msg)
        path = model_file(folder)
    loader = _Loader(search)
    root, version = loader.read_sdf(path)
    node = root.find("model")
    if node is None:
        what = "a world" if root.find("world") is not None else "no <model>"
        msg = f"{path}:{root.line}: expected a <model>, but the file holds {what}"
        raise WorldError(msg)
    loader._include_stack.append(path)
    raw = loader.parse_model(node, version, path, parent_static=False)
    raw.pose = None
    raw.pose_override = None
    holder = _RawModel(name="__spawn__", node=root, version=version, file=path, static=True, pose=None)
    holder.models = [raw]
    scope = _Scope(holder)
    model = loader.build_model(raw, scope.nested(raw.name), np.eye(4), "", _StateOverrides())
    for warning in loader.warnings:
        _log.warning("%s", warning)
    return model
