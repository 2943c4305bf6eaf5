"""The live view's peer errors are rate-limited: one line per kind, then a count.

Found by probing: every peer that failed the WebSocket handshake (a port scan, a browser, `curl`)
printed its own `twin: ERROR:` line, 78 from one probing session. Now the first of a kind is shown,
the rest are counted, and closing the server says how many were not shown.
"""

from __future__ import annotations

import logging
import socket
import time

import pytest

from twin.live import LiveServer

PEERS = 20


def test_repeated_peer_errors_are_one_line_then_a_count(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    with LiveServer(port=0) as server:
        for i in range(PEERS):
            with socket.create_connection(("127.0.0.1", server.port), timeout=30) as peer:
                peer.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n" if i % 2 else b"\x16\x03\x01 not a websocket\r\n\r\n")
                peer.settimeout(30)
                try:
                    while peer.recv(4096):  # until the server drops it
                        pass
                except OSError:
                    pass
        deadline = time.monotonic() + 120  # generous: only bounds a server that never logs
        while server.peer_errors.held_back() < PEERS - 1 and time.monotonic() < deadline:
            time.sleep(0.05)
    shown = [r for r in caplog.records if "handshake failed" in r.getMessage() and r.levelno >= logging.ERROR]
    assert len(shown) == 1, [r.getMessage() for r in caplog.records]
    counts = [r.getMessage() for r in caplog.records if "more peer errors like" in r.getMessage()]
    assert counts == [
        f"live view: {PEERS - 1} more peer errors like 'Dropping client <peer>: handshake failed' were not shown"
    ]
