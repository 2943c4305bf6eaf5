"""An FMU whose binary for this platform is missing or does not load: one line, exit 4, never a traceback.

`twin fmu check`, `twin scenario check` and `twin simulate` (which leaves no bag folder) all name the
FMU and the member (`binaries/linux64/NAME.so`) with what is wrong; loading it in `FmuFile` says the same.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from tests.robustness.helpers import assert_one_line_error
from twin.cli import main
from twin.core.errors import FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.description import binary_problem, read_fmu_info
from twin.cosim.fmu import FmuFile


def _rebuilt(tmp_path: Path, fmi_version: int, edit: Callable[[str, bytes], tuple[str, bytes] | None]) -> Path:
    """A copy of the built-in XM430 FMU with each member passed through `edit` (None drops it)."""
    source = resolve_fmu("builtin:xm430_w210", fmi_version=fmi_version)
    target = tmp_path / f"broken{fmi_version}.fmu"
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
        for name in src.namelist():
            kept = edit(name, src.read(name))
            if kept is not None:
                dst.writestr(*kept)
    return target


def _no_binary(name: str, data: bytes) -> tuple[str, bytes] | None:
    return None if name.startswith("binaries/") else (name, data)


def _garbage(name: str, data: bytes) -> tuple[str, bytes] | None:
    return (name, b"this is not a shared library\n" * 4) if name.endswith(".so") else (name, data)


def _windows_only(name: str, data: bytes) -> tuple[str, bytes] | None:
    if name.startswith("binaries/"):
        return f"binaries/win64/{Path(name).stem}.dll", b"MZ"
    return name, data


def _truncated(name: str, data: bytes) -> tuple[str, bytes] | None:
    return (name, data[:200]) if name.endswith(".so") else (name, data)


CASES = {
    "no_binaries": (_no_binary, "is missing; it has no binaries"),
    "garbage_so": (_garbage, "cannot be loaded on this platform"),
    "windows_only": (_windows_only, "has binaries for win64 only"),
    "truncated_so": (_truncated, "cannot be loaded on this platform"),
}


def _member(fmi_version: int) -> str:
    return "binaries/linux64/xm430_w210.so" if fmi_version == 2 else "binaries/x86_64-linux/xm430_w210.so"


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("case", CASES, ids=str)
def test_fmu_check_names_the_missing_or_unloadable_binary(
    case: str, fmi_version: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    edit, phrase = CASES[case]
    fmu = _rebuilt(tmp_path, fmi_version, edit)
    for argv in (["fmu", "check", str(fmu)], ["fmu", "check", str(fmu), "--json"]):
        code = main(argv)
        captured = capsys.readouterr()
        assert code == 4, captured.err
        line = assert_one_line_error(captured.err, contains=str(fmu))
        assert _member(fmi_version) in line
        assert phrase in line
        assert str(tmp_path / "tmp") not in line  # the member is named, not an extraction folder
    with pytest.raises(FmuError, match=phrase), FmuFile(fmu):
        pass


def test_a_good_fmu_has_no_binary_problem() -> None:
    for fmi_version in (2, 3):
        info = read_fmu_info(resolve_fmu("builtin:xm430_w210", fmi_version=fmi_version))
        assert binary_problem(info) is None


@pytest.mark.parametrize("case", ["no_binaries", "garbage_so"], ids=str)
def test_scenario_check_and_simulate_refuse_the_fmu_before_any_bag(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    edit, phrase = CASES[case]
    fmu = _rebuilt(tmp_path, 2, edit)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump({"name": "case", "drive": {"type": "fmu", "fmu_file": fmu.name}}))
    bag = tmp_path / "bag"
    for argv in (
        ["scenario", "check", str(scenario)],
        ["simulate", str(scenario), "--duration", "0.5", "--out", str(bag)],
    ):
        code = main(argv)
        captured = capsys.readouterr()
        assert code == 4, captured.err
        line = assert_one_line_error(captured.err, contains="drive.fmu_file")
        assert fmu.name in line
        assert phrase in line
    assert not bag.exists()
