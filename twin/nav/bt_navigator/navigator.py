"""nav2_bt_navigator's navigator: NavigateToPose runs a Nav2 behaviour-tree XML, one tick per `bt_loop_duration`.

`BtNavigator.navigate` accepts a goal (and preempts a running one); `tick` is one bt_navigator loop
iteration; `status`/`reason` answer the action's client (the mission's `GoToPose` reaches it through
`twin.mission.navigate_to_pose.Nav2Navigator`). The tree's leaves reach the servers through
`Nav2Servers` (`action_servers`); `BtNavigatorNode` (`bt_navigator_node`) runs it on the node graph.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bt.log import StatusChangeBuffer
from twin.bt.status import NodeStatus
from twin.core.errors import TreeError
from twin.nav.actions import ActionState
from twin.nav.bt_navigator.action_servers import Nav2Servers
from twin.nav.bt_navigator.factory import nav2_factory, unimplemented_leaf
from twin.node import node_logger

__all__ = ["BtNavigator"]


Pose = tuple[float, float, float]
F64 = NDArray[np.float64]


class BtNavigator:
    """NavigateToPose: runs a Nav2 behaviour-tree XML for each goal, one tick per `bt_loop_duration`.

    Raises:
        TreeError: If the XML cannot be loaded with Nav2's nodes (a leaf the twin lacks is named).
    """

    def __init__(self, servers: Nav2Servers, bt_xml: Path, *, now: Callable[[], int]) -> None:
        self._log = node_logger("bt_navigator")  # its node's lines: `[robot1.bt_navigator]` in a fleet
        self.servers = servers
        self.bt_xml = bt_xml
        problem = unimplemented_leaf(bt_xml)
        if problem is not None:
            raise TreeError(problem)
        factory = nav2_factory(servers)
        self.tree = factory.create_tree_from_file(bt_xml, clock=now)
        self.tree.log = self._log
        self.changes = StatusChangeBuffer()
        self.tree.add_listener(self.changes)
        self.now = now
        self._status: dict[int, ActionState] = {}
        self._reasons: dict[int, str] = {}
        self._goal_id = 0
        self.active = False
        self.goal: Pose = (0.0, 0.0, 0.0)
        self.started_ns = 0
        self.recoveries_at_start = 0
        self._path_seen: Any = None
        self._path_xy: F64 = np.zeros((0, 2))
        self._path_left: F64 = np.zeros(0)

    def navigate(self, pose: Pose) -> int:
        """Accept a NavigateToPose goal; a running goal is preempted (the tree sees the new goal).

        As Nav2's bt_navigator, a goal sent before the robot's pose in the map is known (AMCL without
        an initial pose yet) is rejected: it fails at once.
        """
        if not self.servers.frames.localized:
            self._goal_id += 1
            self._status[self._goal_id] = ActionState.FAILED
            self._reasons[self._goal_id] = "Initial robot pose is not available (AMCL has no initial pose yet)"
            self._log.warning("NavigateToPose goal rejected: the robot's pose in map is not available yet")
            return self._goal_id
        if self.active:
            self._status[self._goal_id] = ActionState.FAILED
            self._reasons[self._goal_id] = "preempted by a new goal"
        self._goal_id += 1
        self.goal = pose
        bb = self.tree.root_blackboard
        bb.set("goal", pose)
        bb.set("goals", [pose])
        bb.set("initial_pose_received", self.servers.frames.localized)
        if not self.active:
            self.started_ns = self.now()
            self.recoveries_at_start = self.servers.recoveries
            self.servers.last_error = ""
        self.active = True
        self._status[self._goal_id] = ActionState.RUNNING
        self._log.info("Begin navigating from current location to (%.2f, %.2f)", pose[0], pose[1])
        return self._goal_id

    def status(self, goal_id: int) -> ActionState:
        """The state of a NavigateToPose goal."""
        return self._status.get(goal_id, ActionState.FAILED)

    def reason(self, goal_id: int) -> str:
        """Why a goal failed."""
        return self._reasons.get(goal_id, "")

    def tick(self) -> bool:
        """One bt_navigator loop iteration (only while a goal runs); True while the goal still runs."""
        if not self.active:
            return False
        servers = self.servers
        status = self.tree.tick_unless_settled(lambda: servers.generation)
        if status is None or status is NodeStatus.RUNNING:  # None: the tick would have repeated the last one
            return True
        self.tree.halt_tree()
        self.active = False
        if status is NodeStatus.SUCCESS:
            self._status[self._goal_id] = ActionState.SUCCEEDED
            self._log.info("Goal succeeded")
        else:
            self._status[self._goal_id] = ActionState.FAILED
            reason = self.servers.last_error or "the navigation tree failed"
            self._reasons[self._goal_id] = reason
            self._log.warning("Goal failed: %s", reason)
        return False

    def distance_remaining(self, pose: Pose) -> float:
        """Along the current path from the pose nearest the robot to its end (Nav2's feedback)."""
        entry = self.tree.root_blackboard.get_entry("path")
        path = entry.value if entry is not None else None
        if path is None:
            return math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1])
        if path is not self._path_seen:  # each plan is a new array: its lengths once
            p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
            seg = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
            self._path_seen, self._path_xy = path, p[:, :2]
            self._path_left = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]]) if len(p) else np.zeros(0)
        if len(self._path_xy) == 0:
            return 0.0
        d = self._path_xy - (pose[0], pose[1])
        i = int(np.argmin(np.einsum("ij,ij->i", d, d)))
        return float(self._path_left[i])
