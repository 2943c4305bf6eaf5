"""Missions that drive the robot: a behaviour tree with a navigator, waypoints, or a cmd_vel script.

The loop asks a mission for a velocity command at its rate, given the pose the robot believes it
has, and stops when the mission says it is done. A behaviour-tree mission is also ticked at its own
rate (`tick`), like the thesis's autonomy node on its 500 ms timer.
"""

from __future__ import annotations

import bisect
import logging
import math
import random
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

from twin.bt import NodeStatus
from twin.bt.log import StatusChange, StatusChangeBuffer
from twin.core.clock import s_to_ns
from twin.core.errors import TreeError
from twin.mission.bt_nodes import LOCATION_FILE_KEY, register_mission_nodes, unknown_literal_location
from twin.mission.look_for_object import ImageSlot, register_vision_nodes
from twin.mission.path_follower import PathFollower
from twin.sim.replay import load_commands
from twin.sim.scenario import BehaviorTreeMission, CmdVelScriptMission, ReplayMission, WaypointsMission

if TYPE_CHECKING:
    from twin.mission.navigate_to_pose import Nav2Navigator

__all__ = ["BagReplay", "CmdVelScript", "Mission", "TreeMission", "WaypointFollower"]

_log = logging.getLogger(__name__)


class Mission(Protocol):
    """What the loop asks a mission at its rate."""

    done: bool
    result: str

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return (linear m/s, angular rad/s) for now; set `done` when the mission is over."""
        ...


class CmdVelScript:
    """Holds each segment's velocity for its duration; zero after the last one, then done."""

    def __init__(self, spec: CmdVelScriptMission) -> None:
        self._ends_ns: list[int] = []
        self._cmds: list[tuple[float, float]] = []
        end = 0
        for seg in spec.segments:
            end += s_to_ns(seg.duration_s)
            self._ends_ns.append(end)
            self._cmds.append((seg.linear_mps, seg.angular_radps))
        self.end_ns = end
        self._i = 0
        self.done = False
        self.result = "running"

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the segment's command at `t_ns` (times must not go backwards)."""
        ends = self._ends_ns
        while self._i < len(ends) and t_ns >= ends[self._i]:
            self._i += 1
        if self._i < len(ends):
            return self._cmds[self._i]
        self.done, self.result = True, "complete"
        return (0.0, 0.0)


class BagReplay:
    """Replays a bag's velocity commands at their recorded sim times; done at the bag's last pose.

    Each recorded command is sent once, at the first loop tick at or after its time; the drive holds
    it. Before the first, the bag's first velocity holds (the robot keeps doing what it was doing).

    Raises:
        BagError: If the bag is unreadable or lacks the command topic or poses (see `load_commands`).
    """

    def __init__(self, spec: ReplayMission, log: logging.Logger = _log) -> None:
        self.spec = spec
        self.commands = load_commands(spec)
        t, v, w = self.commands.t_ns.tolist(), self.commands.v_mps.tolist(), self.commands.w_radps.tolist()
        finite = [math.isfinite(a) and math.isfinite(b) for a, b in zip(v, w, strict=True)]
        if not all(finite):  # refused as a user node's are: the drive keeps the command before them
            first = finite.index(False)
            log.warning(
                "%s: %d of %d commands on %s hold NaN or infinity (the first at %.3f s: %s, %s): skipped, the "
                "drive keeps the command before each, as Nav2 drops a NaN velocity",
                spec.bag,
                finite.count(False),
                len(finite),
                spec.topic,
                t[first] / 1e9,
                v[first],
                w[first],
            )
            t, v, w = ([x for x, ok in zip(seq, finite, strict=True) if ok] for seq in (t, v, w))
        self._t, self._v, self._w = t, v, w
        self.end_ns = self.commands.end_ns
        start = self.commands.start_velocity
        self._before = start if all(math.isfinite(x) for x in start) else (0.0, 0.0)
        self._i = -1
        self.done = False
        self.result = "running"
        log.info(
            "replaying %d commands on %s from %s (%s), %.3f s",
            len(self._t),
            spec.topic,
            spec.bag,
            self.commands.time_source,
            self.end_ns * 1e-9,
        )

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float] | None:
        """Return the latest recorded command due by `t_ns` if not sent yet, else None (nothing to send).

        The bag's commands are sent once each, as recorded; the drive holds the last one (the first
        pose's velocity before the first). Times must not go backwards.
        """
        if t_ns >= self.end_ns:
            self.done, self.result = True, "complete"
            return None
        times = self._t
        i = self._i
        while i + 1 < len(times) and times[i + 1] <= t_ns:
            i += 1
        if i == self._i:
            return None
        self._i = i
        return (self._v[i], self._w[i])

    def command_in_force(self, t_ns: int) -> tuple[float, float]:
        """The recorded command in force at `t_ns` (the first pose's velocity before the first; zero after the end)."""
        if t_ns >= self.end_ns:
            return (0.0, 0.0)
        i = bisect.bisect_right(self._t, t_ns) - 1
        return self._before if i < 0 else (self._v[i], self._w[i])


class WaypointFollower:
    """Drives to each point in turn (turning to its heading when one is given); done after the last."""

    def __init__(self, spec: WaypointsMission) -> None:
        self._points = spec.points
        self._follower = PathFollower(spec.follower)
        self._i = -1
        self.done = not spec.points
        self.result = "complete" if self.done else "running"
        self.reached: list[int] = []  # sim time each point was reached, ns

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the command that brings the robot to the current point."""
        follower = self._follower
        while not self.done:
            if self._i >= 0:  # the follower has the current point (set below when the last was reached)
                v, w = follower.command(x_m, y_m, yaw_rad)
                if not follower.done:
                    return (v, w)
                self.reached.append(t_ns)
            self._i += 1
            if self._i == len(self._points):
                self.done, self.result = True, "complete"
                break
            point = self._points[self._i]
            follower.set_path([(point[0], point[1])], point[2] if len(point) == 3 else None)
        return (0.0, 0.0)


class TreeMission:
    """A BehaviorTree.CPP tree whose `GoToPose` nodes drive through a navigator.

    Raises:
        TreeError: If the tree file cannot be loaded (file:line and the problem).
    """

    def __init__(
        self,
        spec: BehaviorTreeMission,
        navigator: Nav2Navigator,
        *,
        clock: Callable[[], int],
        seed: int,
        log: logging.Logger = _log,
    ) -> None:
        self.spec = spec
        self.navigator = navigator
        self._log = log
        from twin.nav.bt_navigator.factory import nav2_factory  # only a tree mission needs Nav2's BT nodes

        factory = nav2_factory()
        register_mission_nodes(factory, navigator=navigator, rng=random.Random(seed), log=log)
        self.images = ImageSlot()
        """Where `LookForObject` finds the camera (filled in when the scenario's camera is on)."""
        register_vision_nodes(factory, slot=self.images, target_color=spec.target_color, log=log)
        factory.load_plugins()
        self.tree = factory.create_tree_from_file(spec.tree, main_tree=spec.main_tree, clock=clock)
        self.tree.log = log
        if spec.locations is not None:
            problem = unknown_literal_location(self.tree, spec.locations)
            if problem is not None:
                raise TreeError(problem)
            self.tree.root_blackboard.set(LOCATION_FILE_KEY, str(spec.locations))
        self._changes = StatusChangeBuffer()
        self.tree.add_listener(self._changes)
        self.done = False
        self.result = "running"
        self.ticks = 0
        self._failed_uid: int | None = None
        self._log.info("BT created from %s", spec.tree)

    def tick(self, t_ns: int) -> Sequence[StatusChange]:
        """Tick the tree once (BT.CPP `tickOnce`) and return the status changes it made."""
        if self.done:
            return ()
        self.ticks += 1
        status = self.tree.tick_once()
        if status in (NodeStatus.SUCCESS, NodeStatus.FAILURE):
            self.done = True
            self.result = status.name
            if status is NodeStatus.SUCCESS:
                self._log.info("Finished Navigation")
            else:
                self._log.warning("Navigation Failed")
                changes = self._changes.flush()
                # Children fail before their parents: the first FAILURE of the last tick is the cause.
                first = next((c for c in changes if c.new is NodeStatus.FAILURE), None)
                self._failed_uid = first.uid if first is not None else None
                return changes
        return self._changes.flush()

    @property
    def failure(self) -> str:
        """Which goal failed last and why, once the tree has returned FAILURE (else empty)."""
        if self.result != "FAILURE":
            return ""
        if self._failed_uid is not None:
            node = self.tree.node_by_uid(self._failed_uid)
            failure = getattr(node, "failure", None)
            if isinstance(failure, tuple):
                return str(failure[1])
            return f"node '{node.full_path}' ({type(node).__name__}) returned FAILURE"
        failures: list[tuple[int, str]] = []
        for _, node in self.tree.walk():
            failure = getattr(node, "failure", None)
            if isinstance(failure, tuple):
                failures.append(failure)
        if not failures:
            return "the tree returned FAILURE with no failed goal"
        return str(max(failures)[1])

    def node_name(self, uid: int) -> str:
        """The name of a node, as Nav2's BT log carries it."""
        return self.tree.node_by_uid(uid).name

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the navigator's command at this pose."""
        return self.navigator.command(t_ns, x_m, y_m, yaw_rad)
