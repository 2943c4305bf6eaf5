"""The live sink: a run's publications go to the recorder as always, and to the live server, on time.

The simulation's bus writes every message to one sink; `LiveSink` stands in that place, wrapping
the recorder. It needs no change to the loop: pacing happens here, as each message's sim time
arrives (at least 100 times a sim second, from `/clock`), so a run at `speed` 1 publishes in real time.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from twin.bag import Durability, QosProfile, default_qos
from twin.bag.typesys import TypeRegistry
from twin.live.pacing import Pacer
from twin.live.server import LiveServer

__all__ = ["LiveSink", "is_latched"]


class _Sink(Protocol):
    """What the bus writes to (`twin.sim.bus.Sink`): the recorder, or another `LiveSink`."""

    def add_topic(self, topic: str, msgtype: str, *, qos: Any = ...) -> Any: ...

    def write(self, handle: Any, t_ns: int, data: bytes) -> None: ...


def is_latched(qos: Sequence[QosProfile]) -> bool:
    """Whether a topic's publishers latch it (every offered profile transient local), as foxglove_bridge decides."""
    return bool(qos) and all(q.durability == Durability.TRANSIENT_LOCAL for q in qos)


class LiveSink:
    """Tees every topic and message to `inner` (the recorder) and to a live server, paced.

    Args:
        inner: The sink that records (a `twin.bag.Recorder`).
        server: Where the live view is served; None paces the run without serving it.
        pacer: Holds the messages to wall time; None runs as fast as possible.
    """

    def __init__(self, inner: _Sink, server: LiveServer | None, *, pacer: Pacer | None = None) -> None:
        self._inner = inner
        self._server = server
        self._pacer = pacer
        self._registry = TypeRegistry()
        self._inner_write = inner.write
        self._publish = server.publish if server is not None else None
        self._wait = pacer.wait if pacer is not None else None

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[QosProfile] | None = None) -> tuple[Any, int]:
        """Declare the topic on the recorder and advertise it live; return the handle `write` takes.

        Raises:
            BagError: From the recorder (topic exists, unknown type, closed bag).
        """
        inner = self._inner.add_topic(topic, msgtype) if qos is None else self._inner.add_topic(topic, msgtype, qos=qos)
        live = -1
        if self._server is not None:
            profiles = tuple(qos) if qos is not None else default_qos(topic)
            live = self._server.add_channel(topic, self._registry.definition(msgtype), latched=is_latched(profiles))
        return inner, live

    def write(self, handle: tuple[Any, int], t_ns: int, data: bytes) -> None:
        """Wait until `t_ns` is due (when paced), then record the message and publish it live."""
        if self._wait is not None:
            self._wait(t_ns)
        inner, live = handle
        self._inner_write(inner, t_ns, data)
        if self._publish is not None:
            self._publish(live, t_ns, data)
