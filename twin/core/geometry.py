"""SE(2)/SE(3) helpers: poses as 4x4 homogeneous matrices, quaternions as (x, y, z, w).

Rotations follow REP-103 and SDF: fixed-axis roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Mat4",
    "Pose",
    "matrix_from_pose",
    "pose_from_matrix",
    "quat_from_rpy",
    "quat_from_yaw",
    "rpy_from_matrix",
    "rpy_from_quat",
    "wrap_angle",
    "yaw_from_quat",
]

Mat4 = NDArray[np.float64]


class Pose(NamedTuple):
    """A 6-DoF pose: translation in metres and fixed-axis roll, pitch, yaw in radians."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _rotation_from_rpy(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_from_pose(pose: Pose) -> Mat4:
    """Return the 4x4 homogeneous matrix of a pose."""
    out = np.eye(4)
    out[:3, :3] = _rotation_from_rpy(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
    out[:3, 3] = (pose.x_m, pose.y_m, pose.z_m)
    return out


def rpy_from_matrix(rot: NDArray[np.float64]) -> tuple[float, float, float]:
    """Return fixed-axis (roll, pitch, yaw) of a rotation matrix (3x3 or the top-left of a 4x4)."""
    r = rot[:3, :3]
    sp = -float(r[2, 0])
    sp = max(-1.0, min(1.0, sp))
    pitch = math.asin(sp)
    if abs(sp) < 1.0 - 1e-12:
        roll = math.atan2(float(r[2, 1]), float(r[2, 2]))
        yaw = math.atan2(float(r[1, 0]), float(r[0, 0]))
    else:  # gimbal lock: put all of the remaining rotation into yaw
        roll = 0.0
        yaw = math.atan2(-float(r[0, 1]), float(r[1, 1]))
    return roll, pitch, yaw


def pose_from_matrix(mat: Mat4) -> Pose:
    """Return the pose of a 4x4 homogeneous matrix."""
    roll, pitch, yaw = rpy_from_matrix(mat)
    return Pose(float(mat[0, 3]), float(mat[1, 3]), float(mat[2, 3]), roll, pitch, yaw)


def quat_from_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> tuple[float, float, float, float]:
    """Return the unit quaternion (x, y, z, w) of fixed-axis roll, pitch, yaw."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def quat_from_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """Return the unit quaternion (x, y, z, w) of a rotation about z."""
    return (0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2))


def rpy_from_quat(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Return fixed-axis (roll, pitch, yaw) of a quaternion (need not be normalised)."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def yaw_from_quat(x: float, y: float, z: float, w: float) -> float:
    """Return the yaw of a quaternion (x, y, z, w)."""
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
