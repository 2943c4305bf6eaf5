"""A run's start-up without Python's cyclic garbage collector, and its loop with a frozen heap.

Importing numpy, fmpy, lxml and twin and building a world, FMUs, maps and nodes allocate hundreds of
thousands of objects that live for the whole run; the collector walks them again and again while they
are made (about 110 collections, 50-60 ms of a 0.6 s start-up). `twin simulate` defers collection
from its first line to the first simulated step, then freezes what exists (`gc.freeze`: those
objects are never walked again) and turns collection back on for the loop, so a run that makes
reference cycles still frees them. Only the simulate command does this, and only through its
console entry point: a library user's process is left as it is.
"""

from __future__ import annotations

import gc

_deferred: list[bool] = []  # one entry while collection is deferred by `defer_collection`


def defer_collection() -> None:
    """Turn the cyclic collector off until `resume_collection` (nothing if it is already off)."""
    if gc.isenabled():
        gc.disable()
        _deferred[:] = [True]


def resume_collection() -> None:
    """Freeze the objects made so far and turn the collector back on, if `defer_collection` turned it off."""
    if _deferred:
        _deferred.clear()
        gc.freeze()
        gc.enable()
