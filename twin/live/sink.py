"""The live sink: a run's publications go to the live server, on time, after the recorder has them.

The executor hands every recorded publication to each of its sinks in turn: the recorder first,
then `LiveSink` (`Simulation(sinks=[LiveSink(...)])`). It needs no change to the loop: pacing
happens here, as each message's sim time arrives (hundreds of times a sim second: `/imu` alone is 200 Hz),
so a run at `speed` 1 publishes in real time, and so does the recorder.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from twin.bag import Durability, QosProfile, default_qos
from twin.bag.typesys import TypeRegistry
from twin.live.namespace import NamespaceView
from twin.live.pacing import Pacer
from twin.live.server import LiveServer

__all__ = ["LiveSink", "is_latched"]


def is_latched(qos: Sequence[QosProfile]) -> bool:
    """Whether a topic's publishers latch it (every offered profile transient local), as foxglove_bridge decides."""
    return bool(qos) and all(q.durability == Durability.TRANSIENT_LOCAL for q in qos)


class LiveSink:
    """A sink (`twin.sim.executor.Sink`) that paces the run and publishes every topic on a live server.

    Args:
        server: Where the live view is served; None paces the run without serving it.
        pacer: Holds the messages to wall time; None runs as fast as possible.
        namespace: A fleet's robot to serve alone (`twin.live.namespace`); None: every topic.
    """

    def __init__(
        self,
        server: LiveServer | None,
        *,
        pacer: Pacer | None = None,
        namespace: str | None = None,
        frame_prefix: bool = False,
        robots: Sequence[str] = (),
    ) -> None:
        self._server = server
        self._view = (
            NamespaceView(namespace, frame_prefix=frame_prefix, robots=robots) if namespace is not None else None
        )
        self._registry = TypeRegistry()
        self._publish = server.publish if server is not None else None
        self._wait = pacer.wait if pacer is not None else None
        self._rewrite: dict[int, Callable[[bytes], bytes | None]] = {}  # by handle: frames to take the prefix off

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[QosProfile] | None = None) -> int:
        """Advertise the topic live with its type's `ros2msg` definition; return the handle `write` takes.

        Raises:
            BagError: If the type has no definition (the recorder refuses it too).
        """
        if self._server is None:
            return -1
        served = self._view.served_as(topic) if self._view is not None else topic
        if served is None:
            return -1  # another robot's: paced, not served
        profiles = tuple(qos) if qos is not None else default_qos(topic)
        handle = self._server.add_channel(served, self._registry.definition(msgtype), latched=is_latched(profiles))
        if self._view is not None:
            rewrite = self._view.rewriter(msgtype, self._registry.store)
            if rewrite is not None:
                self._rewrite[handle] = rewrite
        return handle

    def write(self, handle: int, t_ns: int, data: bytes) -> None:
        """Wait until `t_ns` is due (when paced), then publish the message live."""
        if self._wait is not None:
            self._wait(t_ns)
        if self._publish is not None and handle >= 0:
            if self._rewrite:
                rewrite = self._rewrite.get(handle)
                if rewrite is not None:
                    served = rewrite(data)
                    if served is None:
                        return  # only other robots' transforms
                    data = served
            self._publish(handle, t_ns, data)
