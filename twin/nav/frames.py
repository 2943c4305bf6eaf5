"""The planar transforms Nav2's nodes look up through TF: odom→base from `/odom`, map→odom from AMCL.

`LaserGeometry` is the lidar's scan layout and its mount in the base frame (what AMCL and the
costmaps read from a scan's header and the base→laser transform).

In ROS each Nav2 node keeps a tf2 buffer; in the twin the navigation nodes share one `Frames`
object, fed by their `/odom` subscriptions and by the AMCL node. Poses are `(x_m, y_m, yaw_rad)`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from twin.node import Encoded
from twin.node.readers import odometry_pose

if TYPE_CHECKING:
    from twin.world.robot_model import LidarSpec

__all__ = ["Frames", "LaserGeometry", "compose", "invert"]

Pose = tuple[float, float, float]


def compose(a: Pose, b: Pose) -> Pose:
    """Return `a ⊕ b`: pose `b`, given in frame `a`, expressed in `a`'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    yaw = (a[2] + b[2] + math.pi) % (2.0 * math.pi) - math.pi
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], yaw)


def invert(a: Pose) -> Pose:
    """Return the inverse transform of `a`."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


@dataclass(frozen=True, kw_only=True, slots=True)
class LaserGeometry:
    """A LaserScan's fixed fields and the laser's mount in the robot base frame.

    Beam i points at `mount_yaw_rad + angle_min_rad + i * angle_increment_rad` in the base frame;
    for a lidar mounted upside down (rolled by pi) pass `-angle_min` and `-angle_increment`, as
    AMCL does when it transforms the scan's angles into the base frame.
    """

    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    mount_z_m: float = 0.0
    mount_yaw_rad: float = 0.0

    @classmethod
    def from_spec(cls, spec: LidarSpec) -> LaserGeometry:
        """Return the geometry of a robot's lidar as its scans are published (mirrored if mounted upside down)."""
        mount = spec.mount
        sweep = 1.0 if math.cos(mount.roll_rad) * math.cos(mount.pitch_rad) >= 0.0 else -1.0
        return cls(
            angle_min_rad=sweep * spec.angle_min_rad,
            angle_increment_rad=sweep * spec.angle_increment_rad,
            range_min_m=spec.range_min_m,
            range_max_m=spec.range_max_m,
            mount_x_m=mount.x_m,
            mount_y_m=mount.y_m,
            mount_z_m=mount.z_m,
            mount_yaw_rad=mount.yaw_rad,
        )


class Frames:
    """The latest odom→base pose and speed, and map→odom (identity until a localizer sets it).

    Args:
        localized: False while a localizer runs but has no initial pose yet (map→odom unknown).
    """

    def __init__(self, *, localized: bool = True) -> None:
        self.odom_pose: Pose = (0.0, 0.0, 0.0)
        self.odom_stamp_ns = -1
        self.velocity: tuple[float, float] = (0.0, 0.0)
        self.prev_velocity: tuple[float, float, int] = (0.0, 0.0, -1)
        self.map_odom: Pose = (0.0, 0.0, 0.0)
        self.localized = localized

    def on_odom(self, t_ns: int, msg: Any) -> None:
        """Take an `/odom` message published at `t_ns` (the same message from several nodes is taken once)."""
        if t_ns == self.odom_stamp_ns:
            return
        if type(msg) is Encoded:
            data = msg[2]
            self.odom_pose = (data[0], data[1], data[2])
            v, w = (data[3], data[4]) if len(data) > 4 else (0.0, 0.0)
        else:
            self.odom_pose = odometry_pose(msg)
            twist = msg.twist.twist
            v, w = float(twist.linear.x), float(twist.angular.z)
        self.prev_velocity = (self.velocity[0], self.velocity[1], self.odom_stamp_ns)
        self.velocity = (v, w)
        self.odom_stamp_ns = t_ns

    def map_pose(self) -> Pose:
        """The robot's pose in the map frame (map→odom ⊕ odom→base)."""
        return compose(self.map_odom, self.odom_pose)

    def map_to_odom(self, pose: Pose) -> Pose:
        """A map-frame pose in the odom frame."""
        return compose(invert(self.map_odom), pose)
