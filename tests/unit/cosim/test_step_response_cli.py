"""`twin fmu step-response` of a vendor FMU: without the project's parameter names it says how to give the
motor model (exit 4), and `--scenario FILE` takes drive.motor (and drive.mapping) from a scenario."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_one_line_error
from tests.unit.cosim.helpers import acme
from twin.cli import main

REPO = Path(__file__).resolve().parents[3]
ACME_MAP = REPO / "fmus" / "maps" / "acme_drive.yaml"
ACME_MOTOR = """\
  motor:
    resistance_ohm: Rw
    inductance_h: 1.0e-6
    torque_constant_nm_per_a: k_m
    back_emf_vs_per_rad: k_m
    rotor_inertia_kgm2: J_total
    rotor_friction_nms_per_rad: d_visc
    gear_ratio: 1.0
    load_inertia_kgm2: 0.0
"""


def _scenario(tmp_path: Path, motor: str = ACME_MOTOR, mapping: bool = True) -> Path:
    path = tmp_path / "vendor.yaml"
    lines = ["name: vendor", "drive:", "  type: fmu", f"  fmu_file: {acme()}"]
    if mapping:
        lines.append(f"  mapping: {ACME_MAP}")
    path.write_text("\n".join(lines) + "\n" + motor)
    return path


def test_without_the_motor_model_the_error_says_how_to_give_it(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["fmu", "step-response", str(acme()), "--map", str(ACME_MAP)])
    captured = capsys.readouterr()
    assert code == 4
    line = assert_one_line_error(captured.err, contains=acme().name)
    assert "the FMU has no parameter 'R' with a start value (for resistance_ohm)" in line
    assert "pass --scenario FILE whose drive.motor gives the motor's constants" in line
    assert "drive.motor.resistance_ohm:" not in line  # no scenario key the command cannot take


@pytest.mark.parametrize("with_map", [True, False], ids=["map_given", "map_from_scenario"])
def test_scenario_gives_the_motor_model(with_map: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["fmu", "step-response", str(acme()), "--scenario", str(_scenario(tmp_path)), "--json"]
    if with_map:
        argv += ["--map", str(ACME_MAP)]
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    summary = json.loads(captured.out)
    assert summary["final_speed_fmu_radps"] > 0.0
    assert summary["rms_relative"] < 0.05


def test_a_wrong_motor_model_in_the_scenario_names_the_scenario(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, motor=ACME_MOTOR.replace("resistance_ohm: Rw", "resistance_ohm: R_winding"))
    code = main(["fmu", "step-response", str(acme()), "--scenario", str(scenario)])
    captured = capsys.readouterr()
    assert code == 2
    assert_one_line_error(
        captured.err, contains=f"{scenario}: drive.motor.resistance_ohm: the FMU has no parameter 'R_winding'"
    )


def test_a_scenario_without_a_motor_model_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(tmp_path, motor="  motor: null\n")
    code = main(["fmu", "step-response", str(acme()), "--scenario", str(scenario)])
    captured = capsys.readouterr()
    assert code == 2
    assert_one_line_error(captured.err, contains=f"{scenario}: drive.motor: is null")
