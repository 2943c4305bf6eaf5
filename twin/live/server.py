"""The live view's server: a Foxglove WebSocket server publishing ROS 2 topics as foxglove_bridge does.

Each topic becomes a channel with message encoding `cdr` and a `ros2msg` schema (the message
definition text a rosbag2 MCAP embeds), so Foxglove decodes the bytes as ROS 2 messages and its 3D
panel draws the robot from `/robot_description`, the scan, the map and the transforms. Topics a ROS 2
publisher would latch (transient local durability: `/tf_static`, `/robot_description`, `/map`) keep
their last message(s), sent again to every client that subscribes later. Clients connect through a
front (`twin.live.front`) that lets those still on the `foxglove.websocket.v1` subprotocol in.

```python
from twin.bag.typesys import TypeRegistry
from twin.live import LiveServer

with LiveServer(port=0) as server:             # 127.0.0.1, a free port
    scan = server.add_channel("/scan", TypeRegistry().definition("sensor_msgs/msg/LaserScan"))
    server.publish(scan, t_ns, cdr_bytes)
```
"""

from __future__ import annotations

import logging
import socket
import threading
from collections import deque
from dataclasses import dataclass
from urllib.parse import quote

import foxglove
from foxglove.websocket import Capability, ChannelView, Client, ServerListener

from twin.bag.typesys import MessageDefinition
from twin.core.closing import Closing
from twin.core.errors import ConfigError
from twin.live.front import HandshakeFront
from twin.live.throttle import PeerLogThrottle

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LiveServer"]

_log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765  # foxglove_bridge's default
_TIME_PERIOD_NS = 10_000_000  # broadcast the server time at most 100 times a sim second
_TF_STATIC_KEEP = 100  # /tf_static: every message counts (each carries its own frames), up to this many


@dataclass(frozen=True, kw_only=True, slots=True)
class _Channel:
    channel: foxglove.Channel
    latched: deque[tuple[int, bytes]] | None  # the messages a late subscriber gets, if the topic is latched


class _Listener(ServerListener):
    """Receives the server's client events (on the server's thread)."""

    def __init__(self, server: LiveServer) -> None:
        self._server = server

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self._server._resend_latched(channel.id)


def _listen(host: str, port: int) -> socket.socket:
    """A listening socket on the public address.

    Raises:
        ConfigError: If it cannot be bound (port in use, unknown host).
    """
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
        return socket.create_server((host, port), family=family, backlog=16)
    except OSError as err:
        reason = (err.strerror or str(err)).lower()
        msg = f"cannot serve on {host}:{port}: {reason}; choose another port with --port (or --host)"
        raise ConfigError(msg) from None


class LiveServer(Closing):
    """A Foxglove WebSocket server for one run or one bag. Use as a context manager.

    Args:
        host: Address to bind; 127.0.0.1 (default) serves this machine only, 0.0.0.0 every interface.
        port: TCP port (8765, as foxglove_bridge; 0 picks a free one, see `port`).
        name: The server name Foxglove shows.
        hold_clients: Hold connecting clients until `ready()` or the first `publish` (a run's or a
            bag's channels are all made by then): a client that came while they were being made
            could subscribe to one the SDK did not accept yet and, as Foxglove does, never again.

    Raises:
        ConfigError: If the address cannot be bound (port in use, unknown host).
    """

    def __init__(
        self, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "twin", hold_clients: bool = False
    ) -> None:
        if not 0 <= port <= 65535:
            msg = f"--port must be a TCP port number (0 to 65535), got {port}"
            raise ConfigError(msg)
        self.host = host
        self._context = foxglove.Context()
        self._channels: list[_Channel] = []
        self._by_topic: dict[tuple[str, str], int] = {}
        self._by_id: dict[int, _Channel] = {}
        self._lock = threading.Lock()
        self._next_time_ns = 0
        listener = _listen(host, port)
        self.peer_errors = PeerLogThrottle()  # one line per kind of failing peer, then a count
        self.peer_errors.attach()
        try:
            # The SDK's server on a private loopback port; clients meet the front (twin.live.front).
            self._server = foxglove.start_server(
                name=name,
                host="127.0.0.1",
                port=0,
                context=self._context,
                server_listener=_Listener(self),
                capabilities=[Capability.Time],
                supported_encodings=["cdr"],
            )
        except RuntimeError as err:
            listener.close()
            reason = str(err).removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
            reason = reason.split(" (os error", 1)[0].lower()
            msg = f"cannot serve on {host}:{port}: {reason}; choose another port with --port (or --host)"
            self.peer_errors.detach()
            raise ConfigError(msg) from None
        self._front = HandshakeFront(listener, ("127.0.0.1", self._server.port))
        self.port: int = self._front.port
        self._closed = False
        self._open_to_clients = not hold_clients
        if not hold_clients:
            self._front.open()

    @property
    def url(self) -> str:
        """The address a Foxglove client connects to, e.g. `ws://127.0.0.1:8765`."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def app_url(self) -> str | None:
        """A link that opens this server in the Foxglove web app."""
        link = self._server.app_url()
        if link is None:
            return None
        private = quote(f"ws://127.0.0.1:{self._server.port}", safe="")
        return link.replace(private, quote(self.url, safe=""))

    # -- channels --------------------------------------------------------------------------------

    def add_channel(self, topic: str, definition: MessageDefinition, *, latched: bool = False) -> int:
        """Advertise `topic` with its ROS 2 message definition and return the handle `publish` takes.

        Args:
            topic: Topic name, e.g. `/scan`.
            definition: The type's `ros2msg` definition (`TypeRegistry.definition`).
            latched: Keep the last message (all of them on `/tf_static` and a robot's `/<ns>/tf_static`)
                for clients that subscribe later, as a transient-local publisher does.
        """
        key = (topic, definition.msgtype)
        existing = self._by_topic.get(key)
        if existing is not None:
            return existing
        schema = foxglove.Schema(name=definition.msgtype, encoding=definition.encoding, data=definition.text.encode())
        channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._context)
        keep = _TF_STATIC_KEEP if topic == "/tf_static" or topic.endswith("/tf_static") else 1  # a fleet's too
        entry = _Channel(channel=channel, latched=deque(maxlen=keep) if latched else None)
        self._channels.append(entry)
        self._by_id[channel.id()] = entry
        handle = len(self._channels) - 1
        self._by_topic[key] = handle
        return handle

    def ready(self) -> None:
        """Every channel is made: let clients in (they wait until then; the first `publish` says it too)."""
        self._front.open()

    def publish(self, handle: int, t_ns: int, data: bytes) -> None:
        """Send one CDR message stamped `t_ns` to the clients subscribed to its channel."""
        if not self._open_to_clients:
            self._open_to_clients = True
            self._front.open()
        if t_ns >= self._next_time_ns:
            self._server.broadcast_time(t_ns)
            self._next_time_ns = t_ns + _TIME_PERIOD_NS
        entry = self._channels[handle]
        payload = data if type(data) is bytes else bytes(data)
        if entry.latched is not None:
            with self._lock:
                entry.latched.append((t_ns, payload))
        entry.channel.log(payload, log_time=t_ns)

    def restart_time(self) -> None:
        """Start the time over (a bag played again): clients reset, latched messages are forgotten."""
        with self._lock:
            for entry in self._channels:
                if entry.latched is not None:
                    entry.latched.clear()
        self._next_time_ns = 0
        self._server.clear_session()

    def _resend_latched(self, channel_id: int) -> None:
        entry = self._by_id.get(channel_id)
        if entry is None or entry.latched is None:
            return
        with self._lock:
            messages = list(entry.latched)
        # The SDK sends to every subscriber of the channel: earlier ones get the latched message
        # again, which changes nothing on a latched topic.
        for t_ns, payload in messages:
            entry.channel.log(payload, log_time=t_ns)

    # -- life cycle ------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop serving (idempotent); connected clients are disconnected."""
        if self._closed:
            return
        self._closed = True
        # The SDK's server first, so that its Close frames reach the clients through the front
        # (closing the front first cut them: code 1006, and "connection reset" errors on the console)
        self._server.stop()
        self._front.close(grace_s=1.0)
        for entry in self._channels:
            entry.channel.close()
        self.peer_errors.detach()
        self.peer_errors.flush()
