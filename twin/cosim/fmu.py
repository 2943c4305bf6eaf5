"""Load FMUs and step their instances fast: FMI 2.0 and 3.0 Co-Simulation behind one Protocol.

`FmuFile(path)` reads and extracts an FMU (a context manager that removes the extraction).
`FmuFile.instantiate(...)` returns a `Stepper`: one initialised Co-Simulation instance whose inputs
and outputs are fixed lists of Real/Float64 value references. Its hot path is `step(t_s)`: set the
inputs from `inputs` (a ctypes double array the caller writes), one doStep, read the outputs into
`outputs` (a ctypes double array the caller reads). The low-level adapters call the FMU's C
functions directly with prebuilt ctypes arguments (about 1 µs a call); the `convenience` API goes
through FMPy's Python wrappers (several µs a call) and exists to measure the difference.

The adapter is chosen once, at instantiation; `step` has no version branches. Every FMU status of
Discard, Error or Fatal (and a NULL instance) raises `FmuError` naming the FMU, the instance, the sim
time, the function, the status and the FMU's last log message.
"""

from __future__ import annotations

import collections
import ctypes
import functools
import itertools
import logging
import math
import shutil
import weakref
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal, Protocol

import fmpy
import fmpy.fmi2
import fmpy.fmi3
from fmpy.model_description import read_model_description

from twin.core.closing import Closing
from twin.core.errors import FmuError
from twin.cosim.units import Unit

__all__ = [
    "ME_SOLVER",
    "Api",
    "FmuFile",
    "FmuInfo",
    "StepGroup",
    "Stepper",
    "VariableInfo",
    "binary_problem",
    "fmu_file_problem",
    "fmu_logger",
    "read_fmu_info",
    "stepping",
    "stepping_problem",
]

_log = logging.getLogger(__name__)

Api = Literal["lowlevel", "convenience"]

_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
# Not an FMI status: the get call succeeded but an output is NaN or infinite (TWIN_STATUS_NONFINITE
# in fmus/common/step_shim.h).
_NONFINITE = 6
_REAL_TYPES = frozenset({"Real", "Float64", "Float32"})


@dataclass(frozen=True, kw_only=True, slots=True)
class VariableInfo:
    """One model variable as the model description declares it."""

    name: str
    value_reference: int
    type: str
    causality: str
    variability: str
    unit: str | None
    start: str | None
    description: str
    dimensions: int = 0  # FMI 3 array dimensions (0: a scalar)


def _identifier(interface: object) -> str | None:
    """The model identifier of an fmpy interface description (None when the FMU lacks it)."""
    if interface is None:
        return None
    return str(getattr(interface, "modelIdentifier", "") or "") or None


@dataclass(frozen=True, kw_only=True, slots=True)
class FmuInfo:
    """What twin needs from a model description."""

    path: Path
    fmi_version: str
    model_name: str
    description: str
    generation_tool: str
    co_simulation: str | None  # model identifier, or None without a Co-Simulation interface
    model_exchange: str | None
    guid: str
    scheduled_execution: str | None = None  # FMI 3 Scheduled Execution (not stepped by the twin)
    n_states: int = 0  # continuous states (Model Exchange)
    n_event_indicators: int = 0
    variable_step: bool
    # canBeInstantiatedOnlyOncePerProcess of the interface the twin steps (Co-Simulation, else Model Exchange).
    instantiated_once: bool = False
    variables: Mapping[str, VariableInfo]
    units: Mapping[str, Unit]

    @property
    def major_version(self) -> int:
        """1, 2 or 3."""
        return int(self.fmi_version.split(".")[0])


def read_fmu_info(path: Path) -> FmuInfo:
    """Read an FMU's model description.

    Raises:
        FmuError: If the file is missing, not a zip, or its model description is invalid.
    """
    problem = fmu_file_problem(path)
    if problem is not None:
        msg = f"{path}: {problem}"
        raise FmuError(msg)
    if not zipfile.is_zipfile(path):
        msg = f"{path}: not an FMU (not a zip archive)"
        raise FmuError(msg)
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as err:  # FMPy raises bare Exceptions and XML errors of several kinds
        try:
            problem = _description_problem(path)
        except Exception:  # a diagnosis that fails itself leaves FMPy's message, never a traceback
            problem = None
        if problem is None:
            first = str(err).strip().splitlines()
            problem = f"invalid modelDescription.xml: {first[0] if first else type(err).__name__}"
        msg = f"{path}: {problem}"
        raise FmuError(msg) from None
    variables: dict[str, VariableInfo] = {}
    for v in md.modelVariables:
        problem = _start_problem(v)
        if problem is not None:
            msg = f"{path}: modelDescription.xml: {problem}; fix the start value in the FMU's model description"
            raise FmuError(msg)
        unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
        variables[v.name] = VariableInfo(
            name=v.name,
            value_reference=int(v.valueReference),
            type=str(v.type),
            causality=str(v.causality or "local"),
            variability=str(v.variability or "continuous"),
            unit=unit,
            start=None if v.start is None else str(v.start),
            description=v.description or "",
            dimensions=len(getattr(v, "dimensions", None) or ()),
        )
    units: dict[str, Unit] = {}
    for u in md.unitDefinitions or ():
        b = u.baseUnit
        if u.name and b is not None:
            dims = (b.kg, b.m, b.s, b.A, b.K, b.mol, b.cd, b.rad)
            units[u.name] = Unit(name=u.name, dims=tuple(int(d) for d in dims), factor=b.factor, offset=b.offset)
    cs = md.coSimulation
    stepped = cs if cs is not None else md.modelExchange
    return FmuInfo(
        path=path,
        fmi_version=str(md.fmiVersion),
        model_name=md.modelName or "",
        description=md.description or "",
        generation_tool=md.generationTool or "",
        co_simulation=cs.modelIdentifier if cs is not None else None,
        model_exchange=md.modelExchange.modelIdentifier if md.modelExchange is not None else None,
        guid=md.guid or "",
        scheduled_execution=_identifier(getattr(md, "scheduledExecution", None)),
        n_states=len(md.derivatives or ()),
        n_event_indicators=int(md.numberOfEventIndicators or 0),
        variable_step=bool(cs.canHandleVariableCommunicationStepSize) if cs is not None else False,
        instantiated_once=bool(getattr(stepped, "canBeInstantiatedOnlyOncePerProcess", False)),
        variables=MappingProxyType(variables),
        units=MappingProxyType(units),
    )


# Variable types whose start value is a number (FMI 2 and 3 spellings); arrays list one per element.
_NUMERIC_TYPES = frozenset(
    {"Real", "Integer", "Enumeration", "Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16"}
    | {"Int32", "UInt32", "Int64", "UInt64"}
)


def _start_problem(variable: Any) -> str | None:
    """Why an FMPy model variable's start value is not a number its type needs (None when it is, or has none)."""
    if variable.start is None or str(variable.type) not in _NUMERIC_TYPES:
        return None
    text = str(variable.start)
    try:
        for item in text.split() or [text]:
            float(item)
    except ValueError:
        return f'variable {variable.name!r} ({variable.type}) has start="{text}", which is not a number'
    return None


def fmu_file_problem(path: Path) -> str | None:
    """Why `path` is not a file to read as an FMU (missing, or a folder), as a phrase; None when it is a file."""
    if path.is_dir():
        if (path / "modelDescription.xml").is_file():
            return (
                "is a folder (an unzipped FMU), where an .fmu file is expected; zip its contents into one: "
                f"(cd {path} && zip -r ../{path.name}.fmu .)"
            )
        return "is a folder, where an .fmu file is expected"
    if not path.is_file():
        return "FMU file not found"
    return None


_FMI3_VARIABLE_TAGS = frozenset(
    {"Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
    | {"Boolean", "String", "Binary", "Enumeration", "Clock"}
)


def _description_problem(path: Path) -> str | None:
    """What is wrong with the FMU's model description, in FMI terms; None when nothing known is.

    Called only after FMPy failed to read it, to say why in words a vendor can act on.
    """
    from lxml import etree

    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        if "modelDescription.xml" not in names:
            nested = sorted(n for n in names if n.endswith("/modelDescription.xml"))
            if nested:
                folder = nested[0].rsplit("/", 1)[0]
                return (
                    f"no modelDescription.xml at the archive's root, only {nested[0]}; "
                    f"zip the contents of {folder}/, not the folder itself"
                )
            return "no modelDescription.xml in the archive; an FMU has one at its root (is this an FMU?)"
        data = archive.read("modelDescription.xml")
    try:
        root = etree.fromstring(data, etree.XMLParser(resolve_entities=False, no_network=True))
    except etree.XMLSyntaxError:
        return None  # the parser's own message says where
    if etree.QName(root).localname != "fmiModelDescription":
        return f"modelDescription.xml: the root element is <{etree.QName(root).localname}>, not <fmiModelDescription>"
    version = root.get("fmiVersion")
    if version is None:
        return 'modelDescription.xml: <fmiModelDescription> has no fmiVersion attribute (FMI 2.0: "2.0", 3.0: "3.0")'
    variables = root.find("ModelVariables")
    tags = {child.tag for child in variables} if variables is not None else set()
    if version == "1.0":
        if root.find("CoSimulation") is not None or root.find("ModelExchange") is not None:
            return (
                'modelDescription.xml says fmiVersion="1.0" but is laid out as FMI 2.0 (<CoSimulation>/'
                "<ModelExchange> elements); FMI 1.0 is not supported anyway (FMI 2.0 and 3.0 are)"
            )
        return "modelDescription.xml is not valid FMI 1.0, and FMI 1.0 is not supported (FMI 2.0 and 3.0 are)"
    if version != "2.0" and not version.startswith("3."):
        return f'modelDescription.xml: fmiVersion="{version}" is no FMI version twin reads (2.0 and 3.0 are)'
    if version.startswith("3.") and "ScalarVariable" in tags:
        return (
            f'modelDescription.xml says fmiVersion="{version}" but declares FMI 2.0 <ScalarVariable> elements; '
            "fix fmiVersion or the variables"
        )
    if version == "2.0" and tags & _FMI3_VARIABLE_TAGS:
        found = sorted(tags & _FMI3_VARIABLE_TAGS)[0]
        return (
            f'modelDescription.xml says fmiVersion="2.0" but declares FMI 3.0 variable elements (<{found}>); '
            "fix fmiVersion or the variables"
        )
    if version == "2.0":
        count = sum(1 for child in variables if child.tag == "ScalarVariable") if variables is not None else 0
        structure = root.find("ModelStructure")
        indices = [] if structure is None else [u.get("index") for u in structure.iter("Unknown")]
        for index in indices:
            if index is None or not index.isdigit() or not 1 <= int(index) <= count:
                return (
                    f"modelDescription.xml: <ModelStructure> refers to variable index {index}, but <ModelVariables> "
                    f"declares {count} variable(s); indices count the ScalarVariables from 1"
                )
    return None


def _binary_member(info: FmuInfo) -> str:
    """Where this platform's binary of `info` sits inside the FMU (`binaries/linux64/NAME.so`)."""
    platform = fmpy.platform if info.major_version < 3 else fmpy.platform_tuple
    identifier = info.co_simulation or info.model_exchange or info.model_name
    return f"binaries/{platform}/{identifier}{fmpy.sharedLibraryExtension}"


def _entry_point(info: FmuInfo) -> str:
    """The instantiate function twin calls first: its absence means the binary is not this FMI version's."""
    if info.major_version < 3:
        return "fmi2Instantiate"
    return "fmi3InstantiateCoSimulation" if info.co_simulation else "fmi3InstantiateModelExchange"


def _load_problem(info: FmuInfo, library: Path, member: str) -> str | None:
    """Why the shared library at `library` (the FMU's `member`) cannot be loaded, or None."""
    try:
        dll = ctypes.CDLL(str(library))
    except OSError as err:
        # The loader names the extracted file: say which member of the FMU it was instead.
        text = str(err).replace(f"{library}: ", "").replace(str(library), member).strip()
        return f"{member} cannot be loaded on this platform: {text or type(err).__name__}"
    entry = _entry_point(info)
    if not hasattr(dll, entry):
        return f"{member} has no {entry} function; it is not an FMI {info.fmi_version} binary"
    return None


def binary_problem(info: FmuInfo, extracted: Path | None = None) -> str | None:
    """Why this platform's binary of the FMU is missing or cannot be loaded (None when it loads).

    Args:
        info: The FMU's description (`read_fmu_info`).
        extracted: The folder the FMU was extracted to; when None, the binary is read from the zip.

    Returns:
        A phrase for a one-line error, naming the member (`binaries/linux64/NAME.so`) and the
        loader's message, or naming the platforms the FMU does have binaries for. None as well
        for FMI versions twin does not step (`stepping_problem` names those).
    """
    if info.major_version not in (2, 3):
        return None  # not steppable anyway: `stepping_problem` says why
    member = _binary_member(info)
    with zipfile.ZipFile(info.path) as archive:
        names = archive.namelist()
        if member not in names:
            others = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
            has_sources = any(n.startswith("sources/") for n in names)
            found = f"it has binaries for {', '.join(others)} only" if others else "it has no binaries"
            if has_sources:
                found += " (and sources: compile them for this platform)"
            return f"no binary for this platform: {member} is missing; {found}"
        if extracted is not None:
            return _load_problem(info, extracted / member, member)
        import tempfile

        with tempfile.TemporaryDirectory(prefix="twin-fmu-") as tmp:
            target = Path(tmp) / Path(member).name
            with archive.open(member) as src, target.open("wb") as dst:
                shutil.copyfileobj(src, dst)
            return _load_problem(info, target, member)


# The solver a Model Exchange FMU is integrated with between communication points (fmpy's SUNDIALS
# CVode: BDF with Newton iteration, so stiff motors with microsecond electrical time constants are
# stable at any communication step; explicit Euler at the step would not be).
ME_SOLVER = "CVode"
ME_RELATIVE_TOLERANCE = 1e-6


def stepping_problem(info: FmuInfo) -> str | None:
    """Why twin cannot step this FMU (None when it can), as a phrase for a one-line error."""
    if info.major_version not in (2, 3):
        return f"FMI {info.fmi_version} is not supported (FMI 2.0 and 3.0 are)"
    if info.co_simulation is not None:
        return None
    if info.model_exchange is None:
        only = " (Scheduled Execution only)" if info.scheduled_execution else ""
        return f"no Co-Simulation or Model Exchange interface{only}"
    return None


def stepping(info: FmuInfo) -> str:
    """How twin steps this FMU: `Co-Simulation` or `Model Exchange (solver: CVode)`.

    Raises:
        FmuError: If twin cannot step it (the reason from `stepping_problem`).
    """
    problem = stepping_problem(info)
    if problem is not None:
        msg = f"{info.path}: {problem}"
        raise FmuError(msg)
    if info.co_simulation is not None:
        return "Co-Simulation"
    return f"Model Exchange (solver: {ME_SOLVER}, relative tolerance {ME_RELATIVE_TOLERANCE:g})"


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
        adapters = [s for s in self._steppers if isinstance(s, _Base) and s.slot_fields() is not None]
        if len(adapters) == len(self._steppers) and adapters:
            from twin.cosim.build import build_shim

            try:
                library = ctypes.CDLL(str(build_shim()))
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
        assert isinstance(adapter, _Base)
        adapter.fail_slot(tuple(slot.status), bool(slot.terminate), self._index.value * self._h)


# The Python logging level of each FMI status (OK, Warning, Discard, Error, Fatal, Pending). Error
# and Fatal messages are DEBUG: twin raises an FmuError carrying that message (one line, not two).
_STATUS_LEVELS = (logging.INFO, logging.WARNING, logging.WARNING, logging.DEBUG, logging.DEBUG, logging.INFO)
# An FMU that logs on every step would flood the console and /rosout: past this many lines an
# instance's messages are kept for its error reports only (one line says so).
MAX_FORWARDED_MESSAGES = 1000


def fmu_logger(instance_name: str) -> logging.Logger:
    """The logger an FMU instance's own log messages go to.

    Its records reach the console (INFO with `-v`, warnings always) and, during `twin simulate`,
    `/rosout` under the name `fmu.<instance_name>` (twin.node.rosout maps `twin.node.X` to `X`).
    """
    return logging.getLogger(f"twin.node.fmu.{instance_name}")


class _Messages:
    """Keeps an instance's last log messages for error reports and forwards them to logging.

    The FMU's status picks the level: OK and Pending are INFO, Warning and Discard WARNING; Error and
    Fatal are DEBUG, since the FmuError that follows them repeats the message.
    """

    def __init__(self, label: str, instance_name: str = "fmu") -> None:
        self.label = label
        self.recent: collections.deque[tuple[int, str]] = collections.deque(maxlen=8)
        self._unread = 0
        self.logger = fmu_logger(instance_name)
        self.forwarded = 0

    @property
    def logging_on(self) -> bool:
        """Whether to ask the FMU for its debug (OK-status) messages: when INFO records are wanted."""
        return self.logger.isEnabledFor(logging.INFO)

    def add(self, status: int, category: str, message: str) -> None:
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


# FMI 2 loggers are variadic; FMPy's proxy formats the message in C and calls one process-wide
# Python logger (the last one registered). So every instance gets that same logger, kept alive
# here, and its componentEnvironment: a number that routes the message to the instance's _Messages.
_ROUTES: weakref.WeakValueDictionary[int, _Messages] = weakref.WeakValueDictionary()
_ROUTE_IDS = itertools.count(1)


def _route(messages: _Messages) -> int:
    key = next(_ROUTE_IDS)
    _ROUTES[key] = messages
    return key


def _fmi2_logger(env: int | None, instance: bytes, status: int, category: bytes, message: bytes) -> None:
    messages = _ROUTES.get(env or 0)
    if messages is not None:
        messages.add(status, _decode(category), _decode(message))


_FMI2_LOGGER = fmpy.fmi2.fmi2CallbackLoggerTYPE(_fmi2_logger)


def _decode(value: bytes | None) -> str:
    return value.decode("utf-8", "replace") if value else ""


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
        messages = _Messages(label, name)
        kwargs = {
            "guid": self.info.guid,
            "unzipDirectory": str(self._dir),
            "modelIdentifier": self.info.co_simulation or self.info.model_exchange,
            "instanceName": name,
        }
        exchange = self.info.co_simulation is None
        try:
            if exchange:
                model_class = fmpy.fmi2.FMU2Model if self.info.major_version == 2 else fmpy.fmi3.FMU3Model
                fmu: Any = model_class(**kwargs)
            elif self.info.major_version == 2:
                fmu = fmpy.fmi2.FMU2Slave(**kwargs)
            else:
                fmu = fmpy.fmi3.FMU3Slave(**kwargs)
        except Exception as err:
            platform = fmpy.platform if self.info.major_version == 2 else fmpy.platform_tuple
            msg = f"{label}: cannot load the binary for {platform}: {err}"
            raise FmuError(msg) from None
        stepper: _Base
        by_vr = {v.value_reference: v.name for v in self.info.variables.values() if v.type in _REAL_TYPES}
        try:
            if exchange and self.info.major_version == 3:
                stepper = _Fmi3Exchange(fmu, label, messages, step_s, inputs, outputs, api)
            elif exchange:
                stepper = _Fmi2Exchange(fmu, label, messages, step_s, inputs, outputs, api)
            elif self.info.major_version == 2:
                stepper = _Fmi2(fmu, label, messages, step_s, inputs, outputs, api)
            else:
                stepper = _Fmi3(fmu, label, messages, step_s, inputs, outputs, api)
            stepper.output_names = tuple(by_vr.get(vr, f"vr {vr}") for vr in outputs)
            stepper.initialize(self.info, start or {}, start_time_s)
        except FmuError:
            raise
        except Exception as err:  # a library or ctypes failure during setup
            msg = f"{label}: setup failed: {err}"
            raise FmuError(msg) from None
        self._instances.append(stepper)
        return stepper


class _Base(Closing):
    """What both adapters share: buffers, labels, status checks, start values, closing."""

    def __init__(  # noqa: PLR0917 - private, built in one place
        self,
        fmu: Any,
        label: str,
        messages: _Messages,
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
    # Set by the Model Exchange adapters (`_split_inputs`): where the discrete and continuous inputs are.
    _discrete_at: tuple[int, ...]
    _continuous_at: tuple[int, ...]
    _discrete_refs: Any
    _continuous_refs: Any
    _continuous_values: Any
    _held: tuple[float, ...] | None

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


class _Fmi2(_Base):
    """FMI 2.0 Co-Simulation adapter."""

    _version = 2
    _FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
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
        c = self._c_ptr
        set_status = self._set(c, self._in_refs, self._n_in, self.inputs)
        step_status = self._do(c, t_s, self._h, 1)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs)
        if (set_status | step_status | get_status) > 1:
            self._raise_first(("fmi2SetReal", "fmi2DoStep", "fmi2GetReal"), (set_status, step_status, get_status), t_s)
        self._check_finite("fmi2GetReal", t_s)

    def read_outputs(self) -> None:
        status = self._get(self._c_ptr, self._out_refs, self._n_out, self.outputs)
        if status > 1:
            self.fail("fmi2GetReal", status, 0.0)


class _HeldInputs:
    """fmpy's solvers apply an input at every evaluation; the inputs here are held over each step."""

    def apply(self, time: float) -> None:
        """Nothing to do: `step` sets the inputs before integrating."""


class _Fmi2Exchange(_Fmi2):
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
        if _event_update(self):
            msg = f"{self.name}: the FMU asked to terminate during its initial event update"
            raise FmuError(msg)
        fmu.enterContinuousTimeMode()
        self._solver = _cvode(
            fmu,
            fmu.getDerivatives,
            fmu.getNominalsOfContinuousStates,
            nx=self._nx,
            nz=self._nz,
            t0_s=self._t0,
            max_step_s=self._h,
        )

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        self._nx = info.n_states
        self._nz = info.n_event_indicators
        self._t0 = start_time_s
        self._next_event_s = math.inf
        if self._api == "convenience":
            self._api = "lowlevel"  # one stepping path: the solver calls fmpy's wrappers either way
        _split_inputs(self, info)
        super().initialize(info, start, start_time_s)

    def slot_fields(self) -> dict[str, Any] | None:
        """None: the compiled shim only calls doStep; Model Exchange is integrated from Python."""
        return None

    def step(self, t_s: float) -> None:
        c = self._c_ptr
        _set_inputs(self, t_s)
        terminate = _integrate(self, t_s)
        if terminate:
            self._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            self.fail("fmi2CompletedIntegratorStep", 3, t_s)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs)
        if get_status > 1:
            self.fail("fmi2GetReal", get_status, t_s)
        self._check_finite("fmi2GetReal", t_s)


class _Fmi3(_Base):
    """FMI 3.0 Co-Simulation adapter."""

    _version = 3
    _FUNCTIONS = ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64")
    _INSTANTIATE = "fmi3InstantiateCoSimulation"

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        fmu = self._fmu
        messages = self._messages

        def log_message(env: Any, status: int, category: bytes, message: bytes) -> None:
            messages.add(status, _decode(category), _decode(message))

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
        status = self._get(self._c_ptr, self._out_refs, self._n_out, self.outputs, self._n_out)
        if status > 1:
            self.fail("fmi3GetFloat64", status, 0.0)


class _Fmi3Exchange(_Fmi3):
    """FMI 3.0 Model Exchange adapter: as `_Fmi2Exchange`, through the FMI 3 functions."""

    _FUNCTIONS = ("fmi3SetFloat64", f"{ME_SOLVER} integration", "fmi3GetFloat64")
    _INSTANTIATE = "fmi3InstantiateModelExchange"
    _UPDATE = "fmi3UpdateDiscreteStates"

    def _write(self, refs: Any, n: int, values: Any) -> int:
        """Set `n` Float64 inputs; the status."""
        status: int = self._set(self._c_ptr, refs, n, values, n)
        return status

    def initialize(self, info: FmuInfo, start: Mapping[str, float], start_time_s: float) -> None:
        self._nx = info.n_states
        self._nz = info.n_event_indicators
        self._t0 = start_time_s
        self._next_event_s = math.inf
        if self._api == "convenience":
            self._api = "lowlevel"  # one stepping path: the solver calls fmpy's wrappers either way
        _split_inputs(self, info)
        super().initialize(info, start, start_time_s)

    def _bind_step(self, dll: Any) -> None:
        fmu = self._fmu
        # Array states count element by element: ask the instance (the description lists variables).
        self._nx = int(fmu.getNumberOfContinuousStates())
        self._nz = int(fmu.getNumberOfEventIndicators())
        self._update_events = fmu.updateDiscreteStates
        if _event_update(self):
            msg = f"{self.name}: the FMU asked to terminate during its initial event update"
            raise FmuError(msg)
        fmu.enterContinuousTimeMode()
        self._solver = _cvode(
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
        c = self._c_ptr
        _set_inputs(self, t_s)
        terminate = _integrate(self, t_s)
        if terminate:
            self._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            self.fail("fmi3CompletedIntegratorStep", 3, t_s)
        get_status = self._get(c, self._out_refs, self._n_out, self.outputs, self._n_out)
        if get_status > 1:
            self.fail("fmi3GetFloat64", get_status, t_s)
        self._check_finite("fmi3GetFloat64", t_s)


def _cvode(fmu: Any, get_dx: Any, get_nominals: Any, *, nx: int, nz: int, t0_s: float, max_step_s: float) -> Any:
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
        input=_HeldInputs(),
        startTime=t0_s,
        maxStep=max_step_s,
        relativeTolerance=ME_RELATIVE_TOLERANCE,
    )


def _split_inputs(adapter: _Fmi2Exchange | _Fmi3Exchange, info: FmuInfo) -> None:
    """Find the adapter's discrete inputs (variability `discrete`), which FMI lets change at events only."""
    variability = {v.value_reference: v.variability for v in info.variables.values() if v.type in _REAL_TYPES}
    vrs = adapter._in_vr
    discrete = [k for k, vr in enumerate(vrs) if variability.get(vr) == "discrete"]
    continuous = [k for k in range(len(vrs)) if k not in discrete]
    adapter._discrete_at = tuple(discrete)
    adapter._continuous_at = tuple(continuous)
    adapter._discrete_refs = (ctypes.c_uint * max(1, len(discrete)))(*(vrs[k] for k in discrete))
    adapter._continuous_refs = (ctypes.c_uint * max(1, len(continuous)))(*(vrs[k] for k in continuous))
    adapter._continuous_values = (ctypes.c_double * max(1, len(continuous)))()
    adapter._held = None  # the discrete inputs' values last set (None: not yet)


def _set_inputs(adapter: _Fmi2Exchange | _Fmi3Exchange, t_s: float) -> None:
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
        if _event_update(adapter):
            adapter._messages.add(3, "twin", "the FMU asked to terminate the simulation")
            adapter.fail(adapter._UPDATE, 3, t_s)
        fmu.enterContinuousTimeMode()
    except fmpy.fmi1.FMICallException as err:
        adapter.fail(err.function, int(err.status), t_s)
    adapter._held = now


def _event_update(adapter: _Fmi2Exchange | _Fmi3Exchange) -> bool:
    """Iterate the FMU's discrete states in event mode; True if it asks to terminate."""
    needed = True
    while needed:
        needed, terminate, _, _, time_defined, time_s = adapter._update_events()
        if terminate:
            return True
        adapter._next_event_s = float(time_s) if time_defined else math.inf
    return False


def _integrate(adapter: _Fmi2Exchange | _Fmi3Exchange, t_s: float) -> bool:
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
                if _event_update(adapter):
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
