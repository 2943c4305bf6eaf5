"""Missions that drive the robot. For now: a scripted list of timed `cmd_vel` segments."""

from __future__ import annotations

from twin.core.clock import s_to_ns
from twin.sim.scenario import CmdVelScriptMission

__all__ = ["CmdVelScript"]


class CmdVelScript:
    """Holds each segment's velocity for its duration; zero after the last one."""

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

    def command_at(self, t_ns: int) -> tuple[float, float]:
        """Return (linear m/s, angular rad/s) at `t_ns`; times must not go backwards."""
        ends = self._ends_ns
        while self._i < len(ends) and t_ns >= ends[self._i]:
            self._i += 1
        return self._cmds[self._i] if self._i < len(ends) else (0.0, 0.0)
