"""nav2_behavior_tree's control nodes: `PipelineSequence`, `RecoveryNode`, `RoundRobin`, `RateController`.

They are pure control flow, as Nav2 implements them, with `RateController` on the tree's simulation
clock.
"""

from __future__ import annotations

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.node import ControlNode, DecoratorNode, NodeConfig
from twin.bt.ports import PortSpec, input_port
from twin.bt.status import FAILURE, RUNNING, SKIPPED, SUCCESS, NodeStatus
from twin.core.errors import TreeError

__all__ = [
    "PipelineSequence",
    "RateController",
    "RecoveryNode",
    "RoundRobinNode",
    "register_nav2_controls",
]


class PipelineSequence(ControlNode):
    """Tick children in order every tick; earlier children keep being re-ticked while a later one runs."""

    settles = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._last_child_ticked = 0

    def tick(self) -> NodeStatus:
        """Tick from the first child up to the furthest one that was RUNNING."""
        skipped = 0
        children = self.children
        for index, child in enumerate(children):
            status = child.execute_tick()
            if status is FAILURE:
                self.halt_children()
                self._last_child_ticked = 0
                return FAILURE
            if status is SKIPPED:
                skipped += 1
            elif status is RUNNING:
                if index >= self._last_child_ticked:
                    self._last_child_ticked = index
                    return RUNNING
            elif status is not SUCCESS:
                msg = f"Invalid node status. Received status {status.name} from child {child.name}"
                raise TreeError(msg)
        self.halt_children()
        self._last_child_ticked = 0
        return SKIPPED if skipped == len(children) else SUCCESS

    def halt(self) -> None:
        """Start from the first child next time."""
        super().halt()
        self._last_child_ticked = 0


class RecoveryNode(ControlNode):
    """Two children: the action, and a recovery ticked when the action fails, up to `number_of_retries`."""

    settles = True

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """number_of_retries (default 1)."""
        return (input_port("number_of_retries", int, 1, "Number of retries"),)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._current = 0
        self._number_of_retries = 1
        self._retry_count = 0

    def tick(self) -> NodeStatus:
        """Tick the action; on failure tick the recovery, then the action again."""
        ok, value = self.read_input("number_of_retries")
        if ok:
            self._number_of_retries = int(value)
        children = self.children
        if len(children) != 2:
            msg = f"Recovery Node '{self.name}' must only have 2 children."
            raise TreeError(msg)
        self.set_status(RUNNING)
        while self._current < 2 and self._retry_count <= self._number_of_retries:
            status = children[self._current].execute_tick()
            if self._current == 0:
                if status is SKIPPED:
                    self.halt()
                    return SKIPPED
                if status is SUCCESS:
                    self.halt_child(1)
                    self.halt()
                    return SUCCESS
                if status is RUNNING:
                    return RUNNING
                if status is FAILURE:
                    if self._retry_count < self._number_of_retries:
                        self.halt_child(0)
                        self._current += 1
                        continue
                    self.halt()
                    return FAILURE
                raise TreeError("A child node must never return IDLE")
            if status is SKIPPED:
                self._current = 0
                self.halt_child(1)
                return FAILURE
            if status is RUNNING:
                return RUNNING
            if status is SUCCESS:
                self.halt_child(1)
                self._retry_count += 1
                self._current = 0
                continue
            if status is FAILURE:
                self.halt()
                return FAILURE
            raise TreeError("A child node must never return IDLE")
        self.halt()
        return FAILURE

    def halt(self) -> None:
        """Reset the retry count."""
        super().halt()
        self._retry_count = 0
        self._current = 0


class RoundRobinNode(ControlNode):
    """Tick one child per activation, moving on to the next after it completes; SUCCESS on any success."""

    settles = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._current = 0
        self._failed = 0

    def tick(self) -> NodeStatus:
        """Tick children from the current one until one succeeds or all have failed."""
        children = self.children
        count = len(children)
        self.set_status(RUNNING)
        skipped = 0
        while self._failed + skipped < count:
            status = children[self._current].execute_tick()
            if status is not RUNNING:
                self._current += 1
                if self._current == count:
                    self._current = 0
            if status is SUCCESS:
                self._failed = 0
                self.halt_children()
                return SUCCESS
            if status is FAILURE:
                self._failed += 1
            elif status is SKIPPED:
                skipped += 1
            elif status is RUNNING:
                return RUNNING
            else:
                raise TreeError("Invalid status return from BT node")
        all_skipped = skipped == count
        self.halt()
        return SKIPPED if all_skipped else FAILURE

    def halt(self) -> None:
        """Start from the first child next time."""
        super().halt()
        self._current = 0
        self._failed = 0


class RateController(DecoratorNode):
    """Tick the child at most `hz` times per second of simulation time (and always while it runs)."""

    settles = True

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """Hz (default 10)."""
        return (input_port("hz", float, 10.0, "Rate"),)

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._period_ns = 100_000_000
        self._start_ns = 0
        self._first_time = False

    def tick(self) -> NodeStatus:
        """Tick the child the first time, while it runs, and when a period has passed since it succeeded."""
        if not self._status.is_active:
            ok, hz = self.read_input("hz")
            rate_hz = float(hz) if ok else 1.0
            self._period_ns = round(1e9 / rate_hz) if rate_hz > 0 else 0
            self._start_ns = self.now_ns()
            self._first_time = True
        self.set_status(RUNNING)
        elapsed_ns = self.now_ns() - self._start_ns
        child = self.child
        if self._first_time or child._status is RUNNING or elapsed_ns >= self._period_ns:
            self._first_time = False
            status = child.execute_tick()
            if status is SUCCESS:
                self._start_ns = self.now_ns()
            return status
        return self._status

    def wake_ns(self) -> int | None:
        """When the period since the child last succeeded is over (the child is ticked again)."""
        return self._start_ns + self._period_ns if self._status is RUNNING else None


def register_nav2_controls(factory: BehaviorTreeFactory) -> None:
    """Register PipelineSequence, RecoveryNode, RoundRobin and RateController."""
    factory.register_node_type(PipelineSequence, "PipelineSequence")
    factory.register_node_type(RecoveryNode, "RecoveryNode")
    factory.register_node_type(RoundRobinNode, "RoundRobin")
    factory.register_node_type(RateController, "RateController")
