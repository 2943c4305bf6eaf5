"""Model Exchange FMUs: the project's motor built for Model Exchange steps like its Co-Simulation build."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.cosim.helpers import model_exchange
from twin.cosim.build import FmiVersion, resolve_fmu
from twin.cosim.contract import FmuMapping, Profile, check_contract
from twin.cosim.description import read_fmu_info, stepping
from twin.cosim.fmu import FmuFile

STEP_S = 1e-3


def _run(path: Path, command: str, load_nm: float, steps: int) -> list[tuple[float, ...]]:
    """Step one instance with a held command and load torque; wheel speed, current, wheel angle per step."""
    with FmuFile(path) as fmu:
        vr = {name: v.value_reference for name, v in fmu.info.variables.items()}
        stepper = fmu.instantiate(
            "wheel",
            step_s=STEP_S,
            inputs=[vr[command], vr["load_torque"]],
            outputs=[vr["wheel_speed"], vr["current"], vr["wheel_angle"]],
        )
        stepper.inputs[1] = load_nm
        rows = []
        for k in range(steps):
            stepper.inputs[0] = 6.0 if k < steps // 2 else -2.0  # a step up, then a reversal
            stepper.step(k * STEP_S)
            rows.append(tuple(stepper.outputs[:3]))
        return rows


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_model_exchange_build_declares_states_and_is_stepped_by_cvode(fmi_version: FmiVersion) -> None:
    info = read_fmu_info(model_exchange(fmi_version=fmi_version))
    assert info.co_simulation is None
    assert info.model_exchange == "xm430_w210_servo_me"
    assert info.n_states == 4  # current, wheel speed, wheel angle, the PI's integral
    assert stepping(info).startswith("Model Exchange (solver: CVode")
    assert check_contract(info, FmuMapping(), Profile.VELOCITY_SERVO).ok
    assert stepping(read_fmu_info(resolve_fmu("builtin:xm430_w210_servo"))) == "Co-Simulation"


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize(
    ("me_variant", "cs_variant", "command"),
    [("xm430_w210_me", "xm430_w210", "voltage"), ("xm430_w210_servo_me", "xm430_w210_servo", "speed_setpoint")],
)
def test_model_exchange_motor_steps_within_one_percent_of_co_simulation(
    me_variant: str, cs_variant: str, command: str, fmi_version: FmiVersion
) -> None:
    steps = 600
    me = _run(model_exchange(me_variant, fmi_version), command, 0.02, steps)
    cs = _run(resolve_fmu(f"builtin:{cs_variant}", fmi_version=fmi_version), command, 0.02, steps)
    for column, name in enumerate(("wheel_speed", "current", "wheel_angle")):
        scale = max(abs(row[column]) for row in cs)
        worst = max(abs(a[column] - b[column]) for a, b in zip(me, cs, strict=True))
        assert scale > 0.0
        assert worst / scale < 0.01, f"{name}: worst difference {100 * worst / scale:.3f} % of its range"
    # Both reached the command's steady state (not two equally wrong runs).
    assert abs(cs[steps // 2 - 1][0]) > 1.0
    assert abs(me[-1][0] - cs[-1][0]) < 0.01 * abs(cs[-1][0])


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_check_says_model_exchange_and_the_solver(fmi_version: FmiVersion) -> None:
    path = model_exchange(fmi_version=fmi_version)
    result = run_twin("fmu", "check", str(path), "--profile", "velocity-servo")
    assert result.returncode == 0, result.stderr
    assert "Model Exchange" in result.stdout.splitlines()[1]
    assert "stepped as: Model Exchange (solver: CVode" in result.stdout
    assert "satisfies the velocity-servo contract" in result.stdout


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_discrete_input_is_set_in_event_mode_and_steps_as_a_continuous_one(fmi_version: FmiVersion) -> None:
    # The variant's FMU refuses a discrete input set in continuous-time mode, as FMI requires.
    discrete = model_exchange("xm430_w210_servo_me_discrete_load", fmi_version)
    assert read_fmu_info(discrete).variables["load_torque"].variability == "discrete"
    steps = 300
    got = _run(discrete, "speed_setpoint", 0.05, steps)
    want = _run(model_exchange("xm430_w210_servo_me", fmi_version), "speed_setpoint", 0.05, steps)
    assert got == want


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_discrete_input_change_mid_run_takes_effect(fmi_version: FmiVersion) -> None:
    with FmuFile(model_exchange("xm430_w210_servo_me_discrete_load", fmi_version)) as fmu:
        vr = {name: v.value_reference for name, v in fmu.info.variables.items()}
        wheel = fmu.instantiate(
            "left", step_s=STEP_S, inputs=[vr["speed_setpoint"], vr["load_torque"]], outputs=[vr["current"]]
        )
        wheel.inputs[0] = 5.0
        for k in range(200):
            wheel.step(k * STEP_S)
        no_load_a = wheel.outputs[0]
        wheel.inputs[1] = 0.5
        for k in range(200, 400):
            wheel.step(k * STEP_S)
        assert wheel.outputs[0] > no_load_a + 0.1  # the servo draws current against the new load
