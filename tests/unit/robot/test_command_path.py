"""The command path Gazebo and the TB3 have: the diff-drive plugin's wheel acceleration limit before
the motor servo, and commands beyond the motors' reach at the supply voltage clamped and reported."""

from __future__ import annotations

import logging
import math

import pytest

from tests.unit.robot.gazebo_replay import FIXTURES, STEP_NS, WAFFLE_BAG, read_gazebo_run, replay
from twin.robot.chassis import ChassisParams
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain
from twin.robot.kinematic import KinematicDrivetrain, KinematicParams
from twin.world import load_robot

MODELS = FIXTURES / "gazebo_classic" / "models"


def _waffle() -> tuple[ChassisParams, float | None]:
    robot = load_robot(MODELS / "turtlebot3_waffle" / "model.sdf", model_path=(MODELS,))
    assert robot.drive is not None
    chassis = ChassisParams(
        wheel_radius_m=robot.drive.wheel_radius_m,
        wheel_separation_m=robot.drive.wheel_separation_m,
        mass_kg=1.8,
        yaw_inertia_kgm2=0.0146,
    )
    return chassis, robot.drive.max_wheel_acceleration_mps2


@pytest.mark.parametrize("api", ["native", "lowlevel"])
def test_fmu_drive_replaying_a_gazebo_waffle_bag_stays_within_5_cm_and_2_degrees(api: str) -> None:
    run = read_gazebo_run(WAFFLE_BAG)
    chassis, plugin_accel = _waffle()
    assert plugin_accel == 1.0  # the Waffle SDF's gazebo_ros_diff_drive max_wheel_acceleration
    drive = FmuDrive(fmu="builtin:xm430_w210_servo", profile="velocity-servo", api=api)  # type: ignore[arg-type]
    pose = run.odom[0][1:]
    with FmuDrivetrain(
        drive, chassis, step_ns=STEP_NS, pose=pose, plugin_wheel_acceleration_mps2=plugin_accel
    ) as fmu_drive:
        at_25, at_end = replay(run, fmu_drive, (25.0, math.inf))
    assert at_25.t_s == pytest.approx(25.0, abs=0.05)
    assert at_end.t_s > 29.0
    for err in (at_25, at_end):
        assert err.position_m <= 0.05
        assert err.yaw_deg <= 2.0
    # The kinematic drive, for comparison, is as close.
    ideal = KinematicDrivetrain(
        KinematicParams(wheel_radius_m=0.033, wheel_separation_m=0.287, max_wheel_acceleration_mps2=1.0),
        step_ns=STEP_NS,
        pose=pose,
    )
    for err in replay(run, ideal, (25.0, math.inf)):
        assert err.position_m <= 0.05 and err.yaw_deg <= 2.0


def test_without_the_wheel_acceleration_limit_the_fmu_drive_leaves_gazebo_s_path() -> None:
    run = read_gazebo_run(WAFFLE_BAG)
    chassis, _ = _waffle()
    drive = FmuDrive(fmu="builtin:xm430_w210_servo", profile="velocity-servo", max_wheel_acceleration_mps2=0.0)
    with FmuDrivetrain(drive, chassis, step_ns=STEP_NS, pose=run.odom[0][1:], plugin_wheel_acceleration_mps2=1.0) as d:
        assert d.max_wheel_acceleration_mps2 == math.inf  # 0 in the scenario: none, whatever the SDF says
        (at_end,) = replay(run, d, (math.inf,))
    assert at_end.position_m > 0.05  # what issue 14 measured before the limit (0.11 m)


@pytest.mark.parametrize("api", ["native", "lowlevel"])
def test_setpoints_ramp_at_the_wheel_acceleration_limit(api: str) -> None:
    drive = FmuDrive(fmu="builtin:xm430_w210_servo", profile="velocity-servo", api=api)  # type: ignore[arg-type]
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=STEP_NS, plugin_wheel_acceleration_mps2=1.0) as d:
        d.set_cmd_vel(0.2, 0.0)
        d.advance(100)  # 0.1 s at 1 m/s^2: the rim setpoint has reached 0.1 m/s, half the command
        v_100 = d.chassis_state().v_mps
        d.advance(400)
        v_500 = d.chassis_state().v_mps
    assert 0.05 < v_100 < 0.1  # the servo follows the ramp with its 20 ms lag
    assert v_500 == pytest.approx(0.2, rel=0.01)


def test_burger_commanded_beyond_its_motors_is_clamped_and_warned_once(caplog: pytest.LogCaptureFixture) -> None:
    drive = FmuDrive(fmu="builtin:xl430_w250_servo", profile="velocity-servo")
    with (
        caplog.at_level(logging.WARNING, logger="twin"),
        FmuDrivetrain(drive, ChassisParams.tb3_burger(), step_ns=STEP_NS) as d,
    ):
        cap = d.supply_speed_radps
        assert cap is not None and 0.205 < cap * 0.033 < 0.212  # XL430: 61 rpm no-load at 12 V
        for k in range(20):
            d.set_cmd_vel(0.25 + 0.0025 * k, 0.0)  # 0.25 to 0.30 m/s, as the Burger bags command
            d.advance(100)
        v = d.chassis_state().v_mps
        assert d.saturation.count == 20 and d.saturation.active
        assert d.command_radps[0] == pytest.approx((0.25 + 0.0025 * 19) / 0.033)
        d.set_cmd_vel(0.1, 0.0)
        assert not d.saturation.active
        summary = d.saturation.describe()
    assert v == pytest.approx(cap * 0.033, rel=0.01)  # it runs at the motors' reach, not at 0.3 m/s
    warnings = [r for r in caplog.records if "clamped" in r.getMessage()]
    assert len(warnings) == 1
    assert "xl430_w250_servo reaches 8.0" not in warnings[0].getMessage()
    assert "xl430_w250_servo reaches 6.3" in warnings[0].getMessage()
    assert "20 cmd_vel clamped" in summary


def test_a_turn_beyond_the_motors_keeps_its_curvature() -> None:
    drive = FmuDrive(fmu="builtin:xl430_w250_servo", profile="velocity-servo")
    with FmuDrivetrain(drive, ChassisParams.tb3_burger(), step_ns=STEP_NS) as d:
        d.set_cmd_vel(0.3, 1.5)
        d.advance(1000)
        s = d.chassis_state()
    assert s.yaw_rate_radps / s.v_mps == pytest.approx(1.5 / 0.3, rel=0.01)
