"""The `drive: {type: fmu}` section loads from YAML through the config loader, with file:line errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import MappingProxyType

import pytest

from twin.core.config import load_config
from twin.core.errors import ConfigError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import RoleBinding
from twin.cosim.description import read_fmu_info
from twin.robot.fmu_drive import FmuDrive, MotorModel, motor_constants

REPO = Path(__file__).resolve().parents[3]


def test_full_drive_section_loads(tmp_path: Path) -> None:
    path = tmp_path / "drive.yaml"
    path.write_text(
        """\
type: fmu
fmu_file: vendor/acme.fmu
profile: voltage
mapping:
  roles:
    voltage: U_motor
    load_torque: {name: T_ext, unit: mN.m}
    wheel_speed: {name: n_out, unit: rpm}
  parameters: {Rw: 5.2}
communication_step_s: 0.002
motor: {resistance_ohm: Rw, inductance_h: 1.0e-6, torque_constant_nm_per_a: k_m,
        back_emf_vs_per_rad: k_m, rotor_inertia_kgm2: J_total, rotor_friction_nms_per_rad: d_visc,
        gear_ratio: 1.0, load_inertia_kgm2: 0.0}
speed_loop: {bandwidth_hz: 10.0, phase_margin_deg: 65.0}
limits: {max_linear_mps: 0.26, max_angular_radps: 1.82, max_wheel_speed_radps: 8.08}
slip:
  slip: 0.0
  regions:
    - {x_min_m: 1.0, x_max_m: 2.0, y_min_m: -1.0, y_max_m: 1.0, slip: 0.3}
"""
    )
    drive = load_config(FmuDrive, path)
    assert drive.fmu_file == tmp_path / "vendor" / "acme.fmu"  # relative to the YAML file
    assert not isinstance(drive.mapping, Path)
    assert drive.mapping.binding("wheel_speed") == RoleBinding(name="n_out", unit="rpm")
    assert drive.mapping.binding("voltage") == RoleBinding(name="U_motor")
    assert drive.mapping.binding("current") == RoleBinding(name="current")
    assert drive.motor is not None and drive.motor.inductance_h == 1e-6 and drive.motor.resistance_ohm == "Rw"
    assert drive.slip.regions[0].slip == 0.3


def test_mapping_may_be_a_file(tmp_path: Path) -> None:
    path = tmp_path / "drive.yaml"
    path.write_text(f"type: fmu\nfmu: builtin:xl430_w250\nfmi_version: 3\nmapping: {REPO}/fmus/maps/builtin.yaml\n")
    drive = load_config(FmuDrive, path)
    assert drive.mapping == REPO / "fmus" / "maps" / "builtin.yaml"
    assert drive.resolved_mapping().parameters == {"V_max": 12.0}


@pytest.mark.parametrize(
    "text,error",
    [
        (
            "type: fmu\nprofile: velocity\n",
            r"drive\.yaml:2: profile: 'velocity' is not allowed; did you mean 'velocity-servo'",
        ),
        (
            "type: fmu\nfmu: motor.fmu\n",
            r"drive\.yaml:1: fmu: 'motor\.fmu' is not builtin:NAME or auto; give a file as fmu_file",
        ),
        (
            "type: fmu\nspeed_loop: {bandwith_hz: 5}\n",
            r"drive\.yaml:2: speed_loop\.bandwith_hz: unknown key; did you mean 'bandwidth_hz'",
        ),
        ("type: fmu\nfmi_version: 4\n", r"drive\.yaml:2: fmi_version: 4 is not allowed"),
    ],
)
def test_bad_drive_sections_name_file_line_and_key(tmp_path: Path, text: str, error: str) -> None:
    path = tmp_path / "drive.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=error):
        load_config(FmuDrive, path)


def test_a_motor_constant_named_after_an_array_parameter_is_a_config_error() -> None:
    info = read_fmu_info(resolve_fmu("builtin:xm430_w210", fmi_version=3))
    variables = dict(info.variables)
    variables["R"] = dataclasses.replace(variables["R"], start="5.2 5.3", dimensions=1)
    info = dataclasses.replace(info, variables=MappingProxyType(variables))
    with pytest.raises(ConfigError, match=r"drive\.motor\.resistance_ohm: the FMU's 'R' .* not one number"):
        motor_constants(MotorModel(), info, {})
