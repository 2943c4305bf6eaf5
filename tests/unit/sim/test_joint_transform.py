from __future__ import annotations

import math

import numpy as np
import pytest

from twin.core.geometry import Pose, matrix_from_pose, pose_from_matrix, quat_from_rpy
from twin.robot.nodes import _JointTransform


def rotation_about(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    x, y, z = np.asarray(axis) / np.linalg.norm(axis)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    out = np.eye(4)
    out[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    return out


@pytest.mark.parametrize("angle", [0.0, 0.7, -2.5, 12.0])
def test_wheel_joint_pose_equals_the_matrix_product(angle: float) -> None:
    T_parent = matrix_from_pose(Pose(0.0, 0.144, 0.023, -1.57, 0.0, 0.0))
    axis = (0.0, 0.0, 1.0)
    pose = _JointTransform(T_parent, axis).at(angle)
    expected = pose_from_matrix(T_parent @ rotation_about(axis, angle))
    q = np.array(pose[3:])
    q_expected = np.array(quat_from_rpy(expected.roll_rad, expected.pitch_rad, expected.yaw_rad))
    assert pose[:3] == pytest.approx(tuple(expected[:3]))
    assert min(np.abs(q - q_expected).max(), np.abs(q + q_expected).max()) < 1e-9
