"""Seeded random streams: one independent, named stream per noise source.

A stream's numbers depend only on the scenario seed and the stream's name, never on the order in
which streams are created, so adding a sensor does not change another sensor's noise.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["RngStreams"]


class RngStreams:
    """Hands out `numpy.random.Generator`s keyed by name, all derived from one seed."""

    def __init__(self, seed: int, *, prefix: str = "", issued: dict[str, np.random.Generator] | None = None) -> None:
        self._seed = seed
        self._prefix = prefix
        self._issued: dict[str, np.random.Generator] = {} if issued is None else issued

    def under(self, namespace: str) -> RngStreams:
        """The streams of a robot under `namespace`: `lidar` there is the stream `<namespace>/lidar`.

        The namespace `""` gives these streams themselves (one robot keeps its streams' names).
        """
        ns = namespace.strip("/")
        if not ns:
            return self
        return RngStreams(self._seed, prefix=f"{self._prefix}{ns}/", issued=self._issued)

    @property
    def seed(self) -> int:
        """The scenario seed the streams derive from."""
        return self._seed

    def stream(self, name: str) -> np.random.Generator:
        """Return the generator for `name` (the same object on every call with that name)."""
        name = self._prefix + name
        gen = self._issued.get(name)
        if gen is None:
            key = zlib.crc32(name.encode("utf-8"))
            gen = np.random.default_rng(np.random.SeedSequence([self._seed & 0xFFFFFFFF, self._seed >> 32, key]))
            self._issued[name] = gen
        return gen
