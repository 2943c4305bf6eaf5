"""NavFn's two hot loops in C (`navfn_kernels.c`): the potential propagation and the gradient-descent path trace.

`twin.nav.planner.navfn` holds the same algorithm in Python (`_potential_py`, `_trace_py`) as the reference
and the fallback. Both compute in float32 where Nav2's NavFn does (its potential, gradients and path
points) and in doubles where NavFn's expressions are doubles, so they return identical arrays, equal to
Nav2 Humble's (tests/unit/nav/planner/navfn_cases). The kernel is built on first use with the system C
compiler (`twin.core.native`), without floating-point contraction.

    int twin_navfn_potential(const unsigned char *cost, int nx, int ny, int source, int target,
                             int astar, float *pot, int *blocks, unsigned char *queued)
        NavFn's calcNavFnDijkstra(true) / calcNavFnAstar: set `pot` (nx*ny) to POT_HIGH, the
        `source` cell to 0, and propagate through cells with cost < 254 in cost-threshold batches
        (threshold 254, raised by 100 whenever the batch under it runs dry; A*: starting 50 x the
        cell distance higher, each key plus 50 x the distance to `target`) until `target` has a
        value, the blocks are empty or max(nx*ny/20, nx+ny) batches ran. `blocks` holds 3 x 10000
        ints (NavFn's three priority blocks), `queued` nx*ny bytes, zeroed. Returns the batches run.

    int twin_navfn_trace(const float *pot, int nx, int ny, int start, int goal, int max_cycles,
                         float *out_xy)
        NavFn's calcPath: descend the potential from cell `start` in half-cell steps; write (x, y) in
        cell units to `out_xy` (room for max_cycles points), ending with the cell `goal` (the
        potential's source). Returns the number of points, or -1 on failure.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

from twin.core.native import DEFAULT_CFLAGS, CLibrary, load_library

__all__ = ["load_navfn_kernel"]

_LIB = CLibrary(
    name="twin_navfn",
    files=(Path(__file__).with_name("navfn_kernels.c"),),
    flags=(*DEFAULT_CFLAGS, "-ffp-contract=off"),
)


@functools.cache
def load_navfn_kernel() -> ctypes.CDLL | None:
    """Return the NavFn kernel with its signatures set, or None (no compiler, or TWIN_NO_NATIVE)."""
    lib = load_library(_LIB)
    if lib is None:
        return None
    f32 = ctypes.POINTER(ctypes.c_float)
    u8 = ctypes.POINTER(ctypes.c_ubyte)
    i32 = ctypes.POINTER(ctypes.c_int)
    c_int = ctypes.c_int
    lib.twin_navfn_potential.argtypes = [u8, c_int, c_int, c_int, c_int, c_int, f32, i32, u8]
    lib.twin_navfn_potential.restype = c_int
    lib.twin_navfn_trace.argtypes = [f32, c_int, c_int, c_int, c_int, c_int, f32]
    lib.twin_navfn_trace.restype = c_int
    return lib
