"""Which fields of a message the twin's own nodes read as numbers, and the first of them that is NaN or infinite.

A user's node may publish anything on a topic; the twin's own subscribers (the drive on `/cmd_vel`,
AMCL on `/initialpose`, the EKF on `/odom`...) act on the fields listed here, so a NaN or an
infinity in one of them is refused before it reaches them, as Nav2's velocity smoother, collision
monitor and controller server refuse a Twist that fails `nav2_util::validateTwist`. A LaserScan's
`ranges` are not listed: REP 117 gives `inf` and `NaN` meanings there (no return, an error).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

__all__ = ["checks_finite", "nonfinite_field"]

# Type -> the fields (dotted) its consumers in the twin read as numbers.
_READ_FIELDS: dict[str, tuple[str, ...]] = {
    "geometry_msgs/msg/Twist": ("linear", "angular"),
    "geometry_msgs/msg/TwistStamped": ("twist",),
    "geometry_msgs/msg/PoseStamped": ("pose",),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("pose.pose", "pose.covariance"),
    "nav_msgs/msg/Odometry": ("pose.pose", "twist.twist"),
    "sensor_msgs/msg/Imu": ("orientation", "angular_velocity", "linear_acceleration"),
    "sensor_msgs/msg/JointState": ("position", "velocity", "effort"),
    "sensor_msgs/msg/LaserScan": ("angle_min", "angle_max", "angle_increment", "range_min", "range_max"),
}


def checks_finite(msgtype: str) -> bool:
    """Whether messages of `msgtype` have fields the twin's nodes need finite."""
    return msgtype in _READ_FIELDS


def nonfinite_field(msg: Any, msgtype: str) -> str | None:
    """Return `field = value` for the first NaN or infinite number the twin's nodes would read, or None.

    Args:
        msg: A message object (`twin.msgs`).
        msgtype: Its ROS type name.
    """
    for dotted in _READ_FIELDS.get(msgtype, ()):
        value = msg
        for part in dotted.split("."):
            value = getattr(value, part, None)
        found = _first_nonfinite(value, dotted)
        if found is not None:
            return found
    return None


def _first_nonfinite(value: Any, path: str) -> str | None:
    if isinstance(value, float):
        return None if math.isfinite(value) else f"{path} = {value}"
    if isinstance(value, np.ndarray):
        if value.dtype.kind != "f":
            return None
        bad = np.flatnonzero(~np.isfinite(value))
        return f"{path}[{bad[0]}] = {value.flat[bad[0]]}" if bad.size else None
    if isinstance(value, list | tuple):
        for i, item in enumerate(value):
            found = _first_nonfinite(item, f"{path}[{i}]")
            if found is not None:
                return found
        return None
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            found = _first_nonfinite(getattr(value, f.name), f"{path}.{f.name}")
            if found is not None:
                return found
    return None
