"""Model Exchange event handling: a bouncing ball's state events found by CVode and handled in event mode."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

from twin.cosim.exchange import cvode, event_update, integrate

G_MPS2 = 9.81
RESTITUTION = 0.7


class _Ball:
    """An FMI 2 Model Exchange FMU's functions as fmpy exposes them, for a ball dropped from 1 m."""

    def __init__(self) -> None:
        self.x = [1.0, 0.0]  # height m, velocity m/s
        self.t_s = 0.0
        self.events = 0

    def getContinuousStates(self, px: Any, nx: int) -> None:
        px[0], px[1] = self.x

    def setContinuousStates(self, px: Any, nx: int) -> None:
        self.x = [px[0], px[1]]

    def getDerivatives(self, px: Any, nx: int) -> None:
        px[0], px[1] = self.x[1], -G_MPS2

    def getEventIndicators(self, pz: Any, nz: int) -> None:
        pz[0] = self.x[0]

    def getNominalsOfContinuousStates(self, px: Any, nx: int) -> None:
        px[0] = px[1] = 1.0

    def setTime(self, t_s: float) -> None:
        self.t_s = t_s

    def completedIntegratorStep(self) -> tuple[bool, bool]:
        return False, False

    def enterEventMode(self) -> None:
        pass

    def enterContinuousTimeMode(self) -> None:
        pass

    def newDiscreteStates(self) -> tuple[bool, bool, bool, bool, bool, float]:
        if self.x[0] <= 1e-9 and self.x[1] < 0.0:
            self.x = [0.0, -RESTITUTION * self.x[1]]
            self.events += 1
        return False, False, False, True, False, 0.0


def _adapter(ball: _Ball, step_s: float) -> SimpleNamespace:
    adapter = SimpleNamespace(_fmu=ball, _h=step_s, _next_event_s=math.inf, _update_events=ball.newDiscreteStates)
    adapter.name = "ball"
    adapter._solver = cvode(
        ball, ball.getDerivatives, ball.getNominalsOfContinuousStates, nx=2, nz=1, t0_s=0.0, max_step_s=step_s
    )
    return adapter


def _exact_height(t_s: float) -> float:
    """Height of the ball at t_s (bounces at the ground with the restitution coefficient)."""
    t_hit = math.sqrt(2.0 / G_MPS2)
    if t_s <= t_hit:
        return 1.0 - 0.5 * G_MPS2 * t_s**2
    v_up = RESTITUTION * G_MPS2 * t_hit
    tau = t_s - t_hit
    assert tau <= 2.0 * v_up / G_MPS2  # before the second bounce
    return v_up * tau - 0.5 * G_MPS2 * tau**2


@pytest.mark.parametrize("step_s", [0.01, 0.1])
def test_state_event_reverses_the_ball_within_a_communication_step(step_s: float) -> None:
    ball = _Ball()
    adapter = _adapter(ball, step_s)
    assert not event_update(adapter)  # type: ignore[arg-type]
    steps = round(0.9 / step_s)
    for k in range(steps):
        assert not integrate(adapter, k * step_s)  # type: ignore[arg-type]
    assert ball.events == 1  # the bounce at 0.4515 s, found inside a step
    assert ball.x[0] == pytest.approx(_exact_height(steps * step_s), abs=1e-3)
    assert ball.x[0] > 0.0
