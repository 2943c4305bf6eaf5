"""What the FMI 2 and FMI 3 adapters share: the `Stepper` protocol, buffers, status checks, log messages.

An adapter is one initialised instance whose inputs and outputs are fixed lists of Real/Float64
value references. Its hot path is `step(t_s)`: set the inputs from `inputs` (a ctypes double array
the caller writes), one doStep, read the outputs into `outputs` (a ctypes double array the caller
reads). Every FMU status of Discard, Error or Fatal raises `FmuError` naming the FMU, the instance,
the sim time, the function, the status and the FMU's last log message (kept by `Messages`, which
also forwards the FMU's log to Python logging).
"""

from __future__ import annotations

import collections
import ctypes
import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Protocol

import fmpy

from twin.core.closing import Closing
from twin.core.errors import FmuError
from twin.cosim.description import FmuInfo, VariableInfo

__all__ = ["MAX_FORWARDED_MESSAGES", "Adapter", "Api", "Messages", "Stepper", "decode", "fmu_logger"]

_log = logging.getLogger(__name__)

Api = Literal["lowlevel", "convenience"]

_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
# Not an FMI status: the get call succeeded but an output is NaN or infinite (TWIN_STATUS_NONFINITE
# in fmus/common/step_shim.h).
_NONFINITE = 6


class Stepper(Protocol):
    """One initialised Co-Simulation instance with fixed input and output value references."""

    name: str
    inputs: ctypes.Array[ctypes.c_double]
    outputs: ctypes.Array[ctypes.c_double]

    def step(self, t_s: float) -> None:
        """Write `inputs`, advance from `t_s` by the communication step, read `outputs`."""

    def read_outputs(self) -> None:
        """Read `outputs` without stepping (after initialisation)."""

    def close(self) -> None:
        """Terminate and free the instance (idempotent)."""


# The Python logging level of each FMI status (OK, Warning, Discard, Error, Fatal, Pending). Error
# and Fatal messages are DEBUG: twin raises an FmuError carrying that message (one line, not two).
_STATUS_LEVELS = (logging.INFO, logging.WARNING, logging.WARNING, logging.DEBUG, logging.DEBUG, logging.INFO)
# An FMU that logs on every step would flood the console and /rosout: past this many lines an
# instance's messages are kept for its error reports only (one line says so).
MAX_FORWARDED_MESSAGES = 1000


def fmu_logger(instance_name: str, log_name: str = "fmu") -> logging.Logger:
    """The logger an FMU instance's own log messages go to.

    Its records reach the console (INFO with `-v`, warnings always) and, during `twin simulate`,
    `/rosout` under the name `<log_name>.<instance_name>` (twin.node.rosout maps `twin.node.X` to
    `X`): `fmu.left`, or `robot1.fmu.left` for a fleet robot's drive (`log_name` `robot1.fmu`).
    """
    return logging.getLogger(f"twin.node.{log_name}.{instance_name}")


class Messages:
    """Keeps an instance's last log messages for error reports and forwards them to logging.

    The FMU's status picks the level: OK and Pending are INFO, Warning and Discard WARNING; Error and
    Fatal are DEBUG, since the FmuError that follows them repeats the message.
    """

    def __init__(self, label: str, instance_name: str = "fmu", log_name: str = "fmu") -> None:
        self.label = label
        self.recent: collections.deque[tuple[int, str]] = collections.deque(maxlen=8)
        self._unread = 0
        self.logger = fmu_logger(instance_name, log_name)
        self.forwarded = 0

    @property
    def logging_on(self) -> bool:
        """Whether to ask the FMU for its debug (OK-status) messages: when INFO records are wanted."""
        return self.logger.isEnabledFor(logging.INFO)

    def add(self, status: int, category: str, message: str) -> None:
        """Keep one message the FMU logged with `status` and forward it to logging."""
        text = message.strip()
        self.recent.append((status, text))
        self._unread = min(self._unread + 1, len(self.recent))
        if self.forwarded > MAX_FORWARDED_MESSAGES:
            return
        self.forwarded += 1
        if self.forwarded > MAX_FORWARDED_MESSAGES:
            self.logger.warning("%s: over %d log messages; no more are shown", self.label, MAX_FORWARDED_MESSAGES)
            return
        level = _STATUS_LEVELS[status] if 0 <= status < len(_STATUS_LEVELS) else logging.WARNING
        self.logger.log(level, "%s: [%s] %s", self.label, category or "-", text)

    def last(self) -> str:
        """The message the failing call logged: the first since the last call of the worst status."""
        if not self._unread:
            return ""
        unread = list(self.recent)[-self._unread :]
        self._unread = 0
        worst = max(status for status, _ in unread)
        return next(text for status, text in unread if status == worst)


def decode(value: bytes | None) -> str:
    """The text of a C string an FMU passed (empty for NULL; undecodable bytes replaced)."""
    return value.decode("utf-8", "replace") if value else ""


class Adapter(Closing):
    """What both adapters share: buffers, labels, status checks, start values, closing."""

    def __init__(  # noqa: PLR0917 - private, built in one place
        self,
        fmu: Any,
        label: str,
        messages: Messages,
        step_s: float,
        inputs: Sequence[int],
        outputs: Sequence[int],
        api: Api,
    ) -> None:
        self.name = label
        self.step_s = float(step_s)
        self._fmu = fmu
        self._messages = messages
        self._h = float(step_s)
        self._api = api
        self._in_vr = list(inputs)
        self._out_vr = list(outputs)
        self.inputs = (ctypes.c_double * max(1, len(inputs)))()
        self.outputs = (ctypes.c_double * max(1, len(outputs)))()
        self._open = False
        self._failed = False

    def fail(self, function: str, status: int, t_s: float) -> None:
        """Raise the FmuError for a bad status."""
        self._failed = True
        if status == _NONFINITE:
            bad = [(k, v) for k, v in enumerate(self.outputs[: len(self._out_vr)]) if not math.isfinite(v)]
            named = ", ".join(f"{self._output_name(k)} = {v}" for k, v in bad) or "an output"
            msg = (
                f"{self.name} failed at t = {t_s:.6f} s: {function} returned a non-finite output ({named}); "
                "the FMU's model diverged or is faulty"
            )
            raise FmuError(msg)
        text = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
        detail = self._messages.last()
        msg = f"{self.name} failed at t = {t_s:.6f} s: {function} returned {text}" + (f" ({detail})" if detail else "")
        raise FmuError(msg)

    def _output_name(self, k: int) -> str:
        names = self.output_names
        return names[k] if k < len(names) else f"output vr {self._out_vr[k]}"

    def _check_finite(self, function: str, t_s: float) -> None:
        """Raise if an output is NaN or infinite (the Python step paths; the shim checks in C)."""
        total = sum(self.outputs[: self._n_out])
        if not math.isfinite(total) and not all(math.isfinite(v) for v in self.outputs[: self._n_out]):
            self.fail(function, _NONFINITE, t_s)

    output_names: tuple[str, ...] = ()
    step_s: float = 0.0
    _version: int = 0
    # Set by the adapters' `initialize`.
    _c_ptr: ctypes.c_void_p
    _set: Any
    _get: Any
    _do: Any
    _in_refs: Any
    _out_refs: Any
    _n_in: int
    _n_out: int

    # The FMI 2 and FMI 3 adapters below implement these four; this base is never stepped itself.
    def step(self, t_s: float) -> None:
        """Set the inputs, advance one communication step from `t_s`, and read the outputs."""
        raise NotImplementedError

    def read_outputs(self) -> None:
        """Read the mapped outputs into their buffer."""
        raise NotImplementedError

    _FUNCTIONS: tuple[str, str, str] = ("set", "doStep", "get")

    def slot_fields(self) -> dict[str, Any] | None:
        """The values of a `_Slot` for this instance, or None on the convenience API."""
        if self._api != "lowlevel":
            return None
        return {
            "fmi_version": self._version,
            "instance": self._c_ptr.value,
            "set": ctypes.cast(self._set, ctypes.c_void_p).value,
            "get": ctypes.cast(self._get, ctypes.c_void_p).value,
            "step": ctypes.cast(self._do, ctypes.c_void_p).value,
            "in_vr": ctypes.addressof(self._in_refs),
            "n_in": self._n_in,
            "inputs": ctypes.addressof(self.inputs),
            "out_vr": ctypes.addressof(self._out_refs),
            "n_out": self._n_out,
            "outputs": ctypes.addressof(self.outputs),
        }

    def fail_slot(self, statuses: tuple[int, ...], terminate: bool, t_s: float) -> None:
        """Raise for what the shim reported."""
        if terminate and max(statuses) <= 1:
            self._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            statuses = (statuses[0], 3, statuses[2])
        self._raise_first(self._FUNCTIONS, statuses, t_s)

    def _raise_first(self, functions: tuple[str, ...], statuses: tuple[int, ...], t_s: float) -> None:
        for function, status in zip(functions, statuses, strict=True):
            if status > 1:
                self.fail(function, status, t_s)

    def _set_start(self, info: FmuInfo, start: Mapping[str, float]) -> None:
        for var_name, value in start.items():
            var = info.variables.get(var_name)
            if var is None:
                msg = f"{self.name}: no variable {var_name!r} to set"
                raise FmuError(msg)
            if var.causality not in ("parameter", "input", "calculatedParameter", "local", "output") or (
                var.variability == "constant"
            ):
                msg = f"{self.name}: {var_name!r} ({var.causality}, {var.variability}) cannot be set"
                raise FmuError(msg)
            self._set_one(var, value)

    def _set_one(self, var: VariableInfo, value: float) -> None:
        """Set one variable through the FMI version's typed setter."""
        raise NotImplementedError

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        """Instantiate, apply start values and enter and leave initialisation mode."""
        raise NotImplementedError

    def _call(self, function: str, t_s: float, action: Any) -> None:
        try:
            action()
        except fmpy.fmi1.FMICallException as err:
            self.fail(function, int(err.status), t_s)

    def _step_convenience(self, t_s: float) -> None:
        """The same step through FMPy's wrappers (list building and checks in Python on every call)."""
        fmu = self._fmu
        setter, getter = (fmu.setReal, fmu.getReal) if self._version == 2 else (fmu.setFloat64, fmu.getFloat64)
        try:
            setter(self._in_vr, list(self.inputs)[: self._n_in])
            fmu.doStep(t_s, self._h)
            values = getter(self._out_vr)
        except fmpy.fmi1.FMICallException as err:
            self.fail(err.function, int(err.status), t_s)
        for k, value in enumerate(values):
            self.outputs[k] = value
        self._check_finite(self._FUNCTIONS[2], t_s)

    def close(self) -> None:
        """Terminate (unless the instance failed) and free the instance; idempotent."""
        if not self._open:
            return
        self._open = False
        fmu = self._fmu
        try:
            if not self._failed:
                fmu.terminate()
        except Exception as err:  # terminate may fail after an error; freeing still must happen
            _log.debug("%s: terminate: %s", self.name, err)
        try:
            fmu.freeInstance()
        except Exception as err:
            _log.debug("%s: freeInstance: %s", self.name, err)
