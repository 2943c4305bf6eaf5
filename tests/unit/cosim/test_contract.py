"""The drive contract: mapping roles to variables with unit conversion, refusing FMUs that lack roles."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from tests.unit.cosim.helpers import acme
from twin.core.errors import ConfigError, FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import FmuMapping, Profile, RoleBinding, RoleMap, bind, check_contract, load_mapping
from twin.cosim.description import read_fmu_info

REPO = Path(__file__).resolve().parents[3]
ACME_MAP = REPO / "fmus" / "maps" / "acme_drive.yaml"


def test_builtin_fmu_binds_without_a_mapping() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    binding = bind(info, FmuMapping(), Profile.VOLTAGE)
    assert [b.role for b in binding.inputs] == ["voltage", "load_torque"]
    assert set(binding.outputs) == {"wheel_speed", "wheel_angle", "current", "motor_torque", "applied_voltage"}


def test_servo_fmu_satisfies_velocity_servo_but_not_voltage() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xl430_w250_servo", fmi_version=3))
    assert check_contract(info, FmuMapping(), Profile.VELOCITY_SERVO).ok
    report = check_contract(info, FmuMapping(), Profile.VOLTAGE)
    assert report.missing == ("voltage",)


def test_vendor_mapping_converts_units_from_the_mapping_file() -> None:
    info = read_fmu_info(acme())
    binding = bind(info, load_mapping(ACME_MAP), Profile.VOLTAGE)
    speed = binding.outputs["wheel_speed"]
    assert (speed.name, speed.unit) == ("n_out", "rpm")
    assert speed.factor == pytest.approx(2 * math.pi / 60)
    assert binding.outputs["wheel_angle"].factor == pytest.approx(math.pi / 180)
    assert binding.outputs["current"].factor == pytest.approx(1e-3)
    assert binding.inputs[1].name == "T_ext" and binding.inputs[1].factor == pytest.approx(1e-3)
    assert binding.start == {"Rw": 5.2, "k_m": 1.3}


def test_units_come_from_the_fmu_when_the_mapping_gives_none() -> None:
    info = read_fmu_info(acme())
    mapping = FmuMapping(roles=RoleMap(voltage="U_motor", load_torque="T_ext", wheel_speed="n_out"))
    binding = bind(info, mapping, Profile.VOLTAGE)
    assert binding.outputs["wheel_speed"].unit == "rpm"
    assert binding.inputs[1].unit == "mN.m"


def test_fmu_missing_required_roles_is_refused_with_the_list() -> None:
    info = read_fmu_info(acme("acme_bare"))
    mapping = FmuMapping(roles=RoleMap(voltage="U_motor", load_torque="T_ext", wheel_speed="n_out"))
    with pytest.raises(FmuError, match=r"missing required role\(s\) load_torque, wheel_speed \(") as err:
        bind(info, mapping, Profile.VOLTAGE)
    assert "voltage drive contract" in str(err.value)


def test_wrong_dimension_unit_is_a_problem() -> None:
    info = read_fmu_info(acme())
    mapping = FmuMapping(
        roles=RoleMap(voltage="U_motor", load_torque="T_ext", wheel_speed=RoleBinding(name="n_out", unit="mA"))
    )
    report = check_contract(info, mapping, Profile.VOLTAGE)
    assert report.missing == ("wheel_speed",)
    assert "cannot be converted to rad/s" in (report.roles[2].problem or "")


def test_unknown_parameter_is_named_with_a_suggestion() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210"))
    report = check_contract(info, FmuMapping(parameters={"V_mx": 11.1}), Profile.VOLTAGE)
    assert not report.ok
    assert "did you mean 'V_max'" in report.problems[0]


def test_mapping_file_errors_name_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "map.yaml"
    bad.write_text("roles:\n  wheel_sped: n_out\n")
    with pytest.raises(ConfigError, match=r"map\.yaml:2: roles\.wheel_sped: unknown key; did you mean 'wheel_speed'"):
        load_mapping(bad)


def _twin(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "twin", *args], cwd=REPO, capture_output=True, text=True, check=False, timeout=120
    )


def test_cli_check_lists_missing_roles_and_exits_4() -> None:
    result = _twin("fmu", "check", str(acme("acme_bare")), "--map", str(ACME_MAP))
    assert result.returncode == 4
    assert "missing roles: load_torque, wheel_speed" in result.stdout
    assert "temp_winding" in result.stdout  # every variable is listed


def test_cli_check_passes_vendor_fmu_with_its_mapping() -> None:
    result = _twin("fmu", "check", str(acme(fmi_version=3)), "--map", str(ACME_MAP), "--json")
    assert result.returncode == 0, result.stderr
    assert '"ok": true' in result.stdout


def test_cli_check_reports_garbage_without_a_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "x.fmu"
    bad.write_bytes(b"PK\x03\x04 truncated")
    result = _twin("fmu", "check", str(bad))
    assert result.returncode == 4
    assert "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1


def test_a_declared_unit_of_another_dimension_says_how_the_mapping_overrides_it() -> None:
    # crane-fmu's oscillators declare "dimensionless": the line did not say a mapping may name the unit
    info = read_fmu_info(acme())
    mapping = FmuMapping(roles=RoleMap(voltage="U_motor", load_torque="T_ext", wheel_speed="I_mA"))
    problem = check_contract(info, mapping, Profile.VOLTAGE).roles[2].problem or ""
    assert problem.startswith("unit 'mA' cannot be converted to rad/s, the FMU's declared unit;")
    assert problem.endswith("say so in the mapping: wheel_speed: {name: I_mA, unit: rad/s}")


def test_a_mapping_naming_the_servo_setpoint_is_read_as_a_servo_even_with_a_typo() -> None:
    # the typo made the FMU satisfy neither contract, and the check then inferred voltage and said
    # "no variable 'voltage'", never naming the misspelt setpoint
    from twin.cosim.contract import infer_profile

    info = read_fmu_info(resolve_fmu("builtin:xm430_w210_servo"))
    mapping = FmuMapping(roles=RoleMap(speed_setpoint="speed_setpont"))
    profile, why = infer_profile(info, mapping)
    assert profile is Profile.VELOCITY_SERVO and "the mapping names its speed_setpoint role" in why
    problem = check_contract(info, mapping, profile).roles[0].problem or ""
    assert "no variable 'speed_setpont'; did you mean 'speed_setpoint'?" in problem
