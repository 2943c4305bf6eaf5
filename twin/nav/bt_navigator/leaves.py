"""Nav2 Humble's behaviour-tree leaves, implemented against an abstract set of navigation servers.

Values on the blackboard: a pose is `(x_m, y_m, yaw_rad)` in the global frame (map); a path is an
`(N, 3)` float array of such poses; `goals` is a list of poses. The bt_navigator puts `goal` (or
`goals`) and `initial_pose_received` on the blackboard as Nav2 does.

Action leaves follow Nav2's `BtActionNode`: the first tick sends a goal to a server and, as a quick
server answers within the tick, polls it at once; later ticks poll; a halt cancels. Which server a
leaf talks to is its Nav2 default (`compute_path_to_pose`, `follow_path`, `spin`, `backup`, ...)
unless its `server_name` port names another. Service leaves (`ClearEntireCostmap`, ...) call once
and succeed when the call does.

`NavigationServices` is what the node graph implements (planner_server, controller_server,
behavior_server, smoother_server, the costmaps' clear services, the robot's pose and speed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.node import ConditionNode, DecoratorNode, NodeConfig, StatefulActionNode, SyncActionNode
from twin.bt.ports import PortSpec
from twin.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, NodeStatus
from twin.nav.actions import ActionState, ActionUpdate
from twin.nav.bt_navigator.tree_nodes import NAV2_DECORATORS, NAV2_LEAVES

__all__ = ["ActionState", "ActionUpdate", "NavigationServices", "register_nav2_leaves"]

Pose = tuple[float, float, float]


class NavigationServices(Protocol):
    """The Nav2 servers the leaves call. Server names are Nav2's action/service names.

    Action servers and their request fields:
      compute_path_to_pose {goal, start (None: robot pose), planner_id} -> result {path};
      compute_path_through_poses {goals, start, planner_id} -> {path};
      follow_path {path, controller_id, goal_checker_id}; smooth_path {path, smoother_id,
      max_smoothing_duration, check_for_collisions} -> {path, smoothing_duration, was_completed};
      spin {target_yaw, time_allowance}; backup {target_x, speed, time_allowance};
      drive_on_heading {target_x, speed, time_allowance}; wait {time_s};
      assisted_teleop {time_allowance}.

    `generation` counts every change a leaf could see through `poll` (a goal sent, updated, canceled
    or finished): the navigator skips ticks that would repeat themselves while it stays the same.
    """

    @property
    def generation(self) -> int:
        """A counter that changes whenever any goal's state or result does."""

    def send_goal(self, server: str, request: Mapping[str, Any]) -> int:
        """Send a goal; return its id."""

    def update_goal(self, goal_id: int, request: Mapping[str, Any]) -> None:
        """Give a running goal a new request (FollowPath with a new path: Nav2 preempts the goal)."""

    def poll(self, goal_id: int) -> ActionUpdate:
        """The goal's state now."""

    def cancel(self, goal_id: int) -> None:
        """Cancel a goal (the leaf was halted)."""

    def cancel_all(self, server: str) -> None:
        """Cancel every goal on a server (the Cancel* leaves)."""

    def call_service(self, service: str, request: Mapping[str, Any]) -> bool:
        """Call a service (costmap clearing, global localization); True on success."""

    def robot_pose(self) -> Pose:
        """The robot's pose in the global frame."""

    def robot_speed(self) -> float:
        """The robot's current linear speed, m/s (odometry)."""

    def is_path_valid(self, path: np.ndarray) -> bool:
        """planner_server's is_path_valid service: no lethal cell on the path."""

    def selection(self, topic: str) -> str | None:
        """The last string published on a selector topic, if any."""

    def updated_goal(self) -> Pose | None:
        """The last pose published on `goal_update` (GoalUpdater), if any since the last call."""

    def is_stuck(self) -> bool:
        """Whether the robot is stuck (Nav2's IsStuck: braking harder than it commands)."""


def _bb(node: Any, key: str) -> Any:
    try:
        return node.config.blackboard.get(key)
    except (KeyError, ValueError, LookupError):
        return None


def _same(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is b
    try:
        return bool(np.array_equal(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)))
    except (TypeError, ValueError):
        return bool(a == b)


def _input(node: Any, key: str, default: Any = None) -> Any:
    ok, value = node.read_input(key)
    return value if ok else default


def _path_length(path: Any) -> float:
    p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    return float(np.sum(np.hypot(*np.diff(p[:, :2], axis=0).T))) if len(p) > 1 else 0.0


class _ServerAction(StatefulActionNode):
    server = ""
    settles = True  # a RUNNING goal's poll changes only when the servers' `generation` does
    #: The action's UNKNOWN error code (nav2_msgs, Iron on), written to `error_code_id` when the
    #: server gives none; None: the leaf has no such port.
    unknown_code: int | None = None

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services
        self._goal_id: int | None = None

    def request(self) -> dict[str, Any]:
        """The request to send to the server, from the node's input ports (each leaf defines its own)."""
        msg = f"{type(self).__name__} does not say what it asks its server"
        raise TypeError(msg)

    def on_success(self, result: Mapping[str, Any]) -> None:
        """Write outputs from the result."""

    def _server(self) -> str:
        return str(_input(self, "server_name", None) or self.server)

    def on_start(self) -> NodeStatus:
        self._goal_id = self.services.send_goal(self._server(), self.request())
        return self._poll()

    def on_running(self) -> NodeStatus:
        return self._poll()

    def on_halted(self) -> None:
        if self._goal_id is not None:
            self.services.cancel(self._goal_id)
            self._goal_id = None

    def _poll(self) -> NodeStatus:
        assert self._goal_id is not None
        update = self.services.poll(self._goal_id)
        if update.state is ActionState.RUNNING:
            return RUNNING
        self._goal_id = None
        if update.state is ActionState.SUCCEEDED:
            self.on_success(update.result)
            if self.unknown_code is not None:
                self.set_output("error_code_id", 0)  # NONE
            return SUCCESS
        if self.unknown_code is not None:  # as Iron's leaves: the result's code, for WouldA...RecoveryHelp
            self.set_output("error_code_id", int((update.result or {}).get("error_code", self.unknown_code)))
        return FAILURE


class ComputePathToPose(_ServerAction):
    """Plan to `goal` with `planner_id`; the result goes to `path`."""

    server = "compute_path_to_pose"
    unknown_code = 200

    def request(self) -> dict[str, Any]:
        return {
            "goal": _input(self, "goal"),
            "start": _input(self, "start"),
            "planner_id": _input(self, "planner_id", ""),
        }

    def on_success(self, result: Mapping[str, Any]) -> None:
        self.set_output("path", result["path"])


class ComputePathThroughPoses(_ServerAction):
    """Plan through `goals`; the result goes to `path`."""

    server = "compute_path_through_poses"
    unknown_code = 300

    def request(self) -> dict[str, Any]:
        return {
            "goals": _input(self, "goals"),
            "start": _input(self, "start"),
            "planner_id": _input(self, "planner_id", ""),
        }

    def on_success(self, result: Mapping[str, Any]) -> None:
        self.set_output("path", result["path"])


class FollowPath(_ServerAction):
    """Follow `path` with `controller_id`; a new path on the blackboard updates the running goal."""

    server = "follow_path"
    unknown_code = 100

    def request(self) -> dict[str, Any]:
        self._sent_path = _input(self, "path")
        return {
            "path": self._sent_path,
            "controller_id": _input(self, "controller_id", "FollowPath"),
            "goal_checker_id": _input(self, "goal_checker_id", ""),
        }

    def on_running(self) -> NodeStatus:
        # a path written to the blackboard since the goal was sent (each replan writes a new one, and
        # Nav2's stamped paths always differ) is sent to the running goal, which Nav2 preempts
        path = _input(self, "path")
        if self._goal_id is not None and path is not self._sent_path:
            self.services.update_goal(self._goal_id, self.request())
        return self._poll()


class SmoothPath(_ServerAction):
    """Smooth `unsmoothed_path` into `smoothed_path`."""

    server = "smooth_path"

    def request(self) -> dict[str, Any]:
        return {
            "path": _input(self, "unsmoothed_path"),
            "smoother_id": _input(self, "smoother_id", "SmoothPath"),
            "max_smoothing_duration": _input(self, "max_smoothing_duration", 3.0),
            "check_for_collisions": _input(self, "check_for_collisions", False),
        }

    def on_success(self, result: Mapping[str, Any]) -> None:
        self.set_output("smoothed_path", result["path"])
        self.set_output("smoothing_duration", result.get("smoothing_duration", 0.0))
        self.set_output("was_completed", result.get("was_completed", True))


class Spin(_ServerAction):
    """Spin in place by `spin_dist` radians."""

    server = "spin"

    def request(self) -> dict[str, Any]:
        return {
            "target_yaw": float(_input(self, "spin_dist", 1.57)),
            "time_allowance": float(_input(self, "time_allowance", 10.0)),
        }


class BackUp(_ServerAction):
    """Back up `backup_dist` m at `backup_speed` m/s."""

    server = "backup"

    def request(self) -> dict[str, Any]:
        return {
            "target_x": float(_input(self, "backup_dist", 0.15)),
            "speed": float(_input(self, "backup_speed", 0.025)),
            "time_allowance": float(_input(self, "time_allowance", 10.0)),
        }


class DriveOnHeading(_ServerAction):
    """Drive straight `dist_to_travel` m at `speed` m/s."""

    server = "drive_on_heading"

    def request(self) -> dict[str, Any]:
        return {
            "target_x": float(_input(self, "dist_to_travel", 0.15)),
            "speed": float(_input(self, "speed", 0.025)),
            "time_allowance": float(_input(self, "time_allowance", 10.0)),
        }


class Wait(_ServerAction):
    """Wait `wait_duration` s (behavior_server's Wait)."""

    server = "wait"

    def request(self) -> dict[str, Any]:
        return {"time_s": float(_input(self, "wait_duration", 1.0))}


class AssistedTeleop(_ServerAction):
    """Nav2's assisted teleop behaviour."""

    server = "assisted_teleop"

    def request(self) -> dict[str, Any]:
        return {"time_allowance": float(_input(self, "time_allowance", 10.0))}


def _cancel_leaf(server_default: str) -> type[SyncActionNode]:
    class _Cancel(SyncActionNode):
        def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
            super().__init__(name, config)
            self.services = services

        def tick(self) -> NodeStatus:
            self.services.cancel_all(str(_input(self, "server_name", None) or server_default))
            return SUCCESS

    return _Cancel


class _ServiceCall(SyncActionNode):
    """Call a service once; SUCCESS when it succeeds."""

    clear_kind = "clear_entirely"

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services

    def tick(self) -> NodeStatus:
        service = str(_input(self, "service_name", ""))
        request = {"kind": self.clear_kind, "reset_distance": _input(self, "reset_distance", None)}
        return SUCCESS if self.services.call_service(service, request) else FAILURE


class ClearEntireCostmap(_ServiceCall):
    """Clear a whole costmap (`service_name`)."""

    clear_kind = "clear_entirely"


class ClearCostmapAroundRobot(_ServiceCall):
    """Clear a costmap within `reset_distance` of the robot."""

    clear_kind = "clear_around_robot"


class ClearCostmapExceptRegion(_ServiceCall):
    """Clear a costmap beyond `reset_distance` of the robot."""

    clear_kind = "clear_except_region"


class ReinitializeGlobalLocalization(_ServiceCall):
    """AMCL's reinitialize_global_localization service."""

    clear_kind = "reinitialize_global_localization"


class _Selector(SyncActionNode):
    default_port = ""
    output = ""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services

    def tick(self) -> NodeStatus:
        chosen = self.services.selection(str(_input(self, "topic_name", "")))
        self.set_output(self.output, chosen if chosen else _input(self, self.default_port, ""))
        return SUCCESS


def _selector(default_port: str, output: str) -> type[_Selector]:
    return type(f"Selector_{output}", (_Selector,), {"default_port": default_port, "output": output})


class TruncatePath(SyncActionNode):
    """Drop the poses within `distance` of the path's end (Nav2's TruncatePath)."""

    def tick(self) -> NodeStatus:
        path = np.asarray(_input(self, "input_path"), dtype=np.float64).reshape(-1, 3)
        distance = float(_input(self, "distance", 1.0))
        if len(path) == 0:
            self.set_output("output_path", path)
            return SUCCESS
        d = np.hypot(path[:, 0] - path[-1, 0], path[:, 1] - path[-1, 1])
        keep = np.nonzero(d >= distance)[0]
        self.set_output("output_path", path[: int(keep[-1]) + 1] if len(keep) else path[:1])
        return SUCCESS


class TruncatePathLocal(SyncActionNode):
    """Keep the part of the path from `distance_backward` behind to `distance_forward` ahead of the robot."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services

    def tick(self) -> NodeStatus:
        path = np.asarray(_input(self, "input_path"), dtype=np.float64).reshape(-1, 3)
        if len(path) == 0:
            return FAILURE
        x, y, _ = _input(self, "pose", None) or self.services.robot_pose()
        k = int(np.argmin(np.hypot(path[:, 0] - x, path[:, 1] - y)))
        seg = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path[:, :2], axis=0).T))])
        ahead = seg - seg[k]
        keep = (ahead <= float(_input(self, "distance_forward", 8.0))) & (
            ahead >= -float(_input(self, "distance_backward", 4.0))
        )
        self.set_output("output_path", path[keep])
        return SUCCESS


class RemovePassedGoals(SyncActionNode):
    """Drop the leading goals the robot is within `radius` of."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services

    def tick(self) -> NodeStatus:
        goals = list(_input(self, "input_goals") or [])
        radius = float(_input(self, "radius", 0.5))
        x, y, _ = self.services.robot_pose()
        while len(goals) > 1 and math.hypot(goals[0][0] - x, goals[0][1] - y) < radius:
            goals.pop(0)
        self.set_output("output_goals", goals)
        return SUCCESS


# -- conditions -----------------------------------------------------------------------------


class GoalUpdated(ConditionNode):
    """SUCCESS when the blackboard's `goal` or `goals` changed since the previous tick (FAILURE the first time)."""

    settles = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._seen: tuple[Any, Any] | None = None

    def tick(self) -> NodeStatus:
        current = (_bb(self, "goal"), _bb(self, "goals"))
        if self._seen is None:
            self._seen = current
            return FAILURE
        if not (_same(current[0], self._seen[0]) and _same(current[1], self._seen[1])):
            self._seen = current
            return SUCCESS
        return FAILURE


class GlobalUpdatedGoal(ConditionNode):
    """As GoalUpdated, but SUCCESS on its first tick (Nav2's GloballyUpdatedGoalCondition)."""

    settles = True

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._seen: tuple[Any, Any] | None = None

    def tick(self) -> NodeStatus:
        current = (_bb(self, "goal"), _bb(self, "goals"))
        if self._seen is None or not (_same(current[0], self._seen[0]) and _same(current[1], self._seen[1])):
            self._seen = current
            return SUCCESS
        return FAILURE


class _ServicesCondition(ConditionNode):
    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services


class GoalReached(_ServicesCondition):
    """SUCCESS when the robot is within 0.25 m (Nav2's goal_reached_tol) of `goal`."""

    tolerance_m = 0.25

    def tick(self) -> NodeStatus:
        goal = _input(self, "goal")
        if goal is None:
            return FAILURE
        x, y, _ = self.services.robot_pose()
        return SUCCESS if math.hypot(goal[0] - x, goal[1] - y) <= self.tolerance_m else FAILURE


class IsStuck(_ServicesCondition):
    """SUCCESS when the services report the robot stuck."""

    def tick(self) -> NodeStatus:
        return SUCCESS if self.services.is_stuck() else FAILURE


class IsPathValid(_ServicesCondition):
    """SUCCESS when planner_server finds no lethal cell on `path`."""

    def tick(self) -> NodeStatus:
        path = _input(self, "path")
        return SUCCESS if path is not None and self.services.is_path_valid(np.asarray(path)) else FAILURE


class _ErrorCodesPresent(ConditionNode):
    """Iron's AreErrorCodesPresent: SUCCESS when the `error_code` input is one of `codes`."""

    codes: frozenset[int] = frozenset()

    def tick(self) -> NodeStatus:
        code = _input(self, "error_code", None)
        return SUCCESS if code is not None and int(code) in self.codes else FAILURE


class WouldAPlannerRecoveryHelp(_ErrorCodesPresent):
    """A planner failure a cleared costmap may mend: UNKNOWN, NO_VALID_PATH or TIMEOUT (to pose or through poses)."""

    codes = frozenset({200, 208, 207, 300, 307, 308})


class WouldAControllerRecoveryHelp(_ErrorCodesPresent):
    """A controller failure a recovery may mend: UNKNOWN, PATIENCE_EXCEEDED, FAILED_TO_MAKE_PROGRESS, NO_VALID_CONTROL.

    (The twin's controllers report the first three; NO_VALID_CONTROL is Jazzy's.)
    """

    codes = frozenset({100, 104, 105, 106})


class InitialPoseReceived(ConditionNode):
    """SUCCESS when the blackboard's `initial_pose_received` is true."""

    settles = True

    def tick(self) -> NodeStatus:
        return SUCCESS if _bb(self, "initial_pose_received") else FAILURE


class TimeExpired(ConditionNode):
    """SUCCESS once every `seconds` of sim time (FAILURE on the first tick and in between)."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._start_ns: int | None = None

    def tick(self) -> NodeStatus:
        now = self.now_ns()
        if self._start_ns is None:
            self._start_ns = now
            return FAILURE
        if now - self._start_ns < round(float(_input(self, "seconds", 1.0)) * 1e9):
            return FAILURE
        self._start_ns = now
        return SUCCESS


class PathExpiringTimer(ConditionNode):
    """SUCCESS when `seconds` passed without a new `path` (restarts on a new path)."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._start_ns: int | None = None
        self._path: Any = None

    def tick(self) -> NodeStatus:
        now = self.now_ns()
        path = _input(self, "path")
        if self._start_ns is None or not _same(path, self._path):
            self._start_ns, self._path = now, path
            return FAILURE
        if now - self._start_ns < round(float(_input(self, "seconds", 1.0)) * 1e9):
            return FAILURE
        self._start_ns = now
        return SUCCESS


class DistanceTraveled(_ServicesCondition):
    """SUCCESS each time the robot has moved `distance` m from where it last succeeded (FAILURE first)."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config, services)
        self._start: Pose | None = None

    def tick(self) -> NodeStatus:
        pose = self.services.robot_pose()
        if self._start is None:
            self._start = pose
            return FAILURE
        if math.hypot(pose[0] - self._start[0], pose[1] - self._start[1]) < float(_input(self, "distance", 1.0)):
            return FAILURE
        self._start = pose
        return SUCCESS


class _Constant(ConditionNode):
    result = SUCCESS

    def tick(self) -> NodeStatus:
        return self.result


class TransformAvailable(_Constant):
    """The twin's transforms are always available."""


class IsBatteryLow(_Constant):
    """The twin models no battery: never low."""

    result = FAILURE


class IsBatteryCharging(_Constant):
    """The twin models no battery: never charging."""

    result = FAILURE


# -- decorators -----------------------------------------------------------------------------


class DistanceController(DecoratorNode):
    """Tick the child first, while it runs, and each time the robot has moved `distance` m since it last completed."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services
        self._start: Pose | None = None

    def tick(self) -> NodeStatus:
        pose = self.services.robot_pose()
        if self._status is IDLE:
            self._start = None
        self.set_status(RUNNING)
        child = self.child
        travelled = math.inf if self._start is None else math.hypot(pose[0] - self._start[0], pose[1] - self._start[1])
        if child.status is RUNNING or travelled >= float(_input(self, "distance", 1.0)):
            status = child.execute_tick()
            if status is SUCCESS:
                self._start = pose
                self.reset_child()
            elif status is FAILURE:
                self.reset_child()
            return status
        return SUCCESS


class SpeedController(DecoratorNode):
    """Tick the child at a rate between `min_rate` and `max_rate` scaled by the robot's speed (and on a new goal)."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services
        self._start_ns: int | None = None
        self._goal: Any = None
        self._period_ns = 1_000_000_000

    def tick(self) -> NodeStatus:
        now = self.now_ns()
        goal = (_bb(self, "goal"), _bb(self, "goals"))
        first = self._start_ns is None or self._status is IDLE
        changed = self._goal is None or not (_same(goal[0], self._goal[0]) and _same(goal[1], self._goal[1]))
        if first or changed:
            self._goal = goal
            self._start_ns = now
            first = True
        self.set_status(RUNNING)
        child = self.child
        assert self._start_ns is not None
        if first or child.status is RUNNING or now - self._start_ns >= self._period_ns:
            min_rate, max_rate = float(_input(self, "min_rate", 0.1)), float(_input(self, "max_rate", 1.0))
            min_speed, max_speed = float(_input(self, "min_speed", 0.0)), float(_input(self, "max_speed", 0.5))
            speed = min(max(self.services.robot_speed(), min_speed), max_speed)
            span = max_speed - min_speed
            rate = min_rate + (max_rate - min_rate) * ((speed - min_speed) / span if span > 0 else 0.0)
            self._period_ns = round(1e9 / rate) if rate > 0 else 1 << 62
            self._start_ns = now
            status = child.execute_tick()
            if status in (SUCCESS, FAILURE):
                self.reset_child()
            return status
        return SUCCESS


class GoalUpdater(DecoratorNode):
    """Replace `input_goal` by the last pose published on goal_update, write `output_goal`, tick the child."""

    def __init__(self, name: str, config: NodeConfig, services: NavigationServices) -> None:
        super().__init__(name, config)
        self.services = services
        self._last: Pose | None = None

    def tick(self) -> NodeStatus:
        update = self.services.updated_goal()
        if update is not None:
            self._last = update
        goal = self._last if self._last is not None else _input(self, "input_goal")
        self.set_output("output_goal", goal)
        return self.child.execute_tick()


class SingleTrigger(DecoratorNode):
    """Tick the child until it completes once; FAILURE afterwards."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._done = False

    def tick(self) -> NodeStatus:
        if self._done:
            return FAILURE
        self.set_status(RUNNING)
        status = self.child.execute_tick()
        if status in (SUCCESS, FAILURE):
            self._done = True
            self.reset_child()
        return status


class GoalUpdatedController(DecoratorNode):
    """Tick the child on the first tick, while it runs, and when the goal changed."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._goal: Any = None
        self._first = True

    def tick(self) -> NodeStatus:
        goal = (_bb(self, "goal"), _bb(self, "goals"))
        if self._status is IDLE:
            self._first = True
        self.set_status(RUNNING)
        changed = self._goal is None or not (_same(goal[0], self._goal[0]) and _same(goal[1], self._goal[1]))
        child = self.child
        if self._first or changed or child.status is RUNNING:
            self._first = False
            self._goal = goal
            status = child.execute_tick()
            if status in (SUCCESS, FAILURE):
                self.reset_child()
            return status
        return SUCCESS


class PathLongerOnApproach(DecoratorNode):
    """Tick the child only when a new path, near the goal (`prox_len`), is `length_factor` longer than the old one."""

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._old: Any = None
        self._new: Any = None

    def tick(self) -> NodeStatus:
        path = _input(self, "path")
        if not _same(path, self._new):
            self._old, self._new = self._new, path
        child = self.child
        if child.status is RUNNING:
            return child.execute_tick()
        if self._old is not None and path is not None and not _same(self._old, path):
            old_len, new_len = _path_length(self._old), _path_length(path)
            if (
                old_len < float(_input(self, "prox_len", 3.0))
                and new_len > float(_input(self, "length_factor", 2.0)) * old_len
            ):
                self.set_status(RUNNING)
                status = child.execute_tick()
                if status is not RUNNING:
                    self._old = path  # handled this path
                    self.reset_child()
                return status
        return SUCCESS


def _with_ports(cls: type, node_id: str, ports: Sequence[PortSpec]) -> type:
    return type(node_id, (cls,), {"provided_ports": classmethod(lambda _c: tuple(ports)), "__doc__": cls.__doc__})


_NEEDS_SERVICES: dict[str, type] = {
    "ComputePathToPose": ComputePathToPose,
    "ComputePathThroughPoses": ComputePathThroughPoses,
    "FollowPath": FollowPath,
    "SmoothPath": SmoothPath,
    "Spin": Spin,
    "BackUp": BackUp,
    "DriveOnHeading": DriveOnHeading,
    "Wait": Wait,
    "AssistedTeleop": AssistedTeleop,
    "CancelControl": _cancel_leaf("follow_path"),
    "CancelBackUp": _cancel_leaf("backup"),
    "CancelDriveOnHeading": _cancel_leaf("drive_on_heading"),
    "CancelSpin": _cancel_leaf("spin"),
    "CancelWait": _cancel_leaf("wait"),
    "CancelAssistedTeleop": _cancel_leaf("assisted_teleop"),
    "ClearEntireCostmap": ClearEntireCostmap,
    "ClearCostmapAroundRobot": ClearCostmapAroundRobot,
    "ClearCostmapExceptRegion": ClearCostmapExceptRegion,
    "ReinitializeGlobalLocalization": ReinitializeGlobalLocalization,
    "PlannerSelector": _selector("default_planner", "selected_planner"),
    "ControllerSelector": _selector("default_controller", "selected_controller"),
    "GoalCheckerSelector": _selector("default_goal_checker", "selected_goal_checker"),
    "SmootherSelector": _selector("default_smoother", "selected_smoother"),
    "ProgressCheckerSelector": _selector("default_progress_checker", "selected_progress_checker"),
    "TruncatePathLocal": TruncatePathLocal,
    "RemovePassedGoals": RemovePassedGoals,
    "GoalReached": GoalReached,
    "IsStuck": IsStuck,
    "IsPathValid": IsPathValid,
    "DistanceTraveled": DistanceTraveled,
    "DistanceController": DistanceController,
    "SpeedController": SpeedController,
    "GoalUpdater": GoalUpdater,
}

_PLAIN: dict[str, type] = {
    "TruncatePath": TruncatePath,
    "GoalUpdated": GoalUpdated,
    "GlobalUpdatedGoal": GlobalUpdatedGoal,
    "InitialPoseReceived": InitialPoseReceived,
    "TimeExpired": TimeExpired,
    "PathExpiringTimer": PathExpiringTimer,
    "TransformAvailable": TransformAvailable,
    "IsBatteryLow": IsBatteryLow,
    "IsBatteryCharging": IsBatteryCharging,
    "SingleTrigger": SingleTrigger,
    "GoalUpdatedController": GoalUpdatedController,
    "PathLongerOnApproach": PathLongerOnApproach,
    "WouldAPlannerRecoveryHelp": WouldAPlannerRecoveryHelp,
    "WouldAControllerRecoveryHelp": WouldAControllerRecoveryHelp,
}


IMPLEMENTED: frozenset[str] = frozenset(_NEEDS_SERVICES) | frozenset(_PLAIN)
"""The Nav2 leaves and decorators the twin runs; the others of `tree_nodes` are declared only (trees validate)."""


def register_nav2_leaves(factory: BehaviorTreeFactory, services: NavigationServices) -> None:
    """Register every implemented Nav2 leaf and decorator, bound to `services`, with Nav2's ports."""
    ports: dict[str, tuple[PortSpec, ...]] = {k: v[1] for k, v in NAV2_LEAVES.items()}
    ports.update(NAV2_DECORATORS)
    for node_id, cls in _NEEDS_SERVICES.items():
        factory.register_node_type(_with_ports(cls, node_id, ports[node_id]), node_id, services)
    for node_id, cls in _PLAIN.items():
        factory.register_node_type(_with_ports(cls, node_id, ports[node_id]), node_id)
