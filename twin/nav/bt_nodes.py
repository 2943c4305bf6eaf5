"""Nav2's behaviour-tree nodes for the twin's BT engine, registered as BT.CPP plugins register them.

`PipelineSequence`, `RecoveryNode`, `RoundRobin` and `RateController` are pure control flow, as
Nav2 implements them, with `RateController` on the tree's simulation clock.

The action, condition and decorator leaves of Nav2 Humble's navigator trees (`ComputePathToPose`,
`FollowPath`, `Spin`, `GoalUpdated`, `DistanceController`, ...) carry Nav2's ports and semantics and
talk to the navigation servers through `NavigationServices` (`twin.nav.bt_leaves`), so the node
graph wires the real planner, controller and behaviour servers and tests wire fakes.

- `nav2_factory(services=None)`: a factory with the controls, and the leaves implemented against
  `services` (None: declared with their ports only, enough to validate and show a tree).
- `register_nav2_controls(factory)`, `declare_nav2_leaves(factory)`: the two halves on their own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.node import ControlNode, DecoratorNode, NodeConfig
from twin.bt.ports import PortSpec, input_port, output_port
from twin.bt.status import FAILURE, RUNNING, SKIPPED, SUCCESS, NodeKind, NodeStatus
from twin.core.errors import TreeError

if TYPE_CHECKING:
    from twin.nav.bt_leaves import NavigationServices

__all__ = [
    "NAV2_DECORATORS",
    "NAV2_LEAVES",
    "PipelineSequence",
    "RateController",
    "RecoveryNode",
    "RoundRobinNode",
    "declare_nav2_leaves",
    "nav2_factory",
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
    "ComputePathThroughPoses": (
        NodeKind.ACTION,
        (
            input_port("goals", description="Destinations to plan through"),
            input_port("start", description="Start pose of the path instead of the robot's pose"),
            input_port("planner_id", str, "", "Mapped name to the planner plugin type to use"),
            output_port("path", description="Path created by ComputePathThroughPoses node"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "SmoothPath": (
        NodeKind.ACTION,
        (
            input_port("smoother_id", str, "SmoothPath"),
            input_port("unsmoothed_path", description="Path to be smoothed"),
            input_port("max_smoothing_duration", float, 3.0, "Maximum smoothing duration"),
            input_port("check_for_collisions", bool, False, "If true collision check will be performed"),
            output_port("smoothed_path", description="Path smoothed by SmootherServer node"),
            output_port("smoothing_duration", description="Time taken to smooth path"),
            output_port("was_completed", description="True if smoothing was not interrupted by time limit"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "DriveOnHeading": (
        NodeKind.ACTION,
        (
            input_port("dist_to_travel", float, 0.15, "Distance to travel"),
            input_port("speed", float, 0.025, "Speed at which to travel"),
            input_port("time_allowance", float, 10.0, "Allowed time for driving on heading"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    "AssistedTeleop": (
        NodeKind.ACTION,
        (
            input_port("time_allowance", float, 10.0, "Allowed time for running assisted teleop"),
            input_port("is_recovery", bool, False, "If true the recovery count will be incremented"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
    **{
        name: (NodeKind.ACTION, _BASIC_ACTION_PORTS)
        for name in (
            "CancelControl",
            "CancelBackUp",
            "CancelDriveOnHeading",
            "CancelSpin",
            "CancelWait",
            "CancelAssistedTeleop",
        )
    },
    "ClearCostmapAroundRobot": (
        NodeKind.ACTION,
        (
            input_port("service_name", str, description="Costmap clearing service"),
            input_port("server_timeout", description="Timeout (ms) waiting for the service"),
            input_port("reset_distance", float, 1.0, "Distance from the robot within which to clear"),
        ),
    ),
    "ClearCostmapExceptRegion": (
        NodeKind.ACTION,
        (
            input_port("service_name", str, description="Costmap clearing service"),
            input_port("server_timeout", description="Timeout (ms) waiting for the service"),
            input_port("reset_distance", float, 1.0, "Distance from the robot beyond which to clear"),
        ),
    ),
    "ReinitializeGlobalLocalization": (
        NodeKind.ACTION,
        (
            input_port("service_name", str, description="Service name"),
            input_port("server_timeout", description="Timeout (ms) waiting for the service"),
        ),
    ),
    "NavigateToPose": (
        NodeKind.ACTION,
        (input_port("goal"), input_port("behavior_tree", str, ""), *_BASIC_ACTION_PORTS),
    ),
    "NavigateThroughPoses": (
        NodeKind.ACTION,
        (input_port("goals"), input_port("behavior_tree", str, ""), *_BASIC_ACTION_PORTS),
    ),
    "TruncatePath": (
        NodeKind.ACTION,
        (
            input_port("distance", float, 1.0, "Distance before goal to truncate"),
            input_port("input_path", description="Original Path"),
            output_port("output_path", description="Path truncated to a certain distance"),
        ),
    ),
    "TruncatePathLocal": (
        NodeKind.ACTION,
        (
            input_port("distance_forward", float, 8.0, "Distance in forward direction"),
            input_port("distance_backward", float, 4.0, "Distance in backward direction"),
            input_port("robot_frame", str, "base_link"),
            input_port("transform_tolerance", float, 0.2),
            input_port("pose", description="Manually specified pose to be used"),
            input_port("angular_distance_weight", float, 0.0),
            input_port("max_robot_pose_search_dist", float, float("inf")),
            input_port("input_path", description="Original Path"),
            output_port("output_path", description="Path truncated around the robot"),
        ),
    ),
    "RemovePassedGoals": (
        NodeKind.ACTION,
        (
            input_port("input_goals", description="Original goals to remove viapoints from"),
            input_port("radius", float, 0.5, "Radius tolerance on a goal to consider it passed"),
            input_port("global_frame", str, "map"),
            input_port("robot_base_frame", str, "base_link"),
            output_port("output_goals", description="Goals with passed viapoints removed"),
        ),
    ),
    "GoalCheckerSelector": (
        NodeKind.ACTION,
        (
            input_port("default_goal_checker", str, description="the default goal_checker to use"),
            input_port("topic_name", str, "goal_checker_selector"),
            output_port("selected_goal_checker", str, description="Selected goal_checker by subscription"),
        ),
    ),
    "SmootherSelector": (
        NodeKind.ACTION,
        (
            input_port("default_smoother", str, description="the default smoother to use"),
            input_port("topic_name", str, "smoother_selector"),
            output_port("selected_smoother", str, description="Selected smoother by subscription"),
        ),
    ),
    "ProgressCheckerSelector": (
        NodeKind.ACTION,
        (
            input_port("default_progress_checker", str, description="the default progress_checker to use"),
            input_port("topic_name", str, "progress_checker_selector"),
            output_port("selected_progress_checker", str, description="Selected progress_checker by subscription"),
        ),
    ),
    "GlobalUpdatedGoal": (NodeKind.CONDITION, (input_port("goals"), input_port("goal"))),
    "GoalReached": (
        NodeKind.CONDITION,
        (
            input_port("goal", description="Destination"),
            input_port("global_frame", str, "map"),
            input_port("robot_base_frame", str, "base_link"),
        ),
    ),
    "IsStuck": (NodeKind.CONDITION, ()),
    "IsPathValid": (
        NodeKind.CONDITION,
        (input_port("path", description="Path to Check"), input_port("server_timeout")),
    ),
    "InitialPoseReceived": (NodeKind.CONDITION, ()),
    "TimeExpired": (NodeKind.CONDITION, (input_port("seconds", float, 1.0, "Seconds"),)),
    "PathExpiringTimer": (
        NodeKind.CONDITION,
        (
            input_port("seconds", float, 1.0, "Seconds"),
            input_port("path", description="Check if path has been updated"),
        ),
    ),
    "DistanceTraveled": (
        NodeKind.CONDITION,
        (
            input_port("distance", float, 1.0, "Distance"),
            input_port("global_frame", str, "map"),
            input_port("robot_base_frame", str, "base_link"),
        ),
    ),
    "TransformAvailable": (NodeKind.CONDITION, (input_port("child", str, ""), input_port("parent", str, ""))),
    "IsBatteryLow": (
        NodeKind.CONDITION,
        (
            input_port("min_battery", float, 0.0),
            input_port("battery_topic", str, "/battery_status"),
            input_port("is_voltage", bool, False),
        ),
    ),
    "IsBatteryCharging": (NodeKind.CONDITION, (input_port("battery_topic", str, "/battery_status"),)),
    "WouldAControllerRecoveryHelp": (NodeKind.CONDITION, (input_port("error_code", description="Error code"),)),
    "WouldAPlannerRecoveryHelp": (NodeKind.CONDITION, (input_port("error_code", description="Error code"),)),
}


# Nav2's decorators other than RateController (implemented in `twin.nav.bt_leaves`).
NAV2_DECORATORS: Final[dict[str, tuple[PortSpec, ...]]] = {
    "DistanceController": (
        input_port("distance", float, 1.0, "Distance"),
        input_port("global_frame", str, "map"),
        input_port("robot_base_frame", str, "base_link"),
    ),
    "SpeedController": (
        input_port("min_rate", float, 0.1, "Minimum rate"),
        input_port("max_rate", float, 1.0, "Maximum rate"),
        input_port("min_speed", float, 0.0, "Minimum speed"),
        input_port("max_speed", float, 0.5, "Maximum speed"),
        input_port("filter_duration", float, 0.3, "Duration (secs) for velocity smoothing filter"),
    ),
    "GoalUpdater": (input_port("input_goal", description="Original Goal"), output_port("output_goal")),
    "SingleTrigger": (),
    "PathLongerOnApproach": (
        input_port("path", description="Planned Path"),
        input_port("prox_len", float, 3.0, "Proximity length (m) for the path to be longer on approach"),
        input_port("length_factor", float, 2.0, "Length multiplication factor to check if the path is longer"),
    ),
    "GoalUpdatedController": (),
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
    for node_id, ports in NAV2_DECORATORS.items():
        if node_id not in factory.manifests:
            factory.declare_node_type(node_id, NodeKind.DECORATOR, ports, description="a Nav2 node")


def nav2_factory(services: NavigationServices | None = None) -> BehaviorTreeFactory:
    """A factory with BT.CPP's built-ins, Nav2's controls, and Nav2's leaves.

    Args:
        services: The navigation servers the leaves call; None declares the leaves with their
            ports only (trees validate and show, but cannot be created).
    """
    factory = BehaviorTreeFactory()
    register_nav2_controls(factory)
    if services is not None:
        from twin.nav.bt_leaves import register_nav2_leaves

        register_nav2_leaves(factory, services)
    declare_nav2_leaves(factory)
    return factory
