"""The executor's contract: who hears a message when, in which order, and what a fault says."""

from __future__ import annotations

from typing import Any

import pytest

from twin.core.errors import ConfigError, SimulationError
from twin.msgs import Pose, String, Twist
from twin.node import PRIORITY_SENSOR, PRIORITY_STATE, Encoded, Node, QoSProfile
from twin.sim.executor import Executor, RecordFilter

MS = 1_000_000


class FakeSink:
    """Records what a sink is given: topics as declared, and (topic, t_ns, bytes) writes."""

    def __init__(self) -> None:
        self.topics: list[tuple[str, str]] = []
        self.writes: list[tuple[str, int, bytes]] = []

    def add_topic(self, topic: str, msgtype: str, *, qos: Any = None) -> str:
        self.topics.append((topic, msgtype))
        return topic

    def write(self, handle: Any, t_ns: int, data: bytes) -> None:
        self.writes.append((handle, t_ns, data))


class Log:
    def __init__(self) -> None:
        self.events: list[tuple[str, int, Any]] = []


class Publisher(Node):
    def __init__(self, name: str, topic: str, period_s: float, log: Log) -> None:
        super().__init__(name)
        self.pub = self.create_publisher(String, topic, 10)
        self.log = log
        self.n = 0
        self.create_timer(period_s, self.tick)

    def tick(self) -> None:
        self.n += 1
        now = self.get_clock().now().nanoseconds
        self.log.events.append((f"{self.get_name()}.tick", now, self.n))
        self.pub.publish(String(data=f"{self.get_name()} {self.n}"))


class Listener(Node):
    def __init__(self, name: str, topic: str, log: Log) -> None:
        super().__init__(name)
        self.log = log
        self.create_subscription(String, topic, self.on_msg, 10)

    def on_msg(self, msg: Any) -> None:
        self.log.events.append((f"{self.get_name()}.heard", self.get_clock().now().nanoseconds, msg.data))


def test_a_message_reaches_the_sink_first_then_subscribers_in_creation_order_at_its_time() -> None:
    log, sink = Log(), FakeSink()
    ex = Executor(MS)
    ex.add_sink(sink)
    ex.add_node(Listener("b_listener", "/chat", log))
    ex.add_node(Publisher("talker", "/chat", 0.1, log))
    ex.add_node(Listener("a_listener", "/chat", log))
    ex.spin(250)  # 0.25 s: user timers fire one period after the start, at 0.1 s and 0.2 s
    assert [e for e in log.events if e[1] == 100 * MS] == [
        ("talker.tick", 100 * MS, 1),
        ("b_listener.heard", 100 * MS, "talker 1"),
        ("a_listener.heard", 100 * MS, "talker 1"),
    ]
    assert [(t, w[1]) for t, w in zip(["/chat", "/chat"], sink.writes, strict=True)] == [
        ("/chat", 100 * MS),
        ("/chat", 200 * MS),
    ]
    assert sink.topics == [("/chat", "std_msgs/msg/String")]


def test_timers_of_one_step_fire_by_priority_then_creation_order() -> None:
    order: list[str] = []

    class Timed(Node):
        builtin = True

        def __init__(self, name: str, priority: int) -> None:
            super().__init__(name)
            self.create_rate_timer(10.0, lambda t_ns: order.append(f"{name}@{t_ns // MS}"), priority=priority)

    ex = Executor(MS)
    ex.add_node(Timed("state", PRIORITY_STATE))
    ex.add_node(Timed("sensor_a", PRIORITY_SENSOR))
    ex.add_node(Timed("sensor_b", PRIORITY_SENSOR))
    ex.spin(101)
    assert order == ["sensor_a@0", "sensor_b@0", "state@0", "sensor_a@100", "sensor_b@100", "state@100"]


def test_physics_advances_between_events_to_the_next_due_step() -> None:
    steps: list[int] = []
    ex = Executor(MS)
    ex.add_node(Publisher("talker", "/chat", 0.05, Log()))
    ex.set_physics(steps.append)
    ex.spin(120)
    assert steps == [50, 50, 20]
    assert ex.k == 120


def test_a_latched_topic_reaches_a_subscriber_that_joins_late() -> None:
    heard: list[str] = []

    class Latcher(Node):
        def __init__(self) -> None:
            super().__init__("latcher")
            self.pub = self.create_publisher(String, "/description", QoSProfile(depth=1, durability="transient_local"))

    class Late(Node):
        def __init__(self) -> None:
            super().__init__("late")
            self.create_subscription(String, "/description", lambda m: heard.append(m.data), 1)

    ex = Executor(MS)
    latcher = Latcher()
    ex.add_node(latcher)
    latcher.pub.publish(String(data="first"))
    latcher.pub.publish(String(data="robot"))
    ex.add_node(Late())
    assert heard == ["robot"]


def test_a_subscriber_that_asks_for_a_message_class_gets_encoded_messages_decoded() -> None:
    heard: list[Any] = []

    class Builtin(Node):
        builtin = True

        def __init__(self) -> None:
            super().__init__("builtin")
            self.pub = self.create_publisher("geometry_msgs/msg/Twist", "/cmd_vel", 10)

    class User(Node):
        def __init__(self) -> None:
            super().__init__("user")
            self.create_subscription(Twist, "/cmd_vel", heard.append, 10)

    ex = Executor(MS)
    builtin = Builtin()
    ex.add_node(builtin)
    ex.add_node(User())
    from twin.bag import TwistEncoder

    builtin.pub.publish(Encoded((TwistEncoder().encode, (0.2, -0.5), (0.2, -0.5))))
    assert heard[0].linear.x == pytest.approx(0.2) and heard[0].angular.z == pytest.approx(-0.5)


def test_the_subscription_count_includes_the_recorder() -> None:
    ex = Executor(MS)
    ex.add_sink(FakeSink())
    talker = Publisher("talker", "/chat", 0.1, Log())
    ex.add_node(talker)
    assert talker.pub.get_subscription_count() == 1
    ex.add_node(Listener("listener", "/chat", Log()))
    assert talker.pub.get_subscription_count() == 2


def test_a_record_filter_keeps_excluded_topics_out_of_the_sink() -> None:
    sink = FakeSink()
    ex = Executor(MS)
    ex.add_sink(sink, RecordFilter(exclude=("/noise",)))
    ex.add_node(Publisher("a", "/chat", 0.1, Log()))
    ex.add_node(Publisher("b", "/noise", 0.1, Log()))
    ex.spin(150)
    assert sink.topics == [("/chat", "std_msgs/msg/String")]
    assert {w[0] for w in sink.writes} == {"/chat"}
    assert RecordFilter(include_regex="/(scan|odom)").takes("/odom")
    assert not RecordFilter(include=("/scan",)).takes("/odom")


def test_two_nodes_with_one_name_are_refused() -> None:
    ex = Executor(MS)
    ex.add_node(Publisher("same", "/a", 0.1, Log()))
    with pytest.raises(ConfigError, match="two nodes are named /same"):
        ex.add_node(Publisher("same", "/b", 0.1, Log()))


def test_declaring_a_topic_with_another_type_is_refused_with_both_types() -> None:
    class PosePublisher(Node):
        def __init__(self) -> None:
            super().__init__("poser")
            self.create_publisher(Pose, "/chat", 10)

    ex = Executor(MS)
    ex.add_node(Publisher("talker", "/chat", 0.1, Log()))
    with pytest.raises(
        ConfigError, match=r"poser publishes /chat as geometry_msgs/msg/Pose, but /chat is std_msgs/msg/String"
    ):
        ex.add_node(PosePublisher())


def test_publishing_a_message_of_the_wrong_class_names_node_and_topic() -> None:
    class Wrong(Node):
        def __init__(self) -> None:
            super().__init__("wrong")
            self.pub = self.create_publisher(String, "/chat", 10)
            self.create_timer(0.1, lambda: self.pub.publish(Twist()))

    ex = Executor(MS)
    ex.add_node(Wrong())
    with pytest.raises(SimulationError, match="wrong published a geometry_msgs/msg/Twist on /chat"):
        ex.spin(200)


def test_a_raising_callback_names_node_callback_and_sim_time() -> None:
    class Faulty(Node):
        def __init__(self) -> None:
            super().__init__("faulty")
            self.create_timer(0.25, self.on_timer)

        def on_timer(self) -> None:
            raise ZeroDivisionError("division by zero")

    ex = Executor(MS)
    ex.add_node(Faulty())
    with pytest.raises(
        SimulationError,
        match=r"node faulty: timer callback Faulty.on_timer raised ZeroDivisionError: division by zero at t=0.250 s",
    ):
        ex.spin(1000)


def test_a_cancelled_timer_stops_firing() -> None:
    log = Log()
    ex = Executor(MS)
    talker = Publisher("talker", "/chat", 0.1, log)
    ex.add_node(talker)
    ex.spin(250)
    talker.timers[0].cancel()
    ex.spin(600)
    assert talker.n == 2


def test_a_stop_is_seen_within_20_ms_of_sim_time_not_at_the_next_second() -> None:
    # In a world that runs slower than real time a simulated second can take many wall seconds; a
    # SIGTERM (a sweep's timeout) must not wait for it.
    ex = Executor(MS)
    log = Log()
    ex.add_node(Publisher("p", "/chatter", 0.001, log))
    asked = []

    def should_stop() -> bool:
        asked.append(ex.now_ns)
        return len(asked) == 2  # asked to stop between the first and the second look

    assert ex.spin(10_000, should_stop=should_stop) == "interrupted"
    assert asked == [MS, 21 * MS]  # the first event (the timer at 1 ms), then 20 ms of sim time later


class _LatchedTalker(Node):
    def __init__(self) -> None:
        super().__init__("talker")
        self.pub = self.create_publisher(String, "/latched", QoSProfile(depth=1, durability="transient_local"))
        self.create_one_shot(lambda t_ns: self.pub.publish(String(data="hello")), priority=PRIORITY_STATE)


class _TimerOnMessage(Node):
    """Creates a 10 ms timer when its first message arrives (a latched one: while it joins the graph)."""

    def __init__(self) -> None:
        super().__init__("late_timer")
        self.fired: list[int] = []
        self.create_subscription(String, "/latched", self.on_message, 10)

    def on_message(self, msg: Any) -> None:
        if not self.timers:
            self.create_timer(0.01, lambda: self.fired.append(self.get_clock().now().nanoseconds))


def test_a_timer_created_in_a_callback_fires_once_per_period_also_on_a_latched_message() -> None:
    ex = Executor(MS)
    ex.add_node(_LatchedTalker())
    ex.spin(1)  # the latched message is published at t = 0
    node = _TimerOnMessage()
    ex.add_node(node)  # gets the latched message while it joins: creates its timer then
    ex.spin(50)
    assert node.fired == [11 * MS, 21 * MS, 31 * MS, 41 * MS]  # one period after its creation (at 1 ms), once each


def test_count_publishers_answers_as_rclpy_does() -> None:
    log = Log()
    ex = Executor(MS)
    listener = Listener("listener", "/robot1/chat", log)
    assert listener.count_publishers("/robot1/chat") == 0  # not on a graph yet
    ex.add_node(listener)
    assert listener.count_publishers("/robot1/chat") == 0  # subscribed, not published
    ex.add_node(Publisher("talker", "/robot1/chat", 0.1, log))
    ex.add_node(Publisher("other", "/robot1/chat", 0.1, log))
    assert listener.count_publishers("/robot1/chat") == 2
    assert listener.count_publishers("/nobody") == 0
    inner = Node("probe", namespace="/robot1")
    ex.add_node(inner)
    assert inner.count_publishers("chat") == 2  # a relative name resolves in the node's namespace
