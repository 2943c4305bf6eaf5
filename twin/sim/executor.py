"""The deterministic executor: nodes, topics and timers on the integer simulation clock.

Order, which makes a run reproducible to the byte:
1. Time moves only between events: the physics (the drive node's `advance`) steps whole physics
   steps up to the next step at which a timer is due.
2. At that step the due timers fire in (priority, order of creation) order: the mission's tree (5),
   its commands (10), sensors (40), user nodes (50), state publishers (60), the clock (90); timers
   of one node fire in the order the node created them, nodes in the order they were added.
3. `publish(msg)` delivers before it returns: first to the recorder (and any other sink), then to
   each subscription in the order subscriptions were created. A callback that publishes delivers
   its message the same way, depth first. Every message is stamped with the step's time.

Messages are Python objects in process. A topic serialises a message to CDR only for a sink: once,
with the publishing node's encoder (`Encoded`) or rosbags' serialiser (a `twin.msgs` object).
"""

from __future__ import annotations

import functools
import logging
import re
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Literal, Protocol

from twin.bag import QOS_BEST_EFFORT, QOS_LATCHED, QOS_RELIABLE, QosProfile, default_qos
from twin.core.clock import NS_PER_S, ns_to_s
from twin.core.errors import ConfigError, SimulationError, TwinError
from twin.node import Encoded, Node, QoSProfile, Subscription, Timer
from twin.node.finite import checks_finite, nonfinite_field
from twin.sim.scheduler import Scheduler

__all__ = ["Executor", "RecordFilter", "Sink", "Topic"]

_log = logging.getLogger(__name__)


class Sink(Protocol):
    """Where serialised messages go: the bag recorder, a live view."""

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[QosProfile] | None = None) -> Any:
        """Declare a topic; return the handle `write` takes."""
        ...

    def write(self, handle: Any, t_ns: int, data: bytes) -> None:
        """Store one serialised message published at `t_ns`."""
        ...


@dataclass(frozen=True, kw_only=True, slots=True)
class RecordFilter:
    """Which topics a sink takes, as `ros2 bag record` chooses them: names or a regex, minus exclusions.

    With no `include` and no `include_regex`, every topic is taken.
    """

    include: tuple[str, ...] = ()
    include_regex: str = ""
    exclude: tuple[str, ...] = ()
    exclude_regex: str = ""

    def takes(self, topic: str) -> bool:
        """Whether `topic` is recorded."""
        if topic in self.exclude or (self.exclude_regex and re.fullmatch(self.exclude_regex, topic)):
            return False
        if not self.include and not self.include_regex:
            return True
        return topic in self.include or bool(self.include_regex and re.fullmatch(self.include_regex, topic))


@dataclass(eq=False)
class Topic:
    """One topic: its type, who publishes and subscribes, and the callbacks a publication reaches."""

    name: str
    msgtype: str
    publishers: list[str] = field(default_factory=list)  # node names
    subscribers: list[str] = field(default_factory=list)
    callbacks: list[Callable[[Any], None]] = field(default_factory=list)  # subscriptions, in order
    user_callbacks: list[Callable[[Any], None]] = field(default_factory=list)  # those of users' nodes
    sinks: list[tuple[Callable[[Any, int, bytes], None], Any]] = field(default_factory=list)  # (write, handle)
    count: int = 0
    latched: list[Any] = field(default_factory=list)  # the last messages, for late subscribers
    latch_depth: int = 0
    qos: QoSProfile = field(default_factory=QoSProfile)


def _record_qos(topic: str, qos: QoSProfile) -> tuple[QosProfile, ...]:
    """What the recorder stores as the offered QoS: a TB3 + Nav2 system's for known topics, else the publisher's."""
    known = default_qos(topic)
    if known[0] != QOS_RELIABLE:
        return known
    if qos.durability == "transient_local":
        return (QOS_LATCHED,)
    if qos.reliability == "best_effort":
        return (QOS_BEST_EFFORT,)
    return known


class Executor:
    """Runs nodes on one simulation clock (see the module docstring for the order).

    Args:
        step_ns: The physics step.
        sinks: Where messages are serialised to (the recorder first), each with the topics it takes.
        profile: Time each timer callback and the physics (for benchmarks).
        non_finite: What a message from a user's node with a NaN or infinite number in a field the
            twin's own nodes read does (`twin.node.finite`): `drop` keeps it from them (the bag and
            users' nodes still get it; one warning per publisher and topic; counted in `refused`),
            `error` ends the run with a SimulationError.

    Raises:
        ValueError: If the step is not positive.
    """

    def __init__(
        self,
        step_ns: int,
        *,
        sinks: Sequence[tuple[Sink, RecordFilter]] = (),
        profile: bool = False,
        non_finite: Literal["drop", "error"] = "drop",
    ) -> None:
        self.step_ns = step_ns
        self.scheduler = Scheduler(step_ns)
        self.topics: dict[str, Topic] = {}
        self.nodes: dict[str, Node] = {}
        self._sinks = list(sinks)
        self._profile = profile
        self.timings_s: dict[str, float] = {}
        self._k = 0
        self.now_ns = 0
        self._advance: Callable[[int], None] | None = None
        self._after_advance: Callable[[int], None] | None = None
        self._pending: Any = None
        self._failure: BaseException | None = None
        self.non_finite = non_finite
        self.refused: dict[str, int] = {}  # topic -> messages kept from the twin's nodes (non-finite)
        self._warned: set[tuple[str, str]] = set()

    # -- the graph -------------------------------------------------------------------------------

    def add_sink(self, sink: Sink, keep: RecordFilter | None = None) -> None:
        """Add a sink for the topics `keep` takes (all by default); only before the first node is added.

        Raises:
            RuntimeError: If nodes were added already (their topics would miss the sink).
        """
        if self.topics:
            msg = "add sinks before nodes"
            raise RuntimeError(msg)
        self._sinks.append((sink, keep or RecordFilter()))

    def add_node(self, node: Node) -> None:
        """Add a node: bind its publishers, subscriptions and timers to the graph.

        Raises:
            ConfigError: If another node has the same name, or the node publishes a topic with a
                type other than the topic's.
        """
        name = node.get_fully_qualified_name()
        if name in self.nodes:
            msg = f"two nodes are named {name}; give one of them another `name:` in the scenario's nodes"
            raise ConfigError(msg)
        self.nodes[name] = node
        timers = list(node.timers)  # those created from here on (a callback on a latched message) start themselves
        node.bind(self)
        trusted = bool(getattr(node, "builtin", False)) or type(node).__module__.startswith("twin.")
        for pub in node.publishers:
            topic = self._topic(pub.topic, pub.msg_type, node, publishing=True)
            topic.publishers.append(name)
            if pub.qos.durability == "transient_local":
                topic.latch_depth = max(topic.latch_depth, pub.qos.depth, 1)
            pub.publish = self._publish_function(topic, node, pub.qos, checked=not trusted)
            pub.get_subscription_count = functools.partial(_callback_count, topic)
        for sub in node.subscriptions:
            topic = self._topic(sub.topic, sub.msg_type, node, publishing=False)
            topic.subscribers.append(name)
            callback = self._delivery(topic, sub, guarded=not trusted)
            topic.callbacks.append(callback)
            if not trusted:
                topic.user_callbacks.append(callback)
            for old in topic.latched:
                callback(old)
        for timer in timers:
            self._add_timer(timer, guarded=not trusted)

    def _msgtype(self, msg_type: type | str, node: Node) -> str:
        from twin.msgs import message_type_name

        if isinstance(msg_type, str) and "/msg/" in msg_type:
            return msg_type
        try:
            return message_type_name(msg_type)
        except ConfigError as err:
            msg = f"node {node.get_name()}: {err}"
            raise ConfigError(msg) from None

    def _topic(self, name: str, msg_type: type | str, node: Node, *, publishing: bool) -> Topic:
        msgtype = self._msgtype(msg_type, node)
        topic = self.topics.get(name)
        if topic is None:
            topic = Topic(name, msgtype)
            self.topics[name] = topic
        elif topic.msgtype != msgtype:
            others = ", ".join(topic.publishers or topic.subscribers)
            role = "publishes" if publishing else "subscribes to"
            msg = (
                f"node {node.get_name()} {role} {name} as {msgtype}, but {name} is {topic.msgtype} "
                f"(used by {others}); use another topic name or remap it"
            )
            raise ConfigError(msg)
        if publishing and not topic.publishers:
            self._attach_sinks(topic, node)
        return topic

    def _attach_sinks(self, topic: Topic, node: Node) -> None:
        """Declare the topic to every sink that takes it; publications reach sinks before subscriptions."""
        pub = next(p for p in node.publishers if p.topic == topic.name)
        topic.qos = pub.qos
        for sink, keep in self._sinks:
            if keep.takes(topic.name):
                handle = sink.add_topic(topic.name, topic.msgtype, qos=_record_qos(topic.name, pub.qos))
                topic.sinks.append((sink.write, handle))

    def _publish_function(self, topic: Topic, node: Node, qos: QoSProfile, *, checked: bool) -> Callable[[Any], None]:
        """Build one publisher's `publish`: specialised for its topic's sinks, its QoS and its node's trust."""
        from twin.msgs import misfit_field, serialize

        callbacks, msgtype = topic.callbacks, topic.msgtype
        if len(topic.sinks) == 1:  # the common case, inlined: the recorder
            ((write, handle),) = topic.sinks

            def publish(msg: Any) -> None:
                topic.count += 1
                if type(msg) is Encoded:
                    write(handle, self.now_ns, msg[0](*msg[1]))
                else:
                    write(handle, self.now_ns, serialize(msg, msgtype))
                for callback in callbacks:
                    callback(msg)

        else:
            sinks = topic.sinks

            def publish(msg: Any) -> None:
                topic.count += 1
                if sinks:
                    data = msg[0](*msg[1]) if type(msg) is Encoded else serialize(msg, msgtype)
                    for write, handle in sinks:
                        write(handle, self.now_ns, data)
                for callback in callbacks:
                    callback(msg)

        if qos.durability == "transient_local":  # latched: late subscribers get the last `depth` messages
            latched, depth, plain = topic.latched, max(1, qos.depth), publish

            def publish(msg: Any) -> None:
                plain(msg)
                latched.append(msg)
                del latched[:-depth]

        if not checked:
            return publish
        unchecked = publish
        guard_finite = checks_finite(msgtype)

        def checked_publish(msg: Any) -> None:
            if type(msg) is not Encoded:
                if getattr(msg, "__msgtype__", None) != msgtype:
                    given = getattr(msg, "__msgtype__", type(msg).__name__)
                    text = f"node {node.get_name()} published a {given} on {topic.name}, which carries {msgtype}"
                    raise SimulationError(text)
                if guard_finite and len(topic.callbacks) > len(topic.user_callbacks):  # a twin node listens
                    bad = nonfinite_field(msg, msgtype)
                    if bad is not None:
                        self._refuse(node, topic, bad)
                        self._publish_refused(topic, msg)
                        return
            try:
                unchecked(msg)
            except (struct.error, TypeError, ValueError, OverflowError, AttributeError) as err:
                bad = None if type(msg) is Encoded else misfit_field(msg, msgtype)
                if bad is None:
                    raise
                text = (
                    f"node {node.get_name()} published a {msgtype} on {topic.name} whose {bad} "
                    f"at t={ns_to_s(self.now_ns):.3f} s; fill the field with a value of its type"
                )
                raise SimulationError(text) from err

        return checked_publish

    def _refuse(self, node: Node, topic: Topic, bad: str) -> None:
        """A user's node published a non-finite number the twin's nodes would read: count and warn, or end the run.

        Raises:
            SimulationError: With `non_finite: error`.
        """
        what = f"node {node.get_name()} published {bad} on {topic.name} at t={ns_to_s(self.now_ns):.3f} s"
        if self.non_finite == "error":
            msg = f"{what}; the scenario's non_finite_messages: error ends the run (drop: refuse it and go on)"
            raise SimulationError(msg)
        self.refused[topic.name] = self.refused.get(topic.name, 0) + 1
        key = (node.get_fully_qualified_name(), topic.name)
        if key not in self._warned:
            self._warned.add(key)
            _log.warning(
                "%s: refused: the twin's own subscribers never see it and keep their last finite input (the "
                "drive holds its last command, as Nav2 drops a NaN velocity); warned once per publisher and "
                "topic, the run summary counts them",
                what,
            )

    def _publish_refused(self, topic: Topic, msg: Any) -> None:
        """Deliver a refused message to the sinks (a bag records what was published) and to users' nodes only."""
        from twin.msgs import serialize

        topic.count += 1
        if topic.sinks:
            data = serialize(msg, topic.msgtype)
            for write, handle in topic.sinks:
                write(handle, self.now_ns, data)
        for callback in topic.user_callbacks:
            callback(msg)

    def _delivery(self, topic: Topic, sub: Subscription, *, guarded: bool) -> Callable[[Any], None]:
        callback = sub.callback
        if sub.raw:
            deliver = callback
        else:
            from twin.msgs import deserialize

            msgtype = topic.msgtype

            def deliver(msg: Any) -> None:
                if type(msg) is Encoded:
                    callback(deserialize(msg[0](*msg[1]), msgtype))
                else:
                    callback(msg)

        if not guarded:
            return deliver
        return self._guard(deliver, sub.node, f"subscription callback {_name(callback)} on {topic.name}")

    def _guard(self, fn: Callable[..., None], node: Node, what: str) -> Callable[..., None]:
        """Wrap a user callback: an exception in it ends the run as a SimulationError naming node, callback and time."""

        def guarded(*args: Any) -> None:
            try:
                fn(*args)
            except TwinError:
                raise
            except SystemExit as err:  # sys.exit() in a callback: the node's fault, not the run's exit status
                msg = (
                    f"node {node.get_name()}: {what} called sys.exit({err.code!r}) at t={ns_to_s(self.now_ns):.3f} s; "
                    "a node cannot end the run (end it with the scenario's max_duration_s or the mission)"
                )
                raise SimulationError(msg) from err
            except Exception as err:
                msg = (
                    f"node {node.get_name()}: {what} raised {type(err).__name__}: {err} "
                    f"at t={ns_to_s(self.now_ns):.3f} s"
                )
                raise SimulationError(msg) from err

        return guarded

    def count_publishers(self, topic: str) -> int:
        """How many publishers the graph has on `topic` (a full name)."""
        known = self.topics.get(topic)
        return 0 if known is None else len(known.publishers)

    def add_timer(self, timer: Timer) -> None:
        """Start a timer a node created while running: it first fires one period from now, as rclpy's."""
        node = timer.node
        trusted = bool(getattr(node, "builtin", False)) or type(node).__module__.startswith("twin.")
        self._add_timer(timer, guarded=not trusted, origin_k=self._k)

    def _add_timer(self, timer: Timer, *, guarded: bool, origin_k: int = 0) -> None:
        node = timer.node
        callback = timer.callback
        label = f"{node.get_name()}.{getattr(callback, '__name__', type(callback).__name__)}"
        if timer.pass_time:
            fn: Callable[[int], None] = callback
        else:

            def fn(t_ns: int) -> None:
                del t_ns
                if not timer.cancelled:
                    callback()

        if guarded:
            fn = self._guard(fn, node, f"timer callback {_name(callback)}")
        if self._profile:
            fn = self._timed(label, fn)
        if timer.period_ns == 0:
            self.scheduler.once(label, fn, at_k=origin_k, priority=timer.priority)
            return
        start_k = origin_k if timer.fire_at_start else origin_k + 1
        if timer.rate_hz is not None:
            self.scheduler.add(label, timer.rate_hz, fn, priority=timer.priority, start_k=start_k, origin_k=origin_k)
            return
        # A user's timer: its exact period; shorter than a step, it fires once a step (rclpy skips missed periods).
        rate = Fraction(NS_PER_S, max(timer.period_ns, self.step_ns))
        self.scheduler.add(label, rate, fn, priority=timer.priority, start_k=start_k, origin_k=origin_k)

    def _timed(self, name: str, fn: Callable[[int], None]) -> Callable[[int], None]:
        timings = self.timings_s
        timings.setdefault(name, 0.0)
        clock = time.perf_counter

        def timed(t_ns: int) -> None:
            start = clock()
            fn(t_ns)
            timings[name] += clock() - start

        return timed

    def set_physics(
        self,
        advance: Callable[[int], None],
        after_advance: Callable[[int], None] | None = None,
        pending: Any = None,
    ) -> None:
        """Set what moves the world between events: `advance(n_steps)`, then `after_advance(t_ns)`.

        With `pending` (an object with a boolean `pending` attribute), `after_advance` runs only
        while `pending.pending` is true, so a quiet step costs one attribute read.
        """
        if self._profile:
            timings = self.timings_s
            timings.setdefault("physics", 0.0)
            clock, inner = time.perf_counter, advance

            def advance(n: int) -> None:
                start = clock()
                inner(n)
                timings["physics"] += clock() - start

        self._advance = advance
        self._after_advance = after_advance
        self._pending = pending

    # -- running ---------------------------------------------------------------------------------

    @property
    def k(self) -> int:
        """Physics steps done so far."""
        return self._k

    @property
    def message_count(self) -> int:
        """Messages published so far, over all topics."""
        return sum(t.count for t in self.topics.values())

    def spin(
        self,
        end_k: int,
        *,
        done: Any = None,
        should_stop: Callable[[], bool] = lambda: False,
        progress: Callable[[float, int], None] | None = None,
    ) -> str:
        """Run until step `end_k`, until `done.done` is true after a step's timers, or until `should_stop()`.

        Returns:
            Why it ended: "duration", "done" or "interrupted".

        Raises:
            TwinError: From any node; the sinks hold everything published before it.
        """
        scheduler, advance, after, pending = self.scheduler, self._advance, self._after_advance, self._pending
        fire_due, heap = scheduler.fire_due, scheduler._heap  # the heap's head is the next due step
        step_ns = self.step_ns
        steps_per_s = max(1, NS_PER_S // step_ns)
        # A stop (SIGTERM, Ctrl-C) is looked for every 20 ms of sim time, progress told every second:
        # in a world that runs slower than real time a second of sim time may take many wall seconds.
        steps_per_check = max(1, steps_per_s // 50)
        next_report = next_check = self._k
        k = self._k
        ended = "duration"
        while True:
            due = heap[0][0] if heap and heap[0][0] < end_k else end_k
            if due > k:
                if advance is not None:
                    advance(due - k)
                k = self._k = due
                self.now_ns = k * step_ns
                if after is not None and (pending is None or pending.pending):
                    after(self.now_ns)
            if k >= end_k:
                break
            self.now_ns = k * step_ns
            fire_due(k)
            if done is not None and done.done:
                end_k = k  # this step's publications are the last
                ended = "done"
            if k >= next_check:
                if should_stop():
                    ended = "interrupted"
                    break
                next_check = k + steps_per_check
                if k >= next_report:
                    if progress is not None:
                        progress(k / steps_per_s, self.message_count)
                    next_report = k + steps_per_s
        return ended

    def describe(self) -> list[dict[str, Any]]:
        """The graph as data: per node, what it publishes and subscribes (with types) and its timers."""
        out: list[dict[str, Any]] = []
        for name, node in self.nodes.items():
            out.append(
                {
                    "node": name,
                    "class": f"{type(node).__module__}.{type(node).__qualname__}",
                    "publishes": [{"topic": p.topic, "type": self.topics[p.topic].msgtype} for p in node.publishers],
                    "subscribes": [
                        {"topic": s.topic, "type": self.topics[s.topic].msgtype} for s in node.subscriptions
                    ],
                    "timers_hz": [_rate(t) for t in node.timers],
                }
            )
        return out


def _callback_count(topic: Topic) -> int:
    return len(topic.callbacks) + len(topic.sinks)


def _rate(timer: Timer) -> float | None:
    if timer.period_ns == 0:
        return None
    return timer.rate_hz if timer.rate_hz is not None else NS_PER_S / timer.period_ns


def _name(fn: Callable[..., Any]) -> str:
    name = getattr(fn, "__qualname__", None) or getattr(fn, "__name__", None) or type(fn).__name__
    parts = [p for p in name.replace(".<locals>", "").split(".") if p != "__init__"]
    return ".".join(parts[-2:])  # Class.method, or outer.inner
