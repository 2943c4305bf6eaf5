"""The wheel-speed PI loop of the `voltage` drive profile, designed with python-control.

The plant is the linear DC motor + gearbox + wheel from voltage to wheel speed,

    ω(s)/V(s) = N Kt / ((L s + R)(J s + b) + N² Kt Ke),   J = J_rotor N² + J_load,  b = b_rotor N²,

and the PI `C(s) = kp + ki/s` puts the open-loop crossover at the requested frequency with the
requested phase margin. The controller runs once per physics step with its output held over the
step, so the design counts the hold's half-step delay. `control.margin` and a closed-loop step
response verify the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.core.errors import ConfigError

if TYPE_CHECKING:
    import control

__all__ = ["MotorConstants", "SpeedLoop", "design_speed_pi", "motor_transfer_function"]


@dataclass(frozen=True, kw_only=True, slots=True)
class MotorConstants:
    """Linear motor model in SI units (motor side unless said otherwise)."""

    resistance_ohm: float
    inductance_h: float
    torque_constant_nm_per_a: float
    back_emf_vs_per_rad: float
    rotor_inertia_kgm2: float
    rotor_friction_nms_per_rad: float
    gear_ratio: float
    load_inertia_kgm2: float = 0.0  # at the wheel, e.g. the wheel itself

    def __post_init__(self) -> None:
        for name in ("resistance_ohm", "inductance_h", "torque_constant_nm_per_a", "back_emf_vs_per_rad", "gear_ratio"):
            if not getattr(self, name) > 0.0:
                msg = f"{name} must be positive, got {getattr(self, name)}"
                raise ValueError(msg)
        if self.wheel_inertia_kgm2 <= 0.0:
            msg = "rotor_inertia_kgm2 and load_inertia_kgm2 give no inertia at the wheel"
            raise ValueError(msg)

    @property
    def wheel_inertia_kgm2(self) -> float:
        """Inertia at the wheel: J_rotor N² + J_load."""
        return self.rotor_inertia_kgm2 * self.gear_ratio**2 + self.load_inertia_kgm2

    @property
    def wheel_friction_nms_per_rad(self) -> float:
        """Viscous friction at the wheel: b_rotor N²."""
        return self.rotor_friction_nms_per_rad * self.gear_ratio**2

    def no_load_speed_radps(self, voltage_v: float) -> float:
        """Steady wheel speed at `voltage_v` with no load."""
        n, kt, ke = self.gear_ratio, self.torque_constant_nm_per_a, self.back_emf_vs_per_rad
        return n * kt * voltage_v / (self.resistance_ohm * self.wheel_friction_nms_per_rad + n * n * kt * ke)

    def stall_current_a(self, voltage_v: float) -> float:
        """Current with the wheel held still."""
        return voltage_v / self.resistance_ohm


def motor_transfer_function(motor: MotorConstants) -> control.TransferFunction:
    """ω_wheel(s)/V(s) of the linear motor, rad/s per V."""
    import control  # python-control pulls in scipy.signal: seconds of import, paid only when designing

    r, ind = motor.resistance_ohm, motor.inductance_h
    j, b = motor.wheel_inertia_kgm2, motor.wheel_friction_nms_per_rad
    n, kt, ke = motor.gear_ratio, motor.torque_constant_nm_per_a, motor.back_emf_vs_per_rad
    den = [ind * j, ind * b + r * j, r * b + n * n * kt * ke]
    return control.tf([n * kt], den)


@dataclass(frozen=True, kw_only=True, slots=True)
class SpeedLoop:
    """A designed wheel-speed PI and what python-control says about the loop."""

    kp_v_per_radps: float
    ki_v_per_rad: float
    crossover_hz: float  # measured open-loop gain crossover
    phase_margin_deg: float  # measured, including the hold delay
    gain_margin_db: float  # inf when the phase never crosses -180°
    bandwidth_hz: float  # closed-loop -3 dB bandwidth
    rise_time_s: float  # closed-loop step, 10 % to 90 %
    overshoot_pct: float


def design_speed_pi(motor: MotorConstants, *, crossover_hz: float, phase_margin_deg: float, step_s: float) -> SpeedLoop:
    """Design the PI for a crossover frequency and phase margin, and verify it.

    Raises:
        ConfigError: If a PI cannot reach the targets on this motor.
    """
    plant = motor_transfer_function(motor)
    wc = 2.0 * math.pi * crossover_hz
    response = complex(np.squeeze(plant(1j * wc)))
    plant_phase = math.atan2(response.imag, response.real) - wc * step_s / 2.0
    # PI phase needed so that the loop phase at crossover is -180° + margin.
    pi_phase = -math.pi + math.radians(phase_margin_deg) - plant_phase
    pi_phase = math.remainder(pi_phase, 2.0 * math.pi)
    if not -math.pi / 2.0 < pi_phase <= 0.0:
        msg = (
            f"speed_loop: a PI cannot give {phase_margin_deg:g}° phase margin at {crossover_hz:g} Hz on this motor "
            f"(plant phase {math.degrees(plant_phase):.0f}°); lower bandwidth_hz or phase_margin_deg"
        )
        raise ConfigError(msg)
    magnitude = abs(response)
    kp = math.cos(pi_phase) / magnitude
    ki = -wc * math.sin(pi_phase) / magnitude
    return verify_speed_pi(motor, kp=kp, ki=ki, step_s=step_s)


def verify_speed_pi(motor: MotorConstants, *, kp: float, ki: float, step_s: float) -> SpeedLoop:
    """Measure margins, bandwidth and step response of the loop with this PI (hold delay as a Padé)."""
    import control

    plant = motor_transfer_function(motor)
    num, den = control.pade(step_s / 2.0, 3)
    delay = control.tf(num, den)
    pi = control.tf([kp, ki], [1.0, 0.0])
    loop = pi * plant * delay
    gm, pm, _, wcp = control.margin(loop)
    closed = control.feedback(pi * plant, 1.0)
    bandwidth = float(control.bandwidth(closed))
    horizon = np.linspace(0.0, 20.0 / bandwidth, 2000) if bandwidth > 0 and np.isfinite(bandwidth) else None
    try:
        info = control.step_info(closed, T=horizon)
    except (IndexError, ValueError):  # no 10 %-90 % crossing inside the horizon
        info = {"RiseTime": math.nan, "Overshoot": math.nan}
    return SpeedLoop(
        kp_v_per_radps=kp,
        ki_v_per_rad=ki,
        crossover_hz=float(wcp) / (2.0 * math.pi),
        phase_margin_deg=float(pm),
        gain_margin_db=20.0 * math.log10(gm) if np.isfinite(gm) and gm > 0 else math.inf,
        bandwidth_hz=bandwidth / (2.0 * math.pi),
        rise_time_s=float(info["RiseTime"]),
        overshoot_pct=float(info["Overshoot"]),
    )


@dataclass(frozen=True, kw_only=True, slots=True)
class StepComparison:
    """An FMU's no-load voltage step response next to the linear model's (python-control)."""

    t_s: np.ndarray
    fmu_speed_radps: np.ndarray
    model_speed_radps: np.ndarray
    current_a: np.ndarray  # NaN when the FMU has no current output
    voltage_v: float
    step_s: float

    @property
    def rms_relative(self) -> float:
        """RMS of the difference divided by the model's final speed."""
        diff = self.fmu_speed_radps - self.model_speed_radps
        return float(np.sqrt(np.mean(diff * diff)) / abs(self.model_speed_radps[-1]))


def linear_step_response(motor: MotorConstants, *, voltage_v: float, t_s: np.ndarray) -> np.ndarray:
    """Wheel speed of the linear model after a voltage step at t = 0, at the times `t_s`."""
    import control

    response = control.forced_response(motor_transfer_function(motor), T=t_s, U=np.full_like(t_s, voltage_v), X0=0.0)
    return np.asarray(response.outputs, dtype=np.float64)
