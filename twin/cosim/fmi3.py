"""The FMI 3.0 adapters: Co-Simulation (`Fmi3`) and Model Exchange (`Fmi3Exchange`)."""

from __future__ import annotations

import ctypes
import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from twin.core.errors import FmuError
from twin.cosim.adapter import Adapter, decode
from twin.cosim.description import ME_SOLVER, FmuInfo, VariableInfo
from twin.cosim.exchange import ExchangeAdapter, cvode, event_update, integrate, set_inputs, split_inputs

__all__ = ["Fmi3", "Fmi3Exchange"]


class Fmi3(Adapter):
    """FMI 3.0 Co-Simulation adapter."""

    _version = 3
    _FUNCTIONS = ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64")
    _INSTANTIATE = "fmi3InstantiateCoSimulation"

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        """Instantiate, apply start values, initialise, and bind the C functions the step calls."""
        fmu = self._fmu
        messages = self._messages

        def log_message(env: Any, status: int, category: bytes, message: bytes) -> None:
            messages.add(status, decode(category), decode(message))

        try:
            fmu.instantiate(loggingOn=messages.logging_on, logMessage=log_message)
        except Exception:
            detail = messages.last()
            msg = f"{self.name}: {self._INSTANTIATE} returned NULL" + (f" ({detail})" if detail else "")
            raise FmuError(msg) from None
        self._open = True
        self._set_start(info, start)
        self._call(
            "fmi3EnterInitializationMode", start_time_s, lambda: fmu.enterInitializationMode(startTime=start_time_s)
        )
        self._call("fmi3ExitInitializationMode", start_time_s, fmu.exitInitializationMode)

        dll = fmu.dll
        status = ctypes.c_int
        pointer = ctypes.c_void_p
        dbl_p = ctypes.POINTER(ctypes.c_double)
        uint_p = ctypes.POINTER(ctypes.c_uint)
        size = ctypes.c_size_t
        self._in_refs = (ctypes.c_uint * max(1, len(self._in_vr)))(*self._in_vr)
        self._out_refs = (ctypes.c_uint * max(1, len(self._out_vr)))(*self._out_vr)
        self._set = ctypes.CFUNCTYPE(status, pointer, uint_p, size, dbl_p, size)(("fmi3SetFloat64", dll))
        self._get = ctypes.CFUNCTYPE(status, pointer, uint_p, size, dbl_p, size)(("fmi3GetFloat64", dll))
        self._bind_step(dll)
        self._event = ctypes.c_bool(False)
        self._terminate = ctypes.c_bool(False)
        self._early = ctypes.c_bool(False)
        self._last_time = ctypes.c_double(0.0)
        self._refs = (
            ctypes.byref(self._event),
            ctypes.byref(self._terminate),
            ctypes.byref(self._early),
            ctypes.byref(self._last_time),
        )
        self._c_ptr = ctypes.c_void_p(fmu.component)
        self._n_in = len(self._in_vr)
        self._n_out = len(self._out_vr)
        if self._api == "convenience":
            self.step = self._step_convenience  # type: ignore[method-assign]
        self.read_outputs()

    def _bind_step(self, dll: Any) -> None:
        bool_p = ctypes.POINTER(ctypes.c_bool)
        self._do = ctypes.CFUNCTYPE(
            ctypes.c_int,
            ctypes.c_void_p,
            ctypes.c_double,
            ctypes.c_double,
            ctypes.c_bool,
            bool_p,
            bool_p,
            bool_p,
            ctypes.POINTER(ctypes.c_double),
        )(("fmi3DoStep", dll))

    _SETTERS: Mapping[str, tuple[str, type]] = MappingProxyType(
        {
            "Float64": ("setFloat64", float),
            "Float32": ("setFloat32", float),
            "Int8": ("setInt8", int),
            "UInt8": ("setUInt8", int),
            "Int16": ("setInt16", int),
            "UInt16": ("setUInt16", int),
            "Int32": ("setInt32", int),
            "UInt32": ("setUInt32", int),
            "Int64": ("setInt64", int),
            "UInt64": ("setUInt64", int),
            "Enumeration": ("setInt64", int),
            "Boolean": ("setBoolean", bool),
        }
    )

    def _set_one(self, var: VariableInfo, value: float) -> None:
        setter = self._SETTERS.get(var.type)
        if setter is None:
            msg = f"{self.name}: {var.name!r} is a {var.type}; only numbers can be set"
            raise FmuError(msg)
        method, kind = setter
        function = getattr(self._fmu, method)
        vr = [var.value_reference]
        self._call(f"setting {var.name}", 0.0, lambda: function(vr, [kind(value)]))

    def step(self, t_s: float) -> None:
        """Set the inputs, one doStep from `t_s`, and read the outputs."""
        c = self._c_ptr
        refs = self._refs
        set_status = self._set(c, self._in_refs, self._n_in, self.inputs, self._n_in)
        step_status = self._do(c, t_s, self._h, True, refs[0], refs[1], refs[2], refs[3])
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs, self._n_out)
        if (set_status | step_status | get_status) > 1 or self._terminate.value:
            if self._terminate.value and step_status <= 1:
                self._messages.add(3, "twin", "the FMU asked to terminate the simulation")
                step_status = 3
            self._raise_first(
                ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64"), (set_status, step_status, get_status), t_s
            )
        self._check_finite("fmi3GetFloat64", t_s)

    def read_outputs(self) -> None:
        """Read the mapped outputs into their buffer."""
        status = self._get(self._c_ptr, self._out_refs, self._n_out, self.outputs, self._n_out)
        if status > 1:
            self.fail("fmi3GetFloat64", status, 0.0)


class Fmi3Exchange(Fmi3, ExchangeAdapter):
    """FMI 3.0 Model Exchange adapter: as `Fmi2Exchange`, through the FMI 3 functions."""

    _FUNCTIONS = ("fmi3SetFloat64", f"{ME_SOLVER} integration", "fmi3GetFloat64")
    _INSTANTIATE = "fmi3InstantiateModelExchange"
    _UPDATE = "fmi3UpdateDiscreteStates"

    def _write(self, refs: Any, n: int, values: Any) -> int:
        """Set `n` Float64 inputs; the status."""
        status: int = self._set(self._c_ptr, refs, n, values, n)
        return status

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

    def _bind_step(self, dll: Any) -> None:
        fmu = self._fmu
        # Array states count element by element: ask the instance (the description lists variables).
        self._nx = int(fmu.getNumberOfContinuousStates())
        self._nz = int(fmu.getNumberOfEventIndicators())
        self._update_events = fmu.updateDiscreteStates
        if event_update(self):
            msg = f"{self.name}: the FMU asked to terminate during its initial event update"
            raise FmuError(msg)
        fmu.enterContinuousTimeMode()
        self._solver = cvode(
            fmu,
            fmu.getContinuousStateDerivatives,
            fmu.getNominalsOfContinuousStates,
            nx=self._nx,
            nz=self._nz,
            t0_s=self._t0,
            max_step_s=self._h,
        )

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
            self.fail("fmi3CompletedIntegratorStep", 3, t_s)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs, self._n_out)
        if get_status > 1:
            self.fail("fmi3GetFloat64", get_status, t_s)
        self._check_finite("fmi3GetFloat64", t_s)
