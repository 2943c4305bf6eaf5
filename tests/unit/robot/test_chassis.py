"""The chassis: kinematics, load torques back to the wheels, contact stalls, slip."""

from __future__ import annotations

import math

import pytest

from twin.robot.chassis import Chassis, ChassisParams, SlipModel, SlipRegion
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain

MS = 1_000_000
WAFFLE = ChassisParams.tb3_waffle()


def _run(chassis: Chassis, w_left: float, w_right: float, steps: int) -> None:
    for _ in range(steps):
        chassis.update(w_left, w_right)


def test_equal_wheel_speeds_drive_straight_along_the_heading() -> None:
    chassis = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3, pose=(1.0, 2.0, math.pi / 2))
    _run(chassis, 5.0, 5.0, 1000)
    s = chassis.state()
    assert s.v_mps == pytest.approx(5.0 * 0.033)
    assert (s.x_m, s.y_m) == pytest.approx((1.0, 2.0 + 0.165), abs=1e-9)
    assert s.yaw_rad == pytest.approx(math.pi / 2)


def test_opposite_wheel_speeds_turn_in_place_at_r_dw_over_b() -> None:
    chassis = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3)
    _run(chassis, -2.0, 2.0, 500)
    s = chassis.state()
    assert s.yaw_rate_radps == pytest.approx(0.033 * 4.0 / 0.287)
    assert (s.x_m, s.y_m) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_accelerating_chassis_loads_both_wheels_with_its_inertia() -> None:
    chassis = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3)
    for k in range(100):  # wheels accelerate at 10 rad/s² together
        chassis.update(0.01 * k, 0.01 * k)
    assert chassis.load_left_nm == pytest.approx(chassis.load_right_nm)
    assert chassis.load_left_nm > 0.0  # the chassis resists the acceleration
    assert chassis.state().ax_mps2 == pytest.approx(10.0 * 0.033, rel=1e-6)


def test_rolling_resistance_opposes_steady_motion() -> None:
    rolling = ChassisParams(
        wheel_radius_m=0.033, wheel_separation_m=0.287, mass_kg=1.8, yaw_inertia_kgm2=0.0146, rolling_resistance=0.02
    )
    chassis = Chassis(rolling, step_s=0.001, wheel_inertia_kgm2=4.5e-3)
    _run(chassis, 3.0, 3.0, 200)
    expected = 0.02 * 1.8 * 9.81 / 2 * 0.033
    assert chassis.load_left_nm == pytest.approx(expected, rel=1e-3)


def test_slip_region_shortens_the_distance_travelled() -> None:
    slip = SlipModel(regions=(SlipRegion(x_min_m=-1.0, x_max_m=1.0, y_min_m=-1.0, y_max_m=1.0, slip=0.5),))
    chassis = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3, slip=slip)
    _run(chassis, 5.0, 5.0, 1000)
    assert chassis.state().x_m == pytest.approx(0.5 * 0.165, rel=1e-6)


def test_wall_blocks_translation_but_turning_stays_free() -> None:
    chassis = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3, contact=lambda x, y, yaw: x > 0.01)
    _run(chassis, 5.0, 5.0, 200)
    assert chassis.state().x_m <= 0.01
    assert chassis.state().blocked
    _run(chassis, 0.0, 4.0, 300)  # turning left from the wall: rotation free, translation refused
    s = chassis.state()
    assert s.yaw_rad > 0.1
    assert s.x_m <= 0.01


def test_drivetrain_stalls_against_a_wall_with_rising_current() -> None:
    with FmuDrivetrain(FmuDrive(), WAFFLE, step_ns=MS, contact=lambda x, y, yaw: x > 0.1) as dt:
        dt.set_cmd_vel(0.2, 0.0)
        dt.advance(400)
        free = dt.wheel_state().current_a[0]
        assert not dt.chassis_state().blocked
        currents = []
        for _ in range(10):
            dt.advance(50)
            currents.append(dt.wheel_state().current_a[0])
        state, wheels = dt.chassis_state(), dt.wheel_state()
        assert state.blocked and state.x_m <= 0.1
        assert state.v_mps == 0.0
        assert max(abs(w) for w in wheels.speed_radps) < 0.01
        assert currents[-1] > 10 * free  # from cruising current to stall current
        assert currents[-1] == pytest.approx(12.0 / 5.217391, rel=0.02)  # V/R
        assert wheels.voltage_v[0] == pytest.approx(12.0)  # the PI saturated
        # Reversing frees the robot.
        dt.set_cmd_vel(-0.1, 0.0)
        dt.advance(500)
        assert not dt.chassis_state().blocked
        assert dt.chassis_state().x_m < 0.09


def test_chassis_handed_over_mid_run_continues_the_same() -> None:
    slip = SlipModel(slip=0.1)
    contact = lambda x, y, yaw: x > 0.05  # noqa: E731
    whole = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3, contact=contact, slip=slip)
    for _ in range(1000):  # into the wall, handed over while blocked (with holding torques)
        whole.update(5.0, 4.0)
        if whole.state().blocked:
            break
    assert whole.state().blocked
    other = Chassis(WAFFLE, step_s=0.001, wheel_inertia_kgm2=4.5e-3, contact=contact, slip=slip)
    handed = whole.dynamics()
    other.set_dynamics(handed)
    for k in range(400):  # slowing, then reversing
        w_left, w_right = 5.0 - 0.02 * k, 4.0 - 0.02 * k
        whole.update(w_left, w_right)
        other.update(w_left, w_right)
    assert other.dynamics() == whole.dynamics()
    assert whole.dynamics() != handed  # it went on (turning along the wall), and the other the same
