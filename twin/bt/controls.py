"""Built-in control nodes of BehaviorTree.CPP 4.x, with its exact tick, halt and status order.

Points that matter for traces (all as BT.CPP 4.8 does them):

* Sequence/Fallback (and their Async and WithMemory forms) set RUNNING before ticking a child and
  reset all children before returning a completed status.
* `SequenceWithMemory`, `AsyncSequence` and `AsyncFallback` return RUNNING with a wake-up signal
  after a child that went from IDLE straight to SUCCESS (FAILURE for the fallback) when more
  children remain; `SequenceWithMemory` keeps its position when halted or after a failure.
* The reactive nodes halt every other child when one is RUNNING.
* `Parallel` checks its thresholds after each child and never re-ticks completed children.
* `IfThenElse` does not re-check its condition while a branch runs; `WhileDoElse` does.
* `Switch` does not set RUNNING before ticking the selected child.
* A node whose children are all SKIPPED returns SKIPPED.
"""

from __future__ import annotations

from typing import ClassVar

from twin.bt.node import ControlNode, NodeConfig
from twin.bt.ports import PortSpec, input_port
from twin.bt.status import FAILURE, IDLE, RUNNING, SKIPPED, SUCCESS, NodeStatus
from twin.bt.values import PortType, from_chars_double, parse_string
from twin.core.errors import TreeError

__all__ = [
    "FallbackNode",
    "IfThenElseNode",
    "ParallelAllNode",
    "ParallelNode",
    "ReactiveFallback",
    "ReactiveSequence",
    "SequenceNode",
    "SequenceWithMemory",
    "SwitchNode",
    "WhileDoElseNode",
    "switch_node_type",
]


def _idle_child(node: ControlNode) -> TreeError:
    return TreeError(f"[{node.name}]: a child should not return IDLE")


class _SequentialNode(ControlNode):
    """Shared tick of Sequence (stops at a FAILURE), Fallback (at a SUCCESS) and SequenceWithMemory."""

    _STOP: ClassVar[NodeStatus]  # a child status that ends the node with that status
    _NEXT: ClassVar[NodeStatus]  # a child status that moves on to the next child
    _MEMORY: ClassVar[bool] = False  # keep the position after a stop or a halt (SequenceWithMemory)
    settles = True

    def __init__(self, name: str, config: NodeConfig, asynch: bool = False) -> None:
        super().__init__(name, config)
        self._current = 0
        self._skipped = 0
        self._wakes_up = asynch or self._MEMORY

    def halt(self) -> None:
        """Halt the children; restart from the first child next time unless the node has memory.

        BT.CPP 3.8's SequenceStar (a v3 file's) forgets its position when halted; 4.x keeps it.
        """
        if not self._MEMORY or self.btcpp3:
            self._current = 0
            self._skipped = 0
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick the children from the current one."""
        children = self.children
        count = len(children)
        own = self._status
        if own is IDLE or own is SKIPPED:
            self._skipped = 0
        if own is not RUNNING:
            self.set_status(RUNNING)
        while self._current < count:
            child = children[self._current]
            prev = child._status
            status = child.execute_tick()
            if status is self._NEXT:
                self._current += 1
                if self._wakes_up and self.requires_wake_up() and prev is IDLE and self._current < count:
                    self.emit_wake_up_signal()
                    return RUNNING
            elif status is RUNNING:
                return RUNNING
            elif status is self._STOP:
                if self._MEMORY:
                    for index in range(self._current, count):
                        self.halt_child(index)
                else:
                    self.reset_children()
                    self._current = 0
                return status
            elif status is SKIPPED:
                self._current += 1
                self._skipped += 1
            else:
                raise _idle_child(self)
        all_skipped = self._skipped == count
        if self._current == count:
            self.reset_children()
            self._current = 0
            self._skipped = 0
        return SKIPPED if all_skipped else self._NEXT


class SequenceNode(_SequentialNode):
    """Tick children in order until one fails or is RUNNING; `AsyncSequence` when `asynch`."""

    _STOP = FAILURE
    _NEXT = SUCCESS


class SequenceWithMemory(_SequentialNode):
    """A sequence that resumes at the child that was running or failed, even after a halt."""

    _STOP = FAILURE
    _NEXT = SUCCESS
    _MEMORY = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)


class FallbackNode(_SequentialNode):
    """Tick children in order until one succeeds or is RUNNING; `AsyncFallback` when `asynch`."""

    _STOP = SUCCESS
    _NEXT = FAILURE


class _ReactiveBase(ControlNode):
    """Shared tick of ReactiveSequence (stop on FAILURE) and ReactiveFallback (stop on SUCCESS)."""

    _STOP: ClassVar[NodeStatus]
    _OTHERWISE: ClassVar[NodeStatus]
    settles = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._running_child = -1

    def halt(self) -> None:
        """Forget the running child."""
        self._running_child = -1
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick every child from the first; a RUNNING child halts all the others."""
        all_skipped = True
        own = self._status
        if own is IDLE:
            self._running_child = -1
        if own is not RUNNING:
            self.set_status(RUNNING)
        children = self.children
        for index, child in enumerate(children):
            status = child.execute_tick()
            all_skipped = all_skipped and status is SKIPPED
            if status is RUNNING:
                for other in range(len(children)):
                    if other != index:
                        self.halt_child(other)
                if self._running_child == -1:
                    self._running_child = index
                return RUNNING
            if status is self._STOP:
                self.reset_children()
                return status
            if status is SKIPPED:
                self.halt_child(index)
            elif status is IDLE:
                raise _idle_child(self)
        self.reset_children()
        return SKIPPED if all_skipped else self._OTHERWISE


class ReactiveSequence(_ReactiveBase):
    """Re-tick all children every tick; FAILURE of any child fails the sequence."""

    _STOP = FAILURE
    _OTHERWISE = SUCCESS


class ReactiveFallback(_ReactiveBase):
    """Re-tick all children every tick; SUCCESS of any child succeeds the fallback."""

    _STOP = SUCCESS
    _OTHERWISE = FAILURE


class ParallelNode(ControlNode):
    """Tick all children; succeed after `success_count` successes, fail after `failure_count` failures.

    Negative counts mean "all children but |n| - 1" (-1: all).
    """

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """success_count (default -1, all) and failure_count (default 1)."""
        return (
            input_port("success_count", int, -1, "number of children that need to succeed to trigger a SUCCESS"),
            input_port("failure_count", int, 1, "number of children that need to fail to trigger a FAILURE"),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._success_threshold = -1
        self._failure_threshold = 1
        self._completed: set[int] = set()
        self._success_count = 0
        self._failure_count = 0

    def _threshold(self, value: int) -> int:
        return max(len(self.children) + value + 1, 0) if value < 0 else value

    def _clear(self) -> None:
        self._completed.clear()
        self._success_count = 0
        self._failure_count = 0

    def halt(self) -> None:
        """Forget the completed children."""
        self._clear()
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick the children that have not completed, checking the thresholds after each."""
        ok, value = self.read_input("success_count")
        if not ok:
            raise TreeError(f"Missing parameter [success_count] in ParallelNode: {value}")
        self._success_threshold = int(value)
        ok, value = self.read_input("failure_count")
        if not ok:
            raise TreeError(f"Missing parameter [failure_count] in ParallelNode: {value}")
        self._failure_threshold = int(value)
        children = self.children
        count = len(children)
        required_success = self._threshold(self._success_threshold)
        required_failure = self._threshold(self._failure_threshold)
        if count < required_success:
            raise TreeError("Number of children is less than threshold. Can never succeed.")
        if count < required_failure:
            raise TreeError("Number of children is less than threshold. Can never fail.")
        if not self.btcpp3:  # BT.CPP 3.8's Parallel is RUNNING only once its children were ticked
            self.set_status(RUNNING)
        skipped = 0
        for index, child in enumerate(children):
            if index not in self._completed:
                status = child.execute_tick()
                if status is SKIPPED:
                    skipped += 1
                elif status is SUCCESS:
                    self._completed.add(index)
                    self._success_count += 1
                elif status is FAILURE:
                    self._completed.add(index)
                    self._failure_count += 1
                elif status is IDLE:
                    raise _idle_child(self)
            if self._success_count >= required_success or (
                self._success_threshold < 0 and self._success_count + skipped >= required_success
            ):
                self._clear()
                self.reset_children()
                return SUCCESS
            if count - self._failure_count < required_success or self._failure_count == required_failure:
                self._clear()
                self.reset_children()
                return FAILURE
        return SKIPPED if skipped == count else RUNNING


class ParallelAllNode(ControlNode):
    """Tick all children until every one completed; FAILURE if at least `max_failures` failed."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """max_failures (default 1)."""
        return (
            input_port(
                "max_failures",
                int,
                1,
                "If the number of children returning FAILURE exceeds this value, ParallelAll returns FAILURE",
            ),
        )

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._completed: set[int] = set()
        self._failure_count = 0
        self._failure_threshold = 1

    def halt(self) -> None:
        """Forget the completed children."""
        self._completed.clear()
        self._failure_count = 0
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick the children that have not completed."""
        ok, value = self.read_input("max_failures")
        if not ok:
            raise TreeError(f"Missing parameter [max_failures] in ParallelNode: {value}")
        children = self.children
        count = len(children)
        max_failures = int(value)
        self._failure_threshold = max(count + max_failures + 1, 0) if max_failures < 0 else max_failures
        if count < self._failure_threshold:
            raise TreeError("Number of children is less than threshold. Can never fail.")
        self.set_status(RUNNING)
        skipped = 0
        for index, child in enumerate(children):
            if index in self._completed:
                continue
            status = child.execute_tick()
            if status is SUCCESS:
                self._completed.add(index)
            elif status is FAILURE:
                self._completed.add(index)
                self._failure_count += 1
            elif status is SKIPPED:
                skipped += 1
            elif status is IDLE:
                raise _idle_child(self)
        if skipped == count:
            return SKIPPED
        if skipped + len(self._completed) >= count:
            self.halt_children()
            self._completed.clear()
            status = FAILURE if self._failure_count >= self._failure_threshold else SUCCESS
            self._failure_count = 0
            return status
        return RUNNING


class IfThenElseNode(ControlNode):
    """Condition, then-branch, optional else-branch; the condition is not re-checked while a branch runs."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._child_index = 0

    def halt(self) -> None:
        """Start with the condition next time."""
        self._child_index = 0
        super().halt()

    def tick(self) -> NodeStatus:
        """Tick the condition (unless a branch is running), then the branch."""
        children = self.children
        count = len(children)
        if count not in (2, 3):
            raise TreeError("IfThenElseNode must have either 2 or 3 children")
        self.set_status(RUNNING)
        if self._child_index == 0:
            condition = children[0].execute_tick()
            if condition is RUNNING:
                return RUNNING
            if condition is SUCCESS:
                self._child_index = 1
            elif condition is FAILURE:
                if count == 3:
                    self._child_index = 2
                else:
                    return FAILURE
        if self._child_index > 0:
            status = children[self._child_index].execute_tick()
            if status is RUNNING:
                return RUNNING
            self.reset_children()
            self._child_index = 0
            return status
        raise TreeError("Something unexpected happened in IfThenElseNode")


class WhileDoElseNode(ControlNode):
    """Re-check the condition every tick; run DO while it holds, ELSE (halting DO) when it does not."""

    def tick(self) -> NodeStatus:
        """Tick the condition, then the matching branch."""
        children = self.children
        count = len(children)
        if count not in (2, 3):
            raise TreeError("WhileDoElseNode must have either 2 or 3 children")
        self.set_status(RUNNING)
        condition = children[0].execute_tick()
        if condition is RUNNING:
            return RUNNING
        status = IDLE
        if condition is SUCCESS:
            if count == 3:
                self.halt_child(2)
            status = children[1].execute_tick()
        elif condition is FAILURE:
            if count == 3:
                self.halt_child(1)
                status = children[2].execute_tick()
            else:
                status = FAILURE
        if status is RUNNING:
            return RUNNING
        self.reset_children()
        return status


def _check_string_equality(left: str, right: str, enums: dict[str, int] | None) -> bool:
    """BT.CPP's Switch comparison: as strings, then as integers (prefix), then as reals."""
    if left == right:
        return True

    def as_int(text: str) -> int | None:
        if enums and text in enums:
            return enums[text]
        try:
            return int(parse_string(text, PortType.INT))
        except ValueError:
            return None

    left_int, right_int = as_int(left), as_int(right)
    if left_int is not None and right_int is not None and left_int == right_int:
        return True
    try:
        return abs(from_chars_double(left) - from_chars_double(right)) <= 1.1920928955078125e-07
    except ValueError:
        return False


class SwitchNode(ControlNode):
    """Tick the child whose `case_N` equals `variable`, or the last (default) child."""

    NUM_CASES: ClassVar[int] = 2

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Variable and case_1 … case_N (strings)."""
        return (input_port("variable", str), *(input_port(f"case_{i}", str) for i in range(1, cls.NUM_CASES + 1)))

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._running_child = -1
        self._case_keys = tuple(f"case_{i}" for i in range(1, self.NUM_CASES + 1))

    def halt(self) -> None:
        """Forget the running child."""
        self._running_child = -1
        super().halt()

    def tick(self) -> NodeStatus:
        """Select the child, halt a previously running other one, tick the selected child."""
        cases = self.NUM_CASES
        if len(self.children) != cases + 1:
            raise TreeError("Wrong number of children in SwitchNode; must be (num_cases + default)")
        match = cases
        ok, variable = self.read_input("variable", PortType.STRING)
        if ok:
            enums = dict(self._config.enums)
            for index, key in enumerate(self._case_keys):
                case_ok, value = self.read_input(key, PortType.STRING)
                if case_ok and _check_string_equality(variable, value, enums):
                    match = index
                    break
        if self._running_child not in (-1, match):
            self.halt_child(self._running_child)
        status = self.children[match].execute_tick()
        if status is SKIPPED:
            self._running_child = -1
            return SKIPPED
        if status is RUNNING:
            self._running_child = match
        else:
            self.reset_children()
            self._running_child = -1
        return status


def switch_node_type(cases: int) -> type[SwitchNode]:
    """The class of `Switch<cases>` (BT.CPP registers Switch2 … Switch6)."""
    return type(f"Switch{cases}", (SwitchNode,), {"NUM_CASES": cases, "__doc__": SwitchNode.__doc__})
