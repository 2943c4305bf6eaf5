"""Units of FMU variables: a small table of names with SI dimensions, factors and offsets.

A value `x` in unit `u` is `u.factor * x + u.offset` in the SI unit of the same dimension
(radians count as a base dimension, so rad/s and rpm convert and Hz does not). Names follow the
spellings FMUs use (`N.m`, `rad/s`, `rpm`, `mA`, `degC`); a few aliases are accepted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["BASE_NAMES", "UNITS", "Unit", "find_unit"]

# Order of the exponents in `Unit.dims`; the names are FMI's BaseUnit attributes.
BASE_NAMES: tuple[str, ...] = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True, kw_only=True, slots=True)
class Unit:
    """A unit: SI dimension exponents (in `BASE_NAMES` order), factor and offset to SI."""

    name: str
    dims: tuple[int, ...]
    factor: float = 1.0
    offset: float = 0.0

    def to_si(self, value: float) -> float:
        """Convert a value in this unit to SI."""
        return self.factor * value + self.offset

    def from_si(self, value: float) -> float:
        """Convert an SI value to this unit."""
        return (value - self.offset) / self.factor

    def same_dimension(self, other: Unit) -> bool:
        """Whether a value in `other` can be converted to this unit."""
        return self.dims == other.dims


def _d(*, kg: int = 0, m: int = 0, s: int = 0, A: int = 0, K: int = 0, rad: int = 0) -> tuple[int, ...]:
    return (kg, m, s, A, K, 0, 0, rad)


_VOLT = _d(kg=1, m=2, s=-3, A=-1)
_TORQUE = _d(kg=1, m=2, s=-2)
_SPEED = _d(s=-1, rad=1)

_TABLE: tuple[tuple[str, tuple[int, ...], float, float, tuple[str, ...]], ...] = (
    # name, dims, factor, offset, aliases
    ("1", _d(), 1.0, 0.0, ("", "-")),
    ("s", _d(s=1), 1.0, 0.0, ()),
    ("ms", _d(s=1), 1e-3, 0.0, ()),
    ("V", _VOLT, 1.0, 0.0, ()),
    ("mV", _VOLT, 1e-3, 0.0, ()),
    ("A", _d(A=1), 1.0, 0.0, ()),
    ("mA", _d(A=1), 1e-3, 0.0, ()),
    ("A/s", _d(A=1, s=-1), 1.0, 0.0, ()),
    ("Ohm", _d(kg=1, m=2, s=-3, A=-2), 1.0, 0.0, ("ohm", "Ω")),
    ("mOhm", _d(kg=1, m=2, s=-3, A=-2), 1e-3, 0.0, ()),
    ("H", _d(kg=1, m=2, s=-2, A=-2), 1.0, 0.0, ()),
    ("mH", _d(kg=1, m=2, s=-2, A=-2), 1e-3, 0.0, ()),
    ("N.m", _TORQUE, 1.0, 0.0, ("N·m", "Nm", "N*m")),
    ("mN.m", _TORQUE, 1e-3, 0.0, ("mNm", "mN·m")),
    ("N.mm", _TORQUE, 1e-3, 0.0, ("Nmm", "N·mm")),
    ("N.m/A", _d(kg=1, m=2, s=-2, A=-1), 1.0, 0.0, ("Nm/A",)),
    ("V.s/rad", _d(kg=1, m=2, s=-2, A=-1, rad=-1), 1.0, 0.0, ("Vs/rad",)),
    ("kg.m2", _d(kg=1, m=2), 1.0, 0.0, ("kg.m^2", "kg·m²", "kgm2")),
    ("g.cm2", _d(kg=1, m=2), 1e-7, 0.0, ()),
    ("N.m.s/rad", _d(kg=1, m=2, s=-1, rad=-1), 1.0, 0.0, ("Nms/rad",)),
    ("rad", _d(rad=1), 1.0, 0.0, ()),
    ("deg", _d(rad=1), math.pi / 180.0, 0.0, ("°",)),
    ("rev", _d(rad=1), 2.0 * math.pi, 0.0, ()),
    ("rad/s", _SPEED, 1.0, 0.0, ()),
    ("deg/s", _SPEED, math.pi / 180.0, 0.0, ()),
    ("rpm", _SPEED, 2.0 * math.pi / 60.0, 0.0, ("1/min", "rev/min")),
    ("rad/s2", _d(s=-2, rad=1), 1.0, 0.0, ("rad/s^2",)),
    ("m", _d(m=1), 1.0, 0.0, ()),
    ("mm", _d(m=1), 1e-3, 0.0, ()),
    ("m/s", _d(m=1, s=-1), 1.0, 0.0, ()),
    ("kg", _d(kg=1), 1.0, 0.0, ()),
    ("W", _d(kg=1, m=2, s=-3), 1.0, 0.0, ()),
    ("K", _d(K=1), 1.0, 0.0, ()),
    ("degC", _d(K=1), 1.0, 273.15, ("°C",)),
)

UNITS: Mapping[str, Unit] = {name: Unit(name=name, dims=dims, factor=f, offset=o) for name, dims, f, o, _ in _TABLE}
_ALIASES: Mapping[str, str] = {alias: name for name, _, _, _, aliases in _TABLE for alias in aliases}


def find_unit(name: str | None) -> Unit | None:
    """Return the unit called `name` (or one of its aliases), or None if the table lacks it."""
    if name is None:
        return None
    key = name.strip()
    return UNITS.get(key) or UNITS.get(_ALIASES.get(key, ""))
