"""The costmaps' C kernels (`costmap_kernels.c`), built once per machine.

Ray tracing, marking, footprint clearing, the layers' composition with inflation, and the
footprint's cost (FootprintCollisionChecker). The loops run over thousands of cells per call (360
rays x 60 cells; a 170 x 170 cell window); in C they cost a fraction of the numpy version. Without
a C compiler (or with `TWIN_NO_NATIVE=1`) the callers use their numpy implementations, which give
the same cells (the tests compare them).
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

from twin.core.native import CLibrary, load_library

# -O3; no contraction into fused multiply-adds, so the kernels
# round every product and sum as the numpy paths do.
_FLAGS = ("-O3", "-ffp-contract=off", "-shared", "-fPIC")


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled costmap kernels, building them on first use; None if unavailable."""
    source = Path(__file__).with_name("costmap_kernels.c")
    lib = load_library(CLibrary(name="nav_costmap", files=(source,), flags=_FLAGS), keep_gil=True)
    if lib is None:
        return None
    ptr, long_, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    lib.twin_raytrace.restype = None
    lib.twin_raytrace.argtypes = [
        ptr, long_, long_, long_, long_, ptr, ptr, long_, dbl, dbl, ctypes.c_ubyte, ptr,
    ]  # fmt: skip
    lib.twin_obstacle_update.restype = None
    lib.twin_obstacle_update.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, dbl, dbl, ptr, long_, ctypes.c_int, ctypes.c_int,
        dbl, dbl, dbl, dbl, dbl, dbl, ptr,
    ]  # fmt: skip
    lib.twin_voxel_update.restype = None
    lib.twin_voxel_update.argtypes = [
        ptr, ptr, long_, long_, dbl, dbl, dbl, dbl, dbl, dbl, ptr, long_, ctypes.c_int, ctypes.c_int,
        dbl, dbl, dbl, dbl, ptr, ptr, ptr,
    ]  # fmt: skip
    lib.twin_costmap_compose.restype = ctypes.c_int
    lib.twin_costmap_compose.argtypes = [
        ptr, ctypes.c_ubyte, ptr, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_,
        ctypes.c_int, long_, ptr, ctypes.c_int, ctypes.c_int, ptr,
    ]  # fmt: skip
    lib.twin_inflate.restype = ctypes.c_int
    lib.twin_inflate.argtypes = [
        ptr, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_, ptr,
        ctypes.c_int, ctypes.c_int, ptr,
    ]  # fmt: skip
    lib.twin_scan_update.restype = ctypes.c_int
    lib.twin_scan_update.argtypes = [ptr, ptr, long_, long_, ptr, ptr, ptr, ptr, ptr, ptr]
    lib.twin_fill_footprint.restype = ctypes.c_int
    lib.twin_fill_footprint.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, ptr, long_, dbl, dbl, dbl, dbl, ctypes.c_ubyte, ptr,
    ]  # fmt: skip
    lib.twin_costmap_scan_update.restype = ctypes.c_int
    lib.twin_costmap_scan_update.argtypes = [ptr, ptr, long_, *[ptr] * 13]
    lib.twin_footprint_cost.restype = ctypes.c_int
    lib.twin_footprint_cost.argtypes = [ptr, long_, long_, dbl, dbl, dbl, ptr, ptr, long_, dbl, dbl, dbl]
    return lib
