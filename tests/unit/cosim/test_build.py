"""Building the project's FMUs: valid FMI 2.0 and 3.0 archives, cached, rebuilt on change, clear errors."""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

from twin.core.errors import FmuError
from twin.cosim.build import FMUS_DIR, build_fmu, builtin_variants, resolve_fmu


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("name", ["xm430_w210", "xl430_w250", "xm430_w210_servo"])
def test_builtin_fmu_passes_fmpy_validation(name: str, fmi_version: int) -> None:
    path = resolve_fmu(f"builtin:{name}", fmi_version=fmi_version)  # type: ignore[arg-type]
    assert validate_fmu(str(path)) == []
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    platform = "linux64" if fmi_version == 2 else "x86_64-linux"
    assert "modelDescription.xml" in names
    assert f"binaries/{platform}/{name}.so" in names


def test_builtins_cover_both_turtlebot_motors_and_servo_modes() -> None:
    assert {"xm430_w210", "xl430_w250", "xm430_w210_servo", "xl430_w250_servo"} <= set(builtin_variants())


def test_second_build_reuses_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    first = build_fmu(FMUS_DIR / "dc_motor", "xm430_w210", fmi_version=2)
    second = build_fmu(FMUS_DIR / "dc_motor", "xm430_w210", fmi_version=2)
    assert first.rebuilt and not second.rebuilt
    assert first.path == second.path
    assert first.path.is_relative_to(tmp_path)


def test_changed_source_gives_a_new_build(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "cache"))
    model = tmp_path / "dc_motor"
    shutil.copytree(FMUS_DIR / "dc_motor", model)
    before = build_fmu(model, "xm430_w210", fmi_version=3)
    source = model / "dc_motor.c"
    source.write_text(source.read_text() + "\n/* changed */\n")
    after = build_fmu(model, "xm430_w210", fmi_version=3)
    assert after.rebuilt
    assert after.path != before.path


def test_missing_compiler_is_one_clear_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(FmuError, match=r"no C compiler found.*install one") as err:
        build_fmu(FMUS_DIR / "dc_motor", "xl430_w250", fmi_version=2)
    assert "\n" not in str(err.value)


def test_compile_error_names_the_failing_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "cache"))
    model = tmp_path / "dc_motor"
    shutil.copytree(FMUS_DIR / "dc_motor", model)
    (model / "dc_motor.c").write_text("this is not C;\n")
    with pytest.raises(FmuError, match=r"cannot build FMU 'xm430_w210': .*dc_motor\.c:1"):
        build_fmu(model, "xm430_w210", fmi_version=2)


def test_unknown_builtin_lists_the_builtins() -> None:
    with pytest.raises(FmuError, match=r"unknown built-in FMU 'xm430'.*xm430_w210"):
        resolve_fmu("builtin:xm430")
