"""The topic bus: every publication goes through here to the recorder, stamped with sim time."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["Bus", "Publisher", "Sink"]


class Sink(Protocol):
    """Where publications go: the bag recorder, or a test double."""

    def add_topic(self, topic: str, msgtype: str, *, qos: Any = ...) -> Any:
        """Declare a topic and return the handle `write` takes."""
        ...

    def write(self, handle: Any, t_ns: int, data: bytes) -> None:
        """Store one serialised message received at `t_ns`."""
        ...


class Publisher:
    """One topic: serialised messages in, recorder writes and a count out."""

    __slots__ = ("_handle", "_write", "count", "msgtype", "subscribers", "topic")

    def __init__(self, topic: str, msgtype: str, handle: Any, write: Callable[[Any, int, bytes], None]) -> None:
        self.topic = topic
        self.msgtype = msgtype
        self.count = 0
        self.subscribers: list[Callable[[int, bytes], None]] = []
        self._handle = handle
        self._write = write

    def publish(self, t_ns: int, data: bytes) -> None:
        """Record one message stamped `t_ns` and hand it to in-process subscribers."""
        self._write(self._handle, t_ns, data)
        self.count += 1
        for callback in self.subscribers:
            callback(t_ns, data)


class Bus:
    """Creates publishers on one sink and keeps them for the run's summary."""

    def __init__(self, sink: Sink) -> None:
        self._sink = sink
        self.publishers: dict[str, Publisher] = {}

    def advertise(self, topic: str, msgtype: str, *, qos: Any = None) -> Publisher:
        """Return the publisher of `topic`, declaring it on the sink the first time.

        Raises:
            ValueError: If the topic was already advertised with another type.
        """
        existing = self.publishers.get(topic)
        if existing is not None:
            if existing.msgtype != msgtype:
                msg = f"topic {topic} is {existing.msgtype}, cannot advertise it as {msgtype}"
                raise ValueError(msg)
            return existing
        handle = self._sink.add_topic(topic, msgtype) if qos is None else self._sink.add_topic(topic, msgtype, qos=qos)
        pub = Publisher(topic, msgtype, handle, self._sink.write)
        self.publishers[topic] = pub
        return pub

    @property
    def message_count(self) -> int:
        """Messages published so far, over all topics."""
        return sum(p.count for p in self.publishers.values())
