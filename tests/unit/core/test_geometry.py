from __future__ import annotations

import math

import numpy as np
import pytest

from twin.core.geometry import (
    Pose,
    matrix_from_pose,
    pose_from_matrix,
    quat_from_rpy,
    rpy_from_quat,
    wrap_angle,
    yaw_from_quat,
)


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.0), (0.3, -0.2, 2.5), (-1.57, 0.0, 0.0), (0.1, 1.2, -3.0)])
def test_quaternion_and_matrix_round_trip(rpy: tuple[float, float, float]) -> None:
    q = quat_from_rpy(*rpy)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert rpy_from_quat(*q) == pytest.approx(rpy, abs=1e-12)
    pose = Pose(1.0, -2.0, 0.5, *rpy)
    assert tuple(pose_from_matrix(matrix_from_pose(pose))) == pytest.approx(tuple(pose), abs=1e-12)


def test_matrix_composes_translation_then_rotation() -> None:
    parent = matrix_from_pose(Pose(1.0, 0.0, 0.0, yaw_rad=math.pi / 2))
    child = matrix_from_pose(Pose(1.0, 0.0, 0.0))
    world = parent @ child
    assert world[:3, 3] == pytest.approx([1.0, 1.0, 0.0])


def test_yaw_and_wrap() -> None:
    assert yaw_from_quat(*quat_from_rpy(0.0, 0.0, 3.0)) == pytest.approx(3.0)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(-0.5) == pytest.approx(-0.5)
