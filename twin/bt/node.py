"""Node base classes: the Python API for custom nodes, mirroring BehaviorTree.CPP.

Subclass one of these and register it on a `BehaviorTreeFactory`:

* `SyncActionNode`: `tick()` returns SUCCESS or FAILURE at once.
* `StatefulActionNode`: `on_start()` when ticked while IDLE, `on_running()` while RUNNING,
  `on_halted()` when a parent halts it while RUNNING.
* `ConditionNode`: `tick()` returns SUCCESS or FAILURE.
* `DecoratorNode`: one child (`self.child`), `tick()` decides what to do with it.
* `ControlNode`: children (`self.children`), `tick()` decides the order.

Ports come from the classmethod `provided_ports()`; a node reads them with `get_input(name)` and
writes them with `set_output(name, value)`. The engine calls `execute_tick()`, which evaluates the
pre-conditions (`_skipIf`, `_successIf`, `_failureIf`, `_while`), calls `tick()`, runs the
post-conditions (`_onSuccess`, `_onFailure`, `_post`) and stores the status. Every stored status
change is reported to the tree's listeners. Any exception a node raises reaches the caller of
`Tree.tick_once()` as a `TickError` naming the node's path.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final

from twin.bt.blackboard import Blackboard
from twin.bt.ports import NO_DEFAULT, PortSpec
from twin.bt.script import Environment, Script, script_truth
from twin.bt.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, NodeKind, NodeStatus
from twin.bt.ticking import TickContext
from twin.bt.values import ConversionError, PortType, cast_value, parse_string
from twin.core.errors import TreeError

__all__ = [
    "ActionNode",
    "ConditionNode",
    "ControlNode",
    "DecoratorNode",
    "NodeConfig",
    "NodeManifest",
    "StatefulActionNode",
    "SyncActionNode",
    "TickError",
    "TreeNode",
    "remapped_key",
    "strip_pointer",
]


class TickError(TreeError):
    """A node failed while the tree was ticking.

    Attributes:
        node_path: the full path of the node (`subtree/name`).
        node_type: its registration ID.
    """

    def __init__(self, node_path: str, node_type: str, problem: str, location: str = "") -> None:
        self.node_path = node_path
        self.node_type = node_type
        self.problem = problem
        at = f"{location}: " if location else ""  # the XML element's file:line, when the tree came from a file
        super().__init__(f"{at}node '{node_path}' ({node_type}): {problem}")


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class NodeManifest:
    """What the factory knows about a node type.

    Attributes:
        kind: action, condition, control, decorator or subtree.
        registration_id: the name used in the XML.
        ports: the ports by name.
        description: one line for `twin tree show --models`.
        bound: False for a type that is declared (ports known, so trees validate) but has no
            implementation yet (e.g. Nav2's action nodes).
    """

    kind: NodeKind
    registration_id: str
    ports: Mapping[str, PortSpec]
    description: str = ""
    bound: bool = True


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class NodeConfig:
    """Everything the loader hands a node (BT.CPP `NodeConfig`).

    Attributes:
        path: the full path: the name, prefixed by the SubTree instances (`nav/move`); a node
            without a `name` attribute is `Type::uid`.
        uid: unique number, counted from 1 in creation order (depth first).
        blackboard: the blackboard of the (sub)tree the node belongs to.
        input_ports: port name → XML value (a literal, `{key}` or `{=}`), defaults included.
        output_ports: idem for output and inout ports.
        manifest: the node type's manifest.
        enums: the scripting enums of the factory.
        other_attributes: XML attributes that are neither ports nor reserved.
        pre_conditions: the parsed `_failureIf`, `_successIf`, `_skipIf`, `_while` (None if absent).
        post_conditions: the parsed `_onHalted`, `_onFailure`, `_onSuccess`, `_post`.
        location: `file:line` of the XML element, for messages.
    """

    path: str
    uid: int
    blackboard: Blackboard
    input_ports: Mapping[str, str] = dataclasses.field(default_factory=dict)
    output_ports: Mapping[str, str] = dataclasses.field(default_factory=dict)
    manifest: NodeManifest | None = None
    enums: Mapping[str, int] = dataclasses.field(default_factory=dict)
    other_attributes: Mapping[str, str] = dataclasses.field(default_factory=dict)
    pre_conditions: tuple[Script | None, ...] = (None, None, None, None)
    post_conditions: tuple[Script | None, ...] = (None, None, None, None)
    location: str = ""


def strip_pointer(text: str) -> str | None:
    """`{key}` → `key` (blanks around the braces allowed); None if `text` is not a reference."""
    stripped = text.strip(" ")
    if len(stripped) >= 3 and stripped[0] == "{" and stripped[-1] == "}":
        return stripped[1:-1]
    return None


def remapped_key(port_name: str, value: str) -> str | None:
    """The blackboard key a port value refers to (`{key}`, or `{=}` / `=` for the port's own name)."""
    if value in {"{=}", "="}:
        return port_name
    return strip_pointer(value)


_PRE_RESULT: Final = (FAILURE, SUCCESS, SKIPPED)
_MISSING: Final = object()
_IMMUTABLE_KINDS: Final = frozenset(("any", "string", "int", "double", "bool", "status"))
_WHILE: Final = 3


class TreeNode:
    """Base of every node. Subclass one of the kinds below rather than this class."""

    kind: ClassVar[NodeKind] = NodeKind.ACTION

    __slots__ = (
        "__dict__",
        "_config",
        "_env",
        "_name",
        "_notify",
        "_post",
        "_pre",
        "_registration_id",
        "_settles",
        "_status",
        "_tree",
    )

    #: A tick of a node of this type that changes no status and writes nothing repeats itself exactly
    #: while the blackboard, the tree's external inputs and the clock (before `wake_ns()`) stay as they
    #: were: `Tree.tick_unless_settled` may then skip the tick. False unless a node type says so.
    settles: ClassVar[bool] = False

    def __init__(self, name: str, config: NodeConfig) -> None:
        self._name = name
        self._config = config
        self._status = IDLE
        self._notify: Callable[[TreeNode, NodeStatus, NodeStatus], None] | None = None
        self._tree: TickContext | None = None
        self._registration_id = config.manifest.registration_id if config.manifest else type(self).__name__
        self._pre = config.pre_conditions if any(s is not None for s in config.pre_conditions) else None
        self._post = config.post_conditions if any(s is not None for s in config.post_conditions) else None
        self._settles = type(self).settles and self._pre is None and self._post is None
        self._env = Environment(config.blackboard, config.enums)
        self._literals: dict[tuple[str, str], Any] = {}

    @classmethod
    def provided_ports(cls) -> Sequence[PortSpec]:
        """The ports of this node type (BT.CPP `providedPorts()`); none by default."""
        return ()

    # -- identity ------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The instance name (`name` attribute, or the type ID)."""
        return self._name

    @property
    def full_path(self) -> str:
        """The path used in logs and leaf scripts: `subtree/name`."""
        return self._config.path

    @property
    def uid(self) -> int:
        """Unique number of the node in its tree."""
        return self._config.uid

    @property
    def registration_id(self) -> str:
        """The node type's name in the XML."""
        return self._registration_id

    @property
    def config(self) -> NodeConfig:
        """The node's configuration."""
        return self._config

    @property
    def blackboard(self) -> Blackboard:
        """The blackboard of the (sub)tree this node belongs to."""
        return self._config.blackboard

    @property
    def status(self) -> NodeStatus:
        """The stored status."""
        return self._status

    @property
    def tree(self) -> TickContext | None:
        """The time, timers and wake-up signal of the tree the node belongs to (None while it is being built)."""
        return self._tree

    def _attach(self, tree: TickContext, notify: Callable[[TreeNode, NodeStatus, NodeStatus], None] | None) -> None:
        self._tree = tree
        self._notify = notify

    def children_nodes(self) -> Sequence[TreeNode]:
        """The children (none for a leaf)."""
        return ()

    def __repr__(self) -> str:
        return f"<{self._registration_id} {self._config.path!r} {self._status.name}>"

    # -- ticking -------------------------------------------------------------------------------

    def tick(self) -> NodeStatus:
        """Do the node's work and return its status. Override in subclasses."""
        raise NotImplementedError

    def halt(self) -> None:
        """Interrupt a RUNNING node and reset its status. Override in subclasses."""
        raise NotImplementedError

    def execute_tick(self) -> NodeStatus:
        """Tick the node with its pre- and post-conditions and store the resulting status.

        A SKIPPED result is returned to the parent but not stored (the node stays IDLE).

        Raises:
            TickError: If the node (or a script on it) fails.
        """
        try:
            if not self._settles:
                tree = self._tree
                if tree is not None:
                    tree._unsettled = True
            new = None
            if self._pre is not None:
                new = self._check_pre_conditions(self._pre)
            if new is None:
                new = self.tick()
                if new.__class__ is not NodeStatus:
                    msg = f"tick() returned {new!r}, expected a NodeStatus"
                    raise TypeError(msg)
            if self._post is not None and (new is SUCCESS or new is FAILURE):
                self._run_post_conditions(new)
            if new is not SKIPPED:
                if new is IDLE:
                    msg = "tick() returned IDLE; a node must return RUNNING, SUCCESS, FAILURE or SKIPPED"
                    raise TypeError(msg)
                prev = self._status
                if prev is not new:
                    self._status = new
                    self._changed()
                    notify = self._notify
                    if notify is not None:
                        notify(self, prev, new)
            return new
        except TickError:
            raise
        except Exception as err:
            raise self._tick_error(err) from err

    def _tick_error(self, err: Exception) -> TickError:
        text = str(err) if isinstance(err, TreeError) else f"{type(err).__name__}: {err}"
        return TickError(self._config.path, self._registration_id, text, self._config.location)

    def _check_pre_conditions(self, scripts: tuple[Script | None, ...]) -> NodeStatus | None:
        status = self._status
        for index, script in enumerate(scripts):
            if script is None:
                continue
            if status is IDLE or status is SKIPPED:
                if script_truth(script(self._env)):
                    if index < _WHILE:
                        return _PRE_RESULT[index]
                elif index == _WHILE:
                    return SKIPPED
            elif status is RUNNING and index == _WHILE and not script_truth(script(self._env)):
                self.halt_node()
                return SKIPPED
        return None

    def _run_post_conditions(self, status: NodeStatus) -> None:
        _, on_failure, on_success, always = self._post or (None, None, None, None)
        if status is SUCCESS and on_success is not None:
            on_success(self._env)
        elif status is FAILURE and on_failure is not None:
            on_failure(self._env)
        if always is not None:
            always(self._env)

    def halt_node(self) -> None:
        """Halt the node, then run its `_onHalted` script."""
        self.halt()
        if self._post is not None and self._post[0] is not None:
            self._post[0](self._env)

    def set_status(self, new: NodeStatus) -> None:
        """Store a status; a change is reported to the tree's listeners.

        Raises:
            TreeError: For IDLE (use `reset_status`).
        """
        if new is IDLE:
            msg = f"node '{self._config.path}': the status cannot be set to IDLE; use reset_status()"
            raise TreeError(msg)
        prev = self._status
        if prev is not new:
            self._status = new
            self._changed()
            notify = self._notify
            if notify is not None:
                notify(self, prev, new)

    def reset_status(self) -> None:
        """Set the status to IDLE (reported when it was not IDLE)."""
        prev = self._status
        if prev is not IDLE:
            self._status = IDLE
            self._changed()
            notify = self._notify
            if notify is not None:
                notify(self, prev, IDLE)

    def _changed(self) -> None:
        tree = self._tree
        if tree is not None:
            tree._status_changes += 1

    def wake_ns(self) -> int | None:
        """For a settling node whose ticks depend on time: when a tick of it may stop repeating (None: never)."""
        return None

    # -- wake-ups and time ---------------------------------------------------------------------

    def emit_wake_up_signal(self) -> None:
        """Ask `Tree.tick_once()` to tick the root again at once."""
        if self._tree is not None:
            self._tree.emit_wake_up_signal()

    def requires_wake_up(self) -> bool:
        """True once the node belongs to a tree ticked as BT.CPP 4.x (which installs a wake-up signal)."""
        return self._tree is not None and not self._tree.btcpp3

    @property
    def btcpp3(self) -> bool:
        """Whether the node's tree is ticked as BT.CPP 3.8 ticks a v3 file (`Tree.btcpp3`)."""
        return self._tree is not None and self._tree.btcpp3

    def now_ns(self) -> int:
        """The simulation time of the current tick."""
        return self._tree.now_ns if self._tree is not None else 0

    # -- ports ---------------------------------------------------------------------------------

    def _port_type(self, key: str, as_type: PortType | None) -> PortType:
        if as_type is not None:
            return as_type
        manifest = self._config.manifest
        if manifest is not None:
            spec = manifest.ports.get(key)
            if spec is not None:
                return spec.type
        return PortType.ANY

    def read_input(self, key: str, as_type: PortType | None = None) -> tuple[bool, Any]:
        """Read an input port: `(True, value)`, or `(False, reason)` when it cannot be read.

        Args:
            key: the port name.
            as_type: the type to convert to; by default the port's declared type.
        """
        config = self._config
        ptype = self._port_type(key, as_type)
        raw = config.input_ports.get(key)
        if raw is None:
            manifest = config.manifest
            spec = manifest.ports.get(key) if manifest is not None else None
            if spec is None:
                return (
                    False,
                    f"getInput() of node '{config.path}' failed because the manifest doesn't contain the key: [{key}]",
                )
            if spec.default is NO_DEFAULT:
                return False, f"getInput() of node '{config.path}': neither the XML nor the manifest set [{key}]"
            if not isinstance(spec.default, str):
                try:
                    return True, cast_value(spec.default, ptype)
                except ConversionError as err:
                    return False, f"getInput(): {err}"
            raw = spec.default
        key_on_board = remapped_key(key, raw)
        if key_on_board is None:
            cache_key = (key, ptype.name)
            cached = self._literals.get(cache_key, _MISSING)
            if cached is not _MISSING:
                return True, cached
            try:
                value = parse_string(raw, ptype, config.enums)
            except ConversionError as err:
                return False, f"getInput(): {err}"
            if ptype.kind in _IMMUTABLE_KINDS:
                # A literal port string never changes: parse it once.
                self._literals[cache_key] = value
            return True, value
        entry = config.blackboard.get_entry(key_on_board)
        if entry is not None and entry.value is not None:
            value = entry.value
            try:
                if isinstance(value, str) and ptype.kind not in ("string", "any", "bt_any"):
                    return True, parse_string(value, ptype, config.enums)
                return True, cast_value(value, ptype)
            except ConversionError as err:
                return False, f"getInput(): port [{key}]: {err}"
        return False, f"getInput() failed because it was unable to find the key [{key}] remapped to [{key_on_board}]"

    def get_input(self, key: str, as_type: PortType | None = None) -> Any:
        """Read an input port, converted to its declared type (or `as_type`).

        Raises:
            TreeError: If the port is not set, its blackboard entry is missing or empty, or the
                value does not convert.
        """
        ok, value = self.read_input(key, as_type)
        if not ok:
            raise TreeError(value)
        return value

    def get_input_or(self, key: str, fallback: Any, as_type: PortType | None = None) -> Any:
        """Read an input port, or return `fallback` when it cannot be read."""
        ok, value = self.read_input(key, as_type)
        return value if ok else fallback

    def set_output(self, key: str, value: Any) -> bool:
        """Write an output port; False (as BT.CPP) when the port is not connected to an entry.

        Raises:
            TreeError: If the blackboard entry has another type that the value cannot be stored as.
        """
        raw = self._config.output_ports.get(key)
        if raw is None:
            return False
        if raw in {"{=}", "="}:
            self._config.blackboard.set(key, value)
            return True
        target = strip_pointer(raw)
        if target is None:
            return False
        self._config.blackboard.set(target, value)
        return True

    def raw_port_value(self, key: str) -> str | None:
        """The XML string of a port (no remapping, no conversion); None if absent."""
        raw = self._config.input_ports.get(key)
        return raw if raw is not None else self._config.output_ports.get(key)


# -- leaves ------------------------------------------------------------------------------------


class ActionNode(TreeNode):
    """Base of action nodes."""

    kind: ClassVar[NodeKind] = NodeKind.ACTION


class SyncActionNode(ActionNode):
    """An action that completes within its tick; it must not return RUNNING."""

    def execute_tick(self) -> NodeStatus:
        """Tick; a RUNNING result is an error."""
        status = super().execute_tick()
        if status is RUNNING:
            raise TickError(
                self._config.path,
                self._registration_id,
                "a SyncActionNode must never return RUNNING",
                self._config.location,
            )
        return status

    def halt(self) -> None:
        """Reset the status."""
        self.reset_status()


class StatefulActionNode(ActionNode):
    """An action that runs across ticks: `on_start`, then `on_running` until it completes."""

    def on_start(self) -> NodeStatus:
        """Called when ticked while IDLE."""
        raise NotImplementedError

    def on_running(self) -> NodeStatus:
        """Called when ticked while RUNNING."""
        raise NotImplementedError

    def on_halted(self) -> None:
        """Called when halted while RUNNING."""

    def tick(self) -> NodeStatus:
        """Dispatch to `on_start` or `on_running`; a completed status is returned unchanged."""
        prev = self._status
        if prev is IDLE:
            status = self.on_start()
        elif prev is RUNNING:
            status = self.on_running()
        else:
            return prev
        if status is IDLE:
            msg = "on_start()/on_running() must not return IDLE"
            raise TreeError(msg)
        return status

    def halt(self) -> None:
        """Call `on_halted` if RUNNING, then reset the status."""
        if self._status is RUNNING:
            self.on_halted()
        self.reset_status()


class ConditionNode(TreeNode):
    """A check that returns SUCCESS or FAILURE."""

    kind: ClassVar[NodeKind] = NodeKind.CONDITION

    def halt(self) -> None:
        """Reset the status."""
        self.reset_status()


# -- inner nodes -------------------------------------------------------------------------------


class ControlNode(TreeNode):
    """A node with one or more children."""

    kind: ClassVar[NodeKind] = NodeKind.CONTROL

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self.children: list[TreeNode] = []

    def add_child(self, child: TreeNode) -> None:
        """Append a child (the loader does this)."""
        self.children.append(child)

    def children_nodes(self) -> Sequence[TreeNode]:
        """The children."""
        return self.children

    def halt(self) -> None:
        """Halt the children, then reset the status."""
        self.reset_children()
        self.reset_status()

    def reset_children(self) -> None:
        """Halt every RUNNING child and reset every child to IDLE, in order."""
        for child in self.children:
            status = child._status
            if status is IDLE:
                continue
            if status is RUNNING:
                child.halt_node()
            child.reset_status()

    def halt_child(self, index: int) -> None:
        """Halt one child if RUNNING and reset it to IDLE."""
        child = self.children[index]
        if child._status is RUNNING:
            child.halt_node()
        child.reset_status()

    def halt_children(self, first: int = 0) -> None:
        """Halt and reset the children from `first` on."""
        for index in range(first, len(self.children)):
            self.halt_child(index)


class DecoratorNode(TreeNode):
    """A node with exactly one child."""

    kind: ClassVar[NodeKind] = NodeKind.DECORATOR

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._child: TreeNode | None = None

    @property
    def child(self) -> TreeNode:
        """The child.

        Raises:
            TreeError: If the decorator has no child.
        """
        child = self._child
        if child is None:
            msg = f"decorator '{self._config.path}' has no child"
            raise TreeError(msg)
        return child

    def set_child(self, child: TreeNode) -> None:
        """Set the child (the loader does this).

        Raises:
            TreeError: If a child is already set.
        """
        if self._child is not None:
            msg = f"decorator '{self._config.path}' has already a child"
            raise TreeError(msg)
        self._child = child

    def children_nodes(self) -> Sequence[TreeNode]:
        """The child, as a sequence."""
        return () if self._child is None else (self._child,)

    def halt(self) -> None:
        """Halt the child, then reset the status."""
        self.reset_child()
        self.reset_status()

    def reset_child(self) -> None:
        """Halt the child if RUNNING and reset it to IDLE."""
        child = self._child
        if child is None:
            return
        if child._status is RUNNING:
            child.halt_node()
        child.reset_status()

    def halt_child(self) -> None:
        """Same as `reset_child`."""
        self.reset_child()

    def execute_tick(self) -> NodeStatus:
        """Tick, then reset the child if it completed."""
        status = super().execute_tick()
        child = self._child
        if child is not None and (child._status is SUCCESS or child._status is FAILURE):
            child.reset_status()
        return status


# -- nodes built from functions ----------------------------------------------------------------

TickFunction = Callable[[TreeNode], NodeStatus]
DecoratorFunction = Callable[[NodeStatus, TreeNode], NodeStatus]


class SimpleActionNode(SyncActionNode):
    """A synchronous action whose tick is a function (BT.CPP `registerSimpleAction`)."""

    def __init__(self, name: str, config: NodeConfig, function: TickFunction) -> None:
        super().__init__(name, config)
        self._function = function

    def tick(self) -> NodeStatus:
        """Log IDLE→RUNNING, call the function, store its status (as BT.CPP does)."""
        prev = self._status
        if prev is IDLE:
            self.set_status(RUNNING)
            prev = RUNNING
        status = self._function(self)
        if status is not prev:
            self.set_status(status)
        return status


class SimpleConditionNode(ConditionNode):
    """A condition whose tick is a function (BT.CPP `registerSimpleCondition`)."""

    def __init__(self, name: str, config: NodeConfig, function: TickFunction) -> None:
        super().__init__(name, config)
        self._function = function

    def tick(self) -> NodeStatus:
        """Call the function."""
        return self._function(self)


class SimpleDecoratorNode(DecoratorNode):
    """A decorator whose tick maps the child's status (BT.CPP `registerSimpleDecorator`)."""

    def __init__(self, name: str, config: NodeConfig, function: DecoratorFunction) -> None:
        super().__init__(name, config)
        self._function = function

    def tick(self) -> NodeStatus:
        """Tick the child and map its status with the function."""
        return self._function(self.child.execute_tick(), self)
