"""Import fmpy without the `ldconfig -p` run its import starts on Linux.

fmpy takes `calloc`, `realloc` and `free` from the C library, which it finds with
`ctypes.util.find_library("c")`; on Linux that runs `/sbin/ldconfig -p` and parses its output,
about 14 ms of every run's start-up (`benchmarks/bench_startup.py`). `ctypes.CDLL(None)` opens the
running program instead, whose global symbols include the C library Python itself is linked with:
the same three functions, found without a process. Only that one lookup is answered differently,
and only while fmpy is imported.
"""

from __future__ import annotations

import sys

if sys.platform.startswith("linux") and "fmpy" not in sys.modules:
    import ctypes.util

    _find_library = ctypes.util.find_library

    def _without_ldconfig(name: str) -> str | None:
        return None if name == "c" else _find_library(name)

    ctypes.util.find_library = _without_ldconfig
    try:
        import fmpy  # noqa: F401
    finally:
        ctypes.util.find_library = _find_library
