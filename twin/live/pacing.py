"""Pacing: hold a stream of sim-time stamps to the wall clock at a chosen speed."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from twin.core.errors import ConfigError

__all__ = ["Pacer", "check_speed"]


MIN_SPEED = 1e-6
"""The slowest real-time factor: a message due 1 s of sim time on waits 11.6 days (slower overflows sleep)."""


def check_speed(speed: float) -> float:
    """Return `speed` if it is a usable real-time factor.

    Raises:
        ConfigError: If it is not a positive, finite number.
    """
    if not (math.isfinite(speed) and speed > 0):
        msg = f"--speed must be a positive number (1 = real time, 5 = five times faster), got {speed}"
        raise ConfigError(msg)
    if speed < MIN_SPEED:
        msg = f"--speed must be at least {MIN_SPEED:g} (a million times slower than real time), got {speed}"
        raise ConfigError(msg)
    return speed


class Pacer:
    """Sleeps until the wall clock catches up with the sim time of the next message.

    The schedule is absolute: message time `t_ns` is due at `wall0 + (t_ns - t0_ns) / speed`,
    where (`wall0`, `t0_ns`) is the first call. A late step (a slow tick, a busy CPU) is therefore
    caught up by not sleeping, and errors never accumulate over a long run.

    Args:
        speed: Sim seconds per wall second (1 = real time).
        should_stop: Once it returns true, `wait` stops sleeping so the run ends promptly.
        clock: Wall clock in seconds (monotonic).
        sleep: How to wait, in seconds.
    """

    __slots__ = ("_clock", "_last_ns", "_ns_per_s", "_sleep", "_start", "_stop", "speed")

    def __init__(
        self,
        speed: float,
        *,
        should_stop: Callable[[], bool] = lambda: False,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.speed = check_speed(speed)
        self._ns_per_s = 1e9 * speed  # sim nanoseconds per wall second
        self._stop = should_stop
        self._clock = clock
        self._sleep = sleep
        self._start: tuple[float, int] | None = None
        self._last_ns = -1

    def restart(self) -> None:
        """Forget the schedule: the next message starts a new one (e.g. a bag played again)."""
        self._start = None
        self._last_ns = -1

    def wait(self, t_ns: int) -> None:
        """Return when the message stamped `t_ns` is due (at once if it is late)."""
        if t_ns == self._last_ns:
            return
        self._last_ns = t_ns
        now = self._clock()
        if self._start is None:
            self._start = (now, t_ns)
            return
        wall0, t0_ns = self._start
        delay_s = wall0 + (t_ns - t0_ns) / self._ns_per_s - now
        if delay_s > 0.0 and not self._stop():
            self._sleep(delay_s)

    def lag_s(self, t_ns: int) -> float:
        """How far the wall clock is past the time `t_ns` is due (negative: ahead of schedule)."""
        if self._start is None:
            return 0.0
        wall0, t0_ns = self._start
        return self._clock() - (wall0 + (t_ns - t0_ns) / self._ns_per_s)
