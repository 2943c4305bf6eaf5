"""Small C libraries built on the machine that runs them: cache folder, C compiler, build, load.

Hot loops that numpy cannot vectorise (a ray fan over a few walls, an 8-state Kalman step, an FMU's
step loop) cost microseconds in C and tens of microseconds in Python. Their C sources ship with the
package; this module compiles one into a shared library on first use, installs it atomically into
the cache and loads it with ctypes. The file name carries a hash of everything that shapes the
binary (sources, flags, the compiler and its version), so a change gives a new build and an
unchanged one is reused, also by other processes.

- Cache folder: `$TWIN_CACHE_DIR`, else `$XDG_CACHE_HOME/twin`, else `~/.cache/twin`.
- C compiler: the first found of `$CC`, `cc`, `gcc`, `clang`.
- `TWIN_NO_NATIVE=1` makes `load_library` return None, so every caller takes its Python path.

`load_library` is for optional speed-ups (None, logged, when anything is missing); `build_library`
and `compile_shared` raise `NativeBuildError` with a one-line reason for callers that need the
library and word their own error.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import os
import shutil
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "DEFAULT_CFLAGS",
    "CLibrary",
    "NativeBuildError",
    "build_library",
    "cache_dir",
    "compile_shared",
    "compiler_candidates",
    "compiler_version",
    "find_compiler",
    "load_library",
    "native_disabled",
]

_log = logging.getLogger(__name__)

DEFAULT_CFLAGS: tuple[str, ...] = ("-O2", "-shared", "-fPIC")
"""Flags for a position-independent shared library, optimised."""

_LIBRARIES = ("-lm",)
_KEY_VERSION = "1"  # bump when the build recipe changes shape


class NativeBuildError(RuntimeError):
    """A C library could not be built; the message is one line (no compiler, or the compiler's first error)."""


def cache_dir() -> Path:
    """Return the folder where twin keeps built artefacts.

    `$TWIN_CACHE_DIR`, else `$XDG_CACHE_HOME/twin`, else `~/.cache/twin`.
    """
    if root := os.environ.get("TWIN_CACHE_DIR"):
        return Path(root).expanduser()
    if xdg := os.environ.get("XDG_CACHE_HOME"):
        return Path(xdg).expanduser() / "twin"
    return Path.home() / ".cache" / "twin"


def native_disabled() -> bool:
    """Return True when `TWIN_NO_NATIVE` is set to anything but empty or `0`."""
    return os.environ.get("TWIN_NO_NATIVE", "") not in ("", "0")


def compiler_candidates() -> tuple[str, ...]:
    """The compiler names tried, in order: `$CC` (if set), `cc`, `gcc`, `clang`."""
    cc = os.environ.get("CC")
    return (cc, "cc", "gcc", "clang") if cc else ("cc", "gcc", "clang")


def find_compiler() -> str | None:
    """Return the path of the first C compiler found on PATH (see `compiler_candidates`), or None."""
    for name in compiler_candidates():
        path = shutil.which(name)
        if path:
            return path
    return None


def _require_compiler() -> str:
    compiler = find_compiler()
    if compiler is None:
        msg = (
            f"no C compiler found (tried {', '.join(compiler_candidates())}); "
            "install one (e.g. apt-get install gcc) or set CC"
        )
        raise NativeBuildError(msg)
    return compiler


@functools.lru_cache(maxsize=8)
def compiler_version(path: str) -> str:
    """Return the first line of `path --version` (`unknown` if it does not say).

    Kept in the cache folder, keyed by the compiler binary's resolved path, size and modification
    time (an upgrade replaces the file), so a warm run starts no process to ask again.
    """
    real = os.path.realpath(path)
    try:
        st = os.stat(real)
    except OSError:
        return _ask_version(path)
    key = f"{real}\t{st.st_size}\t{st.st_mtime_ns}"
    record = cache_dir() / "compilers" / f"{hashlib.sha256(key.encode()).hexdigest()[:16]}.txt"
    try:
        stored_key, _, version = record.read_text(encoding="utf-8").partition("\n")
        if stored_key == key and version:
            return version
    except (OSError, UnicodeDecodeError):
        pass
    version = _ask_version(path)
    if version != "unknown":
        try:
            record.parent.mkdir(parents=True, exist_ok=True)
            staged = record.with_name(f"{record.name}.{os.getpid()}.tmp")
            staged.write_text(f"{key}\n{version}", encoding="utf-8")
            os.replace(staged, record)  # whole or not at all, also with another process writing
        except OSError as err:
            _log.debug("cannot keep %s's version in %s (%s)", path, record, err.strerror)
    return version


def _ask_version(path: str) -> str:
    import subprocess

    try:
        out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.splitlines()[0] if out.stdout else "unknown"


def compile_shared(
    compiler: str,
    sources: Sequence[Path],
    output: Path,
    *,
    flags: Sequence[str] = DEFAULT_CFLAGS,
    libraries: Sequence[str] = _LIBRARIES,
    timeout_s: float = 300.0,
) -> str:
    """Run `compiler flags sources -o output libraries` and return its diagnostics (stderr).

    Raises:
        NativeBuildError: If the compiler does not run, times out, or fails; the message is its
            first error line.
    """
    import subprocess

    cmd = [compiler, *flags, *map(str, sources), "-o", str(output), *libraries]
    name = Path(compiler).name
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired:
        msg = f"{name} did not finish within {timeout_s:g} s"
        raise NativeBuildError(msg) from None
    except OSError as err:
        msg = f"{compiler} did not run ({err.strerror})"
        raise NativeBuildError(msg) from None
    if result.returncode != 0:
        lines = result.stderr.splitlines()
        first = next((ln for ln in lines if "error" in ln), lines[0] if lines else f"exit status {result.returncode}")
        msg = f"{name} failed: {first.strip()}"
        raise NativeBuildError(msg)
    return result.stderr


def _machine() -> str:
    """The machine's architecture (`platform.machine()`, without importing `platform`)."""
    return os.uname().machine if hasattr(os, "uname") else os.environ.get("PROCESSOR_ARCHITECTURE", "")


def _digest(compiler: str, source: str | None, files: Sequence[Path], flags: Sequence[str]) -> str:
    h = hashlib.sha256()
    for part in (_KEY_VERSION, compiler, compiler_version(compiler), sys.platform, _machine(), *flags):
        h.update(part.encode() + b"\0")
    if source is not None:
        h.update(b"<source>\0" + source.encode() + b"\0")
    for path in files:
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@dataclass(frozen=True, kw_only=True, slots=True)
class CLibrary:
    """What one shared library is built from; the cache key covers all of it.

    Attributes:
        name: The library's base name (its file is `<cache>/<subdir>/<name>-<hash>.so`).
        source: C source text.
        files: C source files compiled with it.
        depends: Files that shape the build without being compiled (headers).
        flags: Compiler flags (the default builds an optimised shared library).
        subdir: Folder inside the cache.
    """

    name: str
    source: str | None = None
    files: tuple[Path, ...] = ()
    depends: tuple[Path, ...] = ()
    flags: tuple[str, ...] = DEFAULT_CFLAGS
    subdir: str = "kernels"


def build_library(lib: CLibrary, *, force: bool = False) -> Path:
    """Build a shared library, or return the cached build.

    The hash in the file name covers the source text, the files and `depends`, the flags and the
    compiler with its version. The library is compiled in a temporary folder beside its target and
    moved into place in one step, so a concurrent or killed build never leaves a partial file under
    the final name.

    Args:
        lib: What to build.
        force: Build even if the cached library exists.

    Raises:
        NativeBuildError: If there is nothing to compile, no compiler is found, a file cannot be
            read, or compilation fails.
    """
    name, source = lib.name, lib.source
    if source is None and not lib.files:
        msg = f"nothing to compile for {name}: give C source text or files"
        raise NativeBuildError(msg)
    compiler = _require_compiler()
    try:
        digest = _digest(compiler, source, [*lib.files, *lib.depends], lib.flags)
    except OSError as err:
        msg = f"cannot read {err.filename} ({err.strerror})"
        raise NativeBuildError(msg) from None
    target = cache_dir() / lib.subdir / f"{name}-{digest}.so"
    if target.is_file() and not force:
        return target
    _log.info("building %s into %s", name, target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix=f"twin-{name}-", dir=target.parent) as tmp_text:
            tmp = Path(tmp_text)
            sources = list(lib.files)
            if source is not None:
                (tmp / f"{name}.c").write_text(source, encoding="utf-8")
                sources.insert(0, tmp / f"{name}.c")
            staged = tmp / target.name
            for line in compile_shared(compiler, sources, staged, flags=lib.flags).splitlines():
                _log.debug("%s: %s", name, line)
            os.replace(staged, target)
    except OSError as err:
        msg = f"cannot write {target} ({err.strerror})"
        raise NativeBuildError(msg) from None
    return target


def load_library(lib: CLibrary, *, keep_gil: bool = False) -> ctypes.CDLL | None:
    """Build (or reuse) and load a shared library; None if native code is disabled or unavailable.

    None, with the reason logged at INFO, when `TWIN_NO_NATIVE` is set, the platform has no
    shared-library toolchain this module knows (Linux and macOS do), no C compiler is found, or the
    build or the load fails. Callers keep a Python path for that case. `keep_gil` loads it as
    `ctypes.PyDLL`: calls hold the GIL, which is cheaper for microsecond kernels.
    """
    name = lib.name
    if native_disabled():
        _log.debug("TWIN_NO_NATIVE is set: %s is not built", name)
        return None
    if not sys.platform.startswith(("linux", "darwin")):
        _log.info("no native %s on %s; using the Python implementation", name, sys.platform)
        return None
    try:
        path = build_library(lib)
    except NativeBuildError as err:
        _log.info("cannot build %s (%s); using the Python implementation", name, err)
        return None
    try:
        return (ctypes.PyDLL if keep_gil else ctypes.CDLL)(str(path))
    except OSError as err:
        _log.info("cannot load %s (%s); using the Python implementation", path, err)
        return None
