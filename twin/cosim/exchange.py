"""Model Exchange FMUs stepped as Co-Simulation ones: CVode between communication points, events in event mode.

Shared by the FMI 2 and FMI 3 Model Exchange adapters (`Fmi2Exchange`, `Fmi3Exchange`), which
differ only in the FMI functions they call.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable
from typing import Any

import fmpy

from twin.core.errors import FmuError
from twin.cosim.adapter import Adapter
from twin.cosim.description import ME_RELATIVE_TOLERANCE, ME_SOLVER, REAL_TYPES, FmuInfo

__all__ = ["ExchangeAdapter", "HeldInputs", "cvode", "event_update", "integrate", "set_inputs", "split_inputs"]


class ExchangeAdapter(Adapter):
    """What a Model Exchange adapter holds besides an adapter's buffers (set by `split_inputs` and its setup)."""

    _UPDATE: str  # the FMI function that updates the discrete states (for messages)
    _update_events: Callable[[], tuple[Any, ...]]
    _next_event_s: float
    _solver: Any
    # Where the discrete and continuous inputs are (`split_inputs`).
    _discrete_at: tuple[int, ...]
    _continuous_at: tuple[int, ...]
    _discrete_refs: Any
    _continuous_refs: Any
    _continuous_values: Any
    _held: tuple[float, ...] | None

    def _write(self, refs: Any, n: int, values: Any) -> int:
        """Set `n` Real/Float64 inputs through the version's setter; the status."""
        raise NotImplementedError


class HeldInputs:
    """fmpy's solvers apply an input at every evaluation; the inputs here are held over each step."""

    def apply(self, time: float) -> None:
        """Nothing to do: `step` sets the inputs before integrating."""


def cvode(fmu: Any, get_dx: Any, get_nominals: Any, *, nx: int, nz: int, t0_s: float, max_step_s: float) -> Any:
    """CVode of fmpy over an FMU in continuous-time mode (root finding on its event indicators)."""
    from fmpy.sundials import CVodeSolver

    return CVodeSolver(
        nx=nx,
        nz=nz,
        get_x=fmu.getContinuousStates,
        set_x=fmu.setContinuousStates,
        get_dx=get_dx,
        get_z=fmu.getEventIndicators,
        get_nominals=get_nominals,
        set_time=fmu.setTime,
        input=HeldInputs(),
        startTime=t0_s,
        maxStep=max_step_s,
        relativeTolerance=ME_RELATIVE_TOLERANCE,
    )


def split_inputs(adapter: ExchangeAdapter, info: FmuInfo) -> None:
    """Find the adapter's discrete inputs (variability `discrete`), which FMI lets change at events only."""
    variability = {v.value_reference: v.variability for v in info.variables.values() if v.type in REAL_TYPES}
    vrs = adapter._in_vr
    discrete = [k for k, vr in enumerate(vrs) if variability.get(vr) == "discrete"]
    continuous = [k for k in range(len(vrs)) if k not in discrete]
    adapter._discrete_at = tuple(discrete)
    adapter._continuous_at = tuple(continuous)
    adapter._discrete_refs = (ctypes.c_uint * max(1, len(discrete)))(*(vrs[k] for k in discrete))
    adapter._continuous_refs = (ctypes.c_uint * max(1, len(continuous)))(*(vrs[k] for k in continuous))
    adapter._continuous_values = (ctypes.c_double * max(1, len(continuous)))()
    adapter._held = None  # the discrete inputs' values last set (None: not yet)


def set_inputs(adapter: ExchangeAdapter, t_s: float) -> None:
    """Set the inputs for the step from `t_s`: continuous ones now, discrete ones in event mode.

    FMI lets a discrete input change only at an event: when one of their values differs from the
    last step's, the FMU enters event mode, takes them, updates its discrete states and goes back
    to continuous-time mode (the solver restarts at the step's start in any case). Without
    discrete inputs, one set call sets every input.
    """
    inputs = adapter.inputs
    if not adapter._discrete_at:
        status = adapter._write(adapter._in_refs, adapter._n_in, inputs)
        if status > 1:
            adapter.fail(adapter._FUNCTIONS[0], status, t_s)
        return
    if adapter._continuous_at:
        values = adapter._continuous_values
        for j, k in enumerate(adapter._continuous_at):
            values[j] = inputs[k]
        status = adapter._write(adapter._continuous_refs, len(adapter._continuous_at), values)
        if status > 1:
            adapter.fail(adapter._FUNCTIONS[0], status, t_s)
    now = tuple(inputs[k] for k in adapter._discrete_at)
    if now == adapter._held:
        return
    fmu = adapter._fmu
    try:
        fmu.enterEventMode()
        status = adapter._write(adapter._discrete_refs, len(now), (ctypes.c_double * len(now))(*now))
        if status > 1:
            adapter.fail(f"{adapter._FUNCTIONS[0]} in event mode", status, t_s)
        if event_update(adapter):
            adapter._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            adapter.fail(adapter._UPDATE, 3, t_s)
        fmu.enterContinuousTimeMode()
    except fmpy.fmi1.FMICallException as err:
        adapter.fail(err.function, int(err.status), t_s)
    adapter._held = now


def event_update(adapter: ExchangeAdapter) -> bool:
    """Iterate the FMU's discrete states in event mode; True if it asks to terminate."""
    needed = True
    while needed:
        needed, terminate, _, _, time_defined, time_s = adapter._update_events()
        if terminate:
            return True
        adapter._next_event_s = float(time_s) if time_defined else math.inf
    return False


def integrate(adapter: ExchangeAdapter, t_s: float) -> bool:
    """Integrate `adapter`'s FMU from `t_s` over one communication step; True if it asks to terminate.

    The solver restarts at the step's start (the inputs just set are a discontinuity) and after
    every event: a state event (CVode's root finding on the event indicators), a time event the FMU
    announced, or one `completedIntegratorStep` asks for. Each event is handled in event mode.
    """
    fmu = adapter._fmu
    solver = adapter._solver
    t_end = t_s + adapter._h
    eps = 1e-12 * max(1.0, abs(t_end))
    try:
        fmu.setTime(t_s)
        solver.reset(t_s)
        t = t_s
        while t < t_end - eps:
            target = min(t_end, adapter._next_event_s)
            state_event, _, t_reached = solver.step(t, target)
            fmu.setTime(t_reached)
            step_event, terminate = fmu.completedIntegratorStep()
            if terminate:
                return True
            time_event = t_reached >= adapter._next_event_s - eps
            if state_event or time_event or step_event:
                fmu.enterEventMode()
                if event_update(adapter):
                    return True
                fmu.enterContinuousTimeMode()
                solver.reset(t_reached)
            if t_reached <= t:  # no progress: an event at the same instant again and again
                msg = f"{adapter.name} failed at t = {t:.6f} s: events at one instant without end"
                raise FmuError(msg)
            t = t_reached
        fmu.setTime(t_end)
    except fmpy.fmi1.FMICallException as err:
        adapter.fail(err.function, int(err.status), t_s)
    except RuntimeError as err:
        adapter._failed = True
        msg = f"{adapter.name} failed at t = {t_s:.6f} s: {ME_SOLVER} could not integrate the step ({err})"
        raise FmuError(msg) from None
    return False
