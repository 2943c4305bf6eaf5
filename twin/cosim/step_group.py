"""Step several FMU instances together, one communication step at a time, in one C call when possible."""

from __future__ import annotations

import ctypes
import functools
import logging
from collections.abc import Callable, Sequence
from typing import Any

from twin.core.errors import FmuError
from twin.cosim import build
from twin.cosim.adapter import Adapter, Stepper

__all__ = ["StepGroup"]

_log = logging.getLogger(__name__)


class _Slot(ctypes.Structure):
    """One instance for the stepping shim (`TwinSlot` in fmus/common/step_shim.c)."""

    _fields_ = (
        ("fmi_version", ctypes.c_int),
        ("instance", ctypes.c_void_p),
        ("set", ctypes.c_void_p),
        ("get", ctypes.c_void_p),
        ("step", ctypes.c_void_p),
        ("in_vr", ctypes.c_void_p),
        ("n_in", ctypes.c_size_t),
        ("inputs", ctypes.c_void_p),
        ("out_vr", ctypes.c_void_p),
        ("n_out", ctypes.c_size_t),
        ("outputs", ctypes.c_void_p),
        ("status", ctypes.c_int * 3),
        ("terminate", ctypes.c_int),
    )


class StepGroup:
    """Steps several instances together, one communication step at a time.

    With the low-level API a small compiled shim (fmus/common/step_shim.c) sets the inputs, steps and
    reads the outputs of every instance in one C call; with the convenience API, or when the shim
    cannot be built, the instances are stepped one after the other from Python.

    The hot path is `step_next()`: it steps from `index * step_s` and counts the step, and returns -1,
    or the position of the instance that failed (then call `raise_failure`). Step loops bind it once.
    """

    def __init__(self, steppers: Sequence[Stepper], *, step_s: float, start_index: int = 0) -> None:
        """Group `steppers` (all created by this module, with communication step `step_s`)."""
        self._steppers = tuple(steppers)
        self._h = step_s
        self._index = ctypes.c_longlong(start_index)
        self._shim: Any = None
        self.step_next: Callable[[], int] = self._step_next_each
        adapters = [s for s in self._steppers if isinstance(s, Adapter) and s.slot_fields() is not None]
        if len(adapters) == len(self._steppers) and adapters:
            try:
                library = ctypes.CDLL(str(build.build_shim()))
            except (FmuError, OSError) as err:
                _log.warning("stepping FMUs from Python: %s", err)
            else:
                self._library = library
                self._slots = (_Slot * len(adapters))()
                for slot, adapter in zip(self._slots, adapters, strict=True):
                    for name, value in (adapter.slot_fields() or {}).items():
                        setattr(slot, name, value)
                self._h_c = ctypes.c_double(step_s)
                shim = library.twin_step_next
                shim.restype = ctypes.c_int  # no argtypes: every argument is prebuilt below
                self._shim = shim
                self.step_next = functools.partial(
                    shim, self._slots, len(adapters), ctypes.byref(self._index), ctypes.byref(self._h_c)
                )

    @property
    def compiled(self) -> bool:
        """Whether the compiled shim steps the group."""
        return self._shim is not None

    @property
    def index(self) -> int:
        """Communication steps taken so far."""
        return int(self._index.value)

    @property
    def size(self) -> int:
        """How many instances the group steps."""
        return len(self._steppers)

    def shim(self) -> tuple[ctypes.CDLL, ctypes.Array[_Slot], ctypes.c_longlong] | None:
        """The shim library, the slots and the step counter, for a compiled loop that steps the group.

        None when the group is stepped from Python. A compiled loop steps through `twin_step_next`
        with these slots and this counter, so `index` and `raise_failure` stay right.
        """
        if self._shim is None:
            return None
        return self._library, self._slots, self._index

    def step(self) -> None:
        """Take one communication step (not the hot path: it checks and raises itself).

        Raises:
            FmuError: If an instance fails.
        """
        failed = self.step_next()
        if failed >= 0:
            self.raise_failure(failed)

    def _step_next_each(self) -> int:
        t_s = self._index.value * self._h
        for stepper in self._steppers:
            stepper.step(t_s)  # raises itself
        self._index.value += 1
        return -1

    def raise_failure(self, failed: int) -> None:
        """Raise the FmuError for the instance at position `failed` after `step_next` reported it."""
        slot = self._slots[failed]
        adapter = self._steppers[failed]
        assert isinstance(adapter, Adapter)
        adapter.fail_slot(tuple(slot.status), bool(slot.terminate), self._index.value * self._h)
