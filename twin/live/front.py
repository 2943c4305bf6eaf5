"""The live server's front door: the WebSocket handshake read once, so older Foxglove clients connect too.

foxglove-sdk's server accepts only the `foxglove.sdk.v1` (and `.v1.1`) subprotocols and cannot be told
to accept others; clients still on `foxglove.websocket.v1` (the npm `@foxglove/ws-protocol` client's
default, Lichtblick before its `foxglove.sdk.v1` support, foxglove_bridge 0.8-era tools) get HTTP 400
from it, and it logs "handshake failed" at every retry. Foxglove says the two subprotocols are the
same protocol under a new name, so this front accepts both: it reads each connection's HTTP upgrade
request, offers the SDK `foxglove.sdk.v1` in place of `foxglove.websocket.v1`, renames the SDK's
answer back, and from then on copies bytes both ways untouched (the WebSocket accept key does not
depend on the subprotocol). A client asking for neither is refused here with HTTP 400 and one log
line, once per subprotocol, naming what it asked and what is served.
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import socket
import threading
import time
from collections.abc import Sequence

__all__ = ["LEGACY_SUBPROTOCOL", "SERVED_SUBPROTOCOLS", "HandshakeFront"]

_log = logging.getLogger(__name__)

SERVED_SUBPROTOCOLS: tuple[str, ...] = ("foxglove.sdk.v1", "foxglove.sdk.v1.1")
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
_HEADER_LIMIT = 16 * 1024
_HANDSHAKE_TIMEOUT_S = 10.0
_CHUNK = 64 * 1024


def _read_head(sock: socket.socket) -> tuple[bytes, bytes] | None:
    """An HTTP head (through the blank line) and what followed it, or None if the peer closed first."""
    buf = b""
    while b"\r\n\r\n" not in buf:
        if len(buf) > _HEADER_LIMIT:
            return None
        chunk = sock.recv(4096)
        if not chunk:
            return None
        buf += chunk
    end = buf.index(b"\r\n\r\n") + 4
    return buf[:end], buf[end:]


def _protocols(head: bytes) -> list[str] | None:
    """The subprotocols a WebSocket upgrade request offers ([] for none); None if it is no upgrade."""
    lines = head.decode("latin-1").split("\r\n")
    offered: list[str] = []
    upgrade = False
    for line in lines[1:]:
        name, _, value = line.partition(":")
        key = name.strip().lower()
        if key == "upgrade" and value.strip().lower() == "websocket":
            upgrade = True
        elif key == "sec-websocket-protocol":
            offered += [p.strip() for p in value.split(",") if p.strip()]
    return offered if upgrade else None


def _rename_protocol(head: bytes, old: str, new: str) -> bytes:
    """The head with the Sec-WebSocket-Protocol header's `old` subprotocol renamed `new`."""
    lines = head.decode("latin-1").split("\r\n")
    for i, line in enumerate(lines):
        name, sep, value = line.partition(":")
        if sep and name.strip().lower() == "sec-websocket-protocol":
            values = [new if p.strip() == old else p.strip() for p in value.split(",")]
            lines[i] = f"{name}: {', '.join(values)}"
    return "\r\n".join(lines).encode("latin-1")


class HandshakeFront:
    """Listens on the public address and hands each connection to the SDK's server (see the module docstring).

    Args:
        listener: A bound, listening socket (the public address).
        backend: The SDK server's (host, port).
    """

    def __init__(self, listener: socket.socket, backend: tuple[str, int]) -> None:
        self._listener = listener
        self._backend = backend
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._refused: set[str] = set()
        # Connections wait here until the server has every channel (`open`): a client that came
        # while they were being created could subscribe to one the SDK did not know yet, get
        # "Unknown channel ID", and (as Foxglove does) never ask again: no /tf_static all session.
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="twin-live-front", daemon=True)
        self._thread.start()

    def open(self) -> None:
        """Let the waiting and the coming connections through to the server (idempotent)."""
        self._ready.set()

    @property
    def port(self) -> int:
        """The public port."""
        return int(self._listener.getsockname()[1])

    def close(self, grace_s: float = 0.0) -> None:
        """Stop accepting and drop every open connection (after up to `grace_s` for them to end on their own)."""
        self._stop.set()
        self._ready.set()  # (a connection still waiting ends with the rest)
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline:  # the server's Close frames on their way through
            with self._lock:
                if not self._open:
                    break
            time.sleep(0.01)
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        with self._lock:
            socks = list(self._open)
        for s in socks:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=2.0)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(client,), name="twin-live-conn", daemon=True).start()

    def _track(self, *socks: socket.socket) -> None:
        with self._lock:
            self._open.update(socks)

    def _forget(self, *socks: socket.socket) -> None:
        with self._lock:
            self._open.difference_update(socks)
        for s in socks:
            s.close()

    def _refuse(self, client: socket.socket, offered: Sequence[str]) -> None:
        asked = ", ".join(offered) or "no subprotocol"
        line = (
            f"a live-view client asked for WebSocket subprotocol {asked}; this server speaks {SERVED_SUBPROTOCOLS[0]} "
            f"(the current Foxglove app, foxglove_bridge 3.x clients) and {LEGACY_SUBPROTOCOL} (older Foxglove and "
            "Lichtblick releases, @foxglove/ws-protocol's default): refused with HTTP 400"
        )
        with self._lock:
            first = asked not in self._refused
            self._refused.add(asked)
        if first:
            _log.warning("%s", line)
        body = (line + "\n").encode()
        client.sendall(
            b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\nConnection: close\r\n"
            + f"Content-Length: {len(body)}\r\n\r\n".encode()
            + body
        )

    def _serve(self, client: socket.socket) -> None:
        self._track(client)
        backend: socket.socket | None = None
        try:
            client.settimeout(_HANDSHAKE_TIMEOUT_S)
            request = _read_head(client)
            if request is None:
                return
            head, rest = request
            while not self._ready.wait(0.1):  # (the handshake's answer waits; the client just sees a slow server)
                if self._stop.is_set():
                    return
            if self._stop.is_set():
                return
            offered = _protocols(head)
            legacy = False
            if offered is not None and not any(p in SERVED_SUBPROTOCOLS for p in offered):
                if LEGACY_SUBPROTOCOL not in offered:
                    self._refuse(client, offered)
                    return
                legacy = True
                head = _rename_protocol(head, LEGACY_SUBPROTOCOL, SERVED_SUBPROTOCOLS[0])
            backend = socket.create_connection(self._backend, timeout=_HANDSHAKE_TIMEOUT_S)
            self._track(backend)
            backend.sendall(head + rest)
            if legacy:
                answer = _read_head(backend)
                if answer is None:
                    return
                reply, more = answer
                client.sendall(_rename_protocol(reply, SERVED_SUBPROTOCOLS[0], LEGACY_SUBPROTOCOL) + more)
            client.settimeout(None)
            backend.settimeout(None)
            self._splice(client, backend)
        except OSError as err:
            _log.debug("live-view connection ended: %s", err)
        finally:
            self._forget(client, *((backend,) if backend is not None else ()))

    def _splice(self, a: socket.socket, b: socket.socket) -> None:
        peer = {a: b, b: a}
        with selectors.DefaultSelector() as sel:
            sel.register(a, selectors.EVENT_READ)
            sel.register(b, selectors.EVENT_READ)
            while not self._stop.is_set():
                for key, _ in sel.select(timeout=0.5):
                    src: socket.socket = key.fileobj  # type: ignore[assignment]
                    data = src.recv(_CHUNK)
                    if not data:
                        return
                    peer[src].sendall(data)
