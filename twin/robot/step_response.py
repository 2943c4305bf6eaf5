"""A drive FMU's no-load step response beside its linear motor model's (`twin fmu step-response`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from twin.core.errors import ConfigError
from twin.cosim.contract import FmuMapping, Profile, bind
from twin.cosim.fmu import FmuFile
from twin.robot.drive_control import MotorConstants, StepComparison, linear_step_response
from twin.robot.fmu_drive import MotorModel, motor_constants

__all__ = ["fmu_step_response"]


def fmu_step_response(
    path: Path,
    *,
    voltage_v: float = 12.0,
    step_s: float = 0.001,
    duration_s: float | None = None,
    mapping: FmuMapping | None = None,
    motor_model: MotorModel | None = None,
) -> tuple[StepComparison, MotorConstants]:
    """Run the FMU's no-load step response at `voltage_v` and the linear model's at the same times.

    The run lasts `duration_s`, or 8 mechanical time constants of the linear model.

    Raises:
        FmuError: If the FMU cannot be loaded, bound to the voltage profile or stepped.
        MotorModelError: If `motor_model` (default: the project FMUs' parameter names) does not give a
            linear motor model with this FMU.
        ConfigError: If the run would take too many steps.
    """
    mapping = mapping or FmuMapping()
    with FmuFile(path) as fmu:
        binding = bind(fmu.info, mapping, Profile.VOLTAGE)
        motor = motor_constants(motor_model or MotorModel(), fmu.info, binding.start)
        if duration_s is None:
            damping = motor.resistance_ohm * motor.wheel_friction_nms_per_rad + (
                motor.gear_ratio**2 * motor.torque_constant_nm_per_a * motor.back_emf_vs_per_rad
            )
            duration_s = 8.0 * motor.resistance_ohm * motor.wheel_inertia_kgm2 / damping
        n = max(2, math.ceil(duration_s / step_s))
        if n > 1_000_000:
            msg = f"step response: {n} steps of {step_s:g} s is too many; use a larger --step-ms"
            raise ConfigError(msg)
        speed = binding.outputs["wheel_speed"]
        current = binding.outputs.get("current")
        outputs = [speed.value_reference] + ([current.value_reference] if current else [])
        stepper = fmu.instantiate(
            "step",
            purpose="the step-response run",
            step_s=step_s,
            inputs=[b.value_reference for b in binding.inputs],
            outputs=outputs,
            start=binding.start,
        )
        cmd, load = binding.inputs
        stepper.inputs[0] = (voltage_v - cmd.offset) / cmd.factor
        stepper.inputs[1] = (0.0 - load.offset) / load.factor
        t = np.arange(n + 1) * step_s
        w = np.empty(n + 1)
        i = np.full(n + 1, np.nan)
        w[0] = speed.factor * stepper.outputs[0] + speed.offset
        if current:
            i[0] = current.factor * stepper.outputs[1] + current.offset
        for k in range(n):
            stepper.step(k * step_s)
            w[k + 1] = speed.factor * stepper.outputs[0] + speed.offset
            if current:
                i[k + 1] = current.factor * stepper.outputs[1] + current.offset
    model = linear_step_response(motor, voltage_v=voltage_v, t_s=t)
    comparison = StepComparison(
        t_s=t, fmu_speed_radps=w, model_speed_radps=model, current_a=i, voltage_v=voltage_v, step_s=step_s
    )
    return comparison, motor
