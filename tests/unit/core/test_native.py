"""Native builds: the cache folder, the compiler search, cached and atomic builds, clean fallbacks."""

from __future__ import annotations

import ctypes
import logging
from pathlib import Path

import pytest

from twin.core import native
from twin.core.native import (
    CLibrary,
    NativeBuildError,
    build_library,
    cache_dir,
    compiler_candidates,
    find_compiler,
    load_library,
    native_disabled,
)

SOURCE = "int twin_test_add(int a, int b) { return a + b; }\n"
ADDER = CLibrary(name="adder", source=SOURCE)
BROKEN = CLibrary(name="broken", source="this is not C;\n")


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("TWIN_NO_NATIVE", raising=False)
    return tmp_path / "cache"


@pytest.fixture
def no_compiler(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))


def test_cache_dir_prefers_twin_cache_dir_then_xdg_then_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "mine"
    monkeypatch.delenv("TWIN_CACHE_DIR")
    assert cache_dir() == tmp_path / "xdg" / "twin"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "twin"


def test_cc_is_tried_first_then_the_usual_names(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CC", "my-cc")
    assert compiler_candidates() == ("my-cc", "cc", "gcc", "clang")
    monkeypatch.delenv("CC")
    assert compiler_candidates() == ("cc", "gcc", "clang")


def test_a_library_is_built_once_and_loads(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    lib = load_library(ADDER)
    assert lib is not None
    assert lib.twin_test_add(2, 3) == 5
    built = list((cache / "kernels").iterdir())
    assert len(built) == 1 and built[0].name.startswith("adder-") and built[0].suffix == ".so"

    def must_not_compile(*args: object, **kwargs: object) -> str:
        raise AssertionError("the cached library was rebuilt")

    monkeypatch.setattr(native, "compile_shared", must_not_compile)
    assert build_library(ADDER) == built[0]


def test_source_flags_and_files_each_give_a_new_build(cache: Path, tmp_path: Path) -> None:
    first = build_library(ADDER)
    assert build_library(CLibrary(name="adder", source=SOURCE + "/* changed */\n")) != first
    assert build_library(CLibrary(name="adder", source=SOURCE, flags=("-O1", "-shared", "-fPIC"))) != first
    c_file = tmp_path / "sub.c"
    c_file.write_text("int twin_test_sub(int a, int b) { return a - b; }\n")
    with_file = build_library(CLibrary(name="adder", source=SOURCE, files=(c_file,)))
    c_file.write_text("int twin_test_sub(int a, int b) { return b - a; }\n")
    assert build_library(CLibrary(name="adder", source=SOURCE, files=(c_file,))) != with_file
    lib = ctypes.CDLL(str(with_file))
    assert lib.twin_test_add(4, 1) == 5 and lib.twin_test_sub(4, 1) == 3


def test_a_failed_build_names_the_error_line_and_leaves_nothing_behind(cache: Path) -> None:
    with pytest.raises(NativeBuildError, match=r"failed: .*broken\.c:1:.*error") as err:
        build_library(BROKEN)
    assert "\n" not in str(err.value)
    assert list((cache / "kernels").iterdir()) == []  # no partial library, no temporary folder


def test_load_library_returns_none_and_says_why_when_the_build_fails(
    cache: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO, logger="twin.core.native"):
        assert load_library(BROKEN) is None
    assert "cannot build broken" in caplog.text and "Python implementation" in caplog.text


@pytest.mark.usefixtures("cache", "no_compiler")
def test_without_a_compiler_builds_raise_one_line_and_loads_fall_back() -> None:
    assert find_compiler() is None
    with pytest.raises(
        NativeBuildError, match=r"no C compiler found \(tried no-such-compiler, cc, gcc, clang\); install"
    ):
        build_library(ADDER)
    assert load_library(ADDER) is None


@pytest.mark.parametrize(("value", "disabled"), [("1", True), ("yes", True), ("0", False), ("", False)])
def test_twin_no_native_disables_loading(
    value: str, disabled: bool, cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TWIN_NO_NATIVE", value)
    assert native_disabled() is disabled
    assert (load_library(ADDER) is None) is disabled
    assert (cache / "kernels").is_dir() is not disabled  # disabled: nothing is even built


def test_keep_gil_loads_a_pydll(cache: Path) -> None:
    assert isinstance(load_library(ADDER, keep_gil=True), ctypes.PyDLL)


def test_the_compiler_version_is_asked_once_and_again_when_the_compiler_changes(
    cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A warm run starts no `cc --version` (kept in the cache folder); a replaced compiler is asked again."""
    compiler = tmp_path / "bin" / "mycc"
    compiler.parent.mkdir()
    compiler.write_text("#!/bin/sh\necho 'mycc 1.0'\n")
    compiler.chmod(0o755)
    asked: list[str] = []
    ask = native._ask_version
    monkeypatch.setattr(native, "_ask_version", lambda path: asked.append(path) or ask(path))
    native.compiler_version.cache_clear()
    assert native.compiler_version(str(compiler)) == "mycc 1.0"
    native.compiler_version.cache_clear()  # as a new process would start
    assert native.compiler_version(str(compiler)) == "mycc 1.0"
    assert len(asked) == 1
    compiler.write_text("#!/bin/sh\necho 'mycc 2.0 (upgraded)'\n")  # another size: another compiler
    native.compiler_version.cache_clear()
    assert native.compiler_version(str(compiler)) == "mycc 2.0 (upgraded)"
    assert len(asked) == 2
    native.compiler_version.cache_clear()
