"""Issue 3 end to end: FMU drivetrains in `twin simulate`, a vendor FMU swapped in by the scenario alone."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from tests.unit.cosim.helpers import FAULTS, acme, faulty

VENDOR_DRIVE = """\
drive:
  type: fmu
  fmu_file: {fmu}
  fmi_version: 3
  profile: voltage
  mapping: {mapping}
  motor:                       # the vendor's parameter names, for the twin's speed-loop design
    resistance_ohm: Rw
    inductance_h: 1.0e-6
    torque_constant_nm_per_a: k_m
    back_emf_vs_per_rad: k_m
    rotor_inertia_kgm2: J_total
    rotor_friction_nms_per_rad: d_visc
    gear_ratio: 1.0
    load_inertia_kgm2: 0.0
"""


def topics(bag: Path) -> dict[str, list[object]]:
    out: dict[str, list[object]] = {}
    with AnyReader([bag]) as reader:
        for con, _, raw in reader.messages():
            out.setdefault(con.topic, []).append(reader.deserialize(raw, con.msgtype))
    return out


def test_builtin_fmu_drive_runs_the_default_mission_and_records_motor_signals(tmp_path: Path) -> None:
    bag = tmp_path / "fmu"
    result = run_twin("simulate", str(REPO / "scenarios" / "house_fmu.yaml"), "--duration", "15", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    msgs = topics(bag)
    motors = msgs["/motor_state"]
    assert abs(len(motors) - 15 * 30) <= 1
    assert max(abs(c) for m in motors for c in m.current_a) > 0.05  # the motors draw current while driving
    assert all(abs(v) <= 12.0 + 1e-9 for m in motors for v in m.voltage_v)  # the PI's clamp: the battery
    joints = msgs["/joint_states"]
    assert len(joints[-1].effort) == 2  # efforts from the FMU's motor torque
    odom = msgs["/ground_truth/odom"][-1]
    assert math.hypot(odom.pose.pose.position.x, odom.pose.pose.position.y) > 0.5


def test_vendor_fmu_with_other_names_and_units_swaps_in_through_the_scenario(tmp_path: Path) -> None:
    scenario = tmp_path / "vendor.yaml"
    scenario.write_text(
        "name: vendor\n"
        + VENDOR_DRIVE.format(fmu=acme(fmi_version=3), mapping=REPO / "fmus" / "maps" / "acme_drive.yaml")
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--duration", "10", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    msgs = topics(bag)
    motors, truth = msgs["/motor_state"], msgs["/ground_truth/odom"]
    # rpm came back as rad/s: the wheels' rim speeds average to the chassis' true speed.
    ratios = [
        0.033 * (m.velocity_rad_s[0] + m.velocity_rad_s[1]) / 2 / t.twist.twist.linear.x
        for m, t in zip(motors, truth, strict=False)
        if abs(t.twist.twist.linear.x) > 0.05
    ]
    assert len(ratios) > 50
    assert sorted(ratios)[len(ratios) // 2] == pytest.approx(1.0, abs=0.02)
    # mA came back as A: a TB3 wheel motor draws well under its 2.3 A stall current here.
    assert 0.01 < max(abs(c) for m in motors for c in m.current_a) < 2.3


def test_fmu_missing_a_role_is_refused_before_the_run_naming_the_roles(tmp_path: Path) -> None:
    scenario = tmp_path / "bare.yaml"
    scenario.write_text(
        "name: bare\n"
        + VENDOR_DRIVE.format(fmu=acme("acme_bare", fmi_version=3), mapping=REPO / "fmus" / "maps" / "acme_drive.yaml")
    )
    result = run_twin("simulate", str(scenario), "--duration", "5", "--out", str(tmp_path / "bag"))
    assert result.returncode == 4
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert "load_torque" in lines[0] and "wheel_speed" in lines[0]
    assert not (tmp_path / "bag").exists()


def test_fmu_error_mid_run_ends_with_one_line_exit_4_and_a_readable_bag(tmp_path: Path) -> None:
    mapping = tmp_path / "faulty_map.yaml"
    mapping.write_text(
        (REPO / "fmus" / "maps" / "acme_drive.yaml").read_text().replace("Rw: 5.2", "Rw: 5.2\n  fault_time: 3.0")
    )
    scenario = tmp_path / "faulty.yaml"
    scenario.write_text("name: faulty\n" + VENDOR_DRIVE.format(fmu=acme(fmi_version=3), mapping=mapping))
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--duration", "10", "--out", str(bag))
    assert result.returncode == 4, result.stderr
    # One error line (the mission's turns ask more than Acme's motor reaches at 12 V: one warning may precede it).
    lines = [line for line in result.stderr.strip().splitlines() if "WARNING" not in line]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "t=3.0" in lines[0] and str(bag) in lines[0]
    clock = topics(bag)["/clock"]
    assert 29 <= len(clock) <= 31  # /clock at 10 Hz: everything up to the fault is in the bag


def test_burger_above_its_motors_warns_once_and_motor_state_shows_the_saturation(tmp_path: Path) -> None:
    scenario = tmp_path / "burger_fast.yaml"
    scenario.write_text(
        "name: burger_fast\n"
        "robot: {model: turtlebot3_burger}\n"
        "drive: {type: fmu, fmu: builtin:xl430_w250_servo, profile: velocity-servo}\n"
        "mission:\n"
        "  type: cmd_vel_script\n"
        "  segments:\n"
        "    - {duration_s: 2.0, linear_mps: 0.15}\n"
        "    - {duration_s: 2.0, linear_mps: 0.28}\n"  # a Burger's motors reach 0.21 m/s at 12 V
        "    - {duration_s: 1.0, linear_mps: 0.0}\n"
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert "fmu xl430_w250_servo (FMI 2, velocity-servo) drive" in result.stdout
    assert "cmd_vel clamped to the motors' 6.3" in result.stdout
    assert sum("clamped" in line for line in result.stderr.splitlines()) == 1
    msgs = topics(bag)
    logs = [m for m in msgs["/rosout"] if "clamped" in m.msg]
    assert len(logs) == 1 and logs[0].level == 30
    motors = msgs["/motor_state"]
    flagged = [m for m in motors if m.saturated[0]]
    t_flagged = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in flagged]
    assert 55 <= len(flagged) <= 62  # the 2 s at 0.28 m/s, at 30 Hz
    assert min(t_flagged) > 1.95 and max(t_flagged) < 4.05
    assert all(m.velocity_command_rad_s[0] == pytest.approx(0.28 / 0.033) for m in flagged)
    assert max(m.velocity_rad_s[0] for m in motors) < 0.212 / 0.033  # never beyond the motors' reach
    assert not any(m.saturated[0] for m in motors if m not in flagged)


@pytest.mark.parametrize("mode", ["segfault", "hang"])
def test_isolated_fmu_that_crashes_or_hangs_ends_the_run_with_one_line_exit_4_and_a_readable_bag(
    mode: str, tmp_path: Path
) -> None:
    scenario = tmp_path / f"{mode}.yaml"
    scenario.write_text(
        f"name: {mode}\n"
        "drive:\n"
        "  type: fmu\n"
        f"  fmu_file: {faulty()}\n"
        "  profile: velocity-servo\n"
        f"  mapping: {{parameters: {{fault_mode: {FAULTS[mode]}, fault_time: 1.0}}}}\n"
        "  isolation: process\n"
        "  step_timeout_s: 2.0\n"
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--duration", "5", "--out", str(bag))
    assert result.returncode == 4, result.stderr
    lines = [line for line in result.stderr.strip().splitlines() if "WARNING" not in line]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    what = "died with SIGSEGV" if mode == "segfault" else "did not finish a step within 2 s (hung)"
    assert f"in its own process {what} at t = 1.000000 s" in lines[0]
    assert str(bag) in lines[0]
    msgs = topics(bag)
    clock = msgs["/clock"]
    assert 9 <= len(clock) <= 11  # /clock at 10 Hz: everything up to the fault is in the bag
    assert len(msgs["/motor_state"]) >= 29


def test_without_a_c_compiler_the_default_run_says_so_once_and_drives_kinematic(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO), "PATH": str(tmp_path), "CC": "no-such-compiler"}
    env["TWIN_CACHE_DIR"] = str(tmp_path / "cache")  # nothing built yet, nothing can be
    result = subprocess.run(
        [sys.executable, "-m", "twin", "simulate", "--duration", "2", "--out", str(tmp_path / "bag")],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    said = [line for line in result.stderr.splitlines() if "no C compiler to build the robot's motor FMUs" in line]
    assert len(said) == 1 and "running the kinematic drive instead" in said[0]
    assert "kinematic drive" in result.stdout
