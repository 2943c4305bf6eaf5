"""The integer-nanosecond clock: time is `start_ns + k * step_ns`, never an accumulated float."""

from __future__ import annotations

__all__ = ["NS_PER_S", "ns_to_s", "period_ns", "s_to_ns"]

NS_PER_S = 1_000_000_000


def s_to_ns(t_s: float) -> int:
    """Convert seconds to the nearest integer nanosecond."""
    return round(t_s * NS_PER_S)


def ns_to_s(t_ns: int) -> float:
    """Convert integer nanoseconds to float seconds (only at the boundaries that need floats)."""
    return t_ns / NS_PER_S


def period_ns(rate_hz: float) -> int:
    """Return the period of a rate in whole nanoseconds.

    Args:
        rate_hz: A positive rate.

    Raises:
        ValueError: If the rate is not positive.
    """
    if not rate_hz > 0.0:
        msg = f"rate must be positive, got {rate_hz!r} Hz"
        raise ValueError(msg)
    return round(NS_PER_S / rate_hz)
