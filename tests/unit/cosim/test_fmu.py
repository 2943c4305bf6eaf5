"""Loading and stepping FMUs: independent instances, both APIs, FMU errors as FmuError."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from tests.unit.cosim.helpers import acme
from twin.core.errors import FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import FmuMapping, Profile, check_contract
from twin.cosim.description import binary_problem, read_fmu_info, stepping_problem
from twin.cosim.fmu import FmuFile


def _vrs(fmu: FmuFile, *names: str) -> list[int]:
    return [fmu.info.variables[n].value_reference for n in names]


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_two_instances_of_one_fmu_keep_independent_states(fmi_version: int) -> None:
    path = resolve_fmu("builtin:xm430_w210", fmi_version=fmi_version)  # type: ignore[arg-type]
    with FmuFile(path) as fmu:
        ins, outs = _vrs(fmu, "voltage", "load_torque"), _vrs(fmu, "wheel_speed", "current")
        a = fmu.instantiate("a", step_s=0.001, inputs=ins, outputs=outs)
        b = fmu.instantiate("b", step_s=0.001, inputs=ins, outputs=outs)
        a.inputs[0] = 12.0
        b.inputs[0] = -6.0
        for k in range(200):
            a.step(k * 0.001)
            b.step(k * 0.001)
        assert a.outputs[0] == pytest.approx(8.06, rel=0.01)
        assert b.outputs[0] == pytest.approx(-4.03, rel=0.01)
        b.inputs[0] = 0.0
        for k in range(200, 600):
            b.step(k * 0.001)
        assert a.outputs[0] == pytest.approx(8.06, rel=0.01)  # untouched by b's steps
        assert abs(b.outputs[0]) < 0.01


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_lowlevel_and_convenience_paths_agree(fmi_version: int) -> None:
    path = resolve_fmu("builtin:xl430_w250", fmi_version=fmi_version)  # type: ignore[arg-type]
    results = []
    with FmuFile(path) as fmu:
        ins, outs = _vrs(fmu, "voltage", "load_torque"), _vrs(fmu, "wheel_speed", "wheel_angle", "current")
        for api in ("lowlevel", "convenience"):
            s = fmu.instantiate(api, step_s=0.002, inputs=ins, outputs=outs, api=api)  # type: ignore[arg-type]
            s.inputs[0], s.inputs[1] = 9.0, 0.2
            for k in range(100):
                s.step(k * 0.002)
            results.append(list(s.outputs))
    assert results[0] == results[1]


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_error_mid_run_raises_with_name_time_and_status(fmi_version: int) -> None:
    with FmuFile(acme(fmi_version=fmi_version)) as fmu:  # type: ignore[arg-type]
        s = fmu.instantiate(
            "left", step_s=0.001, inputs=_vrs(fmu, "U_motor"), outputs=_vrs(fmu, "n_out"), start={"fault_time": 0.05}
        )
        s.inputs[0] = 12.0
        with pytest.raises(FmuError) as err:
            for k in range(1000):
                s.step(k * 0.001)
    message = str(err.value)
    assert "AcmeWheelDrive" in message and "'left'" in message
    assert "t = 0.050000 s" in message
    assert f"fmi{fmi_version}DoStep returned Error" in message
    assert "simulated drive fault" in message  # the FMU's own log message


def test_fixed_parameter_cannot_change_after_initialisation_is_reported() -> None:
    with FmuFile(resolve_fmu("builtin:xm430_w210")) as fmu:
        s = fmu.instantiate("x", step_s=0.001, inputs=_vrs(fmu, "R"), outputs=_vrs(fmu, "wheel_speed"))
        s.inputs[0] = 1.0
        with pytest.raises(FmuError, match=r"fmi2SetReal returned Error.*fixed parameter"):
            s.step(0.0)


def test_invalid_parameter_fails_initialisation_with_the_reason() -> None:
    with (
        FmuFile(resolve_fmu("builtin:xm430_w210", fmi_version=3)) as fmu,
        pytest.raises(FmuError, match=r"fmi3ExitInitializationMode returned Error.*R = -1 must be positive"),
    ):
        fmu.instantiate("x", step_s=0.001, inputs=[], outputs=[], start={"R": -1.0})


def test_not_a_zip_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "motor.fmu"
    bad.write_text("not an FMU")
    with pytest.raises(FmuError, match=r"motor\.fmu: not an FMU"):
        read_fmu_info(bad)


def test_broken_model_description_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "broken.fmu"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription fmiVersion='2.0'><oops")
    with pytest.raises(FmuError, match=r"broken\.fmu: invalid modelDescription\.xml") as err:
        read_fmu_info(bad)
    assert "\n" not in str(err.value)


def test_scheduled_execution_only_fmu_is_refused_for_stepping(tmp_path: Path) -> None:
    source = resolve_fmu("builtin:xl430_w250", fmi_version=3)
    se_only = tmp_path / "se.fmu"
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(se_only, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b"<CoSimulation", b"<ScheduledExecution")
            dst.writestr(item, data)
    assert read_fmu_info(se_only).co_simulation is None
    with pytest.raises(FmuError, match=r"se\.fmu: no Co-Simulation or Model Exchange interface \(Scheduled Execution"):
        FmuFile(se_only)


@pytest.mark.parametrize(
    ("element", "problem"),
    [
        ("ModelExchange", None),  # stepped by CVode: no interface problem
        ("ScheduledExecution", "no Co-Simulation or Model Exchange interface (Scheduled Execution only)"),
    ],
)
def test_check_names_the_interface_an_fmu_has_instead_of_co_simulation(
    tmp_path: Path, element: str, problem: str | None
) -> None:
    source = resolve_fmu("builtin:xl430_w250", fmi_version=3)
    other = tmp_path / "other.fmu"
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(other, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b"<CoSimulation", f"<{element}".encode())
            dst.writestr(item, data)
    info = read_fmu_info(other)
    assert info.co_simulation is None
    report = check_contract(info, FmuMapping(), Profile.VOLTAGE)
    assert report.ok == (problem is None), report.problems
    if problem is not None:
        assert problem in report.problems


def _rewritten(source: Path, target: Path, old: bytes, new: bytes) -> Path:
    """A copy of an FMU with its model description's `old` bytes replaced by `new`."""
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            dst.writestr(item, data.replace(old, new) if item == "modelDescription.xml" else data)
    return target


def test_a_binary_without_the_functions_of_its_declared_interface_is_named(tmp_path: Path) -> None:
    # Declared Model Exchange, built as Co-Simulation: the check binds what a run binds, not only
    # fmi2Instantiate, so the FMU fails `fmu check` and `scenario check`, not the run's start.
    source = resolve_fmu("builtin:xl430_w250", fmi_version=2)
    me = _rewritten(source, tmp_path / "me.fmu", b"<CoSimulation", b"<ModelExchange")
    problem = binary_problem(read_fmu_info(me))
    assert problem is not None
    assert problem.startswith("binaries/linux64/xl430_w250.so lacks a function of FMI 2.0 Model Exchange: ")
    assert "undefined symbol: fmi2" in problem and str(tmp_path) not in problem and "/tmp" not in problem
    assert binary_problem(read_fmu_info(source)) is None  # the same binary as Co-Simulation: complete


def test_an_fmu_without_an_interface_is_told_so_not_that_its_binary_is_missing(tmp_path: Path) -> None:
    source = resolve_fmu("builtin:xl430_w250", fmi_version=2)
    bare = _rewritten(source, tmp_path / "bare.fmu", b"<CoSimulation", b"<VendorAnnotations")
    info = read_fmu_info(bare)
    assert binary_problem(info) is None
    assert stepping_problem(info) == "no Co-Simulation or Model Exchange interface"


def test_a_model_description_in_the_wrong_encoding_is_named_with_its_line(tmp_path: Path) -> None:
    source = resolve_fmu("builtin:xl430_w250", fmi_version=2)
    latin1 = _rewritten(source, tmp_path / "latin1.fmu", b'description="', b'description="Motor \xe9 ')
    with pytest.raises(FmuError) as err:
        read_fmu_info(latin1)
    text = str(err.value)
    assert text.startswith(f"{latin1}: invalid modelDescription.xml: not well-formed XML: ")
    assert "line" in text and "\n" not in text
    assert str(Path.cwd() / "modelDescription.xml") not in text  # FMPy's message named a file that is not there
