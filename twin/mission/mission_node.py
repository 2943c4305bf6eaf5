"""The mission as a node: the thesis's autonomy node, ticking its tree and commanding the robot.

It steers on the pose the robot believes it has (the latest `/odom`, or the map pose when AMCL
runs), publishes `/cmd_vel` at its controller rate and, for a behaviour-tree mission, ticks the
tree at its own rate and publishes the tree's status changes on `/behavior_tree_log` and each new
plan on `/plan`. When Nav2's stack carries out the goals, the mission publishes no command and no
plan (Nav2's servers do), and its tree's log goes to `/mission/behavior_tree_log`, beside
bt_navigator's `/behavior_tree_log`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from twin.bag import BehaviorTreeLogEncoder, PathEncoder, TwistEncoder
from twin.node import PRIORITY_COMMAND, PRIORITY_TREE, Encoded, Node
from twin.node.readers import odometry_pose

__all__ = ["MissionLike", "MissionNode", "TreeMissionLike"]


class MissionLike(Protocol):
    """A mission the node asks for a command at its rate."""

    done: bool
    result: str

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float] | None:
        """Return (linear m/s, angular rad/s) for now, or None when there is nothing new to send."""
        ...


class _StatusChange(Protocol):
    t_ns: int
    uid: int

    @property
    def prev(self) -> Any: ...

    @property
    def new(self) -> Any: ...


class _Navigator(Protocol):
    plans: int
    path: Sequence[tuple[float, float]]


class TreeMissionLike(MissionLike, Protocol):
    """A behaviour-tree mission: ticked at its own rate, with a navigator that plans."""

    navigator: _Navigator

    def tick(self, t_ns: int) -> Sequence[_StatusChange]:
        """Tick the tree; return the status changes since the last tick."""
        ...

    def node_name(self, uid: int) -> str:
        """The tree node's name for the log."""
        ...


class MissionNode(Node):
    """Commands `/cmd_vel` from a mission; ticks a tree mission and logs it (see the module docstring).

    Args:
        mission: The mission object.
        initial_pose: The pose believed until the first `/odom` message.
        command_rate_hz: Rate of `/cmd_vel`.
        tree_rate_hz: Tick rate of a tree mission (None for other missions).
        ready: For a tree mission, whether it may start: the thesis starts its autonomy node once
            Nav2 runs and AMCL has its initial pose, so the tree's first tick waits for this.
    """

    def __init__(
        self,
        mission: MissionLike,
        *,
        initial_pose: tuple[float, float, float],
        command_rate_hz: float | None,
        tree_rate_hz: float | None = None,
        bt_log_topic: str = "behavior_tree_log",
        pose_source: Callable[[], tuple[float, float, float]] | None = None,
        ready: Callable[[], bool] | None = None,
    ) -> None:
        super().__init__("mission")
        self._ready = ready
        self.mission = mission
        pose = list(initial_pose)

        def on_odom(msg: Any) -> None:
            if type(msg) is Encoded:
                pose[0], pose[1], pose[2] = msg[2][:3]
            else:
                pose[0], pose[1], pose[2] = odometry_pose(msg)

        if tree_rate_hz is not None:
            self._add_tree(mission, tree_rate_hz, bt_log_topic)  # type: ignore[arg-type]
        if command_rate_hz is None:  # Nav2 drives the robot; the mission only sends goals
            return
        cmd_pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode
        command = mission.command

        def on_timer(t_ns: int) -> None:
            if pose_source is not None:
                pose[0], pose[1], pose[2] = pose_source()
            cmd = command(t_ns, pose[0], pose[1], pose[2])
            if cmd is not None:  # None: nothing new to send (a replay sends each recorded command once)
                cmd_pub.publish(Encoded((encode, cmd, cmd)))

        self.create_rate_timer(command_rate_hz, on_timer, priority=PRIORITY_COMMAND)
        self.create_subscription("nav_msgs/msg/Odometry", "odom", on_odom, 10, raw=True)

    def _add_tree(self, mission: TreeMissionLike, rate_hz: float, bt_log_topic: str) -> None:
        bt_pub = self.create_publisher(BehaviorTreeLogEncoder.msgtype, bt_log_topic, 10)
        bt_encode = BehaviorTreeLogEncoder().encode
        plan_pub = self.create_publisher(PathEncoder.msgtype, "plan", 10)
        plan_encode = PathEncoder("map").encode
        navigator = mission.navigator
        plans = [0]
        ready = self._ready
        waiting = [False]

        def tick(t_ns: int) -> None:
            if ready is not None and not ready():
                if not waiting[0]:
                    waiting[0] = True
                    self.get_logger().info("waiting for the robot's map pose (AMCL's initial pose) to start")
                return
            changes = mission.tick(t_ns)
            if changes:
                events = [(c.t_ns, mission.node_name(c.uid), c.prev.name, c.new.name) for c in changes]
                bt_pub.publish(Encoded((bt_encode, (t_ns, events), events)))
            if navigator.plans != plans[0]:
                plans[0] = navigator.plans
                if navigator.path:
                    poses = [(x, y, 0.0) for x, y in navigator.path]
                    plan_pub.publish(Encoded((plan_encode, (t_ns, poses), poses)))

        self.create_rate_timer(rate_hz, tick, priority=PRIORITY_TREE)
