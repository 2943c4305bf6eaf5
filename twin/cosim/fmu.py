"""Load an FMU and create its instances: `FmuFile(path)` picks the FMI 2 or FMI 3 adapter once.

`FmuFile(path)` reads and extracts an FMU (a context manager that removes the extraction).
`FmuFile.instantiate(...)` returns a `Stepper` (`twin.cosim.adapter`): one initialised instance
whose inputs and outputs are fixed lists of Real/Float64 value references, stepped with
`step(t_s)`. The low-level adapters call the FMU's C functions directly with prebuilt ctypes
arguments (about 1 µs a call); the `convenience` API goes through FMPy's Python wrappers (several
µs a call) and exists to measure the difference. A Model Exchange FMU gets an adapter with the
same interface that integrates it between communication points (`twin.cosim.exchange`).

The adapter is chosen once, at instantiation; `step` has no version branches. A NULL instance or
a failed set-up raises `FmuError` naming the FMU and the instance.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import fmpy
import fmpy.fmi2
import fmpy.fmi3

from twin.core.closing import Closing
from twin.core.errors import FmuError
from twin.cosim.adapter import Adapter, Api, Messages, Stepper
from twin.cosim.description import REAL_TYPES, binary_problem, fmpy_class, read_fmu_info, stepping_problem
from twin.cosim.fmi2 import Fmi2, Fmi2Exchange
from twin.cosim.fmi3 import Fmi3, Fmi3Exchange

__all__ = ["FmuFile"]


class FmuFile(Closing):
    """An extracted FMU whose Co-Simulation instances can be created (a context manager)."""

    def __init__(self, path: Path) -> None:
        """Read and extract `path`.

        Raises:
            FmuError: If the FMU cannot be read or has no Co-Simulation interface for FMI 2 or 3.
        """
        self.info = read_fmu_info(path)
        self.path = path
        if self.info.major_version not in (2, 3):
            msg = f"{path}: FMI {self.info.fmi_version} is not supported (FMI 2.0 and 3.0 are)"
            raise FmuError(msg)
        problem = stepping_problem(self.info)
        if problem is not None:
            msg = f"{path}: {problem}"
            raise FmuError(msg)
        try:
            self._dir = Path(fmpy.extract(str(path)))
        except Exception as err:
            msg = f"{path}: cannot extract ({err})"
            raise FmuError(msg) from None
        problem = binary_problem(self.info, self._dir)
        if problem is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            msg = f"{path}: {problem}"
            raise FmuError(msg)
        self._instances: list[Stepper] = []

    def close(self) -> None:
        """Close every instance and remove the extraction."""
        for inst in self._instances:
            inst.close()
        self._instances.clear()
        shutil.rmtree(self._dir, ignore_errors=True)

    @property
    def label(self) -> str:
        """`model name (file name)`, for messages."""
        return f"{self.info.model_name} ({self.path.name})"

    def instantiate(
        self,
        name: str,
        *,
        step_s: float,
        inputs: Sequence[int],
        outputs: Sequence[int],
        start: Mapping[str, float] | None = None,
        start_time_s: float = 0.0,
        api: Api = "lowlevel",
        purpose: str = "",
        log_name: str = "fmu",
    ) -> Stepper:
        """Create, set up and initialise one instance.

        Args:
            name: Instance name (appears in messages).
            step_s: Fixed communication step, s.
            inputs: Value references written from `Stepper.inputs` before each step (Real/Float64).
            outputs: Value references read into `Stepper.outputs` after each step.
            start: Variable name → value set before initialisation (parameters, start values), in
                the FMU's own units.
            start_time_s: Start time, s.
            api: `lowlevel` (direct C calls) or `convenience` (FMPy's wrappers).
            purpose: What the instance is for, said after its name in messages when the name alone
                means nothing to the user (an instance the twin makes for itself).
            log_name: Where the instance's log messages go (`fmu_logger`): `robot1.fmu` for a
                fleet robot's, so its lines name the robot.

        Raises:
            FmuError: If the library cannot be loaded, instantiation returns NULL, a start value
                names an unknown or non-settable variable, or initialisation fails.
        """
        label = f"{self.label} instance {name!r}" + (f" ({purpose})" if purpose else "")
        if self.info.instantiated_once and self._instances:
            msg = (
                f"{label}: the FMU declares canBeInstantiatedOnlyOncePerProcess and this process has an instance "
                f"of it already ({self._instances[0].name.rsplit(' instance ', 1)[-1]}); run each instance in its "
                "own process (drive.isolation: process)"
            )
            raise FmuError(msg)
        messages = Messages(label, name, log_name)
        kwargs = {
            "guid": self.info.guid,
            "unzipDirectory": str(self._dir),
            "modelIdentifier": self.info.co_simulation or self.info.model_exchange,
            "instanceName": name,
        }
        exchange = self.info.co_simulation is None
        try:
            fmu: Any = fmpy_class(self.info)(**kwargs)
        except Exception as err:
            platform = fmpy.platform if self.info.major_version == 2 else fmpy.platform_tuple
            text = str(err).replace(f"{self._dir}/", "")  # the member, not the folder it was extracted to
            msg = f"{label}: cannot load the binary for {platform}: {text}"
            raise FmuError(msg) from None
        stepper: Adapter
        by_vr = {v.value_reference: v.name for v in self.info.variables.values() if v.type in REAL_TYPES}
        try:
            if exchange and self.info.major_version == 3:
                stepper = Fmi3Exchange(fmu, label, messages, step_s, inputs, outputs, api)
            elif exchange:
                stepper = Fmi2Exchange(fmu, label, messages, step_s, inputs, outputs, api)
            elif self.info.major_version == 2:
                stepper = Fmi2(fmu, label, messages, step_s, inputs, outputs, api)
            else:
                stepper = Fmi3(fmu, label, messages, step_s, inputs, outputs, api)
            stepper.output_names = tuple(by_vr.get(vr, f"vr {vr}") for vr in outputs)
            stepper.initialize(self.info, start or {}, start_time_s)
        except FmuError:
            raise
        except Exception as err:  # a library or ctypes failure during setup
            msg = f"{label}: setup failed: {err}"
            raise FmuError(msg) from None
        self._instances.append(stepper)
        return stepper
