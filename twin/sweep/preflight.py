"""What a sweep checks before it starts a cluster or any run: its output folder, and the scheduler's address.

An `--out` that is a file, `/dev/null` or on read-only storage once failed after every run had
run; an address that is not a Dask scheduler (a web server, an SSH port) made Dask wait for ever or
read a banner as a 3 EiB message. Both are told at once, in one line.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import tempfile
from pathlib import Path
from urllib.parse import urlsplit

from twin.core.errors import ConfigError

__all__ = ["check_out_dir", "check_scheduler"]

_PROBE_TIMEOUT_S = 10.0
# A Dask comm's first message is its handshake, a few hundred bytes behind an 8-byte length.
_MAX_HANDSHAKE_BYTES = 64 * 2**20
_DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")


def check_out_dir(out: Path, *, option: str = "--out", create: bool = True) -> None:
    """Refuse an output folder that is not a folder or cannot be written (created if missing, with `create`).

    Without `create` a missing folder is left uncreated (a sweep refused afterwards leaves nothing
    behind); the nearest folder above it that exists must be writable.

    Raises:
        ConfigError: `--out PATH: why; give a writable folder`.
    """
    if out.exists() and not out.is_dir():
        msg = f"{option} {out}: is not a folder; give a folder to write the runs and tables into"
        raise ConfigError(msg)
    if not create and not out.exists():
        above = next((p for p in out.absolute().parents if p.exists()), None)
        if above is None or not above.is_dir() or not os.access(above, os.W_OK | os.X_OK):
            msg = f"{option} {out}: cannot create it ({above} is not a writable folder); give a writable folder"
            raise ConfigError(msg)
        return
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".twin-write-test-"):
            pass
    except OSError as err:
        msg = f"{option} {out}: cannot write there ({err.strerror or err}); give a writable folder"
        raise ConfigError(msg) from None


def _refuse(address: str, why: str) -> ConfigError:
    return ConfigError(
        f"--scheduler {address}: {why}; give a Dask scheduler's address, tcp://HOST:8786 (start one with "
        f"`dask scheduler`), or leave out --scheduler to run on this machine"
    )


def check_scheduler(address: str) -> None:
    """Refuse an address that is no Dask scheduler address, or whose server does not speak Dask's protocol.

    A TCP address whose server accepts the connection must send a Dask handshake (its first message,
    sent unasked) within 10 s. A server that cannot be reached is left to Dask, which retries while
    a scheduler starts and then says so.

    Raises:
        ConfigError: Naming the address and what is wrong with it.
    """
    text = address.strip()
    if not text:
        raise _refuse(repr(address), "empty")
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    if scheme not in _DASK_SCHEMES:
        hint = " (http:// is its dashboard, not its address)" if scheme in ("http", "https") else ""
        raise _refuse(address, f"{scheme}:// is not a Dask protocol{hint}")
    if scheme != "tcp":
        return
    try:
        parts = urlsplit(f"tcp://{rest}")
        host, port = parts.hostname, parts.port
    except ValueError as err:
        raise _refuse(address, f"not HOST:PORT ({err})") from None
    if not host or port is None:
        raise _refuse(address, "no port; a scheduler listens on 8786 by default (tcp://HOST:8786)")
    try:
        conn = socket.create_connection((host, port), timeout=_PROBE_TIMEOUT_S)
    except OSError:
        return  # unreachable, or not up yet: Dask retries and then says so
    with contextlib.closing(conn):
        head = b""
        try:
            while len(head) < 8:
                chunk = conn.recv(8 - len(head))
                if not chunk:
                    break
                head += chunk
        except OSError:
            pass
    if len(head) < 8:
        raise _refuse(
            address,
            f"a server listens there but sent no Dask handshake within {_PROBE_TIMEOUT_S:g} s (a web server? the "
            "scheduler's port is 8786 by default, its dashboard's 8787)",
        )
    (length,) = struct.unpack("<Q", head)
    if not 0 < length <= _MAX_HANDSHAKE_BYTES:
        raise _refuse(address, f"the server there speaks another protocol (it sent {head!r})")
