"""An FMU that declares canBeInstantiatedOnlyOncePerProcess is never instantiated twice in one process: the
drive refuses it in-process (naming drive.isolation: process) and, isolated, runs each wheel in its own process."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from tests.unit.cosim.helpers import FAULTS, faulty
from twin.core.errors import ConfigError, FmuError
from twin.cosim.contract import FmuMapping
from twin.cosim.description import read_fmu_info
from twin.cosim.fmu import FmuFile
from twin.robot.chassis import ChassisParams
from twin.robot.fmu_drive import FmuDrive, check_fmu_drive
from twin.robot.fmu_drivetrain import FmuDrivetrain

MS = 1_000_000


def _once(tmp_path: Path) -> Path:
    """The faulty test motor with canBeInstantiatedOnlyOncePerProcess="true" on its Co-Simulation interface."""
    target = tmp_path / "once.fmu"
    with zipfile.ZipFile(faulty()) as src, zipfile.ZipFile(target, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "modelDescription.xml":
                data = data.replace(b"<CoSimulation ", b'<CoSimulation canBeInstantiatedOnlyOncePerProcess="true" ')
            dst.writestr(name, data)
    return target


def _drive(path: Path, isolation: str, mode: str = "none") -> FmuDrive:
    return FmuDrive(
        fmu_file=path,
        profile="velocity-servo",
        mapping=FmuMapping(parameters={"fault_mode": FAULTS[mode], "fault_time": 0.1}),
        isolation=isolation,  # type: ignore[arg-type]
    )


def test_the_flag_is_read_and_a_second_instance_is_refused(tmp_path: Path) -> None:
    path = _once(tmp_path)
    assert read_fmu_info(path).instantiated_once
    assert not read_fmu_info(faulty()).instantiated_once
    with FmuFile(path) as fmu:
        fmu.instantiate("left", step_s=0.001, inputs=[], outputs=[])
        with pytest.raises(FmuError, match=r"instance 'right': the FMU declares canBeInstantiatedOnlyOncePerProcess"):
            fmu.instantiate("right", step_s=0.001, inputs=[], outputs=[])


def test_the_drive_in_process_is_refused_naming_the_isolation_that_honours_it(tmp_path: Path) -> None:
    drive = _drive(_once(tmp_path), "none")
    for build in (
        lambda: FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS).close(),
        lambda: check_fmu_drive(drive, step_ns=MS),
    ):
        with pytest.raises(ConfigError, match=r"drive\.isolation: once\.fmu declares canBeInstantiatedOnlyOncePer"):
            build()


def _run(drive: FmuDrive) -> tuple[tuple[float, float, float], int | None]:
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS, plugin_wheel_acceleration_mps2=1.0) as dt:
        dt.set_cmd_vel(0.2, 0.5)
        dt.advance(90)
        s = dt.chassis_state()
        processes = dt._isolated.processes if dt._isolated is not None else None
    return (s.x_m, s.y_m, s.yaw_rad), processes


def test_isolated_each_wheel_runs_in_its_own_process_with_the_same_numbers(tmp_path: Path) -> None:
    once, processes = _run(_drive(_once(tmp_path), "process"))
    shared, one = _run(_drive(faulty(), "process"))
    assert processes == 2 and one == 1
    assert once == shared
    assert once[0] > 0.001


def test_a_crash_in_one_wheels_process_names_that_instance(tmp_path: Path) -> None:
    drive = _drive(_once(tmp_path), "process", mode="segfault")
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.2, 0.0)
        with pytest.raises(FmuError) as err:
            dt.advance(200)
    assert "in the process of instance 'left' died with SIGSEGV at t = 0.100000 s" in str(err.value)
