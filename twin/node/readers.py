"""Read the fields built-in nodes need from standard topics, whoever published the message.

A built-in node publishes `Encoded` messages whose `data` follows the layout documented here; a
user node publishes `twin.msgs` message objects. These readers take either, so a user's node can
stand in for any built-in publisher (its own `/cmd_vel`, `/imu`, `/joint_states` or `/odom`).

| topic type | `Encoded.data` |
|---|---|
| geometry_msgs/Twist | (linear x m/s, angular z rad/s) |
| sensor_msgs/JointState | (stamp ns, positions tuple, velocities tuple) |
| sensor_msgs/Imu | (stamp ns, reading with `angular_velocity_z`) |
| nav_msgs/Odometry | (x m, y m, yaw rad, v m/s, yaw rate rad/s) |
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from twin.node.node import Encoded

__all__ = ["imu_yaw_rate", "joint_positions", "odometry_pose", "stamp_ns", "twist_of"]


def stamp_ns(header: Any) -> int:
    """Return a message header's stamp in integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def twist_of(msg: Any) -> tuple[float, float]:
    """Return (linear x, angular z) of a Twist."""
    if type(msg) is Encoded:
        v, w = msg[2]
        return float(v), float(w)
    return float(msg.linear.x), float(msg.angular.z)


def joint_positions(msg: Any, names: Sequence[str]) -> tuple[int, tuple[float, ...]] | None:
    """Return (stamp ns, positions of `names` in that order) of a JointState, or None if a name is missing."""
    if type(msg) is Encoded:
        t_ns, positions, _ = msg[2]
        return t_ns, tuple(positions)
    index = {n: i for i, n in enumerate(msg.name)}
    if any(n not in index for n in names) or len(msg.position) < len(msg.name):
        return None
    return stamp_ns(msg.header), tuple(float(msg.position[index[n]]) for n in names)


def imu_yaw_rate(msg: Any) -> tuple[int, float]:
    """Return (stamp ns, angular velocity z rad/s) of an Imu."""
    if type(msg) is Encoded:
        t_ns, reading = msg[2]
        return t_ns, float(reading.angular_velocity_z)
    return stamp_ns(msg.header), float(msg.angular_velocity.z)


def odometry_pose(msg: Any) -> tuple[float, float, float]:
    """Return the planar pose (x, y, yaw) of an Odometry."""
    if type(msg) is Encoded:
        x, y, yaw = msg[2][:3]
        return x, y, yaw
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return float(p.x), float(p.y), yaw
