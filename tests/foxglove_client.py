"""A minimal Foxglove WebSocket client for the tests: what the Foxglove app does when it connects.

It negotiates the protocol (the SDK's `foxglove.sdk.v1`, or the older `foxglove.websocket.v1`
foxglove_bridge speaks), reads `serverInfo` and `advertise`, subscribes to topics by name, and
collects binary message-data frames (opcode 1: subscription id u32, log time u64, payload) and
time frames (opcode 2). Payloads decode with rosbags' CDR deserialiser against the advertised
`ros2msg` schema, never against a type store the test brought along.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import websockets
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


@dataclass
class Watch:
    """What one client saw."""

    subprotocol: str | None = None
    server_info: dict[str, Any] = field(default_factory=dict)
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # by topic
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)  # topic -> (log time ns, CDR)
    times_ns: list[int] = field(default_factory=list)
    closed_by_server: bool = False
    retried_subscriptions: int = 0  # subscriptions sent again after the server did not know the channel yet

    def decode(self, topic: str, payload: bytes) -> Any:
        """Decode a payload with rosbags against the schema the server advertised for `topic`."""
        channel = self.channels[topic]
        assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg", channel
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(channel["schema"], channel["schemaName"]))
        return store.deserialize_cdr(payload, channel["schemaName"])


async def _connect(url: str, timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return await websockets.connect(url, subprotocols=SUBPROTOCOLS, proxy=None, compression=None)  # type: ignore[arg-type]
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


async def watch(
    url: str,
    topics: list[str],
    *,
    stop: Callable[[Watch], bool] | None = None,
    timeout_s: float = 60.0,
) -> Watch:
    """Connect, subscribe to `topics` as they are advertised, and collect until `stop(watch)`, the server closes, or the timeout."""
    seen = Watch(messages={t: [] for t in topics})
    ws = await _connect(url, timeout_s)
    seen.subprotocol = ws.subprotocol
    subscriptions: dict[int, str] = {}
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=max(0.01, deadline - time.monotonic()))
            except TimeoutError:
                break
            except websockets.ConnectionClosed:
                seen.closed_by_server = True
                break
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "serverInfo":
                    seen.server_info = message
                elif message["op"] == "status" and message["message"].startswith("Unknown channel ID"):
                    # foxglove-sdk 0.30 can send a channel's advertisement a moment before it accepts
                    # subscriptions to it (channels created while a client is connected): ask again.
                    seen.retried_subscriptions += 1
                    channel_id = int(message["message"].rsplit(" ", 1)[1])
                    sub_id = next(i for i, t in subscriptions.items() if seen.channels[t]["id"] == channel_id)
                    await asyncio.sleep(0.05)
                    await ws.send(
                        json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel_id}]})
                    )
                elif message["op"] == "advertise":
                    wanted = []
                    for channel in message["channels"]:
                        seen.channels[channel["topic"]] = channel
                        if channel["topic"] in seen.messages and channel["topic"] not in subscriptions.values():
                            sub_id = len(subscriptions) + 1
                            subscriptions[sub_id] = channel["topic"]
                            wanted.append({"id": sub_id, "channelId": channel["id"]})
                    if wanted:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
            elif frame[0] == 1:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                seen.messages[subscriptions[sub_id]].append((log_time, bytes(frame[13:])))
            elif frame[0] == 2:
                seen.times_ns.append(struct.unpack_from("<Q", frame, 1)[0])
            if stop is not None and stop(seen):
                break
    finally:
        with contextlib.suppress(Exception):
            await ws.close()
    return seen
