"""Frames and poses: where every link, joint, frame, collision and nested model of an SDF model is.

`Scope` resolves a frame name to its pose in one model's frame, SDF 1.7 style (`relative_to`,
`::` into nested models, `__model__`, `placement_frame`) and with every older version's defaults.
`ModelBuilder` composes those poses down the model tree, applies a world's `<state>` poses
(`collect_state`), and builds the final `Model` dataclasses of `twin.world.types`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.core.errors import WorldError
from twin.core.geometry import Mat4
from twin.world._xml import FarPoseError, XmlNode, parse_pose
from twin.world.sdf_parse import RawModel, SdfReader, material_color
from twin.world.types import (
    Collision,
    Frame,
    Inertial,
    Joint,
    JointType,
    Link,
    Model,
    Sensor,
    Visual,
    frozen_matrix,
    inverse,
)

__all__ = ["ModelBuilder", "Scope", "StateOverrides", "collect_state"]

_EYE4 = np.eye(4)  # copied: faster than np.eye for the many small matrices of a big world


class Scope:
    """Resolves frame names to poses in one model's frame (`T_model_X`), SDF 1.7 style."""

    def __init__(self, raw: RawModel) -> None:
        self.raw = raw
        self._cache: dict[str, Mat4] = {"__model__": _EYE4.copy()}
        self._visiting: set[str] = set()
        self._nested: dict[str, Scope] = {}
        self._entries: dict[str, tuple[str, XmlNode | RawModel]] = {}
        for node in raw.links:
            self._entries.setdefault(node.get("name", "") or "", ("link", node))
        for node in raw.joints:
            self._entries.setdefault(node.get("name", "") or "", ("joint", node))
        for node in raw.frames:
            self._entries.setdefault(node.get("name", "") or "", ("frame", node))
        for model in raw.models:
            self._entries.setdefault(model.name, ("model", model))

    def nested(self, name: str) -> Scope:
        """Return the scope of the nested model `name`."""
        if name not in self._nested:
            kind, raw = self._entries[name]
            if not isinstance(raw, RawModel):  # a link or joint of the model's name took it first
                twin = next(m for m in self.raw.models if m.name == name)
                msg = (
                    f"{twin.node.where}: model {name!r} has the name of a <{kind}> at {raw.where} in the same "
                    "scope; the names of a scope's links, joints, models and frames must be unique: rename one"
                )
                raise WorldError(msg)
            self._nested[name] = Scope(raw)
        return self._nested[name]

    def define(self, name: str, T: Mat4) -> None:
        """Give the frame `name` a fixed pose in this scope (the world scope's `world`)."""
        self._cache[name] = T

    def names(self) -> list[str]:
        """Return every frame name of this scope."""
        return ["__model__", *self._entries]

    def has(self, name: str) -> bool:
        """Whether this scope has a frame named `name`."""
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
                if kind == "model" and isinstance(raw, RawModel) and raw.merged and self.nested(other).has(name):
                    return self.T(other, where) @ self.nested(other).T(name, where)
            known = ", ".join(self.names())
            msg = f"{where}: no frame named {name!r} in model {self.raw.name!r} (frames here: {known})"
            raise WorldError(msg)
        if name in self._visiting:
            msg = f"{where}: the pose of {name!r} in model {self.raw.name!r} depends on itself (relative_to cycle)"
            raise WorldError(msg)
        self._visiting.add(name)
        try:
            result = self._resolve(name, where)
        finally:  # (a far pose raised there leaves its model out, and a model placed on it with it)
            self._visiting.discard(name)
        self._cache[name] = result
        return result

    def _resolve(self, name: str, where: str) -> Mat4:
        """`T` of an entry of this scope, from its pose and the frame that pose is relative to."""
        kind, raw = self._entries[name]
        if isinstance(raw, RawModel):
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
        return result


@dataclass(kw_only=True)
class StateOverrides:
    """The poses a world's `<state>` gives models and links (world frame), by scoped name."""

    models: dict[str, Mat4] = field(default_factory=dict)
    links: dict[str, Mat4] = field(default_factory=dict)
    far: dict[str, FarPoseError] = field(default_factory=dict)
    """Top-level models a pose of which lies beyond any world (`FarPoseError`), by name: left out."""


class ModelBuilder:
    """Builds a `RawModel` into a `Model`: poses composed down the model tree, elements read by `reader`."""

    def __init__(self, reader: SdfReader) -> None:
        self.reader = reader

    def build_model(
        self,
        raw: RawModel,
        scope: Scope,
        T_world_model: Mat4,
        prefix: str,
        state: StateOverrides,
    ) -> Model:
        """Build `raw` (placed at `T_world_model`, unless the world's `<state>` moves it) and its nested models."""
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
        plugins = list(raw.plugins)
        for nested in raw.models:
            nested_scope = scope.nested(nested.name)
            nested_prefix = prefix if nested.merged else scoped
            model = self.build_model(
                nested, nested_scope, T_world_model @ scope.T(nested.name, nested.node.where), nested_prefix, state
            )
            if nested.merged:  # (its plugins too: a merged base's diff drive is the model's, as in Gazebo)
                links.extend(model.links)
                joints.extend(model.joints)
                frames.extend(model.frames)
                models.extend(model.models)
                plugins.extend(model.plugins)
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
            plugins=tuple(plugins),
            source=raw.file,
            sdf_version=f"{raw.version[0]}.{raw.version[1]}",
        )

    def on_skipped(self, raw: RawModel, node: XmlNode, frames: tuple[str, ...]) -> bool:
        """Warn and return True if a joint or frame attaches to a model whose include was skipped."""
        for frame in frames:
            head = frame.split("::", 1)[0]
            if head in raw.skipped:
                self.reader.warn(
                    f"on-skipped:{node.where}",
                    f"{node.where}: <{node.tag}> {node.get('name')!r} refers to {frame!r}, whose <include> "
                    "was skipped; it is skipped too",
                )
                return True
        return False

    def element_pose(self, node: XmlNode, scope: Scope, T_model_link: Mat4, link_name: str) -> Mat4:
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
        raw: RawModel,
        scope: Scope,
        model_scoped: str,
        name: str,
        T_model_link: Mat4,
        T_world_link: Mat4,
        base_dir: Path,
    ) -> Link:
        """Build one link: its collisions, visuals, sensors and inertial, posed in the link's frame."""
        collisions: list[Collision] = []
        visuals: list[Visual] = []
        sensors: list[Sensor] = []
        inertial: Inertial | None = None
        for child in node.children:
            tag = child.tag
            if tag == "collision":
                geometry = self.reader.geometry(child, base_dir, model_scoped, name, collision=True)
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
                self.reader.check_children("collision", child)
            elif tag == "visual":
                geometry = self.reader.geometry(child, base_dir, model_scoped, name, collision=False)
                if geometry is None:
                    continue
                visuals.append(
                    Visual(
                        name=child.get("name") or "",
                        geometry=geometry,
                        T_link=frozen_matrix(self.element_pose(child, scope, T_model_link, name)),
                        color_rgba=material_color(child),
                    )
                )
                self.reader.check_children("visual", child)
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
                self.reader.check_known("link", child)
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

    def build_joint(
        self,
        node: XmlNode,
        raw: RawModel,
        scope: Scope,
        T_world_model: Mat4,
        link_world: dict[str, Mat4],
    ) -> Joint:
        """Build one joint: its pose, and its axis expressed in the joint's frame."""
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
        try:
            T_model_joint = scope.T(name, node.where)  # (placed at its child, unless its <pose> says otherwise)
        except WorldError:
            try:
                scope.T(child, node.where)
            except WorldError:  # the child is what is missing: say so, where the joint is
                pass
            else:
                raise
            known = ", ".join(scope.names())
            msg = (
                f"{node.where}: joint {name!r}: its <child> {child!r} is no link or frame of model {raw.name!r} "
                f"(frames here: {known}); name one of them in <child>"
            )
            raise WorldError(msg) from None
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
        self.reader.check_children("joint", node)
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


def collect_state(loader: SdfReader, state: XmlNode, known_models: dict[str, RawModel]) -> StateOverrides:
    """Read a world's `<state>`: the poses it gives models and links (world frame), by scoped name."""
    out = StateOverrides()

    def visit(node: XmlNode, prefix: str, raw: RawModel | None) -> None:
        name = node.get("name") or ""
        scoped = f"{prefix}::{name}" if prefix else name
        if raw is None:
            loader.warn(
                f"state:{scoped}",
                f"{node.where}: <state> names model {scoped!r}, which the world does not have; ignored",
            )
            return
        if (pose := node.find("pose")) is not None:
            try:
                out.models[scoped] = parse_pose(pose)
            except FarPoseError as err:
                out.far.setdefault(scoped.split("::", 1)[0], err)
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
                try:
                    out.links[f"{scoped}::{link_name}"] = parse_pose(pose)
                except FarPoseError as err:
                    out.far.setdefault(scoped.split("::", 1)[0], err)
        nested = {m.name: m for m in raw.models}
        for child in node.findall("model"):
            visit(child, scoped, nested.get(child.get("name") or ""))

    for node in state.findall("model"):
        visit(node, "", known_models.get(node.get("name") or ""))
    return out
