"""The ground-truth trajectory generator the estimation tests and benchmarks drive with."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.robot.disturbances import SlipRegion, WheelSlip
from twin.robot.trajectory import DriveSegment, Trajectory, generate_trajectory

R, B = 0.033, 0.287


def test_a_straight_drive_follows_the_wheels_and_respects_the_acceleration_limit() -> None:
    traj = generate_trajectory((DriveSegment(5.0, 0.2),), wheel_radius_m=R, wheel_separation_m=B)
    assert traj.duration_s == pytest.approx(5.0)
    # Ramp 0.2 s at 1 m/s² (0.02 m), then 4.8 s at 0.2 m/s.
    assert traj.x_m[-1] == pytest.approx(0.02 + 0.2 * 4.8, abs=1e-6)
    assert np.allclose(traj.y_m, 0.0) and np.allclose(traj.yaw_rad, 0.0)
    assert traj.wheel_left_rad[-1] * R == pytest.approx(traj.x_m[-1], abs=1e-9)
    assert np.abs(traj.accel_x_mps2).max() <= 1.0 + 1e-9
    assert traj.v_mps[-1] == pytest.approx(0.2)


def test_a_spin_turns_in_place_by_the_integral_of_the_yaw_rate() -> None:
    traj = generate_trajectory((DriveSegment(3.0, 0.0, 1.0), DriveSegment(1.0)), wheel_radius_m=R, wheel_separation_m=B)
    assert np.abs(traj.x_m).max() < 1e-12 and np.abs(traj.y_m).max() < 1e-12
    yaw = np.concatenate(([0.0], np.cumsum(0.5 * (traj.yaw_rate_radps[1:] + traj.yaw_rate_radps[:-1]) * 1e-3)))
    assert traj.yaw_rad[-1] == pytest.approx(yaw[-1])
    # The ramp lost at spin-up (1 m/s² of rim speed) is made up at spin-down, in the stop that follows.
    assert traj.yaw_rad[-1] == pytest.approx(3.0, abs=1e-9)
    assert traj.yaw_rate_radps[-1] == 0.0


def test_an_arc_has_centripetal_acceleration_v_times_w() -> None:
    traj = generate_trajectory((DriveSegment(8.0, 0.15, 0.3),))
    assert np.allclose(traj.accel_y_mps2, traj.v_mps * traj.yaw_rate_radps)
    radius = 0.15 / 0.3
    tail = slice(len(traj.t_ns) // 2, None)
    cx = traj.x_m[tail] - radius * np.sin(traj.yaw_rad[tail])
    cy = traj.y_m[tail] + radius * np.cos(traj.yaw_rad[tail])
    assert np.ptp(cx) < 1e-6 and np.ptp(cy) < 1e-6  # a circle of radius v / w


def test_uniform_slip_moves_the_chassis_less_than_the_wheels_say() -> None:
    straight = (DriveSegment(10.0, 0.2),)
    free = generate_trajectory(straight)
    slipping = generate_trajectory(straight, slip=WheelSlip(left_fraction=0.1, right_fraction=0.1))
    assert slipping.wheel_left_rad[-1] == free.wheel_left_rad[-1]
    assert slipping.x_m[-1] == pytest.approx(0.9 * free.x_m[-1])


def test_slip_on_one_wheel_inside_a_region_turns_the_robot_there_only() -> None:
    region = SlipRegion.rectangle(
        x_min_m=1.0, y_min_m=-1.0, x_max_m=2.0, y_max_m=1.0, left_fraction=0.2, right_fraction=0.0
    )
    traj = generate_trajectory((DriveSegment(15.0, 0.2),), slip=WheelSlip(regions=(region,)))
    before = traj.x_m < 1.0
    assert np.allclose(traj.yaw_rad[before], 0.0)
    turning = traj.yaw_rate_radps[np.argmax(traj.x_m > 1.2)]
    assert turning == pytest.approx(0.2 * 0.2 / B, rel=1e-3)  # left wheel loses 20 % of 0.2 m/s
    assert traj.yaw_rad[-1] > 0.5


def test_publishers_fire_on_the_first_step_at_or_after_each_period() -> None:
    traj: Trajectory = generate_trajectory((DriveSegment(1.0),))
    idx = traj.indices_at_rate(30.0)
    assert idx[:4].tolist() == [0, 34, 67, 100]
    assert len(traj.indices_at_rate(200.0)) == 201


def test_segments_must_not_have_negative_durations() -> None:
    with pytest.raises(ValueError, match="durations"):
        generate_trajectory((DriveSegment(-1.0),))
    assert math.isfinite(generate_trajectory(()).distance_m)
