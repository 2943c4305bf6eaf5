from __future__ import annotations

import math

import pytest

from twin.robot.kinematic import KinematicDrive, KinematicParams

WAFFLE = KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=1.0, step_s=0.001)


def test_straight_line_ramps_at_the_wheel_acceleration_limit_then_cruises() -> None:
    drive = KinematicDrive(WAFFLE)
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(100)  # 0.1 s at 1 m/s^2 reaches 0.1 m/s
    assert drive.state.v_mps == pytest.approx(0.1)
    drive.advance(1900)  # reaches 0.2 m/s at t = 0.2 s, then cruises
    # distance: 0.02 m of ramp (0.2 s at mean 0.1 m/s) + 1.8 s at 0.2 m/s
    assert drive.state.x_m == pytest.approx(0.02 + 0.36, abs=2e-4)
    assert drive.state.y_m == pytest.approx(0.0)
    assert drive.wheel_speed_radps == pytest.approx([0.2 / 0.033] * 2)


def test_arc_matches_the_closed_form_circle() -> None:
    drive = KinematicDrive(KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=1e9, step_s=0.001))
    drive.set_cmd_vel(0.2, 0.5)
    drive.advance(int(math.pi / 0.5 * 1000))  # half a turn of radius 0.4 m
    assert drive.state.x_m == pytest.approx(0.0, abs=1e-3)
    assert drive.state.y_m == pytest.approx(0.8, abs=1e-3)
    assert abs(drive.state.yaw_rad) == pytest.approx(math.pi, abs=1e-3)


def test_wheel_angles_integrate_wheel_travel() -> None:
    drive = KinematicDrive(KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=1e9, step_s=0.001))
    drive.set_cmd_vel(0.0, 1.0)  # spin in place: wheels turn opposite ways
    drive.advance(1000)
    expected = 1.0 * 0.287 / 2 / 0.033
    assert drive.wheel_angle_rad == pytest.approx([-expected, expected])


def test_stops_at_a_wall_without_penetrating_and_counts_one_contact() -> None:
    wall_x = 0.5
    drive = KinematicDrive(WAFFLE, clearance=lambda x, y, yaw: wall_x - (x + 0.2))
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(5000)
    assert drive.state.in_contact
    assert drive.contacts == 1
    assert drive.state.v_mps == 0.0
    assert 0.3 - 0.2 * 0.001 <= drive.state.x_m <= 0.3
    # Backing away works.
    drive.set_cmd_vel(-0.1, 0.0)
    drive.advance(1000)
    assert not drive.state.in_contact
    assert drive.state.x_m < 0.29


def test_clearance_budget_skips_checks_far_from_walls() -> None:
    calls = 0

    def clearance(x: float, y: float, yaw: float) -> float:
        nonlocal calls
        calls += 1
        return 10.0 - x

    drive = KinematicDrive(WAFFLE, clearance=clearance)
    drive.set_cmd_vel(0.2, 0.0)
    for _ in range(100):
        drive.advance(10)
    assert calls < 20
