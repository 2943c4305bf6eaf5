from __future__ import annotations

import itertools
import math

import pytest

from twin.robot.drivetrain import Drivetrain
from twin.robot.kinematic import KinematicDrivetrain, KinematicParams

STEP_NS = 1_000_000
WAFFLE = KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=1.0)
UNLIMITED = KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=math.inf)


def test_implements_the_drivetrain_protocol() -> None:
    drive: Drivetrain = KinematicDrivetrain(WAFFLE, step_ns=STEP_NS)
    assert drive.step_ns == STEP_NS


def test_straight_line_ramps_at_the_wheel_acceleration_limit_then_cruises() -> None:
    drive = KinematicDrivetrain(WAFFLE, step_ns=STEP_NS)
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(100)  # 0.1 s at 1 m/s^2 reaches 0.1 m/s
    assert drive.chassis_state().v_mps == pytest.approx(0.1)
    assert drive.chassis_state().ax_mps2 == pytest.approx(1.0)
    drive.advance(1900)  # reaches 0.2 m/s at t = 0.2 s, then cruises
    state = drive.chassis_state()
    # distance: 0.02 m of ramp (0.2 s at mean 0.1 m/s) + 1.8 s at 0.2 m/s
    assert state.x_m == pytest.approx(0.02 + 0.36, abs=2e-4)
    assert state.y_m == pytest.approx(0.0)
    assert drive.wheel_state().speed_radps == pytest.approx((0.2 / 0.033, 0.2 / 0.033))


def test_arc_matches_the_closed_form_circle() -> None:
    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS)
    drive.set_cmd_vel(0.2, 0.5)
    drive.advance(round(math.pi / 0.5 * 1000))  # half a turn of radius 0.4 m
    state = drive.chassis_state()
    assert state.x_m == pytest.approx(0.0, abs=1e-3)
    assert state.y_m == pytest.approx(0.8, abs=1e-3)
    assert abs(state.yaw_rad) == pytest.approx(math.pi, abs=1e-3)
    assert state.ay_mps2 == pytest.approx(0.1)  # centripetal v * w


def test_wheel_angles_integrate_wheel_travel() -> None:
    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS)
    drive.set_cmd_vel(0.0, 1.0)  # spin in place: wheels turn opposite ways
    drive.advance(1000)
    expected = 1.0 * 0.287 / 2 / 0.033
    assert drive.wheel_state().angle_rad == pytest.approx((-expected, expected))


def test_stops_at_a_wall_without_penetrating_and_backs_away() -> None:
    wall_x = 0.5
    drive = KinematicDrivetrain(WAFFLE, step_ns=STEP_NS, contact=lambda x, y, yaw: x + 0.2 >= wall_x)
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(5000)
    state = drive.chassis_state()
    assert state.blocked
    assert state.v_mps == 0.0
    assert 0.3 - 0.2 * 0.001 <= state.x_m < 0.3
    assert drive.wheel_state().speed_radps == (0.0, 0.0)
    drive.set_cmd_vel(-0.1, 0.0)
    drive.advance(1000)
    assert not drive.chassis_state().blocked
    assert drive.chassis_state().x_m < 0.29


def test_steady_motion_checks_contact_in_short_pieces() -> None:
    checked: list[float] = []

    def contact(x: float, y: float, yaw: float) -> bool:
        checked.append(x)
        return False

    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS, contact=contact)
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(1000)
    gaps = [b - a for a, b in itertools.pairwise(checked)]
    assert max(gaps) <= 0.002 + 1e-12
    assert len(checked) < 1000  # not every step


def test_known_free_distance_allows_long_pieces() -> None:
    calls = 0

    def contact(x: float, y: float, yaw: float) -> bool:
        nonlocal calls
        calls += 1
        return False

    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS, contact=contact, free_distance=lambda x, y, yaw: 1.0)
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(1000)
    assert calls <= 2  # the first step of the ramp, then one piece for the rest
    assert drive.chassis_state().x_m == pytest.approx(0.2)


def test_slip_moves_the_robot_less_than_the_wheels_turn() -> None:
    from twin.robot.disturbances import WheelSlip

    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS, slip=WheelSlip(left_fraction=0.1, right_fraction=0.1))
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(1000)
    assert drive.chassis_state().x_m == pytest.approx(0.18, abs=1e-4)
    assert drive.wheel_state().angle_rad[0] == pytest.approx(0.2 / 0.033, rel=1e-3)


def test_uneven_slip_turns_the_robot_although_the_wheels_turn_alike() -> None:
    from twin.robot.disturbances import SlipRegion, WheelSlip

    patch = SlipRegion.rectangle(x_min_m=-1, y_min_m=-1, x_max_m=1, y_max_m=1, left_fraction=0.3, right_fraction=0.0)
    drive = KinematicDrivetrain(UNLIMITED, step_ns=STEP_NS, slip=WheelSlip(regions=(patch,)))
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(1000)
    left, right = drive.wheel_state().angle_rad
    assert left == pytest.approx(right)
    assert drive.chassis_state().yaw_rad == pytest.approx(0.3 * 0.2 / 0.287, rel=1e-2)


def test_against_a_wall_the_robot_still_turns_and_backs_away() -> None:
    wall_x = 0.5
    # A footprint whose reach ahead grows with the yaw: turning from 0 to 1 rad stays clear of the wall.
    drive = KinematicDrivetrain(
        WAFFLE, step_ns=STEP_NS, contact=lambda x, y, yaw: x + 0.2 * math.cos(yaw) ** 2 >= wall_x
    )
    drive.set_cmd_vel(0.2, 0.0)
    drive.advance(3000)
    at_wall = drive.chassis_state()
    assert at_wall.blocked and at_wall.yaw_rad == 0.0
    drive.set_cmd_vel(0.2, 0.5)  # forward into the wall while turning: the turn is kept
    drive.advance(1000)
    turned = drive.chassis_state()
    assert turned.yaw_rad > 0.3  # the yaw does not freeze
    assert turned.x_m + 0.2 * math.cos(turned.yaw_rad) ** 2 < wall_x  # and the contact does not deepen
    left, right = drive.wheel_state().angle_rad
    assert right > left  # the wheels turned against each other
    drive.set_cmd_vel(-0.1, 0.0)
    drive.advance(1000)
    assert drive.chassis_state().x_m < turned.x_m - 0.05
