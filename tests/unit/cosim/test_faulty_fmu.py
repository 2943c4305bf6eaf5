"""The faulty test motor: built from the repo's C source into the cache, the motor itself until its
fault, and a NaN output named in the error that stops the drive."""

from __future__ import annotations

import pytest
from fmpy.validation import validate_fmu

from tests.unit.cosim.helpers import FAULTS, faulty
from twin.core.errors import FmuError
from twin.cosim.build import cache_dir, resolve_fmu
from twin.cosim.contract import FmuMapping
from twin.cosim.fmu import FmuFile
from twin.robot.chassis import ChassisParams
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain

MS = 1_000_000


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_faulty_motor_builds_into_the_cache_and_validates(fmi_version: int) -> None:
    path = faulty(fmi_version=fmi_version)  # type: ignore[arg-type]
    assert path.is_relative_to(cache_dir())
    assert validate_fmu(str(path)) == []
    with FmuFile(path) as fmu:
        assert {"fault_mode", "fault_time", "speed_setpoint", "wheel_speed"} <= set(fmu.info.variables)


def _run_wheel(path: object, start: dict[str, float], steps: int) -> list[float]:
    with FmuFile(path) as fmu:  # type: ignore[arg-type]
        vrs = {name: v.value_reference for name, v in fmu.info.variables.items()}
        wheel = fmu.instantiate(
            "w",
            step_s=0.001,
            inputs=[vrs["speed_setpoint"], vrs["load_torque"]],
            outputs=[vrs["wheel_speed"], vrs["current"]],
            start=start,
        )
        wheel.inputs[0] = 5.0
        speeds = []
        for k in range(steps):
            wheel.step(k * 0.001)
            speeds.append(wheel.outputs[0])
        return speeds


def test_before_its_fault_the_faulty_motor_is_the_motor_to_the_bit() -> None:
    builtin = _run_wheel(resolve_fmu("builtin:xm430_w210_servo"), {}, 200)
    before = _run_wheel(faulty(), {"fault_mode": FAULTS["segfault"], "fault_time": 10.0}, 200)
    assert before == builtin


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("api", ["native", "lowlevel", "convenience"])
def test_nan_output_stops_the_drive_naming_the_output_and_time(api: str, fmi_version: int) -> None:
    drive = FmuDrive(
        fmu_file=faulty(fmi_version=fmi_version),  # type: ignore[arg-type]
        profile="velocity-servo",
        mapping=FmuMapping(parameters={"fault_mode": FAULTS["nan"], "fault_time": 0.05}),
        api=api,  # type: ignore[arg-type]
    )
    with FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS) as dt:
        dt.set_cmd_vel(0.1, 0.0)
        dt.advance(49)
        assert dt.chassis_state().x_m > 0.0  # it drove before the fault
        with pytest.raises(FmuError) as err:
            dt.advance(10)
    text = str(err.value)
    assert "instance 'left' failed at t = 0.050000 s" in text
    assert "non-finite output (wheel_speed = nan" in text
    assert "\n" not in text


def test_a_failing_inertia_probe_is_explained_not_just_named() -> None:
    drive = FmuDrive(
        fmu_file=faulty(),  # type: ignore[arg-type]
        profile="velocity-servo",
        motor=None,  # no motor model and no wheel_inertia_kgm2: the twin probes the FMU
        mapping=FmuMapping(parameters={"fault_mode": FAULTS["nan"], "fault_time": 0.0}),
    )
    with pytest.raises(FmuError) as err, FmuDrivetrain(drive, ChassisParams.tb3_waffle(), step_ns=MS):
        pass
    text = str(err.value)
    assert "instance 'probe' (a third instance the twin steps once before the run" in text
    assert "drive.wheel_inertia_kgm2 or drive.motor skips it" in text
