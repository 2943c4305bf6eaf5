"""The loaded world as frozen dataclasses: worlds, models, links, joints, collisions and geometry.

Every pose is a read-only 4x4 homogeneous matrix (`twin.core.geometry.Mat4`). Names follow the
`T_a_b` convention: `T_world` is the pose of the thing in the world frame, `T_model` in its
model's frame, `T_link` in its link's frame. Scoped names join nested model names with `::`, as
Gazebo does (`house::table::link`).
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.core.geometry import Mat4
from twin.world._xml import XmlNode

__all__ = [
    "Box",
    "Capsule",
    "Collision",
    "Cone",
    "Cylinder",
    "Ellipsoid",
    "Frame",
    "Geometry",
    "Inertial",
    "Joint",
    "JointType",
    "Light",
    "Link",
    "Mesh",
    "Model",
    "Physics",
    "Plane",
    "Plugin",
    "Polyline",
    "Sensor",
    "Sphere",
    "Visual",
    "World",
    "plugin_kind",
]


def frozen_matrix(mat: Mat4) -> Mat4:
    """Return a read-only copy of a 4x4 matrix (so frozen dataclasses stay frozen)."""
    out = np.array(mat, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out


_IDENTITY = frozen_matrix(np.eye(4))


def inverse(mat: Mat4) -> Mat4:
    """Return the inverse of a rigid 4x4 transform (rotation transposed, translation rotated back)."""
    out = _IDENTITY.copy()  # a copy is writeable, and faster than np.eye
    out[:3, :3] = mat[:3, :3].T
    out[:3, 3] = -mat[:3, :3].T @ mat[:3, 3]
    return out


# --- geometry -------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True, slots=True)
class Box:
    """A box centred on its frame; `size_m` is the full extent along x, y, z."""

    size_m: tuple[float, float, float]


@dataclass(frozen=True, kw_only=True, slots=True)
class Cylinder:
    """A cylinder centred on its frame, axis along z."""

    radius_m: float
    length_m: float


@dataclass(frozen=True, kw_only=True, slots=True)
class Sphere:
    """A sphere centred on its frame."""

    radius_m: float


@dataclass(frozen=True, kw_only=True, slots=True)
class Capsule:
    """A cylinder of `length_m` along z capped by two half-spheres (SDF 1.9)."""

    radius_m: float
    length_m: float


@dataclass(frozen=True, kw_only=True, slots=True)
class Ellipsoid:
    """An ellipsoid centred on its frame with semi-axes `radii_m` (SDF 1.9)."""

    radii_m: tuple[float, float, float]


@dataclass(frozen=True, kw_only=True, slots=True)
class Cone:
    """A cone centred on its frame (SDF 1.11): base of `radius_m` at z = -length/2, apex at +length/2."""

    radius_m: float
    length_m: float


@dataclass(frozen=True, kw_only=True, slots=True)
class Plane:
    """An infinite plane through the frame origin (Gazebo's physics ignores `size_m`)."""

    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    size_m: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True, kw_only=True, slots=True)
class Polyline:
    """Closed 2D polygons in the frame's xy-plane, extruded from z = 0 up to `height_m`."""

    polygons: tuple[tuple[tuple[float, float], ...], ...]
    height_m: float


@dataclass(frozen=True, kw_only=True, slots=True)
class Mesh:
    """A triangle mesh file; `path` is None when the URI could not be resolved to a file."""

    uri: str
    path: Path | None
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    submesh: str | None = None
    center_submesh: bool = False


Geometry = Box | Cylinder | Cone | Sphere | Capsule | Ellipsoid | Plane | Polyline | Mesh


def geometry_kind(geometry: Geometry) -> str:
    """Return the SDF element name of a geometry (`box`, `mesh`, ...)."""
    return type(geometry).__name__.lower()


# --- link contents --------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Collision:
    """One collision shape of a link, with its pose in the link and in the world."""

    name: str
    model: str
    link: str
    geometry: Geometry
    T_link: Mat4 = field(default_factory=lambda: _IDENTITY)
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)
    where: str = ""


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Visual:
    """One visual of a link (drawn by viewers, never used for physics)."""

    name: str
    geometry: Geometry
    T_link: Mat4 = field(default_factory=lambda: _IDENTITY)
    color_rgba: tuple[float, float, float, float] | None = None


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Inertial:
    """Mass, centre of mass and inertia tensor (about the centre of mass, in the inertial frame)."""

    mass_kg: float
    T_link: Mat4 = field(default_factory=lambda: _IDENTITY)
    inertia_kgm2: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    """(ixx, iyy, izz, ixy, ixz, iyz)."""


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Sensor:
    """A sensor as declared: type, pose in its link, rate, and the full element kept as data."""

    name: str
    type: str
    T_link: Mat4 = field(default_factory=lambda: _IDENTITY)
    update_rate_hz: float = 0.0
    topic: str | None = None
    element: XmlNode | None = None
    where: str = ""


@dataclass(frozen=True, kw_only=True, slots=True)
class Plugin:
    """A plugin or system as declared (the twin runs its own models; the XML is kept as data)."""

    name: str
    filename: str
    element: XmlNode
    where: str = ""
    scope: str = ""
    """The nested model it belongs to below the robot's model, `create::` (empty: the model's own)."""

    @property
    def kind(self) -> str:
        """The plugin's library as one name whatever its spelling (`plugin_kind`)."""
        return plugin_kind(self.filename)

    def param(self, tag: str) -> str | None:
        """Return the text of a direct child element, or None."""
        return self.element.text_at(tag)

    def params(self, tag: str) -> tuple[str, ...]:
        """Return the texts of every direct child element with this tag."""
        return tuple(child.text for child in self.element.findall(tag))


def plugin_kind(filename: str) -> str:
    """A plugin's library as one name, whatever spelling Gazebo finds it by.

    `libgz-sim8-diff-drive-system.so`, `ignition-gazebo-diff-drive-system` and
    `gz-sim-diff-drive-system` are all `gz-sim-diff-drive-system`; `libgazebo_ros_diff_drive.so` is
    `gazebo_ros_diff_drive`.
    """
    name = filename.strip().replace("\\", "/").rsplit("/", 1)[-1]
    for suffix in (".so", ".dylib", ".dll"):
        name = name.removesuffix(suffix)
    name = name.removeprefix("lib")
    return re.sub(r"^(?:ignition-gazebo|gz-sim)\d*-", "gz-sim-", name)


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Link:
    """A rigid body: its frame, collisions, visuals, sensors and inertia."""

    name: str
    scoped_name: str
    T_model: Mat4 = field(default_factory=lambda: _IDENTITY)
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)
    collisions: tuple[Collision, ...] = ()
    visuals: tuple[Visual, ...] = ()
    sensors: tuple[Sensor, ...] = ()
    inertial: Inertial | None = None


class JointType(enum.Enum):
    """SDF joint types."""

    FIXED = "fixed"
    REVOLUTE = "revolute"
    CONTINUOUS = "continuous"
    PRISMATIC = "prismatic"
    BALL = "ball"
    UNIVERSAL = "universal"
    SCREW = "screw"
    GEARBOX = "gearbox"
    REVOLUTE2 = "revolute2"


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Joint:
    """A joint: its frame (in the model and the world), parent and child, axis in the joint frame."""

    name: str
    type: JointType
    parent: str
    child: str
    T_model: Mat4 = field(default_factory=lambda: _IDENTITY)
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)
    axis_xyz: tuple[float, float, float] = (0.0, 0.0, 1.0)
    lower: float = -np.inf
    upper: float = np.inf
    effort: float = np.inf
    velocity: float = np.inf


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Frame:
    """An explicit `<frame>` (SDF 1.7+), or a named frame from an older file."""

    name: str
    attached_to: str
    T_model: Mat4 = field(default_factory=lambda: _IDENTITY)
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Model:
    """A model with its links, joints, frames, nested models and plugins, placed in the world."""

    name: str
    scoped_name: str
    static: bool = False
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)
    links: tuple[Link, ...] = ()
    joints: tuple[Joint, ...] = ()
    frames: tuple[Frame, ...] = ()
    models: tuple[Model, ...] = ()
    plugins: tuple[Plugin, ...] = ()
    source: Path | None = None
    sdf_version: str = ""

    def all_models(self) -> tuple[Model, ...]:
        """Return this model and every nested model, depth first."""
        out: list[Model] = [self]
        for child in self.models:
            out.extend(child.all_models())
        return tuple(out)

    def all_links(self) -> tuple[Link, ...]:
        """Return the links of this model and every nested model."""
        return tuple(link for model in self.all_models() for link in model.links)

    def all_collisions(self) -> tuple[Collision, ...]:
        """Return every collision of this model and its nested models."""
        return tuple(c for link in self.all_links() for c in link.collisions)

    def link(self, name: str) -> Link:
        """Return a link by name (or scoped name relative to this model).

        Raises:
            KeyError: If there is no such link.
        """
        for link in self.all_links():
            if link.name == name or link.scoped_name in (name, f"{self.scoped_name}::{name}"):
                return link
        raise KeyError(name)


@dataclass(frozen=True, kw_only=True, slots=True)
class Physics:
    """The world's physics settings, as declared (the twin keeps its own fixed step)."""

    max_step_size_s: float = 0.001
    real_time_update_rate_hz: float = 1000.0
    real_time_factor: float = 1.0
    gravity_mps2: tuple[float, float, float] = (0.0, 0.0, -9.8)


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class Light:
    """A light: the camera renderer shades with directional lights (`direction` in the light's frame)."""

    name: str
    type: str
    T_world: Mat4 = field(default_factory=lambda: _IDENTITY)
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    diffuse_rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class World:
    """A loaded world: its models placed in the world frame, plus what was declared around them.

    `warnings` holds one line per problem that did not stop loading (missing visual meshes,
    unresolvable includes, unknown elements, plugins the twin does not run), each naming its
    file and line.
    """

    name: str
    models: tuple[Model, ...] = ()
    lights: tuple[Light, ...] = ()
    plugins: tuple[Plugin, ...] = ()
    physics: Physics = field(default_factory=Physics)
    ambient_rgba: tuple[float, float, float, float] = (0.4, 0.4, 0.4, 1.0)
    """`<scene><ambient>` (Gazebo Classic's default when absent)."""
    background_rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)
    """`<scene><background>` (Gazebo Classic's default when absent)."""
    unknown: tuple[XmlNode, ...] = ()
    warnings: tuple[str, ...] = ()
    source: Path | None = None
    sdf_version: str = ""

    def all_models(self) -> tuple[Model, ...]:
        """Return every model, nested ones included, depth first."""
        return tuple(m for top in self.models for m in top.all_models())

    def all_collisions(self) -> tuple[Collision, ...]:
        """Return every collision in the world."""
        return tuple(c for top in self.models for c in top.all_collisions())

    def model(self, name: str) -> Model:
        """Return a model by name or scoped name.

        Raises:
            KeyError: If there is no such model.
        """
        for model in self.all_models():
            if name in (model.name, model.scoped_name):
                return model
        raise KeyError(name)
