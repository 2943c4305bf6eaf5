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
