"""One check for every number a user gives the twin: finite, and within what its unit can mean.

Scenario values (through the config loader, with file, line and key), `scenario check`, and the
command line's numeric options all ask `number_problem`. The bounds are far beyond any real use
and exist so that a typo (`1e300`) is refused in one line instead of overflowing deep inside a run:

| key ends in | at most | because |
|---|---|---|
| `_s` | 1e9 s (about 31.7 years) | sim times are integer nanoseconds in 64 bits (up to 9.2e9 s) |
| `_hz` | 1e9 Hz | a period must be at least the clock's 1 ns |
| `_m` | 1e7 m (10,000 km) | no world is larger; coordinates must stay exact to a millimetre |
| anything else | 1e15 (integers: 64-bit) | nothing the twin reads is larger |
"""

from __future__ import annotations

import math

__all__ = ["INT64_MAX", "number_problem"]

INT64_MAX = 2**63 - 1

# (key suffix, largest magnitude, unit, why) in the order they are matched.
_BOUNDS: tuple[tuple[str, float, str, str], ...] = (
    ("_s", 1e9, "s", "about 31.7 years; sim time is counted in 64-bit nanoseconds"),
    ("_hz", 1e9, "Hz", "a period shorter than the clock's 1 ns"),
    ("_m", 1e7, "m", "10,000 km; no world is that large"),
)
_ANY_BOUND = 1e15


def number_problem(value: float, key: str, *, unit: str | None = None) -> str | None:
    """Return why `value` cannot be taken for `key`, or None when it can.

    Args:
        value: The number (an int or a float; a bool is not checked).
        key: The setting's name (`max_duration_s`, `obstacles[0].path_xy_m[1][0]`, `--duration`); the
            unit is read from its last part's suffix.
        unit: The unit suffix (`s`, `hz`, `m`) when the key does not end in one (a CLI option).

    Returns:
        `"is NaN; give a number"`, `"is inf; give a finite number"`, or a bound with its reason.
    """
    if isinstance(value, bool):
        return None
    whole = isinstance(value, int)
    if whole:
        if abs(value) > INT64_MAX:
            return f"{value} does not fit a 64-bit whole number (at most {INT64_MAX})"
        magnitude = float(value)
    else:
        if math.isnan(value):
            return "is NaN; give a number"
        if math.isinf(value):
            return f"is {value}; give a finite number"
        magnitude = abs(value)
    leaf = key.rsplit(".", 1)[-1].split("[", 1)[0].lower()
    suffix = f"_{unit.lower()}" if unit is not None else leaf
    for ending, bound, unit_name, why in _BOUNDS:
        if suffix.endswith(ending):
            if magnitude > bound:
                return f"{value:g} {unit_name} is out of range: give at most {bound:g} {unit_name} ({why})"
            return None
    if not whole and magnitude > _ANY_BOUND:
        return f"{value:g} is out of range: give at most {_ANY_BOUND:g}"
    return None
