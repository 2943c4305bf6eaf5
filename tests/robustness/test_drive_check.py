"""`twin scenario check` refuses every FMU drive `twin simulate` refuses before its first step, with the same line.

Both bind the drive contract, resolve the motor model and design the speed loop through one code path
(`twin.robot.fmu_drive.plan_fmu_drive`); `scenario check` does it without instantiating a built-in FMU,
and makes and steps one instance of a user's (`drive.fmu_file`), whose binary may not match its description.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.robustness.helpers import assert_one_line_error
from tests.unit.cosim.helpers import acme
from twin.cli import main

REPO = Path(__file__).resolve().parents[2]

# name: (drive section, exit code, phrase of the error line)
CASES: dict[str, tuple[dict[str, Any], int, str]] = {
    "communication_step": (
        {"fmu": "builtin:xm430_w210", "communication_step_s": 0.0025},
        2,
        "drive.communication_step_s: 0.0025 s must be a whole multiple of the physics step",
    ),
    "negative_motor_constant": (
        {"fmu": "builtin:xm430_w210", "motor": {"resistance_ohm": -5.0}},
        2,
        "drive.motor: resistance_ohm must be positive, got -5.0",
    ),
    "motor_parameter_the_fmu_lacks": (
        {
            "fmu_file": "ACME",
            "mapping": str(REPO / "fmus" / "maps" / "acme_drive.yaml"),
            "motor": {"inductance_h": "L"},
        },
        2,
        "drive.motor.resistance_ohm: the FMU has no parameter 'R' with a start value",
    ),
    "voltage_profile_without_motor": (
        {"fmu": "builtin:xm430_w210", "motor": None},
        2,
        "drive.motor: the voltage profile needs the motor model",
    ),
    "isolated_without_inertia": (
        {"fmu": "builtin:xm430_w210_servo", "profile": "velocity-servo", "motor": None, "isolation": "process"},
        2,
        "drive.wheel_inertia_kgm2: give it (or drive.motor) with isolation: process",
    ),
    "missing_role": (
        {"fmu": "builtin:xm430_w210", "mapping": {"roles": {"load_torque": "load_torqe"}}},
        4,
        "missing required role(s) load_torque",
    ),
    "wrong_causality": (
        {"fmu": "builtin:xm430_w210", "mapping": {"roles": {"voltage": "wheel_speed", "wheel_speed": "voltage"}}},
        4,
        "'wheel_speed' is an output, the role needs an input",
    ),
    "parameter_naming_an_output": (
        {"fmu": "builtin:xm430_w210", "mapping": {"parameters": {"current": 1.0}}},
        4,
        "parameters.current: 'current' is an output, not a parameter",
    ),
}


@pytest.mark.parametrize("case", CASES, ids=str)
def test_scenario_check_refuses_what_simulate_refuses_with_the_same_line(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    drive, exit_code, phrase = CASES[case]
    drive = {"type": "fmu", "profile": "voltage", **drive}
    if drive.get("fmu_file") == "ACME":
        drive["fmu_file"] = str(acme())
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump({"name": case, "drive": drive}))
    bag = tmp_path / "bag"
    lines = []
    for argv in (
        ["scenario", "check", str(scenario)],
        ["simulate", str(scenario), "--duration", "0.1", "--out", str(bag)],
    ):
        code = main(argv)
        captured = capsys.readouterr()
        assert code == exit_code, (argv, captured.err)
        lines.append(assert_one_line_error(captured.err, contains=phrase))
    assert lines[0] == lines[1]
    assert not bag.exists()


@pytest.mark.parametrize(
    "drive",
    [
        {"type": "fmu", "fmu": "auto", "profile": "velocity-servo"},
        {"type": "fmu", "fmu": "builtin:xm430_w210", "profile": "voltage", "communication_step_s": 0.002},
    ],
    ids=["auto_servo", "voltage_2ms"],
)
def test_scenario_check_passes_a_drive_that_binds(
    drive: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump({"name": "ok", "drive": drive}))
    assert main(["scenario", "check", str(scenario)]) == 0, capsys.readouterr().err


def _rezipped(source: Path, target: Path, edit: Any) -> Path:
    """The FMU at `source` with its modelDescription.xml text edited (the binary untouched)."""
    import zipfile

    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as new:
        for item in old.infolist():
            data = old.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode()).encode()
            new.writestr(item, data)
    return target


@pytest.mark.parametrize(
    ("case", "edit", "phrase"),
    [
        ("guid", lambda md: md.replace('guid="{', 'guid="{0', 1), "instance 'left'"),
        ("value_reference", lambda md: md.replace('name="n_out" valueReference="3"', 'name="n_out" valueReference="999"', 1),
         "value reference 999 is role wheel_speed (n_out) in the model description"),
    ],
)  # fmt: skip
def test_scenario_check_steps_a_users_fmu_once_and_refuses_what_only_its_binary_tells(
    case: str, edit: Any, phrase: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A model description the binary does not match: `scenario check` read the description alone and
    # said ok, then the run refused the FMU (exit 4)
    fmu = _rezipped(acme(), tmp_path / f"{case}.fmu", edit)
    motor = {
        "resistance_ohm": "Rw", "inductance_h": 1.0e-6, "torque_constant_nm_per_a": "k_m", "back_emf_vs_per_rad": "k_m",
        "rotor_inertia_kgm2": "J_total", "rotor_friction_nms_per_rad": "d_visc", "gear_ratio": 1.0,
        "load_inertia_kgm2": 0.0,
    }  # fmt: skip
    mapping = str(REPO / "fmus" / "maps" / "acme_drive.yaml")
    drive = {"type": "fmu", "profile": "voltage", "fmu_file": str(fmu), "mapping": mapping, "motor": motor}
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump({"name": case, "drive": drive}))
    code = main(["scenario", "check", str(scenario)])
    captured = capsys.readouterr()
    assert code == 4, captured.err
    assert phrase in assert_one_line_error(captured.err, contains=fmu.name)
    code = main(["simulate", str(scenario), "--duration", "0.1", "--out", str(tmp_path / "bag")])
    assert code == 4, capsys.readouterr().err
