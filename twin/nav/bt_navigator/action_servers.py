"""The navigation servers as the navigator tree's leaves reach them (`NavigationServices`).

`Nav2Servers` stands where ROS's action layer stands between Nav2's BT leaves (action clients)
and its servers: the leaves send goals by Nav2's action names, poll and cancel them, and it hands
each goal to its server, which answers as Nav2's does within the simulated time the server takes:

- planner_server (`twin.nav.planner.planner_server`): a path is computed when asked (NavFn on the
  global costmap, map frame);
- controller_server (`twin.nav.controller.controller_server`): a FollowPath goal advances one
  controller cycle per `controller_frequency` tick;
- behavior_server (`twin.nav.behaviors.behavior_server`): a behaviour one cycle per
  `cycle_frequency` tick;
- smoother_server (`twin.nav.smoother.simple_smoother`): SmoothPath at once;
- the costmaps' clear services, the robot's pose and speed, IsStuck.

Each server's node (`PlannerServerNode`, `ControllerServerNode`, `BehaviorServerNode`) takes this
object and runs its server's cycles on the node graph.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from twin.nav.actions import ActionGoal, ActionState, ActionUpdate
from twin.nav.behaviors.behavior_server import BehaviorServer
from twin.nav.controller.controller_server import ControllerServer
from twin.nav.costmap_2d.layered_costmap import Costmap
from twin.nav.frames import Frames
from twin.nav.planner.planner_server import PlannerServer
from twin.nav.server_params import Nav2Config
from twin.nav.smoother.simple_smoother import smooth_path
from twin.node import node_logger

__all__ = ["Nav2Servers"]


Pose = tuple[float, float, float]

_BRAKE_ACCEL_LIMIT = -10.0  # Nav2 IsStuck's brake_accel_limit, m/s^2


# A NavFn failure's nav2_msgs error code, less the action's UNKNOWN (ComputePathToPose 200 + offset):
# Iron's NavFn throws StartOutsideMapBounds, GoalOutsideMapBounds, and NoValidPathCouldBeFound for the
# rest (a start on a lethal cell that is also the goal included).
_PLAN_FAILURE_CODES = {"START_OUTSIDE_MAP": 3, "GOAL_OUTSIDE_MAP": 4, "START_IN_LETHAL": 8, "NO_VALID_PATH": 8}


class Nav2Servers:
    """planner_server, controller_server, smoother_server, behavior_server and the costmaps' services.

    Args:
        config: The servers' parameters.
        frames: The shared transforms (robot pose in odom and map).
        global_costmap: The planner's costmap (map frame).
        local_costmap: The controller's and behaviours' costmap (odom frame, rolling).
        now: The simulation clock, ns.
        native: Use the C kernels where they are available.
    """

    def __init__(
        self,
        config: Nav2Config,
        frames: Frames,
        global_costmap: Costmap,
        local_costmap: Costmap,
        *,
        now: Callable[[], int],
        native: bool = True,
    ) -> None:
        self._log = node_logger("bt_navigator")  # its node's lines: `[robot1.bt_navigator]` in a fleet
        self.config = config
        self.frames = frames
        self.global_costmap = global_costmap
        self.local_costmap = local_costmap
        self.now = now
        self.planner_server = PlannerServer(config.planner, frames, global_costmap, native=native)
        self.controller_server = ControllerServer(
            config.controllers,
            config.goal_checkers,
            frames,
            local_costmap,
            finish=self._finish,
            controller_frequency_hz=config.controller_frequency_hz,
            failure_tolerance_s=config.failure_tolerance_s,
            velocity_thresholds=config.velocity_thresholds,
            progress_radius_m=config.progress_radius_m,
            progress_allowance_s=config.progress_allowance_s,
            progress_angle_rad=config.progress_angle_rad,
        )
        self.behavior_server = BehaviorServer(
            config.behaviors, frames, local_costmap, finish=self._finish, servers=config.behavior_servers
        )
        self._goals: dict[int, ActionGoal] = {}
        self._next_id = 0
        self._generation = 0
        #: The last failure any server reported (the navigator's failure reason).
        self.last_error = ""

    @property
    def recoveries(self) -> int:
        """Behaviour goals started so far (NavigateToPose's feedback counts them)."""
        return self.behavior_server.recoveries

    # -- NavigationServices ---------------------------------------------------------------------

    @property
    def generation(self) -> int:
        """Changes whenever a goal is sent, updated, canceled or finished (what a leaf's poll can see)."""
        return self._generation

    def send_goal(self, server: str, request: Mapping[str, Any]) -> int:
        """Accept a goal on an action server (see `twin.nav.bt_navigator.leaves.NavigationServices`)."""
        self._generation += 1
        self._next_id += 1
        goal = ActionGoal(server=server, request=dict(request))
        self._goals[self._next_id] = goal
        if len(self._goals) > 64:  # finished goals are kept only for the leaves' polls
            for gid in [g for g, v in self._goals.items() if v.state is not ActionState.RUNNING][:32]:
                del self._goals[gid]
        gid = self._next_id
        t_ns = self.now()
        if server == "compute_path_to_pose":
            self._plan(goal, [request["goal"]], request.get("start"), t_ns, base=200)
        elif server == "compute_path_through_poses":
            self._plan(goal, list(request.get("goals") or []), request.get("start"), t_ns, base=300)
        elif server == "smooth_path":
            path = np.asarray(request["path"], dtype=np.float64).reshape(-1, 3)
            self._finish(
                goal, ActionState.SUCCEEDED, path=smooth_path(path), smoothing_duration=0.0, was_completed=True
            )
        elif server == "follow_path":
            self.controller_server.start(goal, t_ns)
        elif self.behavior_server.servers.get(server) is not None:
            running = self.behavior_server.active
            if running is not None:
                self._cancel(running)
            self.behavior_server.start(goal, t_ns)
        elif server in self.behavior_server.servers:  # AssistedTeleop: loaded by the params, not simulated
            self._finish(goal, ActionState.FAILED, reason=f"the twin does not simulate the {server!r} behaviour")
        else:
            self._finish(goal, ActionState.FAILED, reason=f"the twin has no {server!r} action server")
        return gid

    def update_goal(self, goal_id: int, request: Mapping[str, Any]) -> None:
        """A new path for a running FollowPath goal (Nav2 preempts it with the new path)."""
        goal = self._goals.get(goal_id)
        if goal is None or goal.state is not ActionState.RUNNING:
            return
        self._generation += 1
        goal.request = dict(request)
        self.controller_server.update(goal, request["path"])

    def poll(self, goal_id: int) -> ActionUpdate:
        """The goal's state."""
        goal = self._goals.get(goal_id)
        if goal is None:
            return ActionUpdate(state=ActionState.FAILED)
        return ActionUpdate(state=goal.state, result=goal.result)

    def cancel(self, goal_id: int) -> None:
        """Cancel a goal (a halted leaf)."""
        goal = self._goals.get(goal_id)
        if goal is not None:
            self._cancel(goal)

    def _cancel(self, goal: ActionGoal) -> None:
        if goal.state is not ActionState.RUNNING:
            return
        self._generation += 1
        goal.state = ActionState.FAILED
        goal.reason = "canceled"
        self.controller_server.cancel(goal)
        self.behavior_server.cancel(goal)

    def cancel_all(self, server: str) -> None:
        """Cancel every running goal on a server."""
        for gid, goal in list(self._goals.items()):
            if goal.server == server:
                self.cancel(gid)

    def call_service(self, service: str, request: Mapping[str, Any]) -> bool:
        """Costmap clearing services; `reinitialize_global_localization` is not offered."""
        kind = str(request.get("kind", "clear_entirely"))
        targets = [c for key, c in (("global", self.global_costmap), ("local", self.local_costmap)) if key in service]
        if not targets:
            self._log.warning("no service %r in the twin (costmap clearing services only)", service)
            return False
        for costmap in targets:
            if kind == "clear_entirely":
                costmap.clear_entirely()
                continue
            distance = request.get("reset_distance")
            distance = 1.0 if distance is None else float(distance)
            x, y, _ = self.frames.map_pose() if costmap is self.global_costmap else self.frames.odom_pose
            if kind == "clear_around_robot":
                costmap.clear_around_robot(x, y, distance)
            else:
                costmap.clear_except_region(x, y, distance)
        for costmap in targets:  # the master grid again from the layers kept (the static map), at once
            x, y, yaw = self.frames.map_pose() if costmap is self.global_costmap else self.frames.odom_pose
            costmap.update(x, y, yaw, ())
        return True

    def robot_pose(self) -> Pose:
        """The robot's map pose."""
        return self.frames.map_pose()

    def robot_speed(self) -> float:
        """The odometry's linear speed."""
        return abs(self.frames.velocity[0])

    def is_path_valid(self, path: np.ndarray) -> bool:
        """planner_server's is_path_valid: no lethal or inscribed cell under the path (Humble)."""
        return self.planner_server.is_path_valid(path)

    def selection(self, topic: str) -> str | None:
        """Nothing publishes on the selector topics in the twin: the selectors keep their defaults."""
        return None

    def updated_goal(self) -> Pose | None:
        """Nothing publishes on `goal_update` in the twin."""
        return None

    def is_stuck(self) -> bool:
        """Nav2's IsStuck: the odometry decelerates harder than the brake limit."""
        v, _ = self.frames.velocity
        pv, _, pt = self.frames.prev_velocity
        dt = (self.frames.odom_stamp_ns - pt) / 1e9
        return pt >= 0 and dt > 0 and (v - pv) / dt < _BRAKE_ACCEL_LIMIT

    # -- the servers' answers -------------------------------------------------------------------

    def _plan(self, goal: ActionGoal, targets: list[Any], start: Any, t_ns: int, *, base: int) -> None:
        result = self.planner_server.compute_path(targets, start, t_ns)
        if isinstance(result, str):
            # nav2_msgs' codes (Iron on), `base` the action's UNKNOWN: 200 to a pose, 300 through poses
            failure = self.planner_server.last_failure
            offset = _PLAN_FAILURE_CODES.get(failure.name, 0) if failure is not None else (9 if base == 300 else 0)
            self._finish(goal, ActionState.FAILED, reason=result, error_code=base + offset)
        else:
            self._finish(goal, ActionState.SUCCEEDED, path=result)

    def _finish(self, goal: ActionGoal, state: ActionState, *, reason: str = "", **result: Any) -> None:
        self._generation += 1
        goal.state = state
        goal.result = result
        goal.reason = reason
        if reason:
            self.last_error = f"{goal.server}: {reason}"
