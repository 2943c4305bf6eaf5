"""NavFn's two hot loops in C (`navfn_kernels.c`): the potential propagation and the gradient-descent path trace.

`twin.nav.planner.navfn` holds the same algorithm in Python (`_potential_py`, `_trace_py`) as the reference
and the fallback; both do the arithmetic in doubles in the same order, so they return identical
arrays. The kernel is built on first use with the system C compiler (`twin.core.native`).

    int twin_navfn_potential(const unsigned char *cost, int nx, int ny, int source, int target,
                             int astar, double *pot, int *heap_cells, double *heap_keys,
                             unsigned char *done)
        Fill `pot` (nx*ny, preset to POT_HIGH by the caller) outward from `source` (potential 0)
        through cells with cost < 254, by NavFn's interpolated update, in Dijkstra order (A* order
        with `astar`: key + 50 * Euclidean cell distance to `target`). Stops once `target` (-1:
        never) is settled; a settled cell is not updated again. The heap arrays hold 4*nx*ny
        entries; `done` (nx*ny, zeroed) marks settled cells. Returns the cells settled.

    int twin_navfn_trace(const double *pot, const unsigned char *cost, int nx, int ny, int start, int goal,
                         int max_cycles, double *out_xy, int max_points)
        NavFn's calcPath: descend the potential from cell `start` in half-cell steps; write (x, y) in
        cell units to `out_xy`, ending with the node `goal` (the potential's source). Returns the
        number of points, or -1 on failure.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

from twin.core.native import CLibrary, load_library

__all__ = ["load_navfn_kernel"]

_LIB = CLibrary(name="twin_navfn", files=(Path(__file__).with_name("navfn_kernels.c"),))


@functools.cache
def load_navfn_kernel() -> ctypes.CDLL | None:
    """Return the NavFn kernel with its signatures set, or None (no compiler, or TWIN_NO_NATIVE)."""
    lib = load_library(_LIB)
    if lib is None:
        return None
    dbl = ctypes.POINTER(ctypes.c_double)
    u8 = ctypes.POINTER(ctypes.c_ubyte)
    i32 = ctypes.POINTER(ctypes.c_int)
    c_int = ctypes.c_int
    lib.twin_navfn_potential.argtypes = [u8, c_int, c_int, c_int, c_int, c_int, dbl, i32, dbl, u8]
    lib.twin_navfn_potential.restype = c_int
    lib.twin_navfn_trace.argtypes = [dbl, u8, c_int, c_int, c_int, c_int, c_int, dbl, c_int]
    lib.twin_navfn_trace.restype = c_int
    return lib
