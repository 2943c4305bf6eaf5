"""`twin fmu check` strictness: arrays, one variable for two roles, a mapping naming a variable the FMU
lacks, the failure message; and an FMU without a torque output gives no effort (or current x Kt)."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import zipfile
from pathlib import Path
from types import MappingProxyType

import pytest

from tests.unit.cosim.helpers import acme
from twin.core.errors import FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import FmuMapping, Profile, RoleBinding, RoleMap, bind, check_contract, load_mapping
from twin.cosim.description import read_fmu_info
from twin.robot.chassis import ChassisParams
from twin.robot.fmu_drive import FmuDrive, MotorModel
from twin.robot.fmu_drivetrain import FmuDrivetrain

REPO = Path(__file__).resolve().parents[3]
ACME_MAP = REPO / "fmus" / "maps" / "acme_drive.yaml"


def test_an_array_variable_cannot_take_a_role() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210", fmi_version=3))
    variables = dict(info.variables)
    variables["wheel_speed"] = dataclasses.replace(variables["wheel_speed"], dimensions=1)
    report = check_contract(
        dataclasses.replace(info, variables=MappingProxyType(variables)), FmuMapping(), Profile.VOLTAGE
    )
    assert not report.ok
    assert report.missing == ("wheel_speed",)
    (role,) = [r for r in report.roles if r.role == "wheel_speed"]
    assert role.problem == "'wheel_speed' is an array (1-D), the role needs a scalar"


def test_two_roles_on_one_variable_are_refused() -> None:
    mapping = load_mapping(ACME_MAP)
    roles = dataclasses.replace(mapping.roles, wheel_angle=RoleBinding(name="n_out", unit="rpm"))
    report = check_contract(read_fmu_info(acme()), dataclasses.replace(mapping, roles=roles), Profile.VOLTAGE)
    assert not report.ok
    assert "roles.wheel_angle: 'n_out' is already bound to role wheel_speed; a variable serves one role" in (
        report.problems
    )


def test_a_mapping_naming_a_missing_variable_for_an_optional_role_is_a_problem() -> None:
    mapping = load_mapping(ACME_MAP)
    roles = dataclasses.replace(mapping.roles, current=RoleBinding(name="I_motor", unit="mA"))
    report = check_contract(read_fmu_info(acme()), dataclasses.replace(mapping, roles=roles), Profile.VOLTAGE)
    assert not report.ok and report.missing == ()
    assert any(p.startswith("roles.current: no variable 'I_motor'") for p in report.problems)


def test_cli_failure_without_missing_roles_names_the_problems_not_none(tmp_path: Path) -> None:
    bad = tmp_path / "map.yaml"
    bad.write_text(ACME_MAP.read_text().replace("current: {name: I_mA", "current: {name: I_motor"))
    result = subprocess.run(
        [sys.executable, "-m", "twin", "fmu", "check", str(acme()), "--map", str(bad)],
        capture_output=True, text=True, check=False, cwd=REPO,
    )  # fmt: skip
    assert result.returncode == 4
    assert "missing roles: none" not in result.stdout
    assert "does NOT satisfy the voltage contract; 1 problem(s) above" in result.stdout


def _acme_drive(roles: RoleMap) -> FmuDrive:
    mapping = load_mapping(ACME_MAP)
    return FmuDrive(
        fmu_file=acme(),
        mapping=dataclasses.replace(mapping, roles=roles),
        motor=MotorModel(
            resistance_ohm="Rw",
            inductance_h=1e-6,
            torque_constant_nm_per_a="k_m",
            back_emf_vs_per_rad="k_m",
            rotor_inertia_kgm2="J_total",
            rotor_friction_nms_per_rad="d_visc",
            gear_ratio=1.0,
            load_inertia_kgm2=0.0,
        ),
    )


def test_without_a_torque_output_the_effort_is_current_times_kt_or_none() -> None:
    roles = load_mapping(ACME_MAP).roles
    no_torque = dataclasses.replace(roles, motor_torque=None)  # binds by its own name, which the FMU lacks
    with FmuDrivetrain(_acme_drive(no_torque), ChassisParams.tb3_waffle(), step_ns=1_000_000) as dt:
        dt.set_cmd_vel(0.1, 0.0)
        dt.advance(200)
        ws = dt.wheel_state()
        assert dt.has_effort
        assert ws.effort_nm[0] == 1.3 * ws.current_a[0]  # k_m 1.3 N.m/A at the output, gear ratio 1
        assert math.isfinite(ws.effort_nm[0]) and ws.effort_nm[0] != 0.0
    no_current = dataclasses.replace(no_torque, current=None)
    with FmuDrivetrain(_acme_drive(no_current), ChassisParams.tb3_waffle(), step_ns=1_000_000) as dt:
        assert not dt.has_effort  # /joint_states then carries no effort, not NaN


def test_a_parameter_entry_naming_an_output_is_refused_by_the_check() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    report = check_contract(info, FmuMapping(parameters={"wheel_speed": 5.0}), Profile.VOLTAGE)
    assert not report.ok
    assert report.problems == (
        "parameters.wheel_speed: 'wheel_speed' is an output, not a parameter; the FMU computes it, it cannot be set",
    )


def test_a_parameter_entry_naming_an_input_points_to_start_values() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    report = check_contract(info, FmuMapping(parameters={"load_torque": 0.1}), Profile.VOLTAGE)
    assert report.problems == (
        "parameters.load_torque: 'load_torque' is an input, not a parameter; set it under start_values, "
        "or name one of the FMU's parameters",
    )
    assert check_contract(info, FmuMapping(start_values={"load_torque": 0.1}), Profile.VOLTAGE).ok


def test_a_start_value_for_a_computed_output_is_refused() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    report = check_contract(info, FmuMapping(start_values={"current": 1.0}), Profile.VOLTAGE)
    assert report.problems == (
        "start_values.current: 'current' is an output the FMU computes (it has no start value); it cannot be set",
    )


def test_role_problems_use_the_right_article() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    mapping = FmuMapping(roles=RoleMap(voltage="wheel_speed", wheel_speed="voltage"))
    problems = {r.role: r.problem for r in check_contract(info, mapping, Profile.VOLTAGE).roles}
    assert problems["voltage"] == "'wheel_speed' is an output, the role needs an input"
    assert problems["wheel_speed"] == "'voltage' is an input, the role needs an output"


def test_a_parameter_that_is_not_finite_is_refused() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    report = check_contract(info, FmuMapping(parameters={"R": math.nan}), Profile.VOLTAGE)
    assert report.problems == ("parameters.R: nan is not a finite number",)


def test_two_roles_sharing_one_value_reference_are_refused(tmp_path: Path) -> None:
    source = resolve_fmu("builtin:xm430_w210")
    aliased = tmp_path / "aliased.fmu"
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(aliased, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "modelDescription.xml":
                data = data.replace(b'name="load_torque" valueReference="2"', b'name="load_torque" valueReference="0"')
            dst.writestr(name, data)
    info = read_fmu_info(aliased)
    assert info.variables["load_torque"].value_reference == info.variables["voltage"].value_reference
    report = check_contract(info, FmuMapping(), Profile.VOLTAGE)
    assert not report.ok
    assert report.problems[0].startswith(
        "roles.load_torque: 'load_torque' shares value reference 0 with 'voltage' (role voltage)"
    )
    with pytest.raises(FmuError, match="shares value reference 0"):
        bind(info, FmuMapping(), Profile.VOLTAGE)
