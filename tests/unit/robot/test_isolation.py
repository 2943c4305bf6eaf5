"""FMUs in a child process (`drive: {isolation: process}`): the same numbers as in-process, and a
segfault, an abort or a hang in the FMU raises one FmuError naming what happened and when."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.unit.cosim.helpers import FAULTS, faulty
from twin.core.errors import FmuError
from twin.cosim.contract import FmuMapping
from twin.robot.chassis import ChassisParams
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain

MS = 1_000_000


def _drive(mode: str, *, isolation: str = "process", fault_time_s: float = 0.2, **extra: object) -> FmuDrive:
    return FmuDrive(
        fmu_file=faulty(),
        profile="velocity-servo",
        mapping=FmuMapping(parameters={"fault_mode": FAULTS[mode], "fault_time": fault_time_s}),
        isolation=isolation,  # type: ignore[arg-type]
        **extra,  # type: ignore[arg-type]
    )


def _drive_for(drive: FmuDrive, steps: int) -> tuple[float, float, float]:
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS, plugin_wheel_acceleration_mps2=1.0) as dt:
        dt.set_cmd_vel(0.2, 0.5)
        dt.advance(steps)
        s = dt.chassis_state()
    return s.x_m, s.y_m, s.yaw_rad


def test_an_isolated_fmu_drives_exactly_as_in_process() -> None:
    isolated = _drive_for(_drive("none", fault_time_s=99.0), 300)
    in_process = _drive_for(_drive("none", isolation="none", fault_time_s=99.0, api="lowlevel"), 300)
    assert isolated == in_process
    assert isolated[0] > 0.01


@pytest.mark.parametrize(
    ("mode", "what"),
    [
        ("segfault", "died with SIGSEGV"),
        ("abort", "died with SIGABRT"),
        ("hang", "did not finish a step within 1 s (hung)"),
    ],
)
def test_a_crashing_or_hanging_fmu_ends_the_drive_with_one_error_naming_it(mode: str, what: str) -> None:
    drive = _drive(mode, step_timeout_s=1.0)
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.2, 0.0)
        dt.advance(150)
        assert dt.chassis_state().x_m > 0.0
        with pytest.raises(FmuError) as err:
            dt.advance(100)
        assert dt.t_ns == 200 * MS  # every step before the fault was taken
    text = str(err.value)
    assert "\n" not in text
    assert f"in its own process {what} at t = 0.200000 s" in text
    assert "faulty_motor_servo" in text or "FaultyDcMotorWheel" in text


def test_an_fmu_error_status_in_the_child_is_reported_as_in_process() -> None:
    drive = _drive("nan", fault_time_s=0.05)
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.1, 0.0)
        with pytest.raises(
            FmuError, match=r"instance 'left' failed at t = 0\.050000 s.*non-finite output \(wheel_speed"
        ):
            dt.advance(100)


def test_sigterm_to_the_process_group_stops_the_run_not_blames_the_fmu(tmp_path: Path) -> None:
    # `timeout` and a shell's kill signal the whole group: the FMU's child process took SIGTERM itself
    # and the run said "... died with SIGTERM" (exit 4) instead of stopping as asked (143).
    import os
    import signal
    import subprocess
    import sys
    import time

    from tests.conftest import REPO

    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: t\ndrive: {type: fmu, fmu: auto, isolation: process}\n")
    bag = tmp_path / "bag"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin", "simulate", str(scenario), "--out", str(bag), "--duration", "3600"],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while not any(bag.glob("*.mcap")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    time.sleep(1.0)  # running, its FMU's child started
    os.killpg(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "died" not in err


@pytest.mark.parametrize(("mode", "signal_number"), [("segfault", 11), ("abort", 6)])
def test_an_fmu_crashing_the_run_in_process_leaves_one_line_naming_it_and_the_fix(
    tmp_path: Path, mode: str, signal_number: int
) -> None:
    # isolation: none, the FMU dereferences a bad pointer: the run died without a word, its bag unclosed
    import os
    import subprocess
    import sys

    from tests.conftest import REPO

    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        f"name: t\ndrive: {{type: fmu, fmu_file: {faulty()}, profile: velocity-servo, isolation: none, "
        f"mapping: {{parameters: {{fault_mode: {FAULTS[mode]}, fault_time: 0.5}}}}}}\n"
    )
    bag = tmp_path / "bag"
    proc = subprocess.run(
        [sys.executable, "-m", "twin", "simulate", str(scenario), "--out", str(bag), "--duration", "5"],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == -signal_number, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if ln.startswith("twin: error:")]
    assert f"the drive's FMU {faulty().name} ran in it" in line and "drive.isolation: process" in line
    assert line.endswith(f"`twin bag recover {bag}` (signal {signal_number})")
    recovered = subprocess.run(
        [sys.executable, "-m", "twin", "bag", "recover", str(bag)],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert recovered.returncode == 0, recovered.stderr  # as the line says


def test_an_fmu_hanging_in_process_is_named_by_the_watchdog(tmp_path: Path) -> None:
    # the line named fmu_drivetrain.py, not the FMU nor the fix
    import os
    import subprocess
    import sys

    from tests.conftest import REPO

    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        f"name: t\ndrive: {{type: fmu, fmu_file: {faulty()}, profile: velocity-servo, isolation: none, "
        f"mapping: {{parameters: {{fault_mode: {FAULTS['hang']}, fault_time: 0.5}}}}}}\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "twin", "simulate", str(scenario), "--out", str(tmp_path / "bag"), "--duration", "5",
         "--watchdog-s", "3"],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 8, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if ln.startswith("twin: error:")]
    assert "the drive's FMU" in line and faulty().name in line and "drive.isolation: process" in line
