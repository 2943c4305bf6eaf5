"""The FMU drivetrain: motor fidelity against the datasheets and the linear model, the PI design,
vendor FMUs through a mapping, and FMU errors mid-run."""

from __future__ import annotations

import math
from pathlib import Path

import control
import pytest

from tests.unit.cosim.helpers import acme
from twin.core.errors import ConfigError, FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import load_mapping
from twin.robot.chassis import ChassisParams
from twin.robot.drive_control import MotorConstants, design_speed_pi, motor_transfer_function
from twin.robot.fmu_drive import CommandLimits, FmuDrive, MotorModel
from twin.robot.fmu_drivetrain import FmuDrivetrain, wheel_setpoints
from twin.robot.step_response import fmu_step_response

REPO = Path(__file__).resolve().parents[3]
RPM = 2 * math.pi / 60
# Datasheet at 12 V (TB3_FACTS.md §3.1): no-load speed, stall current.
DATASHEET = {"xm430_w210": (77.0 * RPM, 2.3), "xl430_w250": (61.0 * RPM, 1.4)}
MS = 1_000_000
# The stand-in vendor FMU's linear model, by its own parameter names (it has no inductance).
ACME_MOTOR = MotorModel(
    resistance_ohm="Rw",
    inductance_h=1e-6,
    torque_constant_nm_per_a="k_m",
    back_emf_vs_per_rad="k_m",
    rotor_inertia_kgm2="J_total",
    rotor_friction_nms_per_rad="d_visc",
    gear_ratio=1.0,
    load_inertia_kgm2=0.0,
)


@pytest.mark.parametrize("step_ms", [1.0, 5.0])
@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("motor", ["xm430_w210", "xl430_w250"])
def test_no_load_step_matches_the_linear_model_within_1_percent(motor: str, fmi_version: int, step_ms: float) -> None:
    path = resolve_fmu(f"builtin:{motor}", fmi_version=fmi_version)  # type: ignore[arg-type]
    comparison, _ = fmu_step_response(path, voltage_v=12.0, step_s=step_ms * 1e-3, duration_s=0.3)
    assert comparison.rms_relative < 0.01
    assert comparison.fmu_speed_radps[1] > 0.0  # it moved within the first step


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("motor", ["xm430_w210", "xl430_w250"])
def test_steady_no_load_speed_is_within_5_percent_of_the_datasheet(motor: str, fmi_version: int) -> None:
    path = resolve_fmu(f"builtin:{motor}", fmi_version=fmi_version)  # type: ignore[arg-type]
    comparison, _ = fmu_step_response(path, voltage_v=12.0, step_s=0.001, duration_s=0.5)
    no_load, _ = DATASHEET[motor]
    assert comparison.fmu_speed_radps[-1] == pytest.approx(no_load, rel=0.05)


@pytest.mark.parametrize("motor,chassis", [("xm430_w210", "tb3_waffle"), ("xl430_w250", "tb3_burger")])
def test_stall_current_against_a_wall_is_within_5_percent_of_the_datasheet(motor: str, chassis: str) -> None:
    params = getattr(ChassisParams, chassis)()
    drive = FmuDrive(fmu=f"builtin:{motor}")
    with FmuDrivetrain(drive, params, step_ns=MS, contact=lambda x, y, yaw: x > 0.05) as dt:
        dt.set_cmd_vel(0.2, 0.0)
        dt.advance(1500)
        state = dt.wheel_state()
    _, stall = DATASHEET[motor]
    assert state.current_a[0] == pytest.approx(stall, rel=0.05)
    assert state.current_a[1] == pytest.approx(stall, rel=0.05)
    assert abs(state.speed_radps[0]) < 0.01


def test_pi_design_meets_its_targets_by_python_control() -> None:
    info_path = resolve_fmu("builtin:xm430_w210")
    with FmuDrivetrain(FmuDrive(fmu="builtin:xm430_w210"), ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        loop, motor = dt.speed_loop, dt.motor
    assert loop is not None and motor is not None and info_path.exists()
    assert loop.phase_margin_deg == pytest.approx(60.0, abs=1.0)
    assert loop.crossover_hz == pytest.approx(15.0, rel=0.02)
    assert loop.gain_margin_db > 6.0
    assert 0.0 < loop.rise_time_s < 0.05  # closed-loop step, python-control's step_info
    # Independent check of the plant: its DC gain is the no-load speed per volt.
    assert control.dcgain(motor_transfer_function(motor)) * 12.0 == pytest.approx(77.0 * RPM, rel=0.01)


def test_unreachable_design_target_is_a_config_error() -> None:
    motor = MotorConstants(
        resistance_ohm=5.2,
        inductance_h=0.01,
        torque_constant_nm_per_a=0.006,
        back_emf_vs_per_rad=0.0067,
        rotor_inertia_kgm2=1e-7,
        rotor_friction_nms_per_rad=0.0,
        gear_ratio=212.6,
    )
    with pytest.raises(ConfigError, match=r"lower bandwidth_hz or phase_margin_deg"):
        design_speed_pi(motor, crossover_hz=2000.0, phase_margin_deg=80.0, step_s=0.001)


@pytest.mark.parametrize("profile,fmu", [("voltage", "xm430_w210"), ("velocity-servo", "xm430_w210_servo")])
def test_robot_follows_cmd_vel_in_both_profiles(profile: str, fmu: str) -> None:
    drive = FmuDrive(fmu=f"builtin:{fmu}", profile=profile)  # type: ignore[arg-type]
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.15, 0.5)
        dt.advance(2000)
        state = dt.chassis_state()
    assert state.v_mps == pytest.approx(0.15, rel=0.01)
    assert state.yaw_rate_radps == pytest.approx(0.5, rel=0.01)
    assert state.ay_mps2 == pytest.approx(0.075, rel=0.02)


def test_vendor_fmu_with_other_names_and_units_drives_through_the_mapping() -> None:
    drive = FmuDrive(
        fmu_file=acme(),
        mapping=REPO / "fmus" / "maps" / "acme_drive.yaml",
        motor=ACME_MOTOR,
    )
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.15, 0.0)
        dt.advance(2000)
        chassis, wheels = dt.chassis_state(), dt.wheel_state()
    target = 0.15 / 0.033
    assert wheels.speed_radps[0] == pytest.approx(target, rel=0.01)  # rpm converted to rad/s
    assert wheels.angle_rad[0] == pytest.approx(chassis.x_m / 0.033, rel=0.01)  # deg converted to rad
    assert 0.0 < wheels.current_a[0] < 1.0  # mA converted to A
    assert chassis.x_m == pytest.approx(0.15 * 2.0, rel=0.1)


@pytest.mark.parametrize("api", ["native", "lowlevel"])
def test_fmu_error_mid_run_raises_fmu_error_naming_time_and_status(api: str) -> None:
    mapping = load_mapping(REPO / "fmus" / "maps" / "acme_drive.yaml")
    drive = FmuDrive(
        fmu_file=acme(fmi_version=3),
        profile="velocity-servo",
        mapping=type(mapping)(roles=mapping.roles, parameters={"fault_time": 0.25}),
        motor=None,
        wheel_inertia_kgm2=0.004,
    )
    # The acme FMU has no speed setpoint: the servo profile must be refused before any run...
    with pytest.raises(FmuError, match=r"missing required role\(s\) speed_setpoint"):
        FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS)
    # ...and in the voltage profile it runs until its fault, in the compiled loop as in Python.
    drive = FmuDrive(
        fmu_file=acme(fmi_version=3),
        mapping=type(mapping)(roles=mapping.roles, parameters={"fault_time": 0.25}),
        motor=ACME_MOTOR,
        api=api,  # type: ignore[arg-type]
    )
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        assert dt.native == (api == "native")
        dt.set_cmd_vel(0.1, 0.0)
        with pytest.raises(FmuError) as err:
            for _ in range(100):
                dt.advance(10)
        t_ns = dt.t_ns
    assert "instance 'left' failed at t = 0.250000 s: fmi3DoStep returned Error" in str(err.value)
    assert t_ns == 250 * MS


def test_servo_drive_without_motor_model_probes_the_wheel_inertia() -> None:
    drive = FmuDrive(fmu="builtin:xl430_w250_servo", profile="velocity-servo", motor=None)
    with FmuDrivetrain(drive, ChassisParams.tb3_burger(), step_ns=MS) as dt:
        probed = dt.wheel_inertia_kgm2
    expected = 1e-7 * 258.5**2 + 2.07e-5
    assert probed == pytest.approx(expected, rel=0.5)


def test_firmware_clamps_limit_command_and_wheels() -> None:
    limits = CommandLimits(max_linear_mps=0.26, max_angular_radps=1.82, max_wheel_speed_radps=8.08)
    left, right = wheel_setpoints(1.0, 0.0, ChassisParams.tb3_waffle(), limits)
    assert left == right == pytest.approx(0.26 / 0.033 if 0.26 / 0.033 < 8.08 else 8.08)
    left, right = wheel_setpoints(0.26, 1.82, ChassisParams.tb3_waffle(), limits)
    assert right == pytest.approx(8.08)
    assert left == pytest.approx((0.26 - 1.82 * 0.287 / 2) / 0.033)


@pytest.mark.parametrize(("v", "w"), [(1e308, 0.0), (0.0, 1e308), (1e300, -1e308), (-1e308, 1e-3)])
def test_a_finite_command_too_large_for_the_arithmetic_keeps_its_direction(v: float, w: float) -> None:
    # 1e308 m/s overflowed the wheel speeds to inf, the supply cap's scale made NaN of them, and the
    # drive ran both wheels backwards: the command keeps its curvature and direction at any size
    chassis = ChassisParams.tb3_waffle()
    left, right = wheel_setpoints(v, w, chassis, CommandLimits())
    assert math.isfinite(left) and math.isfinite(right) and max(abs(left), abs(right)) > 1e9
    # the same curvature as the command scaled into range
    small_l, small_r = wheel_setpoints(v / 1e308, w / 1e308, chassis, CommandLimits())
    assert left / max(abs(left), abs(right)) == pytest.approx(small_l / max(abs(small_l), abs(small_r)))
    assert right / max(abs(left), abs(right)) == pytest.approx(small_r / max(abs(small_l), abs(small_r)))
    with FmuDrivetrain(FmuDrive(), chassis, step_ns=MS) as dt:
        dt.set_cmd_vel(v, w)
        target = (dt._target_left, dt._target_right)
    cap = dt.supply_speed_radps
    assert cap is not None and all(math.isfinite(t) and abs(t) <= cap * (1 + 1e-12) for t in target)
    assert math.copysign(1.0, target[0]) == math.copysign(1.0, left) and math.copysign(1.0, target[1]) == (
        math.copysign(1.0, right)
    )


def test_communication_step_must_be_a_multiple_of_the_physics_step() -> None:
    with pytest.raises(ConfigError, match=r"whole multiple of the physics step"):
        FmuDrivetrain(FmuDrive(communication_step_s=0.0015), ChassisParams.tb3_waffle(), step_ns=MS)


def test_coarser_communication_step_advances_the_same_time() -> None:
    with FmuDrivetrain(FmuDrive(communication_step_s=0.005), ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.2, 0.0)
        for _ in range(400):
            dt.advance(3)
        assert dt.t_ns == 1200 * MS
        assert dt.chassis_state().v_mps == pytest.approx(0.2, rel=0.01)


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_compiled_and_python_stepping_give_the_same_run(fmi_version: int) -> None:
    runs = []
    for api in ("lowlevel", "convenience"):
        drive = FmuDrive(fmi_version=fmi_version, api=api)  # type: ignore[arg-type]
        with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
            assert dt._group.compiled == (api == "lowlevel")
            dt.set_cmd_vel(0.1, 0.4)
            for _ in range(100):
                dt.advance(5)
            runs.append((dt.chassis_state(), dt.wheel_state(), dt.t_ns))
    assert runs[0] == runs[1]
    assert runs[0][2] == 500 * MS
