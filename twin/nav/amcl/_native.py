"""AMCL's C kernels (`amcl_kernels.c`), built once per machine.

The laser model, the motion model's sampling, the likelihood field's distances, resampling with
KLD-sampling's count, histogram clusters and the estimate. The loops are short per element but
run over thousands of elements per call (2000 particles x 60 beams); in C they cost a fraction
of the numpy version. Without a C compiler (or with `TWIN_NO_NATIVE=1`) the filter uses its numpy
implementation, which gives the same counts and clusters, and the same weights up to the order of
a floating-point sum (the tests compare them). Random numbers are always drawn in Python.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

from twin.core.native import CLibrary, load_library

# -O3 lets the compiler vectorise the loops; no contraction into fused multiply-adds, so the kernels
# round every product and sum as the numpy paths do.
_FLAGS = ("-O3", "-ffp-contract=off", "-shared", "-fPIC")


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled AMCL kernels, building them on first use; None if unavailable."""
    source = Path(__file__).with_name("amcl_kernels.c")
    lib = load_library(CLibrary(name="nav_amcl", files=(source,), flags=_FLAGS), keep_gil=True)
    if lib is None:
        return None
    ptr, long_, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    lib.twin_amcl_likelihood.restype = ctypes.c_int
    lib.twin_amcl_likelihood.argtypes = [
        ptr,
        long_,
        dbl,
        dbl,
        dbl,
        ptr,
        ptr,
        ptr,
        ptr,
        long_,
        dbl,
        dbl,
        dbl,
        ptr,
        long_,
        long_,
        ptr,
    ]
    lib.twin_amcl_motion.restype = None
    lib.twin_amcl_motion.argtypes = [ptr, long_, ptr, dbl, dbl, dbl, dbl, dbl, dbl]
    lib.twin_amcl_distances.restype = ctypes.c_int
    lib.twin_amcl_distances.argtypes = [ptr, long_, long_, dbl, dbl, ptr]
    lib.twin_kld_count.restype = long_
    lib.twin_kld_count.argtypes = [ptr, long_, ptr]
    lib.twin_pf_clusters.restype = long_
    lib.twin_pf_clusters.argtypes = [ptr, long_, ptr]
    lib.twin_pf_resample.restype = long_
    lib.twin_pf_resample.argtypes = [ptr, long_, ptr, ptr, long_, ptr, ptr, ptr]
    lib.twin_pf_keys.restype = None
    lib.twin_pf_keys.argtypes = [ptr, long_, ptr, ptr]
    lib.twin_pf_estimate.restype = ctypes.c_int
    lib.twin_pf_estimate.argtypes = [ptr, ptr, long_, ptr, long_, ptr]
    return lib
