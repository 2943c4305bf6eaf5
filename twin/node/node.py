"""Nodes as rclpy shapes them: publishers, subscriptions, timers, a sim-time clock, a logger, parameters.

A node declares what it publishes and subscribes in its constructor, as an rclpy node does; the
executor (`twin.sim`) binds those declarations to topics when the node is added to the graph, and
from then on drives its callbacks on the simulation clock. Until then a publisher cannot publish.

Launch arguments (the node's name, parameter overrides and topic remappings from the scenario's
`nodes:` entry) reach a node's constructor the way `--ros-args` reach rclpy's: through the launch
context that `launch_context` opens around the constructor call, so a user's `MyNode()` with no
arguments still gets them.
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from twin.core.clock import NS_PER_S
from twin.core.errors import ConfigError

__all__ = [
    "MAX_TIMER_PERIOD_S",
    "PRIORITY_CLOCK",
    "PRIORITY_COMMAND",
    "PRIORITY_SENSOR",
    "PRIORITY_STATE",
    "PRIORITY_TREE",
    "PRIORITY_USER",
    "Clock",
    "Encoded",
    "Graph",
    "LaunchArguments",
    "Node",
    "NodeLogger",
    "Parameter",
    "ParameterNotDeclaredError",
    "Publisher",
    "QoSProfile",
    "Subscription",
    "Time",
    "Timer",
    "launch_context",
    "logger_name",
    "node_logger",
    "resolve_topic_name",
    "validate_topic_name",
]

# Timer priorities of built-in nodes within one step (lower first): the mission's tree, its
# commands, the sensors, user nodes (50), what reports state, and the clock last.
PRIORITY_TREE = 5
PRIORITY_COMMAND = 10
PRIORITY_SENSOR = 40
PRIORITY_USER = 50
PRIORITY_STATE = 60
PRIORITY_CLOCK = 90

_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")

#: The longest timer period a node may ask for (about 31.7 years of sim time; nothing runs longer).
MAX_TIMER_PERIOD_S = 1e9


def validate_topic_name(name: str) -> str | None:
    """Return what is wrong with a topic name by ROS 2's rules, or None when it is valid.

    A name is tokens of letters, digits and underscores (not starting with a digit) joined by
    single `/`, optionally absolute (leading `/`) or private (leading `~/`), never ending in `/`.
    """
    if not name:
        return "a topic name cannot be empty"
    body = name[1:] if name.startswith("/") else name[2:] if name.startswith("~/") else name
    if name == "/" or not body:
        return f"{name!r} names no topic"
    for token in body.split("/"):
        if not _TOKEN.match(token):
            return f"{name!r} is not a topic name: {token!r} must be letters, digits and _ and not start with a digit"
    return None


def in_robot_namespace(topic: str, robot_namespace: str) -> str:
    """An absolute topic of a params file shared by a fleet, on one robot's graph.

    Under `robot_namespace` (`/robot1`: `/scan` is `/robot1/scan`), unless it names that namespace
    already (`/robot1/scan`, or `<robot_namespace>/scan` as the launch fills it in).
    """
    namespace = robot_namespace.rstrip("/")
    if not namespace or topic.startswith(f"{namespace}/"):
        return topic
    return f"{namespace}{topic}"


def resolve_topic_name(name: str, *, node_name: str, namespace: str) -> str:
    """Return the absolute topic name of `name` for a node, as rcl expands it (`~` is the node's name).

    Raises:
        ConfigError: If the name is not a valid topic name.
    """
    problem = validate_topic_name(name)
    if problem is not None:
        raise ConfigError(problem)
    ns = namespace.rstrip("/")
    if name.startswith("/"):
        return name
    if name.startswith("~/"):
        return f"{ns}/{node_name}/{name[2:]}"
    return f"{ns}/{name}"


@dataclass(frozen=True, slots=True)
class QoSProfile:
    """The parts of a ROS 2 QoS profile the twin uses: history depth, and whether late joiners get the last messages.

    `durability="transient_local"` makes a topic latched, as `/tf_static` and `/map` are.
    """

    depth: int = 10
    durability: str = "volatile"  # or "transient_local"
    reliability: str = "reliable"  # or "best_effort"

    def __post_init__(self) -> None:
        if self.durability not in ("volatile", "transient_local"):
            msg = f"QoSProfile durability must be 'volatile' or 'transient_local', got {self.durability!r}"
            raise ConfigError(msg)
        if self.reliability not in ("reliable", "best_effort"):
            msg = f"QoSProfile reliability must be 'reliable' or 'best_effort', got {self.reliability!r}"
            raise ConfigError(msg)


def _qos(qos: QoSProfile | int) -> QoSProfile:
    return QoSProfile(depth=qos) if isinstance(qos, int) else qos


class Encoded(tuple[Any, ...]):
    """A message a built-in node publishes: `Encoded((encode, args, data))`.

    `data` (item 2) is whatever the publishing node documents, for in-process readers (a tuple of
    numbers, a reading); `encode(*args)` (items 0 and 1) makes the CDR bytes, run only for a sink (the
    recorder, a live view). A subscriber that asked for a message class gets the decoded ROS message
    (`twin.msgs`) instead. A plain tuple subclass, because a built-in node makes hundreds a simulated
    second and a tuple is the cheapest object Python builds.
    """

    __slots__ = ()

    @property
    def data(self) -> Any:
        """The publishing node's in-process payload."""
        return self[2]

    def cdr(self) -> bytes:
        """Return the message's CDR bytes (encoded on each call)."""
        data: bytes = self[0](*self[1])
        return data


class Time:
    """A point on the simulation clock (integer nanoseconds), as `rclpy.time.Time`."""

    __slots__ = ("nanoseconds",)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(nanoseconds) + round(seconds * NS_PER_S)

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """Return (sec, nanosec) as `builtin_interfaces/Time` holds them."""
        return divmod(self.nanoseconds, NS_PER_S)

    def to_msg(self) -> Any:
        """Return the time as a `builtin_interfaces/msg/Time` message."""
        from twin.msgs import get_message

        sec, nanosec = self.seconds_nanoseconds()
        return get_message("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)

    def __sub__(self, other: Time) -> float:
        """Return the difference in seconds (rclpy returns a Duration; seconds are what users take from it)."""
        return (self.nanoseconds - other.nanoseconds) / NS_PER_S

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Time) and other.nanoseconds == self.nanoseconds

    def __lt__(self, other: Time) -> bool:
        return self.nanoseconds < other.nanoseconds

    def __hash__(self) -> int:
        return hash(self.nanoseconds)

    def __repr__(self) -> str:
        return f"Time(nanoseconds={self.nanoseconds})"


class Graph(Protocol):
    """What a node needs from the executor it is added to."""

    @property
    def now_ns(self) -> int:
        """The simulation time, ns."""
        ...

    def add_timer(self, timer: Timer) -> None:
        """Start a timer a node created while running (in a callback): first firing one period from now."""
        ...

    def count_publishers(self, topic: str) -> int:
        """How many publishers the graph has on `topic` (a full name)."""
        ...


class Clock:
    """The simulation clock as a node sees it (`node.get_clock().now()`)."""

    __slots__ = ("_node",)

    def __init__(self, node: Node) -> None:
        self._node = node

    def now(self) -> Time:
        """Return the current simulation time."""
        return Time(nanoseconds=self._node._graph_now())


@dataclass(slots=True, eq=False)
class Publisher:
    """A node's publisher on one topic. `publish(msg)` delivers `msg` to every subscriber before it returns."""

    node: Node
    msg_type: type | str
    topic: str
    qos: QoSProfile
    publish: Callable[[Any], None] = field(default=lambda _msg: _not_bound())
    get_subscription_count: Callable[[], int] = field(default=lambda: 0)

    @property
    def topic_name(self) -> str:
        """The topic's absolute name."""
        return self.topic


@dataclass(slots=True, eq=False)
class Subscription:
    """A node's subscription: `callback(msg)` for every message on `topic`, at its publication time."""

    node: Node
    msg_type: type | str
    topic: str
    callback: Callable[[Any], None]
    qos: QoSProfile
    raw: bool = False  # deliver what was published (an `Encoded` or a message object) without decoding

    @property
    def topic_name(self) -> str:
        """The topic's absolute name."""
        return self.topic


@dataclass(slots=True, eq=False)
class Timer:
    """A periodic callback on the simulation clock. rclpy's timers first fire one period after start.

    Built-in nodes may ask for `fire_at_start` and a `priority` (lower first among timers due at the
    same step); user timers have priority 50.
    """

    node: Node
    period_ns: int
    callback: Callable[..., None]
    priority: int = PRIORITY_USER
    fire_at_start: bool = False
    pass_time: bool = False  # call `callback(t_ns)` (built-in nodes) instead of `callback()`
    rate_hz: float | None = None  # exact rate for built-in timers (the period in ns may round)
    cancelled: bool = False

    @property
    def timer_period_ns(self) -> int:
        """The period, ns (rclpy's name)."""
        return self.period_ns

    def cancel(self) -> None:
        """Stop firing."""
        self.cancelled = True

    def is_canceled(self) -> bool:
        """Whether `cancel` was called."""
        return self.cancelled


class NodeLogger:
    """A node's logger as rclpy's: `info`, `warn`, `error`, `fatal`, `debug`, with `once` and `skip_first`.

    Lines go to the console and, stamped with sim time, to `/rosout` under the node's name.
    """

    __slots__ = ("_logger", "_seen")

    def __init__(self, name: str) -> None:
        """`name`: the logger name (`logger_name`), `robot1.amcl` for a node in a namespace."""
        self._logger = logging.getLogger(f"twin.node.{name}")
        self._seen: set[tuple[int, str]] = set()

    @property
    def name(self) -> str:
        """The underlying Python logger's name."""
        return self._logger.name

    def _log(self, level: int, message: str, once: bool, skip_first: bool) -> bool:
        if once or skip_first:
            key = (level, message)
            first = key not in self._seen
            self._seen.add(key)
            if (once and not first) or (skip_first and first):
                return False
        self._logger.log(level, "%s", message, stacklevel=3)
        return True

    def debug(self, message: str, *, once: bool = False, skip_first: bool = False, **_: Any) -> bool:
        """Log at DEBUG."""
        return self._log(logging.DEBUG, message, once, skip_first)

    def info(self, message: str, *, once: bool = False, skip_first: bool = False, **_: Any) -> bool:
        """Log at INFO."""
        return self._log(logging.INFO, message, once, skip_first)

    def warn(self, message: str, *, once: bool = False, skip_first: bool = False, **_: Any) -> bool:
        """Log at WARN."""
        return self._log(logging.WARNING, message, once, skip_first)

    warning = warn

    def error(self, message: str, *, once: bool = False, skip_first: bool = False, **_: Any) -> bool:
        """Log at ERROR."""
        return self._log(logging.ERROR, message, once, skip_first)

    def fatal(self, message: str, *, once: bool = False, skip_first: bool = False, **_: Any) -> bool:
        """Log at FATAL."""
        return self._log(logging.CRITICAL, message, once, skip_first)


def _not_bound() -> None:
    msg = "this publisher's node is not in a running graph yet; publish from callbacks, not from __init__"
    raise RuntimeError(msg)


class ParameterNotDeclaredError(ConfigError):
    """A node read a parameter it never declared."""


@dataclass(frozen=True, slots=True)
class Parameter:
    """A node parameter, as `rclpy.parameter.Parameter` exposes it (`.name`, `.value`)."""

    name: str
    value: Any

    def get_parameter_value(self) -> Any:
        """Return the value (rclpy wraps it in a ParameterValue message; the plain value is what users read)."""
        return self.value


@dataclass(frozen=True, kw_only=True, slots=True)
class LaunchArguments:
    """What a launch file gives a node: its name and namespace, parameter overrides, remappings.

    `push_namespace` is what an enclosing group pushes (launch's `PushRosNamespace`): it leads the
    node's namespace (`namespace`, else the one the node's code gives) unless that is absolute.
    """

    name: str | None = None
    namespace: str = ""
    push_namespace: str = ""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    remappings: Mapping[str, str] = field(default_factory=dict)


_LAUNCH: contextvars.ContextVar[LaunchArguments | None] = contextvars.ContextVar("twin_launch", default=None)


def logger_name(node_name: str, namespace: str = "") -> str:
    """The logger name rcl gives a node: `amcl` alone, `robot1.amcl` for `/robot1/amcl` (the namespace's `/` as `.`).

    It names the node's lines on the console (`[robot1.amcl]`) and in `/rosout`, as ROS 2 does.
    """
    ns = namespace.strip("/").replace("/", ".")
    return f"{ns}.{node_name}" if ns else node_name


def node_logger(node_name: str, namespace: str | None = None) -> logging.Logger:
    """The Python logger whose lines are node `node_name`'s (`twin.node.<logger_name>`).

    For the parts of a node that are not the node (Nav2's planner inside planner_server, a mission's
    tree inside the mission node): their lines then name the node, and in a fleet its robot.
    `namespace` None is the enclosing launch context's (a robot group's nodes are built in one).
    """
    if namespace is None:
        launch = _LAUNCH.get()
        namespace = launch.push_namespace if launch is not None else ""
    return logging.getLogger(f"twin.node.{logger_name(node_name, namespace)}")


@contextlib.contextmanager
def launch_context(arguments: LaunchArguments) -> Iterator[None]:
    """Give nodes constructed inside this block these launch arguments (as `--ros-args` does)."""
    token = _LAUNCH.set(arguments)
    try:
        yield
    finally:
        _LAUNCH.reset(token)


class Node:
    """A ROS 2 node on the simulation clock, shaped like `rclpy.node.Node`.

    Args:
        node_name: The node's name (the scenario's `name:` overrides it).
        namespace: Namespace for relative topic names.
        parameter_overrides: Values for declared parameters (the scenario's `parameters:` win).

    Raises:
        ConfigError: If the name is not a valid node name.
    """

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str = "",
        parameter_overrides: Mapping[str, Any] | None = None,
    ) -> None:
        launch = _LAUNCH.get() or LaunchArguments()
        name = launch.name or node_name
        if not _TOKEN.match(name):
            msg = f"node name {name!r} must be letters, digits and _ and not start with a digit"
            raise ConfigError(msg)
        ns = launch.namespace or namespace
        if not ns.startswith("/"):
            ns = f"{launch.push_namespace.strip('/')}/{ns}"
        self._name = name
        if ns.strip("/") and not all(_TOKEN.match(token) for token in ns.strip("/").split("/")):
            msg = f"node {name}: namespace {ns!r} is not a ROS namespace: names of letters, digits and _ joined by /"
            raise ConfigError(msg)
        self._namespace = "/" + ns.strip("/") if ns.strip("/") else ""
        self._overrides: dict[str, Any] = {**(parameter_overrides or {}), **launch.parameters}
        self._remappings: dict[str, str] = {}
        for source, target in launch.remappings.items():
            problem = validate_topic_name(target)
            if problem is not None:
                msg = f"node {name}: remapping {source} -> {target}: {problem}"
                raise ConfigError(msg)
            self._remappings[self._resolve(source, remap=False)] = self._resolve(target, remap=False)
        self._parameters: dict[str, Parameter] = {}
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.timers: list[Timer] = []
        self._graph: Graph | None = None
        self._logger = NodeLogger(logger_name(name, self._namespace))

    # -- identity --------------------------------------------------------------------------------

    def get_name(self) -> str:
        """Return the node's name."""
        return self._name

    def get_namespace(self) -> str:
        """Return the node's namespace (`/` when it has none)."""
        return self._namespace or "/"

    def get_fully_qualified_name(self) -> str:
        """Return `/namespace/name`."""
        return f"{self._namespace}/{self._name}"

    def resolve_topic_name(self, topic: str, *, only_expand: bool = False) -> str:
        """Return a topic's full name as this node's publishers and subscriptions use it, as rclpy's does.

        A relative name resolves in the node's namespace, `~` in the node's own; remappings apply
        unless `only_expand`.

        Raises:
            ConfigError: If the name is not a valid ROS topic name.
        """
        return self._resolve(topic, remap=not only_expand)

    def _resolve(self, topic: str, *, remap: bool = True) -> str:
        try:
            full = resolve_topic_name(topic, node_name=self._name, namespace=self._namespace)
        except ConfigError as err:
            msg = f"node {self._name}: {err}"
            raise ConfigError(msg) from None
        return self._remappings.get(full, full) if remap else full

    # -- communication ---------------------------------------------------------------------------

    def create_publisher(self, msg_type: type | str, topic: str, qos_profile: QoSProfile | int = 10) -> Publisher:
        """Declare a publisher of `msg_type` (a `twin.msgs` class or a ROS type name) on `topic`."""
        pub = Publisher(node=self, msg_type=msg_type, topic=self._resolve(topic), qos=_qos(qos_profile))
        self.publishers.append(pub)
        return pub

    def create_subscription(
        self,
        msg_type: type | str,
        topic: str,
        callback: Callable[[Any], None],
        qos_profile: QoSProfile | int = 10,
        *,
        raw: bool = False,
    ) -> Subscription:
        """Declare a subscription: `callback(msg)` for each message on `topic`, at the time it is published.

        Args:
            msg_type: The message class (`twin.msgs`) or ROS type name the callback expects.
            topic: Topic name (relative names resolve in the node's namespace; remappings apply).
            callback: Called with each message.
            qos_profile: A depth or a `QoSProfile` (delivery is immediate, so depth does not drop messages).
            raw: Built-in nodes only: receive what the publisher sent (an `Encoded` or a message object).
        """
        sub = Subscription(
            node=self, msg_type=msg_type, topic=self._resolve(topic), callback=callback, qos=_qos(qos_profile), raw=raw
        )
        self.subscriptions.append(sub)
        return sub

    def create_timer(self, timer_period_sec: float, callback: Callable[[], None]) -> Timer:
        """Call `callback()` every `timer_period_sec` of simulation time, first one period after it is created.

        As rclpy's: a timer created in a callback fires too, and a period shorter than the physics
        step fires once per step (missed periods are skipped, not caught up).

        Raises:
            ConfigError: If the period is not a positive, finite number of seconds of at least 1 ns
                (the clock's resolution) and at most `MAX_TIMER_PERIOD_S`.
        """
        period: object = timer_period_sec  # users' code passes anything
        if isinstance(period, bool) or not isinstance(period, int | float) or not 0 < period < float("inf"):
            msg = f"node {self._name}: timer period must be a positive number of seconds, got {period!r}"
            raise ConfigError(msg)
        if period > MAX_TIMER_PERIOD_S:  # before rounding: 1e300 s in ns is no integer
            msg = (
                f"node {self._name}: timer period {period!r} s is longer than any run "
                f"({MAX_TIMER_PERIOD_S:g} s at most)"
            )
            raise ConfigError(msg)
        period_ns = round(period * NS_PER_S)
        if period_ns < 1:
            msg = (
                f"node {self._name}: timer period {period!r} s is below the clock's resolution (1 ns); "
                "give 1e-09 s or more"
            )
            raise ConfigError(msg)
        timer = Timer(node=self, period_ns=period_ns, callback=callback)
        self.timers.append(timer)
        if self._graph is not None:  # created while running: the executor starts it now
            self._graph.add_timer(timer)
        return timer

    def create_rate_timer(
        self, rate_hz: float, callback: Callable[[int], None], *, priority: int, fire_at_start: bool = True
    ) -> Timer:
        """Built-in nodes: call `callback(t_ns)` at `rate_hz` (exact rational rate), from t = 0 by default."""
        timer = Timer(
            node=self,
            period_ns=round(NS_PER_S / rate_hz),
            callback=callback,
            priority=priority,
            fire_at_start=fire_at_start,
            pass_time=True,
            rate_hz=rate_hz,
        )
        self.timers.append(timer)
        return timer

    def create_one_shot(self, callback: Callable[[int], None], *, priority: int) -> Timer:
        """Built-in nodes: call `callback(t_ns)` once, at t = 0 (latched topics publish their one message so)."""
        timer = Timer(node=self, period_ns=0, callback=callback, priority=priority, fire_at_start=True, pass_time=True)
        self.timers.append(timer)
        return timer

    def destroy_timer(self, timer: Timer) -> bool:
        """Stop a timer."""
        timer.cancel()
        return True

    # -- clock and logger ------------------------------------------------------------------------

    def _graph_now(self) -> int:
        graph = self._graph
        return 0 if graph is None else graph.now_ns

    def get_clock(self) -> Clock:
        """Return the simulation clock."""
        return Clock(self)

    def count_publishers(self, topic_name: str) -> int:
        """Return how many publishers the graph has on a topic, as rclpy's does.

        A relative name resolves in the node's namespace. 0 before the node is added to an executor.
        """
        graph = self._graph
        return 0 if graph is None else graph.count_publishers(self._resolve(topic_name))

    def get_logger(self) -> NodeLogger:
        """Return the node's logger: its lines go to the console and, stamped with sim time, to `/rosout`."""
        return self._logger

    # -- parameters ------------------------------------------------------------------------------

    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None) -> Parameter:
        """Declare a parameter with a default; the scenario's `parameters:` value wins when given.

        Raises:
            ConfigError: If the override's type does not fit the default's (an int for a float is fine).
        """
        del descriptor
        if name in self._overrides:
            given = self._overrides[name]
            if value is not None and not _same_kind(value, given):
                msg = (
                    f"node {self._name}: parameter {name} = {given!r} is a {type(given).__name__}, "
                    f"the node declares a {type(value).__name__} (default {value!r})"
                )
                raise ConfigError(msg)
            value = float(given) if isinstance(value, float) and isinstance(given, int) else given
        param = Parameter(name, value)
        self._parameters[name] = param
        return param

    def declare_parameters(self, namespace: str, parameters: list[tuple[str, Any]]) -> list[Parameter]:
        """Declare several parameters (`namespace.name` when a namespace is given)."""
        prefix = f"{namespace}." if namespace else ""
        return [self.declare_parameter(f"{prefix}{n}", v) for n, v in parameters]

    def has_parameter(self, name: str) -> bool:
        """Whether the parameter is declared."""
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        """Return a declared parameter.

        Raises:
            ParameterNotDeclaredError: If it was never declared.
        """
        try:
            return self._parameters[name]
        except KeyError:
            msg = f"node {self._name}: parameter {name!r} is not declared; call declare_parameter first"
            raise ParameterNotDeclaredError(msg) from None

    def get_parameter_or(self, name: str, alternative_value: Parameter | None = None) -> Parameter | None:
        """Return a declared parameter, or the alternative."""
        return self._parameters.get(name, alternative_value)

    def undeclared_overrides(self) -> list[str]:
        """Names given in the launch arguments that the node never declared (for a warning)."""
        return sorted(set(self._overrides) - set(self._parameters))

    # -- life cycle ------------------------------------------------------------------------------

    def bind(self, graph: Graph) -> None:
        """Called by the executor when the node joins the graph."""
        self._graph = graph

    def destroy_node(self) -> None:
        """Cancel the node's timers (the executor drops it at the end of the run)."""
        for timer in self.timers:
            timer.cancel()


def _same_kind(default: Any, given: Any) -> bool:
    if isinstance(default, bool) or isinstance(given, bool):
        return isinstance(default, bool) and isinstance(given, bool)
    if isinstance(default, float):
        return isinstance(given, int | float)
    if isinstance(default, int):
        return isinstance(given, int)
    if isinstance(default, str):
        return isinstance(given, str)
    if isinstance(default, list | tuple):
        return isinstance(given, list | tuple)
    return True
