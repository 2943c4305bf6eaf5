"""A wheel servo in velocity mode, written for PythonFMU (a third-party exporter) as a vendor might.

Its own names and units (speed in rpm), none of the twin's roles: `fmus/maps/pythonfmu_servo.yaml`
maps them. The test suite exports it with `pythonfmu build` into a temporary folder and runs it.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class ServoWheel(Fmi2Slave):
    """First-order speed response to the setpoint; current from the torque the wheel must give."""

    author = "twin tests"
    description = "A wheel servo in velocity mode: first-order speed response, current from torque"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.n_ref = 0.0
        self.tau_ext = 0.0
        self.n_out = 0.0
        self.phi = 0.0
        self.i_motor = 0.0
        self.T = 0.02
        self.k_t = 1.1
        self.J = 1.0e-3
        self.register_variable(Real("n_ref", causality=Fmi2Causality.input))
        self.register_variable(Real("tau_ext", causality=Fmi2Causality.input))
        self.register_variable(Real("n_out", causality=Fmi2Causality.output))
        self.register_variable(Real("phi", causality=Fmi2Causality.output))
        self.register_variable(Real("i_motor", causality=Fmi2Causality.output))
        self.register_variable(Real("T", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("k_t", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("J", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        w = self.n_out * math.pi / 30.0
        w_ref = self.n_ref * math.pi / 30.0
        a = (w_ref - w) / self.T
        w += a * step_size
        self.phi += w * step_size
        self.n_out = w * 30.0 / math.pi
        self.i_motor = (self.J * a + self.tau_ext) / self.k_t
        return True
