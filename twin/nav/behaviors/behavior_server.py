"""nav2_behaviors' behavior_server: Spin, BackUp, DriveOnHeading and Wait, one cycle per `cycle_frequency`.

`BehaviorServer` runs one behaviour goal at a time (a new one replaces the running one) on the
local costmap; `BehaviorServerNode` publishes its commands on `/cmd_vel`. Humble's bringup does not
remap the behaviours' `cmd_vel`: their commands reach the drive unsmoothed, beside the velocity
smoother's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Protocol

from twin.bag import TwistEncoder
from twin.nav.actions import ActionGoal, ActionState
from twin.nav.behaviors.drive_on_heading import BackUp, DriveOnHeading
from twin.nav.behaviors.spin import Spin
from twin.nav.behaviors.timed_behavior import BehaviorParams, BehaviorStatus
from twin.nav.behaviors.wait import Wait
from twin.nav.costmap_2d.layered_costmap import Costmap
from twin.nav.frames import Frames
from twin.node import PRIORITY_COMMAND, Encoded, Node, node_logger

__all__ = ["BEHAVIORS", "BehaviorServer", "BehaviorServerNode", "make_behavior"]


BEHAVIORS = ("spin", "backup", "drive_on_heading", "wait")
"""The behaviour action servers, by Nav2's action names."""


def make_behavior(server: str, params: BehaviorParams | None = None) -> Spin | DriveOnHeading | Wait:
    """The behaviour for an action server name: spin, backup, drive_on_heading, wait."""
    kinds: dict[str, type[Spin] | type[DriveOnHeading] | type[Wait]] = {
        "spin": Spin,
        "backup": BackUp,
        "drive_on_heading": DriveOnHeading,
        "wait": Wait,
    }
    return kinds[server](params)


class BehaviorServer:
    """behavior_server: one behaviour goal at a time, stepped on the local costmap.

    Args:
        params: The behaviours' parameters (the footprint is taken from the local costmap).
        frames: The shared transforms (the robot's odom pose).
        local_costmap: The costmap the behaviours check their footprint on.
        finish: Called as `finish(goal, state, reason=...)` when a goal ends.
    """

    def __init__(
        self,
        params: BehaviorParams,
        frames: Frames,
        local_costmap: Costmap,
        *,
        finish: Callable[..., None],
        servers: Mapping[str, str | None] | None = None,
    ) -> None:
        self._log = node_logger("behavior_server")  # its node's lines: `[robot1.behavior_server]` in a fleet
        self.params = params
        #: The action servers it loads: name → behaviour (None: one the twin does not simulate).
        self.servers: Mapping[str, str | None] = (
            dict(zip(BEHAVIORS, BEHAVIORS, strict=True)) if servers is None else servers
        )
        self.frames = frames
        self.local_costmap = local_costmap
        self._finish = finish
        self._goal: ActionGoal | None = None
        self._impl: Spin | DriveOnHeading | Wait | None = None
        self._stop = False
        #: Behaviour goals started so far (Nav2's feedback counts them as recoveries).
        self.recoveries = 0

    @property
    def active(self) -> ActionGoal | None:
        """The running goal, if any."""
        return self._goal

    def start(self, goal: ActionGoal, t_ns: int) -> None:
        """Start a behaviour goal (the caller cancels a running one first)."""
        request = dict(goal.request)
        kind = self.servers.get(goal.server) or goal.server
        if kind == "wait" and "time_s" not in request:
            request["time_s"] = request.get("wait_duration", 1.0)
        # the behaviours check the local costmap's footprint, as behavior_server reads it from that costmap
        params = dataclasses.replace(self.params, footprint=tuple(self.local_costmap.footprint))
        self._stop = False
        behavior = make_behavior(kind, params)
        self.recoveries += 1
        self._log.info("Running %s", goal.server)
        refusal = behavior.start(request, self.frames.odom_pose, t_ns)
        if refusal:  # Nav2's onRun refused it: "Initial checks failed", the goal is aborted at once
            self._log.warning("Initial checks failed for %s: %s", goal.server, refusal)
            self._finish(goal, ActionState.FAILED, reason=refusal)
            return
        self._goal, self._impl = goal, behavior

    def cancel(self, goal: ActionGoal) -> None:
        """Stop `goal` if it is the running one: the next cycle publishes a zero command (TimedBehavior's stopRobot)."""
        if goal is self._goal:
            self._goal = None
            self._stop = True

    def cycle(self, t_ns: int) -> tuple[float, float] | None:
        """One behavior_server cycle: the command for `/cmd_vel` (None when idle or waiting)."""
        goal, impl = self._goal, self._impl
        if goal is None or impl is None:
            if self._stop:  # a canceled behaviour, Wait too, stops the robot
                self._stop = False
                return (0.0, 0.0)
            return None
        step = impl.step(t_ns, self.frames.odom_pose, self.local_costmap.grid)
        waits = isinstance(impl, Wait)  # (Wait commands nothing)
        if step.status is BehaviorStatus.RUNNING:
            return None if waits else step.cmd
        if step.status is BehaviorStatus.SUCCEEDED:
            self._finish(goal, ActionState.SUCCEEDED)
        else:
            self._log.warning("%s failed: %s", goal.server, step.reason)
            self._finish(goal, ActionState.FAILED, reason=step.reason)
        self._goal = None
        return None if waits else (0.0, 0.0)


class _Servers(Protocol):
    @property
    def behavior_server(self) -> BehaviorServer: ...


class BehaviorServerNode(Node):
    """behavior_server: one cycle per `cycle_frequency`, commands on `/cmd_vel` (see the module docstring)."""

    def __init__(self, servers: _Servers) -> None:
        super().__init__("behavior_server")
        server = servers.behavior_server
        pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode
        cycle = server.cycle

        def on_timer(t_ns: int) -> None:
            cmd = cycle(t_ns)
            if cmd is not None:
                pub.publish(Encoded((encode, cmd, cmd)))

        self.create_rate_timer(server.params.cycle_frequency_hz, on_timer, priority=PRIORITY_COMMAND)
