"""A malformed model description is named in FMI terms: one line, exit 4, never Python's or FMPy's own words.

Each case is a copy of the built-in XM430 FMU with its `modelDescription.xml` (or the archive's
layout) broken the way third-party FMUs have been seen to be.
"""

from __future__ import annotations

import re
import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_one_line_error
from tests.robustness.test_fmu_binary import _rebuilt
from twin.cli import main
from twin.core.errors import FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.description import read_fmu_info

Edit = Callable[[str, bytes], tuple[str, bytes] | None]


def _copy(tmp_path: Path, edit: Edit, *, fmi_version: int = 2) -> Path:
    """A copy of the built-in XM430 FMU with each member passed through `edit` (None drops it)."""
    return _rebuilt(tmp_path, fmi_version, edit)


def _description(change: Callable[[str], str]) -> Edit:
    def edit(name: str, data: bytes) -> tuple[str, bytes]:
        if name == "modelDescription.xml":
            return name, change(data.decode()).encode()
        return name, data

    return edit


def _version(version: str | None) -> Callable[[str], str]:
    def change(text: str) -> str:
        replacement = f'fmiVersion="{version}"' if version is not None else ""
        return re.sub(r'fmiVersion="[^"]*"', replacement, text, count=1)

    return change


def _no_variables(text: str) -> str:
    return re.sub(r"<ModelVariables>.*</ModelVariables>", "<ModelVariables />", text, flags=re.DOTALL)


def _no_description(name: str, data: bytes) -> tuple[str, bytes] | None:
    return None if name == "modelDescription.xml" else (name, data)


def _in_a_folder(name: str, data: bytes) -> tuple[str, bytes]:
    return f"xm430/{name}", data


CASES: dict[str, tuple[Edit, int, str]] = {
    "fmi2_relabelled_1.0": (
        _description(_version("1.0")),
        2,
        'says fmiVersion="1.0" but is laid out as FMI 2.0',
    ),
    "no_fmi_version": (_description(_version(None)), 2, "has no fmiVersion attribute"),
    "fmi2_relabelled_3.0": (_description(_version("3.0")), 2, "declares FMI 2.0 <ScalarVariable> elements"),
    "fmi3_relabelled_2.0": (_description(_version("2.0")), 3, "declares FMI 3.0 variable elements (<Float64>)"),
    "no_model_variables": (_description(_no_variables), 2, "<ModelStructure> refers to variable index"),
    "no_model_description": (_no_description, 2, "no modelDescription.xml in the archive"),
    # Reference-FMUs' Feedthrough edited by hand: FMPy said "8" and "int() argument must be ... 'NoneType'"
    "fmi3_output_of_no_variable": (
        _description(lambda t: t.replace('<Output valueReference="3" />', '<Output valueReference="999" />', 1)),
        3,
        "<ModelStructure> <Output> refers to value reference 999, which no variable of <ModelVariables> has",
    ),
    "variable_without_value_reference": (
        _description(lambda t: t.replace(' valueReference="2"', "", 1)),
        2,
        "has no valueReference attribute; every variable needs one",
    ),
    "zipped_folder": (_in_a_folder, 2, "only xm430/modelDescription.xml; zip the contents of xm430/"),
}
# What the messages said before: Python's and FMPy's words, meaningless to whoever made the FMU.
_LEAKS = ("NoneType", "list index", "'ScalarVariable'", "There is no item named")


@pytest.mark.parametrize("case", CASES, ids=str)
def test_a_malformed_description_is_named_in_fmi_terms(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    edit, fmi_version, phrase = CASES[case]
    fmu = _copy(tmp_path, edit, fmi_version=fmi_version)
    with pytest.raises(FmuError) as err:
        read_fmu_info(fmu)
    assert phrase in str(err.value)
    assert not any(leak in str(err.value) for leak in _LEAKS), err.value
    code = main(["fmu", "check", str(fmu)])
    captured = capsys.readouterr()
    assert code == 4
    line = assert_one_line_error(captured.err, contains=str(fmu))
    assert phrase in line


def test_an_unzipped_fmu_folder_is_told_to_be_zipped(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "motor"
    with zipfile.ZipFile(resolve_fmu("builtin:xm430_w210")) as archive:
        archive.extractall(folder)
    for argv in (["fmu", "check", str(folder)], ["fmu", "step-response", str(folder)]):
        code = main(argv)
        captured = capsys.readouterr()
        assert code == 4
        line = assert_one_line_error(captured.err, contains=str(folder))
        assert "is a folder (an unzipped FMU)" in line
        assert "zip -r ../motor.fmu ." in line
        assert "not found" not in line
    with pytest.raises(FmuError, match="is a folder"):
        read_fmu_info(folder)


def _start_of_r(value: str) -> Callable[[str], str]:
    def change(text: str) -> str:
        return re.sub(r'(name="R".*?start=")[^"]*"', rf'\g<1>{value}"', text, count=1, flags=re.DOTALL)

    return change


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_start_value_that_is_not_a_number_is_named_by_check_and_simulate(
    fmi_version: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fmu = _copy(tmp_path, _description(_start_of_r("abc")), fmi_version=fmi_version)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(f"name: s\ndrive: {{type: fmu, fmu_file: {fmu.name}}}\n")
    bag = tmp_path / "bag"
    for argv in (
        ["fmu", "check", str(fmu)],
        ["scenario", "check", str(scenario)],
        ["simulate", str(scenario), "--duration", "0.1", "--out", str(bag)],
    ):
        code = main(argv)
        captured = capsys.readouterr()
        assert code == 4, (argv, captured.err)
        line = assert_one_line_error(captured.err, contains=fmu.name)
        assert "variable 'R'" in line and 'start="abc"' in line and "not a number" in line
    assert not bag.exists()
