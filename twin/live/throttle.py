"""Peer errors of the live view, rate-limited: one line per kind, then a count.

The Foxglove SDK logs an error for every peer that fails (a port scan, a browser that is not a
Foxglove client, a client that drops): one probing session once printed 78 `twin: ERROR:` lines.
`PeerLogThrottle` lets the first message of each kind through (a kind: the message with peer
addresses and numbers taken out), then at most one a minute carrying how many were held back, and
`flush` says how many were never shown when the server closes.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

__all__ = ["FOXGLOVE_LOGGERS", "PeerLogThrottle"]

#: The SDK's loggers that report peers (its Rust log targets, as Python logger names).
FOXGLOVE_LOGGERS = (
    "foxglove.websocket.server",
    "foxglove.websocket_server",
    "foxglove.websocket.connected_client",
    "foxglove.websocket.connected_client.poller",
    "foxglove.websocket.connected_client.send_lossy",
    "foxglove.websocket.advertise",
)

_PEER = re.compile(r"\[[0-9A-Fa-f:.]+\]:\d+|\b\d{1,3}(?:\.\d{1,3}){3}(?::\d+)?\b")
_NUMBER = re.compile(r"\d+")
_log = logging.getLogger(__name__)


@dataclass(slots=True)
class _Kind:
    shown_at: float
    held: int = 0  # since the last line shown
    held_total: int = 0


class PeerLogThrottle(logging.Filter):
    """A logging filter: the first WARNING-or-worse record of each kind passes, repeats are counted.

    Args:
        interval_s: After a kind's line, its repeats are held back this long; the next one shown
            says how many were.
        clock: Monotonic seconds (for tests).
    """

    def __init__(self, *, interval_s: float = 60.0, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self._interval_s = interval_s
        self._clock = clock
        self._kinds: dict[str, _Kind] = {}
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        """Whether `record` is shown (it may be given the count of the ones held back before it)."""
        if record.levelno < logging.WARNING:
            return True
        text = record.getMessage()
        key = _NUMBER.sub("N", _PEER.sub("<peer>", text))
        now = self._clock()
        with self._lock:
            kind = self._kinds.get(key)
            if kind is None:
                self._kinds[key] = _Kind(shown_at=now)
                return True
            if now - kind.shown_at < self._interval_s:
                kind.held += 1
                kind.held_total += 1
                return False
            held, kind.held, kind.shown_at = kind.held, 0, now
        if held:
            record.msg = f"{text} ({held} more like it in the last {self._interval_s:g} s were not shown)"
            record.args = ()
        return True

    def held_back(self) -> int:
        """How many records were held back so far, over all kinds."""
        with self._lock:
            return sum(k.held_total for k in self._kinds.values())

    def flush(self) -> None:
        """Say how many of each kind were held back since their last line (one warning per kind)."""
        with self._lock:
            pending = [(key, kind.held) for key, kind in self._kinds.items() if kind.held]
            for _, kind in self._kinds.items():
                kind.held = 0
        for key, held in pending:
            _log.warning("live view: %d more peer errors like %r were not shown", held, key)

    def attach(self, names: Iterable[str] = FOXGLOVE_LOGGERS) -> None:
        """Filter the records of these loggers."""
        for name in names:
            logging.getLogger(name).addFilter(self)

    def detach(self, names: Iterable[str] = FOXGLOVE_LOGGERS) -> None:
        """Stop filtering them."""
        for name in names:
            logging.getLogger(name).removeFilter(self)
