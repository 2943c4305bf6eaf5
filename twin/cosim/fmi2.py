"""The FMI 2.0 adapters: Co-Simulation (`Fmi2`) and Model Exchange (`Fmi2Exchange`)."""

from __future__ import annotations

import ctypes
import itertools
import math
import weakref
from collections.abc import Mapping
from typing import Any

import fmpy
import fmpy.fmi2

from twin.core.errors import FmuError
from twin.cosim.adapter import Adapter, Messages, decode
from twin.cosim.description import ME_SOLVER, FmuInfo, VariableInfo
from twin.cosim.exchange import ExchangeAdapter, cvode, event_update, integrate, set_inputs, split_inputs

__all__ = ["Fmi2", "Fmi2Exchange"]

# FMI 2 loggers are variadic; FMPy's proxy formats the message in C and calls one process-wide
# Python logger (the last one registered). So every instance gets that same logger, kept alive
# here, and its componentEnvironment: a number that routes the message to the instance's Messages.
_ROUTES: weakref.WeakValueDictionary[int, Messages] = weakref.WeakValueDictionary()
_ROUTE_IDS = itertools.count(1)


def _route(messages: Messages) -> int:
    key = next(_ROUTE_IDS)
    _ROUTES[key] = messages
    return key


def _fmi2_logger(env: int | None, instance: bytes, status: int, category: bytes, message: bytes) -> None:
    messages = _ROUTES.get(env or 0)
    if messages is not None:
        messages.add(status, decode(category), decode(message))


_FMI2_LOGGER = fmpy.fmi2.fmi2CallbackLoggerTYPE(_fmi2_logger)


class Fmi2(Adapter):
    """FMI 2.0 Co-Simulation adapter."""

    _version = 2
    _FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        """Instantiate, apply start values, initialise, and bind the C functions the step calls."""
        fmu = self._fmu
        messages = self._messages

        callbacks = fmpy.fmi2.fmi2CallbackFunctions()
        callbacks.logger = _FMI2_LOGGER
        callbacks.componentEnvironment = _route(messages)
        callbacks.allocateMemory = fmpy.fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        callbacks.freeMemory = fmpy.fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(ctypes.byref(callbacks))
        self._callbacks = callbacks  # keep the ctypes callbacks alive
        try:
            fmu.instantiate(callbacks=callbacks, loggingOn=messages.logging_on)
        except Exception:
            detail = messages.last()
            msg = f"{self.name}: fmi2Instantiate returned NULL" + (f" ({detail})" if detail else "")
            raise FmuError(msg) from None
        self._open = True
        c = fmu.component
        self._c = c
        self._call("fmi2SetupExperiment", start_time_s, lambda: fmu.setupExperiment(startTime=start_time_s))
        self._set_start(info, start)
        self._call("fmi2EnterInitializationMode", start_time_s, fmu.enterInitializationMode)
        self._call("fmi2ExitInitializationMode", start_time_s, fmu.exitInitializationMode)

        dll = fmu.dll
        status = ctypes.c_int
        vr_array = ctypes.c_uint * max(1, len(self._in_vr))
        self._in_refs = vr_array(*self._in_vr)
        self._out_refs = (ctypes.c_uint * max(1, len(self._out_vr)))(*self._out_vr)
        pointer = ctypes.c_void_p
        dbl_p = ctypes.POINTER(ctypes.c_double)
        uint_p = ctypes.POINTER(ctypes.c_uint)
        self._set = ctypes.CFUNCTYPE(status, pointer, uint_p, ctypes.c_size_t, dbl_p)(("fmi2SetReal", dll))
        self._get = ctypes.CFUNCTYPE(status, pointer, uint_p, ctypes.c_size_t, dbl_p)(("fmi2GetReal", dll))
        self._bind_step(dll)
        self._c_ptr = ctypes.c_void_p(c)
        self._n_in = len(self._in_vr)
        self._n_out = len(self._out_vr)
        if self._api == "convenience":
            self.step = self._step_convenience  # type: ignore[method-assign]
        self.read_outputs()

    def _bind_step(self, dll: Any) -> None:
        self._do = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)(
            ("fmi2DoStep", dll)
        )

    def _set_one(self, var: VariableInfo, value: float) -> None:
        fmu = self._fmu
        vr = [var.value_reference]
        if var.type == "Real":
            action = lambda: fmu.setReal(vr, [float(value)])  # noqa: E731
        elif var.type in ("Integer", "Enumeration"):
            action = lambda: fmu.setInteger(vr, [int(value)])  # noqa: E731
        elif var.type == "Boolean":
            action = lambda: fmu.setBoolean(vr, [bool(value)])  # noqa: E731
        else:
            msg = f"{self.name}: {var.name!r} is a {var.type}; only numbers can be set"
            raise FmuError(msg)
        self._call(f"setting {var.name}", 0.0, action)

    def step(self, t_s: float) -> None:
        """Set the inputs, one doStep from `t_s`, and read the outputs."""
        c = self._c_ptr
        set_status = self._set(c, self._in_refs, self._n_in, self.inputs)
        step_status = self._do(c, t_s, self._h, 1)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs)
        if (set_status | step_status | get_status) > 1:
            self._raise_first(("fmi2SetReal", "fmi2DoStep", "fmi2GetReal"), (set_status, step_status, get_status), t_s)
        self._check_finite("fmi2GetReal", t_s)

    def read_outputs(self) -> None:
        """Read the mapped outputs into their buffer."""
        status = self._get(self._c_ptr, self._out_refs, self._n_out, self.outputs)
        if status > 1:
            self.fail("fmi2GetReal", status, 0.0)


class Fmi2Exchange(Fmi2, ExchangeAdapter):
    """FMI 2.0 Model Exchange adapter: the same interface as the Co-Simulation one.

    Each communication step sets the inputs (held constant over the step), restarts CVode at the
    step's start (an input change is a discontinuity), integrates to the step's end with steps no
    longer than the communication step, completes the integrator step and reads the outputs.
    Stepped from Python (not by the compiled shim: `slot_fields` is None).
    """

    _FUNCTIONS = ("fmi2SetReal", f"{ME_SOLVER} integration", "fmi2GetReal")
    _UPDATE = "fmi2NewDiscreteStates"

    def _write(self, refs: Any, n: int, values: Any) -> int:
        """Set `n` Real inputs; the status."""
        status: int = self._set(self._c_ptr, refs, n, values)
        return status

    def _bind_step(self, dll: Any) -> None:
        fmu = self._fmu
        self._update_events = fmu.newDiscreteStates
        if event_update(self):
            msg = f"{self.name}: the FMU asked to terminate during its initial event update"
            raise FmuError(msg)
        fmu.enterContinuousTimeMode()
        self._solver = cvode(
            fmu,
            fmu.getDerivatives,
            fmu.getNominalsOfContinuousStates,
            nx=self._nx,
            nz=self._nz,
            t0_s=self._t0,
            max_step_s=self._h,
        )

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        """As the Co-Simulation adapter, after finding the discrete inputs; then set up CVode."""
        self._nx = info.n_states
        self._nz = info.n_event_indicators
        self._t0 = start_time_s
        self._next_event_s = math.inf
        if self._api == "convenience":
            self._api = "lowlevel"  # one stepping path: the solver calls fmpy's wrappers either way
        split_inputs(self, info)
        super().initialize(info, start, start_time_s)

    def slot_fields(self) -> dict[str, Any] | None:
        """None: the compiled shim only calls doStep; Model Exchange is integrated from Python."""
        return None

    def step(self, t_s: float) -> None:
        """Set the inputs, integrate one communication step from `t_s`, and read the outputs."""
        c = self._c_ptr
        set_inputs(self, t_s)
        terminate = integrate(self, t_s)
        if terminate:
            self._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            self.fail("fmi2CompletedIntegratorStep", 3, t_s)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs)
        if get_status > 1:
            self.fail("fmi2GetReal", get_status, t_s)
        self._check_finite("fmi2GetReal", t_s)
