"""Missions that drive the robot until navigation and behaviour trees take over.

A mission is asked for a velocity command at its rate, given the chassis pose, and says when it
is done. `cmd_vel_script` replays timed velocity segments open loop; `waypoints` steers through
a list of points (and optional final headings) with a simple go-to-point law on the pose it is
given, like a robot following a hand-made route.
"""

from __future__ import annotations

import math
from typing import Protocol

from twin.core.clock import s_to_ns
from twin.core.geometry import wrap_angle
from twin.sim.scenario import CmdVelScriptMission, WaypointsMission

__all__ = ["CmdVelScript", "Mission", "WaypointFollower", "make_mission"]


class Mission(Protocol):
    """What the loop asks a mission at its rate."""

    done: bool

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

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the segment's command at `t_ns` (times must not go backwards)."""
        ends = self._ends_ns
        while self._i < len(ends) and t_ns >= ends[self._i]:
            self._i += 1
        if self._i < len(ends):
            return self._cmds[self._i]
        self.done = True
        return (0.0, 0.0)


class WaypointFollower:
    """Turns towards the next point, drives to it, and turns to its heading if one is given."""

    def __init__(self, spec: WaypointsMission) -> None:
        self.spec = spec
        self._i = 0
        self.done = not spec.points
        self.reached: list[int] = []  # sim time each point was reached, ns

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return the command that brings the robot to the current point."""
        spec = self.spec
        while self._i < len(spec.points):
            point = spec.points[self._i]
            dx, dy = point[0] - x_m, point[1] - y_m
            dist = math.hypot(dx, dy)
            if dist > spec.tolerance_m:
                err = wrap_angle(math.atan2(dy, dx) - yaw_rad)
                w = max(-spec.max_angular_radps, min(spec.max_angular_radps, spec.heading_gain * err))
                if abs(err) > spec.turn_in_place_rad:
                    return (0.0, w)
                v = min(spec.max_linear_mps, spec.distance_gain * dist) * math.cos(err)
                return (v, w)
            if len(point) == 3:
                err = wrap_angle(point[2] - yaw_rad)
                if abs(err) > spec.yaw_tolerance_rad:
                    w = max(-spec.max_angular_radps, min(spec.max_angular_radps, spec.heading_gain * err))
                    return (0.0, w)
            self.reached.append(t_ns)
            self._i += 1
        self.done = True
        return (0.0, 0.0)


def make_mission(spec: CmdVelScriptMission | WaypointsMission) -> CmdVelScript | WaypointFollower:
    """Return the mission a scenario's `mission:` section describes."""
    if isinstance(spec, CmdVelScriptMission):
        return CmdVelScript(spec)
    return WaypointFollower(spec)
