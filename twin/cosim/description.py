"""What an FMU declares, and whether and how twin steps it on this platform.

`read_fmu_info(path)` reads the model description into an `FmuInfo` (variables, units, interfaces).
`fmu_file_problem`, `binary_problem` and `stepping_problem` say in one phrase why a file is not an
FMU to read, why its binary does not load here, or why twin cannot step it; `stepping` names how
twin steps it (Co-Simulation, or Model Exchange integrated by CVode).
"""

from __future__ import annotations

import ctypes
import shutil
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import fmpy
from fmpy.model_description import read_model_description

from twin.core.errors import FmuError
from twin.cosim.units import Unit

__all__ = [
    "ME_RELATIVE_TOLERANCE",
    "ME_SOLVER",
    "REAL_TYPES",
    "FmuInfo",
    "VariableInfo",
    "binary_problem",
    "fmu_file_problem",
    "read_fmu_info",
    "stepping",
    "stepping_problem",
]

#: The variable types twin reads and writes as doubles (FMI 2 `Real`, FMI 3 `Float64`/`Float32`).
REAL_TYPES = frozenset({"Real", "Float64", "Float32"})


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
    except etree.XMLSyntaxError as err:  # (FMPy's message names a file of that name in the working folder)
        return f"invalid modelDescription.xml: not well-formed XML: {err}"
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
    for child in variables if variables is not None else ():
        if isinstance(child.tag, str) and child.get("valueReference") is None:
            return (
                f"modelDescription.xml:{child.sourceline}: variable {child.get('name')!r} has no valueReference "
                "attribute; every variable needs one"
            )
    if version.startswith("3.") and variables is not None:
        references = {child.get("valueReference") for child in variables}
        structure = root.find("ModelStructure")
        for element in structure if structure is not None else ():
            if isinstance(element.tag, str) and element.get("valueReference") not in references:
                return (
                    f"modelDescription.xml:{element.sourceline}: <ModelStructure> <{element.tag}> refers to value "
                    f"reference {element.get('valueReference')}, which no variable of <ModelVariables> has"
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
    # Every function of the interface twin steps, bound as a run binds them (FMPy's class for it,
    # without instantiating): a Model Exchange binary without fmi2CompletedIntegratorStep, say,
    # fails here and not at the run's start.
    unzipped = library.parents[2]  # library is <unzipped>/binaries/<platform>/<name>
    try:
        fmpy_class(info)(
            guid=info.guid,
            unzipDirectory=str(unzipped),
            modelIdentifier=info.co_simulation or info.model_exchange,
            instanceName="check",
        )
    except Exception as err:  # FMPy raises what ctypes does: AttributeError, OSError
        text = str(err).replace(f"{library}: ", "").replace(str(library), member).strip()
        interface = "Co-Simulation" if info.co_simulation else "Model Exchange"
        return f"{member} lacks a function of FMI {info.fmi_version} {interface}: {text or type(err).__name__}"
    return None


def fmpy_class(info: FmuInfo) -> Any:
    """FMPy's class for the interface twin steps: Co-Simulation when the FMU has it, else Model Exchange."""
    import fmpy.fmi2
    import fmpy.fmi3

    if info.co_simulation is None:
        return fmpy.fmi2.FMU2Model if info.major_version == 2 else fmpy.fmi3.FMU3Model
    return fmpy.fmi2.FMU2Slave if info.major_version == 2 else fmpy.fmi3.FMU3Slave


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
    if info.major_version not in (2, 3) or (info.co_simulation is None and info.model_exchange is None):
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
            target = Path(tmp) / member  # laid out as in the FMU, where FMPy looks for it
            target.parent.mkdir(parents=True)
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
