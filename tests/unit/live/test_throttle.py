"""The peer-error throttle: the first of a kind shown, repeats counted, one line a minute with the count."""

from __future__ import annotations

import logging

import pytest

from twin.live.throttle import PeerLogThrottle


def _record(text: str, level: int = logging.ERROR) -> logging.LogRecord:
    return logging.LogRecord("foxglove.websocket.server", level, __file__, 1, text, None, None)


def test_one_line_per_kind_then_the_count_a_minute_later(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    throttle = PeerLogThrottle(interval_s=60.0, clock=lambda: now[0])
    shown = [throttle.filter(_record(f"Dropping client 10.0.0.{i}:5{i}000: handshake failed")) for i in range(5)]
    assert shown == [True, False, False, False, False]
    assert throttle.filter(_record("Client 7 sent an invalid message"))  # another kind: shown
    assert throttle.filter(_record("connected", logging.INFO))  # never held back
    now[0] = 61.0
    late = _record("Dropping client [::1]:4000: handshake failed")
    assert throttle.filter(late)
    assert late.getMessage().endswith("(4 more like it in the last 60 s were not shown)")
    assert not throttle.filter(_record("Dropping client 10.0.0.9:1: handshake failed"))
    caplog.set_level(logging.WARNING)
    throttle.flush()
    assert [r.getMessage() for r in caplog.records] == [
        "live view: 1 more peer errors like 'Dropping client <peer>: handshake failed' were not shown"
    ]
    assert throttle.held_back() == 5
