"""Build FMUs from C sources into a cache outside git, rebuilding when any input changes.

A model directory holds `fmu.yaml` (model name, C sources, variables, variants) and its C files.
Each variant is built for FMI 2.0 or 3.0 Co-Simulation (or, when `fmu.yaml` says
`interface: model_exchange`, Model Exchange with the model's own `fmi<N>_me_layer.c` and `local`
derivative variables naming their state in `derivative_of`): the model description and a header of
value references and start values are generated from `fmu.yaml`, the sources are compiled with the system
C compiler (`$CC`, else `cc`, `gcc` or `clang`) together with the FMI layer of `fmus/common`, and the
result is zipped into `<cache>/fmus/<variant>-fmi<N>-<hash>.fmu`. The hash covers every source,
header and build setting, so a changed input gives a new file and an unchanged one is reused.

The cache is `$TWIN_CACHE_DIR`, else `$XDG_CACHE_HOME/twin`, else `~/.cache/twin` (`twin.core.native`).
"""

from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import logging
import os
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import fmpy

from twin.core.config import load_config
from twin.core.errors import FmuError
from twin.core.native import (
    CLibrary,
    NativeBuildError,
    build_library,
    cache_dir,
    compile_shared,
    compiler_candidates,
    compiler_version,
    find_compiler,
)
from twin.cosim.description import fmu_file_problem
from twin.cosim.units import BASE_NAMES, find_unit

__all__ = [
    "BUILTIN_PREFIX",
    "FMUS_DIR",
    "BuiltFmu",
    "FmiVersion",
    "FmuSourceSpec",
    "build_all",
    "build_fmu",
    "build_shim",
    "builtin_variants",
    "cache_dir",
    "load_source_spec",
    "resolve_fmu",
]

_log = logging.getLogger(__name__)

FmiVersion = Literal[2, 3]

FMUS_DIR = Path(__file__).resolve().parent.parent.parent / "fmus"
BUILTIN_PREFIX = "builtin:"
CFLAGS: tuple[str, ...] = ("-O2", "-shared", "-fPIC", "-std=c11", "-Wall")
_BUILDER_VERSION = "1"  # bump when the generated files change shape
# The shim library's files (not part of any FMU, so they do not enter the FMUs' hashes).
_SHIM_SOURCES = ("step_shim.c", "drive_loop.c", "crash_note.c")
_SHIM_FILES = ("step_shim.h", *_SHIM_SOURCES)
_SHIM_CFLAGS = ("-ffp-contract=off",)
_TIME_VR = 4096  # MODEL_TIME_VR in fmus/common/model.h


@dataclass(frozen=True, kw_only=True, slots=True)
class VariableSpec:
    """One Float64 variable of a model, as `fmu.yaml` declares it."""

    name: str
    vr: int
    causality: Literal["input", "output", "parameter", "local"]
    unit: str = "1"
    start: float | None = None
    description: str = ""
    only: str | None = None  # present only when this define is set
    unless: str | None = None  # absent when this define is set
    derivative_of: str | None = None  # Model Exchange: the state variable this is the derivative of
    # discrete: an input that changes only at events (a Model Exchange FMU takes it in event mode only).
    variability: Literal["continuous", "discrete"] = "continuous"

    def __post_init__(self) -> None:
        if self.variability == "discrete" and self.causality != "input":
            msg = f"variable {self.name!r}: only inputs may be discrete, not a {self.causality}"
            raise ValueError(msg)
        if self.vr < 0 or self.vr > 4095:
            msg = f"vr must be between 0 and 4095, got {self.vr}"
            raise ValueError(msg)
        if self.causality not in {"output", "local"} and self.start is None:
            msg = f"variable {self.name!r} ({self.causality}) needs a start value"
            raise ValueError(msg)
        if find_unit(self.unit) is None:
            msg = f"unit {self.unit!r} of {self.name!r} is not in twin.cosim.units"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class VariantSpec:
    """One FMU built from the model: compile-time defines and parameter start values."""

    description: str = ""
    defines: tuple[str, ...] = ()
    start: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True, kw_only=True, slots=True)
class FmuSourceSpec:
    """A model directory's `fmu.yaml`."""

    model_name: str
    description: str = ""
    sources: tuple[str, ...]
    # Folders (relative to the model directory) searched for included files; their .c and .h files
    # enter the build hash (a model that compiles in another model's source names its folder here).
    include_dirs: tuple[str, ...] = ()
    variables: tuple[VariableSpec, ...]
    variants: Mapping[str, VariantSpec]
    # model_exchange: the FMI layer is the model's own fmi2_me_layer.c / fmi3_me_layer.c (not listed in
    # `sources`) instead of fmus/common's.
    interface: Literal["co_simulation", "model_exchange"] = "co_simulation"


@dataclass(frozen=True, kw_only=True, slots=True)
class BuiltFmu:
    """A built FMU in the cache."""

    variant: str
    fmi_version: FmiVersion
    path: Path
    rebuilt: bool


def load_source_spec(model_dir: Path) -> FmuSourceSpec:
    """Read `model_dir/fmu.yaml`.

    Raises:
        ConfigError: Naming file, line and key, if the file is missing or wrong.
    """
    spec = load_config(FmuSourceSpec, model_dir / "fmu.yaml")
    names = [v.name for v in spec.variables]
    for variant, vspec in spec.variants.items():
        unknown = sorted(set(vspec.start) - set(names))
        if unknown:
            msg = f"{model_dir / 'fmu.yaml'}: variants.{variant}.start: unknown variable(s) {', '.join(unknown)}"
            raise FmuError(msg)
    return spec


def builtin_variants(fmus_dir: Path = FMUS_DIR) -> dict[str, Path]:
    """Return every variant of the project's models, by name, with its model directory."""
    found: dict[str, Path] = {}
    for yaml_path in sorted(fmus_dir.glob("*/fmu.yaml")):
        for name in load_source_spec(yaml_path.parent).variants:
            found[name] = yaml_path.parent
    return found


def resolve_fmu(ref: str | Path, *, fmi_version: FmiVersion = 2, base_dir: Path | None = None) -> Path:
    """Return the `.fmu` file a drive names: `builtin:NAME` (built on first use) or a path.

    Raises:
        FmuError: If the built-in is unknown, cannot be built, or the file does not exist.
    """
    text = str(ref)
    if text.startswith(BUILTIN_PREFIX):
        name = text[len(BUILTIN_PREFIX) :]
        variants = builtin_variants()
        if name not in variants:
            msg = f"unknown built-in FMU {name!r}; built-ins: {', '.join(sorted(variants))}"
            raise FmuError(msg)
        return build_fmu(variants[name], name, fmi_version=fmi_version).path
    path = Path(text).expanduser()
    if base_dir is not None and not path.is_absolute():
        path = base_dir / path
    problem = fmu_file_problem(path)
    if problem is not None:
        hint = " (give a .fmu path or builtin:NAME)" if not path.exists() else ""
        msg = f"{path}: {problem}{hint}"
        raise FmuError(msg)
    return path


def build_all(fmus_dir: Path = FMUS_DIR, *, force: bool = False) -> list[BuiltFmu]:
    """Build every variant of every model under `fmus_dir` for FMI 2 and FMI 3.

    Raises:
        FmuError: On the first variant that cannot be built.
    """
    built = []
    for name, model_dir in builtin_variants(fmus_dir).items():
        for version in (2, 3):
            built.append(build_fmu(model_dir, name, fmi_version=version, force=force))
    return built


def build_fmu(model_dir: Path, variant: str, *, fmi_version: FmiVersion = 2, force: bool = False) -> BuiltFmu:
    """Build one variant of the model in `model_dir`, or return the cached build.

    Raises:
        FmuError: If the variant is unknown, no C compiler is found, or compilation fails.
    """
    spec = load_source_spec(model_dir)
    if variant not in spec.variants:
        msg = f"{model_dir / 'fmu.yaml'}: no variant {variant!r}; variants: {', '.join(spec.variants)}"
        raise FmuError(msg)
    compiler = _compiler(variant)
    inputs = _input_files(model_dir, spec)
    digest = _digest(inputs, compiler, variant, fmi_version)
    target = cache_dir() / "fmus" / f"{variant}-fmi{fmi_version}-{digest[:16]}.fmu"
    if target.is_file() and not force:
        return BuiltFmu(variant=variant, fmi_version=fmi_version, path=target, rebuilt=False)
    _log.info("building %s (FMI %d) into %s", variant, fmi_version, target)
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"twin-fmu:{digest}")) + "}"
    variables = _variables(spec, spec.variants[variant])
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="twin-fmu-", dir=target.parent) as tmp_text:
        tmp = Path(tmp_text)
        (tmp / "model_vars.h").write_text(_header(variables, spec.variants[variant]), encoding="utf-8")
        library = tmp / f"{variant}.so"
        _compile(compiler, model_dir, spec, spec.variants[variant], fmi_version, token, tmp, library, variant)
        description = _model_description(spec, variant, variables, fmi_version, token)
        staged = tmp / "out.fmu"
        platform_dir = fmpy.platform if fmi_version == 2 else fmpy.platform_tuple
        with zipfile.ZipFile(staged, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("modelDescription.xml", description)
            zf.write(library, f"binaries/{platform_dir}/{variant}.so")
        os.replace(staged, target)
    return BuiltFmu(variant=variant, fmi_version=fmi_version, path=target, rebuilt=True)


def build_shim() -> Path:
    """Build (or reuse) the stepping shim and the compiled drive loop as a shared library in the cache.

    The library holds `fmus/common/step_shim.c` (FMU instances stepped in one call) and
    `fmus/common/drive_loop.c` (the drivetrain's whole per-step path). It is compiled without FMA
    contraction so that the drive loop's arithmetic matches Python's to the last bit.

    Raises:
        FmuError: If no C compiler is found or compilation fails.
    """
    common = FMUS_DIR / "common"
    try:
        shim = CLibrary(
            name="step_shim",
            files=tuple(common / name for name in _SHIM_SOURCES),
            depends=tuple(common / name for name in _SHIM_FILES if name not in _SHIM_SOURCES),
            flags=(*CFLAGS, *_SHIM_CFLAGS),
            subdir="fmus",
        )
        return build_library(shim)
    except NativeBuildError as err:
        msg = f"cannot build the step shim: {err}"
        raise FmuError(msg) from None


def crash_note(line: str) -> None:
    """Have a fatal signal (SIGSEGV, SIGABRT...) write `line` to stderr before the process dies of it ("" stops it).

    The handler is `twin_crash_note` in fmus/common/crash_note.c, in the shim's library; it hands the
    signal on to the handler that was there before, so the process still dies of it.
    """
    try:  # best effort: without a C compiler the run goes on, as its stepping does (in Python)
        library = ctypes.CDLL(str(build_shim()))
    except (FmuError, OSError) as err:
        _log.debug("no note on a fatal signal: %s", err)
        return
    library.twin_crash_note.argtypes = [ctypes.c_char_p]
    library.twin_crash_note(line.encode())


# --- inputs and hashing ------------------------------------------------------------------------


def _input_files(model_dir: Path, spec: FmuSourceSpec) -> list[Path]:
    files = [model_dir / "fmu.yaml", *(model_dir / s for s in spec.sources)]
    if spec.interface == "model_exchange":
        files.extend(model_dir / f"fmi{n}_me_layer.c" for n in (2, 3))
    for extra in spec.include_dirs:
        folder = (model_dir / extra).resolve()
        if not folder.is_dir():
            msg = f"{model_dir / 'fmu.yaml'}: include_dirs: {extra} is not a folder"
            raise FmuError(msg)
        files.extend(sorted(p for p in folder.iterdir() if p.suffix in {".c", ".h"}))
    for folder in (FMUS_DIR / "common", FMUS_DIR / "include"):
        files.extend(sorted(p for p in folder.iterdir() if p.suffix in {".c", ".h"} and p.name not in _SHIM_FILES))
    for path in files:
        if not path.is_file():
            msg = f"{model_dir / 'fmu.yaml'}: source file {path} not found"
            raise FmuError(msg)
    return files


def _digest(files: list[Path], compiler: tuple[str, str], variant: str, fmi_version: int) -> str:
    h = hashlib.sha256()
    for part in (_BUILDER_VERSION, *compiler, *CFLAGS, variant, str(fmi_version), fmpy.platform_tuple):
        h.update(part.encode() + b"\0")
    for path in files:
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def _compiler(variant: str) -> tuple[str, str]:
    path = find_compiler()
    if path is None:
        msg = (
            f"cannot build FMU {variant!r}: no C compiler found (tried {', '.join(compiler_candidates())}); "
            "install one (e.g. apt-get install gcc) or set CC"
        )
        raise FmuError(msg)
    return path, compiler_version(path)


def _compile(  # noqa: PLR0917 - one private call site
    compiler: tuple[str, str],
    model_dir: Path,
    spec: FmuSourceSpec,
    variant_spec: VariantSpec,
    fmi_version: int,
    token: str,
    gen_dir: Path,
    library: Path,
    variant: str,
) -> None:
    common = FMUS_DIR / "common"
    layer = common / ("fmi2_layer.c" if fmi_version == 2 else "fmi3_layer.c")
    flags = [
        *CFLAGS,
        f'-DMODEL_GUID="{token}"',
        *(f"-D{d}=1" for d in variant_spec.defines),
        f"-I{gen_dir}",
        f"-I{model_dir}",
        *(f"-I{(model_dir / extra).resolve()}" for extra in spec.include_dirs),
        f"-I{common}",
        f"-I{FMUS_DIR / 'include'}",
    ]
    if spec.interface == "model_exchange":
        layer = model_dir / f"fmi{fmi_version}_me_layer.c"
    sources = [*(model_dir / s for s in spec.sources), layer, common / "linsys.c"]
    try:
        diagnostics = compile_shared(compiler[0], sources, library, flags=flags)
    except NativeBuildError as err:
        msg = f"cannot build FMU {variant!r}: {err}"
        raise FmuError(msg) from None
    for line in diagnostics.splitlines():
        _log.debug("%s: %s", variant, line)


# --- generated files ---------------------------------------------------------------------------


def _variables(spec: FmuSourceSpec, variant: VariantSpec) -> list[VariableSpec]:
    chosen = []
    for var in spec.variables:
        if var.only is not None and var.only not in variant.defines:
            continue
        if var.unless is not None and var.unless in variant.defines:
            continue
        start = variant.start.get(var.name, var.start)
        chosen.append(dataclasses.replace(var, start=start))
    return sorted(chosen, key=lambda v: v.vr)


_KIND = {"parameter": 1, "input": 2, "output": 3, "local": 3}  # locals: not settable
_KIND_DISCRETE_INPUT = 4  # KIND_DISCRETE_INPUT in fmus/common/var_table.h


def _header(variables: list[VariableSpec], variant: VariantSpec) -> str:
    nvr = max(v.vr for v in variables) + 1
    start = ["0.0"] * nvr
    kind = ["0"] * nvr
    names = ['""'] * nvr
    lines = ["/* Generated by twin.cosim.build from fmu.yaml: do not edit. */", f"#define MODEL_NVR {nvr}"]
    for var in variables:
        lines.append(f"#define VR_{var.name} {var.vr}")
        start[var.vr] = repr(float(var.start if var.start is not None else 0.0))
        kind[var.vr] = str(_KIND_DISCRETE_INPUT if var.variability == "discrete" else _KIND[var.causality])
        names[var.vr] = f'"{var.name}"'
    lines.append(f"static const double MODEL_START[MODEL_NVR] = {{{', '.join(start)}}};")
    lines.append(f"static const unsigned char MODEL_KIND[MODEL_NVR] = {{{', '.join(kind)}}};")
    lines.append(f"static const char *const MODEL_NAME[MODEL_NVR] = {{{', '.join(names)}}};")
    return "\n".join(lines) + "\n"


def _unit_elements(parent: ET.Element, variables: list[VariableSpec]) -> None:
    used = sorted({v.unit for v in variables})
    if not used:
        return
    defs = ET.SubElement(parent, "UnitDefinitions")
    for name in used:
        unit = find_unit(name)
        assert unit is not None  # checked by VariableSpec
        element = ET.SubElement(defs, "Unit", name=name)
        base = {b: str(e) for b, e in zip(BASE_NAMES, unit.dims, strict=True) if e}
        if unit.factor != 1.0:
            base["factor"] = repr(unit.factor)
        if unit.offset != 0.0:
            base["offset"] = repr(unit.offset)
        ET.SubElement(element, "BaseUnit", base)


def _model_description(
    spec: FmuSourceSpec, variant: str, variables: list[VariableSpec], fmi_version: int, token: str
) -> bytes:
    vspec = spec.variants[variant]
    description = vspec.description or spec.description
    common: dict[str, str] = {
        "modelName": spec.model_name,
        "description": description,
        "generationTool": "twin fmu build",
    }
    if fmi_version == 2:
        root = ET.Element(
            "fmiModelDescription",
            {"fmiVersion": "2.0", **common, "guid": token, "variableNamingConvention": "flat"},
        )
        root.set("numberOfEventIndicators", "0")
        if spec.interface == "model_exchange":
            ET.SubElement(
                root,
                "ModelExchange",
                modelIdentifier=variant,
                completedIntegratorStepNotNeeded="true",
                canNotUseMemoryManagementFunctions="true",
            )
        else:
            ET.SubElement(
                root,
                "CoSimulation",
                modelIdentifier=variant,
                canHandleVariableCommunicationStepSize="true",
                canNotUseMemoryManagementFunctions="true",
            )
    else:
        root = ET.Element("fmiModelDescription", {"fmiVersion": "3.0", **common, "instantiationToken": token})
        if spec.interface == "model_exchange":
            ET.SubElement(root, "ModelExchange", modelIdentifier=variant, needsCompletedIntegratorStep="false")
        else:
            ET.SubElement(
                root,
                "CoSimulation",
                modelIdentifier=variant,
                canHandleVariableCommunicationStepSize="true",
                providesIntermediateUpdate="false",
                canReturnEarlyAfterIntermediateUpdate="false",
                hasEventMode="false",
            )
    _unit_elements(root, variables)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime="1.0", stepSize="0.001")
    model_vars = ET.SubElement(root, "ModelVariables")
    if fmi_version == 3:
        ET.SubElement(
            model_vars,
            "Float64",
            name="time",
            valueReference=str(_TIME_VR),
            causality="independent",
            variability="continuous",
            description="simulation time",
        )
    outputs: list[tuple[int, VariableSpec]] = []
    derivatives: list[int] = []
    states: list[int] = []  # calculated at initialisation like the outputs
    index_of = {var.name: index for index, var in enumerate(variables, start=1)}
    for index, var in enumerate(variables, start=1):
        attrs = {"name": var.name, "valueReference": str(var.vr), "causality": var.causality}
        attrs["variability"] = "fixed" if var.causality == "parameter" else var.variability
        if var.description:
            attrs["description"] = var.description
        typed = {"unit": var.unit}
        if var.derivative_of is not None:
            if var.derivative_of not in index_of:
                msg = f"{variant}: {var.name}.derivative_of names {var.derivative_of!r}, not a variable of this variant"
                raise FmuError(msg)
            # FMI 2 names the state by its index, FMI 3 by its value reference.
            state = variables[index_of[var.derivative_of] - 1]
            typed["derivative"] = str(index_of[var.derivative_of] if fmi_version == 2 else state.vr)
            derivatives.append(index)
            states.append(index_of[var.derivative_of])
        if var.causality in {"output", "local"}:
            attrs["initial"] = "calculated"
        else:
            typed["start"] = repr(float(var.start if var.start is not None else 0.0))
        if fmi_version == 2:
            element = ET.SubElement(model_vars, "ScalarVariable", attrs)
            ET.SubElement(element, "Real", typed)
        else:
            ET.SubElement(model_vars, "Float64", {**attrs, **typed})
        if var.causality == "output":
            outputs.append((index, var))
    structure = ET.SubElement(root, "ModelStructure")
    if fmi_version == 2:
        out_el = ET.SubElement(structure, "Outputs")
        for index, _ in outputs:
            ET.SubElement(out_el, "Unknown", index=str(index))
        if derivatives:
            der_el = ET.SubElement(structure, "Derivatives")
            for index in derivatives:
                ET.SubElement(der_el, "Unknown", index=str(index))
        init_el = ET.SubElement(structure, "InitialUnknowns")
        for index in sorted({index for index, _ in outputs} | set(derivatives) | set(states)):
            ET.SubElement(init_el, "Unknown", index=str(index))
    else:
        for _, var in outputs:
            ET.SubElement(structure, "Output", valueReference=str(var.vr))
        for index in derivatives:
            ET.SubElement(structure, "ContinuousStateDerivative", valueReference=str(variables[index - 1].vr))
        for index in sorted({index for index, _ in outputs} | set(derivatives) | set(states)):
            ET.SubElement(structure, "InitialUnknown", valueReference=str(variables[index - 1].vr))
    ET.indent(root)
    text: bytes = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    return text
