"""Nav2's control-flow nodes, and the ports of the Nav2 leaves its navigator trees use.

`PipelineSequence`, `RecoveryNode`, `RoundRobin` and `RateController` are pure control flow; they
are implemented here as Nav2 (Jazzy, BT.CPP 4) implements them, with `RateController` on the
tree's simulation clock. Register them with `register_nav2_controls(factory)`.

The action and condition leaves (`ComputePathToPose`, `FollowPath`, `Spin`, ...) talk to Nav2's
servers. `declare_nav2_leaves(factory)` declares them with their ports, so Nav2 trees validate
and show; creating a tree that uses one fails until an implementation is registered under its
name (the navigation package provides them, and the benchmark registers stand-ins).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from twin.bt.node import ControlNode, DecoratorNode, NodeConfig
from twin.bt.ports import PortSpec, input_port, output_port
from twin.bt.status import FAILURE, RUNNING, SKIPPED, SUCCESS, NodeKind, NodeStatus
from twin.core.errors import TreeError

if TYPE_CHECKING:
    from twin.bt.factory import BehaviorTreeFactory

__all__ = [
    "NAV2_LEAVES",
    "PipelineSequence",
    "RateController",
    "RecoveryNode",
    "RoundRobinNode",
    "declare_nav2_leaves",
    "register_nav2_controls",
]


class PipelineSequence(ControlNode):
    """Tick children in order every tick; earlier children keep being re-ticked while a later one runs."""

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


_BASIC_ACTION_PORTS: Final = (
    input_port("server_name", str, description="Action server name"),
    input_port("server_timeout", description="Timeout (ms) waiting for the server"),
)

# Nav2's leaf nodes used by its navigator trees (Humble and Jazzy), with their ports.
NAV2_LEAVES: Final[dict[str, tuple[NodeKind, tuple[PortSpec, ...]]]] = {
    "ComputePathToPose": (
        NodeKind.ACTION,
        (
            input_port("goal", description="Destination to plan to"),
            input_port("start", description="Start pose of the path instead of the robot's pose"),
            input_port("use_start", bool, description="Use the start pose"),
            input_port("planner_id", str, "", "Mapped name to the planner plugin type to use"),
            output_port("path", description="Path created by ComputePathToPose node"),
            output_port("error_code_id", description="The compute path to pose error code"),
            output_port("error_msg", description="The compute path to pose error message"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "FollowPath": (
        NodeKind.ACTION,
        (
            input_port("path", description="Path to follow"),
            input_port("controller_id", str, ""),
            input_port("goal_checker_id", str, ""),
            input_port("progress_checker_id", str, ""),
            output_port("error_code_id", description="The follow path error code"),
            output_port("error_msg", description="The follow path error message"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "ClearEntireCostmap": (
        NodeKind.ACTION,
        (
            input_port("service_name", str, description="Costmap clearing service"),
            input_port("server_timeout", description="Timeout (ms) waiting for the service"),
        ),
    ),
    "Spin": (
        NodeKind.ACTION,
        (
            input_port("spin_dist", float, 1.57, "Spin distance"),
            input_port("time_allowance", float, 10.0, "Allowed time for spinning"),
            input_port("is_recovery", bool, True, "True if recovery"),
            output_port("error_code_id", description="The spin behavior error code"),
            output_port("error_msg", description="The spin behavior error message"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "Wait": (NodeKind.ACTION, (input_port("wait_duration", float, 1.0, "Wait time"), *_BASIC_ACTION_PORTS)),
    "BackUp": (
        NodeKind.ACTION,
        (
            input_port("backup_dist", float, 0.15, "Distance to backup"),
            input_port("backup_speed", float, 0.025, "Speed at which to backup"),
            input_port("time_allowance", float, 10.0, "Allowed time for reversing"),
            output_port("error_code_id", description="The back up behavior server error code"),
            output_port("error_msg", description="The back up behavior server error message"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "GoalUpdated": (
        NodeKind.CONDITION,
        (
            input_port("goals", description="Vector of navigation goals"),
            input_port("goal", description="Navigation goal"),
        ),
    ),
    "ControllerSelector": (
        NodeKind.ACTION,
        (
            input_port("default_controller", str, description="the default controller to use"),
            input_port("topic_name", str, "controller_selector", "the input topic name to select the controller"),
            output_port("selected_controller", str, description="Selected controller by subscription"),
        ),
    ),
    "PlannerSelector": (
        NodeKind.ACTION,
        (
            input_port("default_planner", str, description="the default planner to use"),
            input_port("topic_name", str, "planner_selector", "the input topic name to select the planner"),
            output_port("selected_planner", str, description="Selected planner by subscription"),
        ),
    ),
    "WouldAControllerRecoveryHelp": (NodeKind.CONDITION, (input_port("error_code", description="Error code"),)),
    "WouldAPlannerRecoveryHelp": (NodeKind.CONDITION, (input_port("error_code", description="Error code"),)),
}


def register_nav2_controls(factory: BehaviorTreeFactory) -> None:
    """Register PipelineSequence, RecoveryNode, RoundRobin and RateController."""
    factory.register_node_type(PipelineSequence, "PipelineSequence")
    factory.register_node_type(RecoveryNode, "RecoveryNode")
    factory.register_node_type(RoundRobinNode, "RoundRobin")
    factory.register_node_type(RateController, "RateController")


def declare_nav2_leaves(factory: BehaviorTreeFactory) -> None:
    """Declare Nav2's navigator leaves (ports known, no implementation) unless already registered."""
    for node_id, (kind, ports) in NAV2_LEAVES.items():
        if node_id not in factory.manifests:
            factory.declare_node_type(node_id, kind, ports, description="a Nav2 node")
