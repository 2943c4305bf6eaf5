"""Nav2 Humble's BT leaves as its `nav2_tree_nodes.xml` lists them: each action, condition and decorator with its ports.

The leaves the twin implements (`leaves`) take their ports from here; `declare_nav2_leaves` declares
every leaf (ports known, no implementation) so that any Nav2 tree validates and shows.
"""

from __future__ import annotations

from typing import Final

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.ports import PortSpec, input_port, output_port
from twin.bt.status import NodeKind

__all__ = ["NAV2_DECORATORS", "NAV2_LEAVES", "declare_nav2_leaves"]


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
    "Wait": (
        NodeKind.ACTION,
        (
            input_port("wait_duration", float, 1.0, "Wait time"),
            output_port("error_code_id", description="The wait behavior error code"),
            output_port("error_msg", description="The wait behavior error message"),
            *_BASIC_ACTION_PORTS,
        ),
    ),
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
            output_port("error_code_id", description="The compute path through poses error code"),
            output_port("error_msg", description="The compute path through poses error message"),
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
            output_port("error_code_id", description="The drive on heading behavior error code"),
            output_port("error_msg", description="The drive on heading behavior error message"),
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


# Nav2's decorators other than RateController (implemented in `twin.nav.bt_navigator.leaves`).
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


def declare_nav2_leaves(factory: BehaviorTreeFactory) -> None:
    """Declare Nav2's navigator leaves (ports known, no implementation) unless already registered."""
    for node_id, (kind, ports) in NAV2_LEAVES.items():
        if node_id not in factory.manifests:
            factory.declare_node_type(node_id, kind, ports, description="a Nav2 node")
    for node_id, ports in NAV2_DECORATORS.items():
        if node_id not in factory.manifests:
            factory.declare_node_type(node_id, NodeKind.DECORATOR, ports, description="a Nav2 node")
