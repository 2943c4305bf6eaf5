"""A go-to-point path follower: turn towards the next point, drive to it, turn to the final heading.

The velocity law of a simple waypoint controller (not DWB): in place turns while the heading error
is large, else forward speed proportional to the distance (capped) with a proportional heading
correction. Commands are clamped to the robot's limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["FollowerParams", "PathFollower"]


def _wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True, kw_only=True, slots=True)
class FollowerParams:
    """Limits and gains of the follower; defaults are the TurtleBot3's Nav2 (DWB) limits."""

    max_linear_mps: float = 0.22  # TB3 DWB max_vel_x
    max_angular_radps: float = 1.0  # TB3 DWB max_vel_theta
    tolerance_m: float = 0.1  # a point counts as reached this close
    yaw_tolerance_rad: float = 0.1  # the final heading counts as reached this close
    turn_in_place_rad: float = 0.4  # turn on the spot while the heading error is larger
    heading_gain: float = 2.0  # rad/s per rad of heading error
    distance_gain: float = 1.0  # m/s per m to the point

    def __post_init__(self) -> None:
        if not (self.max_linear_mps > 0.0 and self.max_angular_radps > 0.0 and self.tolerance_m > 0.0):
            msg = "max_linear_mps, max_angular_radps and tolerance_m must be positive"
            raise ValueError(msg)


class PathFollower:
    """Follows points `(x, y)` and an optional final heading; `done` once the last is reached."""

    def __init__(self, params: FollowerParams) -> None:
        self.params = params
        self._points: list[tuple[float, float]] = []
        self._yaw: float | None = None
        self._i = 0
        self.done = True

    def set_path(self, points: Sequence[tuple[float, float]], final_yaw_rad: float | None = None) -> None:
        """Start following new points (the previous path is dropped)."""
        self._points = [(float(x), float(y)) for x, y in points]
        self._yaw = final_yaw_rad
        self._i = 0
        self.done = False

    @property
    def remaining(self) -> int:
        """Points not reached yet."""
        return len(self._points) - self._i

    def command(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Return (linear m/s, angular rad/s) towards the current point at this pose."""
        p = self.params
        limit = p.max_angular_radps
        while self._i < len(self._points):
            px, py = self._points[self._i]
            dx, dy = px - x_m, py - y_m
            dist = math.hypot(dx, dy)
            if dist > p.tolerance_m:
                err = _wrap(math.atan2(dy, dx) - yaw_rad)
                w = max(-limit, min(limit, p.heading_gain * err))
                if abs(err) > p.turn_in_place_rad:
                    return (0.0, w)
                return (min(p.max_linear_mps, p.distance_gain * dist) * math.cos(err), w)
            self._i += 1
        if self._yaw is not None:
            err = _wrap(self._yaw - yaw_rad)
            if abs(err) > p.yaw_tolerance_rad:
                return (0.0, max(-limit, min(limit, p.heading_gain * err)))
        self.done = True
        return (0.0, 0.0)
