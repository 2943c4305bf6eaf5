"""The drive wheels of a differential-drive robot read from its URDF (as a bag's `/robot_description` carries it).

A wheel is a `continuous` (or `revolute`) joint whose child link has a cylinder (collision, else
visual): its radius is the wheel radius. The two wheels are the pair of such joints on opposite
sides (joint origins' y in the parent frame); the separation is the lateral distance between those
origins, as a diff-drive plugin's `wheel_separation`. A skid-steer robot (two or more wheels a
side) gives its front axle's pair and lists every wheel of each side.
"""

from __future__ import annotations

from dataclasses import dataclass

from lxml import etree

__all__ = ["UrdfWheels", "wheels_from_urdf"]


@dataclass(frozen=True, kw_only=True, slots=True)
class UrdfWheels:
    """Wheel geometry and joint names read from a URDF."""

    robot: str
    left_joint: str
    right_joint: str
    wheel_radius_m: float
    wheel_separation_m: float
    # Every drive wheel on each side: one for a differential drive, one per axle for a skid-steer robot.
    left_joints: tuple[str, ...] = ()
    right_joints: tuple[str, ...] = ()

    @property
    def skid_steer(self) -> bool:
        """Whether a side has more than one drive wheel."""
        return len(self.left_joints) > 1 or len(self.right_joints) > 1


# (joint origin y, joint name, parent link, wheel radius, joint origin xyz)
_Wheel = tuple[float, str, str, float, tuple[float, float, float]]


def _floats(text: str | None, n: int) -> list[float]:
    values = [float(v) for v in (text or "").split()]
    return values if len(values) == n else [0.0] * n


def _cylinder_radius(link: etree._Element) -> float | None:
    for kind in ("collision", "visual"):
        for cyl in link.iterfind(f"{kind}/geometry/cylinder"):
            radius = cyl.get("radius")
            if radius is not None:
                return float(radius)
    return None


def wheels_from_urdf(text: str) -> UrdfWheels | None:
    """The left and right drive wheels of a URDF, or None when it has no such pair (or does not parse)."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, remove_comments=True)
    try:
        root = etree.fromstring(text.encode(), parser)
    except (etree.XMLSyntaxError, ValueError):
        return None
    links = {link.get("name"): link for link in root.iterfind("link")}
    wheels: list[_Wheel] = []
    for joint in root.iterfind("joint"):
        if joint.get("type") not in ("continuous", "revolute"):
            continue
        child = joint.find("child")
        parent = joint.find("parent")
        link = links.get(child.get("link") if child is not None else None)
        if link is None or parent is None:
            continue
        radius = _cylinder_radius(link)
        if radius is None:
            continue
        origin = joint.find("origin")
        x, y, z = _floats(origin.get("xyz") if origin is not None else None, 3)
        wheels.append((y, str(joint.get("name")), str(parent.get("link")), radius, (x, y, z)))
    left = [w for w in wheels if w[0] > 0.0]
    right = [w for w in wheels if w[0] < 0.0]
    if not left or not right:
        return None
    # The outermost pair sharing a parent: casters sit nearer the middle or lack cylinders. A skid-steer
    # robot has several such pairs, one per axle: take the front axle's wheels, never a diagonal pair.
    pairs = [(lw, rw) for lw in left for rw in right if lw[2] == rw[2]]
    if not pairs:
        return None

    def rank(pair: tuple[_Wheel, _Wheel]) -> tuple[float, float, float]:
        (lw, rw) = pair
        # widest first; then the pair on one axle (not a diagonal); then the front one
        return (round(lw[0] - rw[0], 6), -abs(lw[4][0] - rw[4][0]), lw[4][0])

    lw, rw = max(pairs, key=rank)
    ly, ry = lw[0], rw[0]
    same_side = 0.25 * (ly - ry)  # wheels within a quarter of the track of this pair's y are on its side
    return UrdfWheels(
        robot=str(root.get("name") or ""),
        left_joint=lw[1],
        right_joint=rw[1],
        wheel_radius_m=0.5 * (lw[3] + rw[3]),
        wheel_separation_m=ly - ry,
        left_joints=tuple(w[1] for w in left if w[2] == lw[2] and abs(w[0] - ly) <= same_side),
        right_joints=tuple(w[1] for w in right if w[2] == rw[2] and abs(w[0] - ry) <= same_side),
    )
