"""A one-line progress display on stderr, shown only when stderr is a terminal."""

from __future__ import annotations

import contextlib
import sys
import time
from typing import TextIO

__all__ = ["Progress", "clear_progress_line"]

# The progress lines drawn and not yet cleared: a log line printed while one is drawn clears it
# first (`clear_progress_line`), so the message starts at the line's beginning, not after the bar.
_drawn: list[Progress] = []


def clear_progress_line() -> None:
    """Clear every drawn progress line (each redraws at its next update)."""
    for bar in list(_drawn):
        bar.close()


class Progress:
    """Redraws `sim 12.3/60.0 s  [#####-----]  RTF 412x  msgs 5123` at most a few times a second."""

    def __init__(self, total_s: float | None, *, stream: TextIO | None = None, min_interval_s: float = 0.2) -> None:
        self._stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self._stream, "isatty", lambda: False)())
        self._total_s = total_s
        self._start = time.monotonic()
        self._last = 0.0
        self._min_interval_s = min_interval_s
        self._drawn = False

    def update(self, sim_s: float, messages: int) -> None:
        """Redraw if enough wall time has passed since the last redraw."""
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < self._min_interval_s:
            return
        self._last = now
        wall = max(now - self._start, 1e-9)
        rtf = sim_s / wall
        if self._total_s:
            frac = min(1.0, sim_s / self._total_s)
            bar = "#" * int(frac * 24) + "-" * (24 - int(frac * 24))
            head = f"sim {sim_s:7.1f}/{self._total_s:.1f} s [{bar}]"
        else:
            head = f"sim {sim_s:7.1f} s"
        self._stream.write(f"\r{head}  RTF {rtf:6.0f}x  msgs {messages}\x1b[K")
        self._stream.flush()
        if not self._drawn:
            _drawn.append(self)
        self._drawn = True

    def close(self) -> None:
        """Clear the line so the summary prints cleanly."""
        if self._drawn:
            self._stream.write("\r\x1b[K")
            self._stream.flush()
            self._drawn = False
            self._last = 0.0  # (redrawn at the next update)
            with contextlib.suppress(ValueError):  # (a log line from another thread cleared it meanwhile)
                _drawn.remove(self)
