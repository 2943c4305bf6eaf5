"""`twin fmu check` infers the profile from the FMU's inputs and says so; step-response says what it supports."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_one_line_error
from twin.cli import main
from twin.cosim.build import resolve_fmu


@pytest.mark.parametrize(
    ("fmu", "profile"),
    [("builtin:xm430_w210_servo", "velocity-servo"), ("builtin:xm430_w210", "voltage")],
)
def test_check_infers_the_profile_and_says_which(fmu: str, profile: str, capsys: pytest.CaptureFixture[str]) -> None:
    # The project's default drive runs xm430_w210_servo: it passes without --profile.
    assert main(["fmu", "check", fmu]) == 0, capsys.readouterr().out
    out = capsys.readouterr().out
    assert f"contract ({profile}; inferred:" in out and f"satisfies the {profile} contract" in out
    assert main(["fmu", "check", fmu, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["profile"] == profile and doc["profile_from"] == "inferred" and doc["ok"]


def test_a_given_profile_is_checked_as_given(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fmu", "check", "builtin:xm430_w210", "--profile", "velocity-servo"]) == 4
    out = capsys.readouterr().out
    assert "contract (velocity-servo; given with --profile)" in out and "missing roles: speed_setpoint" in out


def test_profile_option_has_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["fmu", "check", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "takes a speed setpoint" in text and "takes a voltage" in text and "default: inferred" in text


def test_step_response_says_it_supports_voltage_fmus_only(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fmu", "step-response", "builtin:xm430_w210_servo"]) == 4
    line = assert_one_line_error(capsys.readouterr().err, contains="xm430_w210_servo")
    assert "supports voltage-profile FMUs only" in line and "velocity-servo" in line
    assert "map the roles" not in line


def test_a_servo_fmu_with_a_wrong_setpoint_is_checked_as_a_servo(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Its speed_setpoint in an unknown unit: a velocity-servo FMU with that to fix, not a voltage FMU
    # without 'voltage' (the inference used to count the unit's problem as a missing role and pick voltage).
    source = resolve_fmu("builtin:xm430_w210_servo", fmi_version=2)
    bad = tmp_path / "bad_unit.fmu"
    setpoint = b'description="wheel-speed setpoint of the built-in velocity controller">\n      <Real unit="rad/s"'
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                assert setpoint in data
                data = data.replace(setpoint, setpoint.replace(b"rad/s", b"furlong/fortnight"))
            dst.writestr(item, data)
    assert main(["fmu", "check", str(bad)]) == 4
    out = capsys.readouterr().out
    assert "contract (velocity-servo; inferred: it satisfies neither contract; it has every variable" in out
    assert "unit 'furlong/fortnight' is unknown" in out and "no variable 'voltage'" not in out
