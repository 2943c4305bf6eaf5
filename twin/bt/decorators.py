"""Built-in decorators of BehaviorTree.CPP 4.x (and the SubTree node), with its exact semantics.

Every decorator resets a completed child; most do it inside their tick, before their own status
is stored, and `DecoratorNode.execute_tick` does it afterwards for the others. `Repeat` and
`RetryUntilSuccessful` return RUNNING with a wake-up signal after an instant child when more
cycles remain. `Delay`, `Timeout` and `Sleep` run on the tree's simulation clock.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any, ClassVar, Final

from twin.bt.actions import ScriptPort
from twin.bt.node import DecoratorNode, NodeConfig, TreeNode, remapped_key
from twin.bt.ports import PortSpec, bidirectional_port, input_port, output_port
from twin.bt.script import script_truth
from twin.bt.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, NodeKind, NodeStatus, PortDirection
from twin.bt.ticking import TimerHandle
from twin.bt.values import PortType
from twin.core.errors import TreeError

__all__ = [
    "BlackboardCheckNode",
    "DelayNode",
    "EntryUpdatedDecorator",
    "ForceFailureNode",
    "ForceSuccessNode",
    "InverterNode",
    "KeepRunningUntilFailureNode",
    "LoopNode",
    "PreconditionNode",
    "RepeatNode",
    "RetryNode",
    "RunOnceNode",
    "SubTreeNode",
    "TimeoutNode",
    "loop_node_type",
]

_NS_PER_MS: Final = 1_000_000


def _idle_child(node: TreeNode) -> TreeError:
    return TreeError(f"[{node.name}]: a child should not return IDLE")


def _add_timer(node: TreeNode, msec: int, callback: Callable[[bool], None]) -> TimerHandle:
    tree = node.tree
    if tree is None:
        msg = f"node '{node.full_path}' needs a tree (its timers run on the tree's clock)"
        raise TreeError(msg)
    return tree.timers.add(tree.now_ns + msec * _NS_PER_MS, callback)


class InverterNode(DecoratorNode):
    """SUCCESS ↔ FAILURE; RUNNING and SKIPPED pass through."""

    settles = True

    def tick(self) -> NodeStatus:
        """Tick the child and swap its result."""
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is SUCCESS:
            self.reset_child()
            return FAILURE
        if status is FAILURE:
            self.reset_child()
            return SUCCESS
        if status is IDLE:
            raise _idle_child(self)
        return status


class ForceSuccessNode(DecoratorNode):
    """A completed child gives SUCCESS."""

    settles = True

    def tick(self) -> NodeStatus:
        """Tick the child."""
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self.reset_child()
            return SUCCESS
        return status


class ForceFailureNode(DecoratorNode):
    """A completed child gives FAILURE."""

    settles = True

    def tick(self) -> NodeStatus:
        """Tick the child."""
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self.reset_child()
            return FAILURE
        return status


class KeepRunningUntilFailureNode(DecoratorNode):
    """RUNNING while the child succeeds; FAILURE when it fails."""

    def tick(self) -> NodeStatus:
        """Tick the child."""
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is FAILURE:
            self.reset_child()
            return FAILURE
        if status is SUCCESS:
            self.reset_child()
            return RUNNING
        if status is RUNNING:
            return RUNNING
        return self._status


class _CountingNode(DecoratorNode):
    """Shared tick of Repeat (counts successes) and RetryUntilSuccessful (counts failures)."""

    _PORT: ClassVar[str]
    _AGAIN: ClassVar[NodeStatus]  # a child status that counts one cycle and ticks the child again
    _STOP: ClassVar[NodeStatus]  # a child status that ends the node with that status
    _REREAD: ClassVar[bool]  # read the limit again after each cycle (Retry does)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._limit = 0
        self._count = 0

    def halt(self) -> None:
        """Restart the count."""
        self._count = 0
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick the child until a cycle is RUNNING, it stops early, or the cycles are used up."""
        ok, value = self.read_input(self._PORT)
        if not ok:
            raise TreeError(f"Missing parameter [{self._PORT}] in {type(self).__name__}: {value}")
        self._limit = int(value)
        do_loop = self._count < self._limit or self._limit == -1
        self.set_status(RUNNING)
        child = self.child
        while do_loop:
            prev = child._status
            status = child.execute_tick()
            if status is self._AGAIN:
                self._count += 1
                if self._REREAD and not self.btcpp3:  # BT.CPP 3.8 reads num_attempts once per tick
                    ok, value = self.read_input(self._PORT)
                    if ok:
                        self._limit = int(value)
                do_loop = self._count < self._limit or self._limit == -1
                self.reset_child()
                if self.requires_wake_up() and prev is IDLE and do_loop:
                    self.emit_wake_up_signal()
                    return RUNNING
            elif status is self._STOP:
                self._count = 0
                self.reset_child()
                return status
            elif status is RUNNING:
                return RUNNING
            elif status is SKIPPED:
                self.reset_child()
                return SKIPPED
            else:
                raise _idle_child(self)
        self._count = 0
        return self._AGAIN


class RepeatNode(_CountingNode):
    """Repeat a succeeding child `num_cycles` times (-1: forever); a failure stops it."""

    _PORT = "num_cycles"
    _AGAIN = SUCCESS
    _STOP = FAILURE
    _REREAD = False

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """num_cycles."""
        return (
            input_port(
                "num_cycles",
                int,
                description="Repeat a successful child up to N times. Use -1 to create an infinite loop.",
                required=True,
            ),
        )


class RetryNode(_CountingNode):
    """Retry a failing child up to `num_attempts` times (-1: forever); a success stops it."""

    _PORT = "num_attempts"
    _AGAIN = FAILURE
    _STOP = SUCCESS
    _REREAD = True

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """num_attempts."""
        return (
            input_port(
                "num_attempts",
                int,
                description="Execute again a failing child up to N times. Use -1 to create an infinite loop.",
                required=True,
            ),
        )


class _TimerOwner(DecoratorNode):
    """A decorator that owns timers on the tree's clock."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._timers: list[TimerHandle] = []

    def _start_timer(self, msec: int, callback: Callable[[bool], None]) -> TimerHandle:
        self._timers = [timer for timer in self._timers if timer.pending]
        timer = _add_timer(self, msec, callback)
        self._timers.append(timer)
        return timer

    def _cancel_timers(self) -> None:
        timers, self._timers = self._timers, []
        for timer in timers:
            timer.cancel()


class TimeoutNode(_TimerOwner):
    """Halt the child and fail when it is still RUNNING `msec` after it started."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Msec."""
        return (
            input_port(
                "msec",
                PortType.UINT,
                description="After a certain amount of time, halt() the child if it is still running.",
                required=True,
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._started = False
        self._child_halted = False
        self._timer: TimerHandle | None = None

    def _on_timer(self, aborted: bool) -> None:
        if aborted:
            return
        if self.child._status is RUNNING:
            self._child_halted = True
            self.halt_child()
            self.emit_wake_up_signal()

    def tick(self) -> NodeStatus:
        """Start the timer on the first tick, then tick the child until it completes or times out."""
        ok, value = self.read_input("msec")
        if not ok:
            raise TreeError(f"Missing parameter [msec] in TimeoutNode: {value}")
        msec = int(value)
        if not self._started:
            self._started = True
            self.set_status(RUNNING)
            self._child_halted = False
            if msec > 0:
                self._timer = self._start_timer(msec, self._on_timer)
        if self._child_halted:
            self._started = False
            return FAILURE
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self._started = False
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self.reset_child()
        return status

    def halt(self) -> None:
        """Stop the timer and halt the child."""
        self._started = False
        self._cancel_timers()
        super().halt()


class DelayNode(_TimerOwner):
    """Wait `delay_msec` (RUNNING), then tick the child until it completes."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """delay_msec."""
        return (
            input_port(
                "delay_msec", PortType.UINT, description="Tick the child after a few milliseconds", required=True
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._started = False
        self._aborted = False
        self._complete = False

    def _on_timer(self, aborted: bool) -> None:
        self._complete = not aborted
        if not aborted:
            self.emit_wake_up_signal()

    def tick(self) -> NodeStatus:
        """Start the delay on the first tick; once it is over, tick the child."""
        ok, value = self.read_input("delay_msec")
        if not ok:
            raise TreeError(f"Missing parameter [delay_msec] in DelayNode: {value}")
        if not self._started:
            self._complete = False
            self._aborted = False
            self._started = True
            self.set_status(RUNNING)
            self._start_timer(int(value), self._on_timer)
        if self._aborted:
            self._aborted = False
            self._started = False
            return FAILURE
        if self._complete:
            status = self.child.execute_tick()
            if status is SUCCESS or status is FAILURE:
                self._started = False
                self._aborted = False
                self.reset_child()
            return status
        return RUNNING

    def halt(self) -> None:
        """Stop the delay and halt the child."""
        self._started = False
        self._cancel_timers()
        super().halt()


class RunOnceNode(DecoratorNode):
    """Tick the child until it completes once; afterwards SKIPPED (or its status, `then_skip=false`)."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """then_skip (default true)."""
        return (
            input_port(
                "then_skip",
                bool,
                True,
                "If true, skip after the first execution, otherwise return the same NodeStatus returned "
                "once by the child.",
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._already_ticked = False
        self._returned_status = IDLE

    def tick(self) -> NodeStatus:
        """Tick the child, or repeat the remembered outcome."""
        ok, value = self.read_input("then_skip")
        skip = bool(value) if ok else True
        if self._already_ticked:
            return SKIPPED if skip else self._returned_status
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self._already_ticked = True
            self._returned_status = status
            self.reset_child()
        return status


class PreconditionNode(DecoratorNode):
    """Tick the child when the script `if` is true (or the child is running); otherwise return `else`."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """If (a script) and else (default FAILURE)."""
        return (
            input_port("if", str, required=True),
            input_port("else", NodeStatus, NodeStatus.FAILURE, "Return status if condition is false"),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._script = ScriptPort(self, "if")
        self._children_running = False
        self._script.load()

    def tick(self) -> NodeStatus:
        """Evaluate the condition unless the child is running, then tick the child or return `else`."""
        script = self._script.load()
        ok, else_status = self.read_input("else")
        if not ok:
            raise TreeError(f"Missing parameter [else] in Precondition: {else_status}")
        if not self._children_running:
            if script is None:
                raise TreeError("the condition script [if] is empty")
            self._children_running = script_truth(script(self._env))
        if not self._children_running:
            return else_status  # type: ignore[no-any-return]
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self.reset_child()
            self._children_running = False
        return status


class LoopNode(DecoratorNode):
    """Pop values from a queue into `value` and tick the child once per value (LoopInt, ...)."""

    ITEM_TYPE: ClassVar[PortType] = PortType.STRING

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """queue, if_empty (default SUCCESS) and value."""
        return (
            bidirectional_port("queue", PortType.sequence_of(cls.ITEM_TYPE, container="std::deque"), required=True),
            input_port(
                "if_empty",
                NodeStatus,
                NodeStatus.SUCCESS,
                "Status to return if queue is empty: SUCCESS, FAILURE, SKIPPED",
            ),
            output_port("value", cls.ITEM_TYPE),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._child_running = False
        self._static_queue: deque[Any] | None = None
        self._current_queue: deque[Any] | None = None
        raw = self.raw_port_value("queue")
        if raw is None:
            msg = "[queue] not found"
            raise TreeError(msg)
        if remapped_key("queue", raw) is None:
            queue_type = PortType.sequence_of(self.ITEM_TYPE, container="std::deque")
            self._static_queue = queue_type.parse(raw)

    def tick(self) -> NodeStatus:
        """Pop the next value (unless the child is running) and tick the child."""
        popped = False
        if self._status is IDLE:
            self._child_running = False
            if self._static_queue is not None:
                self._current_queue = deque(self._static_queue)
        if not self._child_running:
            if self._static_queue is None:
                raw = self.raw_port_value("queue") or ""
                key = remapped_key("queue", raw)
                entry = self.blackboard.get_entry(key) if key is not None else None
                if entry is not None:
                    if entry.value is None:
                        raise TreeError("Any::cast failed because it is empty")
                    if not isinstance(entry.value, deque):
                        msg = f"the queue [{key}] holds {type(entry.value).__name__}, not a queue"
                        raise TreeError(msg)
                    self._current_queue = entry.value
            queue = self._current_queue
            if queue:
                value = queue.popleft()
                popped = True
                self.set_output("value", value)
        if not popped and not self._child_running:
            ok, status = self.read_input("if_empty")
            if not ok:
                raise TreeError(status)
            return status  # type: ignore[no-any-return]
        if self._status is IDLE:
            self.set_status(RUNNING)
        status = self.child.execute_tick()
        self._child_running = status is RUNNING
        if status is SUCCESS or status is FAILURE:
            self.reset_child()
        return FAILURE if status is FAILURE else RUNNING


def loop_node_type(name: str, item: PortType) -> type[LoopNode]:
    """The class of a Loop node over items of one type."""
    return type(name, (LoopNode,), {"ITEM_TYPE": item, "__doc__": LoopNode.__doc__})


class EntryUpdatedDecorator(DecoratorNode):
    """Tick the child only when the entry changed since the last check (SkipUnlessUpdated, WaitValueUpdate)."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Entry."""
        return (input_port("entry", PortType.BT_ANY, description="Entry to check", required=True),)

    def __init__(self, name: str, config: NodeConfig, if_not_updated: NodeStatus) -> None:
        super().__init__(name, config)
        self._if_not_updated = if_not_updated
        self._sequence_id = 0
        self._still_executing_child = False
        raw = config.input_ports.get("entry", "")
        if not raw:
            msg = f"Missing port 'entry' in {name}"
            raise TreeError(msg)
        self._entry_key = remapped_key("entry", raw) or raw

    def tick(self) -> NodeStatus:
        """Tick the child if the entry was written since the previous check."""
        if self._still_executing_child:
            status = self.child.execute_tick()
            self._still_executing_child = status is RUNNING
            return status
        entry = self.blackboard.get_entry(self._entry_key)
        if entry is None:
            return self._if_not_updated
        previous, self._sequence_id = self._sequence_id, entry.seq
        if previous == entry.seq:
            return self._if_not_updated
        status = self.child.execute_tick()
        self._still_executing_child = status is RUNNING
        return status

    def halt(self) -> None:
        """Forget a running child (BT.CPP neither halts the child nor resets the status here)."""
        self._still_executing_child = False


class SubTreeNode(DecoratorNode):
    """The root of a SubTree instance; its child is the subtree's root node."""

    kind: ClassVar[NodeKind] = NodeKind.SUBTREE

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """_autoremap (handled by the loader)."""
        return (
            PortSpec(
                name="_autoremap",
                direction=PortDirection.INPUT,
                type=PortType.BOOL,
                default=False,
                default_str="false",
                description="If true, all the ports with the same name will be remapped",
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self.subtree_id = ""

    def tick(self) -> NodeStatus:
        """Set RUNNING (when IDLE) and tick the subtree's root."""
        if self._status is IDLE:
            self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self.reset_child()
        return status


class BlackboardCheckNode(DecoratorNode):
    """BT.CPP 3 `BlackboardCheckInt/Double/String/Bool` (v3 files only): tick the child if A == B."""

    VALUE_TYPE: ClassVar[PortType] = PortType.STRING

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """value_A, value_B, return_on_mismatch."""
        return (
            input_port("value_A", required=True),
            input_port("value_B", required=True),
            input_port("return_on_mismatch", NodeStatus, NodeStatus.FAILURE),
        )

    def tick(self) -> NodeStatus:
        """Compare the two values; tick the child when they are equal."""
        self.set_status(RUNNING)
        ok_a, value_a = self.read_input("value_A", self.VALUE_TYPE)
        ok_b, value_b = self.read_input("value_B", self.VALUE_TYPE)
        if ok_a and ok_b:
            same = (
                abs(value_a - value_b) <= 1.1920928955078125e-07 if isinstance(value_a, float) else value_a == value_b
            )
            if same:
                return self.child.execute_tick()
        if self.child._status is RUNNING:
            self.halt_child()
        ok, status = self.read_input("return_on_mismatch")
        return status if ok else FAILURE


def blackboard_check_type(name: str, value_type: PortType) -> type[BlackboardCheckNode]:
    """The class of a v3 BlackboardCheck node comparing values of one type."""
    return type(name, (BlackboardCheckNode,), {"VALUE_TYPE": value_type, "__doc__": BlackboardCheckNode.__doc__})
