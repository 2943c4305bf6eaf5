"""The compiled code of the methods `dataclasses` writes, kept in the cache folder between runs.

When a dataclass is defined, Python's `dataclasses` writes its `__init__`, `__repr__`, `__eq__`,
`__hash__` (and, frozen, `__setattr__` and `__delattr__`) as source text and compiles each with
`exec`. A run of the default scenario defines 347 classes (1,307 methods) before its first step;
compiling them is about 80 ms of that start (first step 0.256 s with this cache, 0.335 s with
`TWIN_NO_CODE_CACHE=1`, medians of 9 alternated pairs, 2026-11-27). The text is the same on every
run, and so is the code it compiles to. `enable()` gives the `dataclasses` module an `exec`
that looks the text up in a table of compiled code loaded from the cache folder, compiles only text
it has not seen, and writes the grown table back when the process exits (atomically: a concurrent
run or a killed one never leaves a partial file). Each method is still made by executing its code
with the same globals and locals as before, so the classes are the same; only the compiling is
skipped.

There is a table per command (`simulate`, `analyze`...) and per interpreter (its file name carries
the bytecode magic number); it holds exact source
text as keys (so it can never return another method's code), is ignored when it does not load, and
is left alone past `_MAX_ENTRIES`. Only the `twin` command enables it (as it defers the garbage
collector: `twin.core.gcpolicy`); a library user's process is left as it is. `TWIN_NO_CODE_CACHE=1`
turns it off.
"""

from __future__ import annotations

import atexit
import builtins
import dataclasses
import importlib.util
import logging
import marshal
import os
import sys
from pathlib import Path
from types import CodeType
from typing import Any

_log = logging.getLogger(__name__)

_MAX_ENTRIES = 20_000  # ~20 MB: far past what twin defines; a table that grows so far is not written
_FILE_MODE = "exec"


class _Table:
    """The compiled code of source texts, loaded on first use and written back at exit if it grew."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.codes: dict[str, CodeType] | None = None
        self.compiled = 0  #: texts compiled by this process (not found in the table)

    def load(self) -> dict[str, CodeType]:
        codes: dict[str, CodeType] = {}
        try:
            loaded = marshal.loads(self.path.read_bytes())
            if isinstance(loaded, dict):
                codes = {k: v for k, v in loaded.items() if isinstance(k, str) and isinstance(v, CodeType)}
        except FileNotFoundError:
            pass
        except (OSError, ValueError, EOFError, TypeError) as err:  # damaged or written by something else
            _log.debug("code cache %s not used (%s)", self.path, err)
        self.codes = codes
        return codes

    def code(self, source: str) -> CodeType:
        codes = self.codes if self.codes is not None else self.load()
        found = codes.get(source)
        if found is None:
            # dont_inherit: compiled with no __future__ flags, as exec() in dataclasses compiles it
            found = codes[source] = compile(source, "<string>", _FILE_MODE, dont_inherit=True)
            self.compiled += 1
        return found

    def save(self) -> None:
        if not self.compiled or self.codes is None or len(self.codes) > _MAX_ENTRIES:
            return
        staged = self.path.with_name(f"{self.path.name}.{os.getpid()}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            staged.write_bytes(marshal.dumps(self.codes))
            os.replace(staged, self.path)
        except (OSError, ValueError) as err:
            _log.debug("cannot write the code cache %s (%s)", self.path, err)
            staged.unlink(missing_ok=True)


_enabled: list[_Table] = []  # the table, while `enable` has given dataclasses its exec


def table_path(command: str = "twin") -> Path:
    """The table's file: in the cache folder, per command and per interpreter (bytecode magic number).

    One table per command keeps each small: a run loads only the methods of the classes its own
    command defines (a union of every command's would cost `twin simulate` ~5 ms more to load).
    """
    from twin.core.native import cache_dir

    tag = f"{sys.implementation.cache_tag}-{importlib.util.MAGIC_NUMBER.hex()}"
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in command) or "twin"
    return cache_dir() / "pycode" / f"dataclasses-{name}-{tag}.marshal"


def enable(command: str = "twin") -> None:
    """Give `dataclasses` the caching `exec` (see the module's text); nothing if it is off or already on.

    `command` names the table (the `twin` command's subcommand: `simulate`, `analyze`...).
    """
    if _enabled or os.environ.get("TWIN_NO_CODE_CACHE", "") not in ("", "0"):
        return
    if sys.implementation.name != "cpython" or "exec" in vars(dataclasses):
        return  # another interpreter, or someone else's exec there already: leave it
    table = _Table(table_path(command))

    def exec_cached(source: Any, globs: Any = None, locs: Any = None, /) -> None:
        if type(source) is str:
            source = table.code(source)
        builtins.exec(source, globs, locs)

    dataclasses.exec = exec_cached  # type: ignore[attr-defined]  # found before the builtin by name lookup
    _enabled.append(table)
    atexit.register(table.save)


def compiled_count() -> int:
    """How many source texts this process compiled rather than found in the table (0 when not enabled)."""
    return _enabled[0].compiled if _enabled else 0
