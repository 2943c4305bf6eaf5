"""An FMU's own log messages (the fmi2 logger / fmi3 logMessage callback) reach the console and `/rosout`.

In the simulate process, or forwarded from the child process of an isolated FMU. The faulty test
motor with `fault_mode` warn is the motor, but logs a warning through the FMU's
logger every simulated second; with INFO enabled the FMU is instantiated with logging on and also
logs its OK-status "initialized" message. Levels follow the FMU's status.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_bag_reads_back
from tests.unit.cosim.helpers import faulty
from twin.bag import read_messages
from twin.cli import main
from twin.cosim.fmu import FmuFile

WARN = 5  # fault_mode "warn" of fmus/testing/faulty_motor/faulty_motor.c


def _step(fmi_version: int, seconds: float) -> None:
    with FmuFile(faulty("faulty_motor", fmi_version=fmi_version)) as fmu:
        stepper = fmu.instantiate(
            "left", step_s=1e-3, inputs=[0], outputs=[3], start={"fault_mode": WARN, "fault_time": 0.0}
        )
        stepper.inputs[0] = 6.0
        for k in range(round(seconds / 1e-3)):
            stepper.step(k * 1e-3)


def _fmu_records(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == "twin.node.fmu.left"]


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_warnings_are_logged_at_warning_level(fmi_version: int, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="twin")
    _step(fmi_version, 2.5)
    records = _fmu_records(caplog)
    assert [r.levelno for r in records] == [logging.WARNING, logging.WARNING]
    assert "winding temperature check at t = 1 s" in records[0].getMessage()
    assert "winding temperature check at t = 2 s" in records[1].getMessage()
    assert "FaultyDcMotorWheel" in records[0].getMessage()  # names the FMU and the instance
    assert "'left'" in records[0].getMessage()


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_with_info_enabled_the_fmu_logs_its_debug_messages_at_info(
    fmi_version: int, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="twin")
    _step(fmi_version, 1.5)
    records = _fmu_records(caplog)
    assert [r.levelno for r in records] == [logging.INFO, logging.WARNING]
    assert "[logEvents] initialized; stepping from t = 0 s" in records[0].getMessage()


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_an_fmu_error_is_said_once_in_the_fmu_error(fmi_version: int, caplog: pytest.LogCaptureFixture) -> None:
    # INFO on: the FMU also logs its OK-status "initialized", which must not become the error's detail.
    caplog.set_level(logging.DEBUG, logger="twin")
    from twin.core.errors import FmuError

    with FmuFile(faulty("faulty_motor", fmi_version=fmi_version)) as fmu:
        start = {"fault_mode": 9.0, "fault_time": 0.0}
        stepper = fmu.instantiate("left", step_s=1e-3, inputs=[0], outputs=[3], start=start)
        with pytest.raises(FmuError, match=r"DoStep returned Error \(fmi3DoStep|DoStep returned Error \(fmi2DoStep"):
            stepper.step(0.0)
    records = _fmu_records(caplog)
    assert [r.levelno for r in records] == [logging.INFO, logging.DEBUG]  # the error: not a second line
    assert "fault_mode 9 is not one of 0 to 5" in records[1].getMessage()


def _warning_scenario(folder: Path, isolation: str, more: str = "") -> Path:
    """A scenario whose drive is the faulty motor warning once a simulated second (`more`: further keys)."""
    scenario = folder / "warn.yaml"
    scenario.write_text(
        "name: fmu_warns\n"
        "drive:\n"
        "  type: fmu\n"
        f"  fmu_file: {faulty()}\n"
        "  profile: velocity-servo\n"
        f"  mapping: {{parameters: {{fault_mode: {WARN}, fault_time: 0.0}}}}\n"
        f"  isolation: {isolation}\n" + more
    )
    return scenario


@pytest.mark.parametrize("isolation", ["none", "process"])
def test_simulate_records_the_fmu_messages_on_rosout(
    isolation: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _warning_scenario(tmp_path, isolation)
    bag = tmp_path / "bag"
    code = main(["-v", "simulate", str(scenario), "--duration", "2.5", "--out", str(bag)])
    err = capsys.readouterr().err
    assert code in (0, 1), err
    # The console: each instance's warnings, once per simulated second.
    console = [line for line in err.splitlines() if "winding temperature check" in line]
    assert len(console) == 4, err  # left and right, at t = 1 s and 2 s
    assert all(line.startswith("twin: WARNING: ") for line in console)
    # With -v, the FMU's OK-status messages too (the FMU is instantiated with logging on).
    infos = [line for line in err.splitlines() if "[logEvents] initialized" in line]
    assert len(infos) == 2, err
    assert all(line.startswith("twin: INFO: ") for line in infos)
    assert_bag_reads_back(bag)
    logs = [m.msg for m in read_messages(bag) if m.topic == "/rosout"]
    fmu_logs = [m for m in logs if m.name.startswith("fmu.")]
    warnings = [m for m in fmu_logs if "winding temperature check" in m.msg]
    assert sorted(m.name for m in warnings) == ["fmu.left", "fmu.left", "fmu.right", "fmu.right"]
    assert all(m.level == 30 for m in warnings)  # rcl_interfaces/msg/Log WARN
    stamps_s = sorted({m.stamp.sec + m.stamp.nanosec * 1e-9 for m in warnings})
    # Stamped with sim time: the step that reached each whole second (stamped at its start).
    assert len(stamps_s) == 2
    assert stamps_s == pytest.approx([1.0, 2.0], abs=0.011)


@pytest.mark.parametrize("isolation", ["none", "process"])
def test_a_fleet_robots_fmu_messages_name_the_robot(
    isolation: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Two robots' drives both had the logger fmu.left: their lines could not be told apart.
    fleet = (
        "robots:\n"
        "  - {name: robot1, robot: {initial_pose: {x_m: 0.0, y_m: 0.0}}}\n"
        "  - {name: robot2, robot: {initial_pose: {x_m: 1.5, y_m: -0.2}}}\n"
    )
    scenario = _warning_scenario(tmp_path, isolation, fleet)
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "1.5", "--out", str(bag)])
    err = capsys.readouterr().err
    assert code in (0, 1), err
    console = sorted(line.split("] ")[0] for line in err.splitlines() if "winding temperature check" in line)
    assert console == [f"twin: WARNING: [robot{i}.fmu.{side}" for i in (1, 2) for side in ("left", "right")], err
    logs = [m.msg for m in read_messages(bag) if m.topic == "/rosout" and "winding temperature check" in m.msg.msg]
    assert sorted(m.name for m in logs) == [f"robot{i}.fmu.{side}" for i in (1, 2) for side in ("left", "right")]
