"""A URDF of the robot, generated from its SDF model, for `/robot_description` (Foxglove, RViz).

One URDF link per robot frame (SDF links and `<frame>`s alike, so every TF frame has a link),
with the SDF visuals and collisions re-expressed in that frame: boxes, cylinders and spheres as
URDF primitives, meshes as absolute `file://` URIs (URDF has no capsules or ellipsoids: they
become cylinders and spheres of the same extent; polylines are left out). Joints carry the
frames' fixed transforms; wheel joints are `continuous`, SDF ball joints become `fixed`.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from twin.core.geometry import Mat4, rpy_from_matrix
from twin.world.robot_model import FrameSpec, RobotModelSpec
from twin.world.types import Box, Capsule, Cylinder, Ellipsoid, Geometry, JointType, Mesh, Sphere, inverse

__all__ = ["urdf_from_robot"]

_ESCAPES = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", "\n": "&#10;", "\r": "&#13;", "\t": "&#9;"})


def _quoteattr(text: str) -> str:
    """Return `text` as a quoted XML attribute value, as `xml.sax.saxutils.quoteattr` writes it.

    `&`, `<`, `>` and line breaks and tabs become entities; the value is put in double quotes, in
    single quotes if it holds a double quote but no single one, else its double quotes become
    `&quot;`. Written here because `xml.sax.saxutils` imports `urllib.request` (tens of ms).
    """
    text = text.translate(_ESCAPES)
    if '"' not in text:
        return f'"{text}"'
    if "'" not in text:
        return f"'{text}'"
    return '"{}"'.format(text.replace('"', "&quot;"))


def _num(value: float) -> str:
    if abs(value) < 1e-12:
        return "0"
    text = f"{value:.9g}"
    return "0" if text in ("-0", "0") else text


def _origin(T: Mat4) -> str:
    roll, pitch, yaw = rpy_from_matrix(T)
    xyz = " ".join(_num(float(v)) for v in T[:3, 3])
    rpy = " ".join(_num(v) for v in (roll, pitch, yaw))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _geometry(geometry: Geometry) -> str | None:
    match geometry:
        case Box(size_m=size):
            return f'<box size="{" ".join(_num(v) for v in size)}"/>'
        case Cylinder(radius_m=r, length_m=length):
            return f'<cylinder radius="{_num(r)}" length="{_num(length)}"/>'
        case Capsule(radius_m=r, length_m=length):
            return f'<cylinder radius="{_num(r)}" length="{_num(length + 2 * r)}"/>'
        case Sphere(radius_m=r):
            return f'<sphere radius="{_num(r)}"/>'
        case Ellipsoid(radii_m=radii):
            return f'<sphere radius="{_num(max(radii))}"/>'
        case Mesh(path=path, scale=scale) if path is not None:
            return f'<mesh filename={_quoteattr(path.resolve().as_uri())} scale="{" ".join(_num(v) for v in scale)}"/>'
    return None


def urdf_from_robot(robot: RobotModelSpec) -> str:
    """Return the robot as URDF XML text."""
    frames = [robot.base_frame, *(f.name for f in robot.frames)]
    T_base = {name: robot.T_base(name) for name in frames}
    # Which frame each SDF link's contents belong to: the link's own frame when it has one.
    owner = {link.name: link.name for link in robot.links if link.name in T_base}
    body: dict[str, list[str]] = {name: [] for name in frames}
    T_base_model = np.asarray(robot.T_base_model)
    for link in robot.links:
        host = owner.get(link.name, robot.base_frame)
        T_frame_link = inverse(T_base[host]) @ T_base_model @ np.asarray(link.T_model)
        if link.inertial is not None:
            ixx, iyy, izz, ixy, ixz, iyz = link.inertial.inertia_kgm2
            body[host].append(
                f"    <inertial>{_origin(T_frame_link @ np.asarray(link.inertial.T_link))}"
                f'<mass value="{_num(link.inertial.mass_kg)}"/>'
                f'<inertia ixx="{_num(ixx)}" ixy="{_num(ixy)}" ixz="{_num(ixz)}" '
                f'iyy="{_num(iyy)}" iyz="{_num(iyz)}" izz="{_num(izz)}"/>'
                "</inertial>"
            )
        for visual in link.visuals:
            shape = _geometry(visual.geometry)
            if shape is None:
                continue
            color = ""
            if visual.color_rgba is not None:
                rgba = " ".join(_num(v) for v in visual.color_rgba)
                color = f'<material name={_quoteattr(f"{link.name}_{visual.name}")}><color rgba="{rgba}"/></material>'
            body[host].append(
                f"    <visual name={_quoteattr(visual.name)}>{_origin(T_frame_link @ np.asarray(visual.T_link))}"
                f"<geometry>{shape}</geometry>{color}</visual>"
            )
        for collision in link.collisions:
            shape = _geometry(collision.geometry)
            if shape is None:
                continue
            body[host].append(
                f"    <collision name={_quoteattr(collision.name)}>"
                f"{_origin(T_frame_link @ np.asarray(collision.T_link))}"
                f"<geometry>{shape}</geometry></collision>"
            )
    lines = ['<?xml version="1.0"?>', f"<robot name={_quoteattr(robot.name)}>"]
    for name in frames:
        lines.extend(_link(name, body[name]))
    lines.extend(_joint(spec) for spec in robot.frames)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _link(name: str, contents: Iterable[str]) -> list[str]:
    items = list(contents)
    if not items:
        return [f"  <link name={_quoteattr(name)}/>"]
    return [f"  <link name={_quoteattr(name)}>", *items, "  </link>"]


def _joint(frame: FrameSpec) -> str:
    name = frame.joint or f"{frame.parent}_to_{frame.name}"
    urdf_type = {
        JointType.CONTINUOUS: "continuous",
        JointType.REVOLUTE: "continuous",
        JointType.PRISMATIC: "prismatic",
    }.get(frame.joint_type, "fixed")
    axis_xml = ""
    if urdf_type != "fixed":
        axis_xml = f'<axis xyz="{" ".join(_num(v) for v in frame.axis)}"/>'
    if urdf_type == "prismatic":
        axis_xml += '<limit lower="-1e9" upper="1e9" effort="0" velocity="0"/>'
    return (
        f'  <joint name={_quoteattr(name)} type="{urdf_type}"><parent link={_quoteattr(frame.parent)}/>'
        f"<child link={_quoteattr(frame.name)}/>{_origin(np.asarray(frame.T_parent))}{axis_xml}</joint>"
    )
