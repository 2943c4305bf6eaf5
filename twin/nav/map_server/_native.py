"""The map server's C kernel (`map_kernels.c`): the flood fill of `map_from_scene`, built once per machine.

Without a C compiler (or with `TWIN_NO_NATIVE=1`) the caller uses scipy's labelling, which gives
the same region.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

from twin.core.native import CLibrary, load_library

_FLAGS = ("-O3", "-ffp-contract=off", "-shared", "-fPIC")


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled flood fill, building it on first use; None if unavailable."""
    source = Path(__file__).with_name("map_kernels.c")
    lib = load_library(CLibrary(name="nav_map", files=(source,), flags=_FLAGS), keep_gil=True)
    if lib is None:
        return None
    ptr, long_ = ctypes.c_void_p, ctypes.c_long
    lib.twin_flood_fill.restype = long_
    lib.twin_flood_fill.argtypes = [ptr, long_, long_, long_, ptr]
    return lib
