"""An FMU no one on this project built: a wheel servo exported by PythonFMU, checked and driving the mission.

The FMI layer's other tests use FMUs the project's own build writes (`fmus/common`), so a mistake made
on both ends would pass them. This FMU comes from a third-party exporter (PythonFMU, MIT, in the
`test` extra): its model description, binary and file layout are that tool's. It is exported here,
into the test's temporary folder, from `tests/unit/cosim/fmus/pythonfmu_servo/ServoWheel.py`.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin

SOURCE = REPO / "tests" / "unit" / "cosim" / "fmus" / "pythonfmu_servo" / "ServoWheel.py"
MAPPING = REPO / "fmus" / "maps" / "pythonfmu_servo.yaml"


@pytest.fixture(scope="module")
def servo_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pythonfmu")
    proc = subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(SOURCE), "-d", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    return out / "ServoWheel.fmu"


def test_fmu_check_reads_the_pythonfmu_export_and_infers_its_profile(servo_fmu: Path) -> None:
    proc = run_twin("fmu", "check", str(servo_fmu), "--map", str(MAPPING), "--json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["generation_tool"].startswith("PythonFMU")
    assert doc["profile"] == "velocity-servo" and doc["profile_from"] == "inferred" and doc["ok"]
    bound = {r["role"]: (r["variable"], r["unit"]) for r in doc["roles"] if r["problem"] is None}
    assert bound["speed_setpoint"] == ("n_ref", "rpm") and bound["wheel_speed"] == ("n_out", "rpm")


def test_the_pythonfmu_servo_drives_the_default_mission_through_a_mapping_file(servo_fmu: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "third_party.yaml"
    scenario.write_text(
        "name: third_party_servo\n"
        "drive:\n"
        "  type: fmu\n"
        f"  fmu_file: {servo_fmu}\n"
        "  profile: velocity-servo\n"
        f"  mapping: {MAPPING}\n"
        "  motor: null\n"
    )
    bag = tmp_path / "bag"
    proc = run_twin("simulate", str(scenario), "--out", str(bag), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["ended_by"] == "mission complete" and summary["mission_result"] == "SUCCESS"
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/motor_state", "/ground_truth/odom")]
        msgs: dict[str, list[object]] = {"/motor_state": [], "/ground_truth/odom": []}
        for con, _, raw in reader.messages(connections=conns):
            msgs[con.topic].append(reader.deserialize(raw, con.msgtype))
    # The FMU's rpm came back as rad/s: the wheels' rim speeds average to the chassis' true speed.
    ratios = [
        0.033 * (m.velocity_rad_s[0] + m.velocity_rad_s[1]) / 2 / t.twist.twist.linear.x  # type: ignore[attr-defined]
        for m, t in zip(msgs["/motor_state"], msgs["/ground_truth/odom"], strict=False)
        if abs(t.twist.twist.linear.x) > 0.05  # type: ignore[attr-defined]
    ]
    assert len(ratios) > 100
    assert sorted(ratios)[len(ratios) // 2] == pytest.approx(1.0, abs=0.02)


def test_a_mapping_whose_wheel_speed_never_moves_is_warned_of(tmp_path: Path) -> None:
    # wheel_speed bound to an output that stays 0 (this servo's `stuck`): the run drove nothing for its
    # whole length and said so only through Nav2's failures
    source = tmp_path / "ServoWheel.py"
    text = SOURCE.read_text().replace(
        "        self.n_out = 0.0\n", "        self.n_out = 0.0\n        self.stuck = 0.0\n", 1
    )
    text = text.replace(
        '        self.register_variable(Real("n_out", causality=Fmi2Causality.output))\n',
        '        self.register_variable(Real("n_out", causality=Fmi2Causality.output))\n'
        '        self.register_variable(Real("stuck", causality=Fmi2Causality.output))\n',
        1,
    )
    assert "stuck" in text
    source.write_text(text)
    built = subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(source), "-d", str(tmp_path)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert built.returncode == 0, built.stderr
    mapping = tmp_path / "stuck.yaml"
    mapping.write_text(MAPPING.read_text().replace("wheel_speed: {name: n_out", "wheel_speed: {name: stuck", 1))
    scenario = tmp_path / "stuck_scenario.yaml"
    scenario.write_text(
        f"name: stuck\ndrive: {{type: fmu, fmu_file: {tmp_path / 'ServoWheel.fmu'}, profile: velocity-servo, "
        f"mapping: {mapping}, motor: null}}\n"
    )
    proc = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"), "--duration", "8")
    assert proc.returncode == 0, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if "stayed at exactly 0 rad/s" in ln]
    assert "wheel_speed output never moves" in line


def test_a_load_torque_that_speeds_the_wheel_up_is_warned_of(servo_fmu: Path, tmp_path: Path) -> None:
    # the roles swapped: the probe's load torque goes into the speed setpoint and speeds the wheel up
    mapping = tmp_path / "swapped.yaml"
    text = MAPPING.read_text().replace(
        "speed_setpoint: {name: n_ref, unit: rpm}", "speed_setpoint: {name: tau_ext, unit: rpm}"
    )
    mapping.write_text(text.replace("load_torque: {name: tau_ext, unit: N.m}", "load_torque: {name: n_ref, unit: N.m}"))
    scenario = tmp_path / "swapped_scenario.yaml"
    scenario.write_text(
        f"name: swapped\ndrive: {{type: fmu, fmu_file: {servo_fmu}, profile: velocity-servo, mapping: {mapping}, "
        "motor: null}\n"
    )
    proc = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"), "--duration", "1")
    (line,) = [ln for ln in proc.stderr.splitlines() if "a load torque of" in ln]
    assert "on 'n_ref' sped up 'n_out'" in line and "wrong variable or sign" in line
