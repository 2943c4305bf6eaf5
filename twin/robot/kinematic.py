"""The ideal drive: wheel speeds follow the command under an acceleration limit, no slip, no dynamics.

It reproduces what Gazebo's `gazebo_ros_diff_drive` does to a TurtleBot3 (wheel-rim acceleration
limited to `max_wheel_acceleration_mps2`) without the motor dynamics the FMU drivetrain adds.
Contact with the world is checked through a `Contact` callable; the robot stops at contact.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["ChassisState", "KinematicDrive", "KinematicParams"]

# A contact lasts until the robot is this far from the world again (no chatter while pushing).
_RELEASE_M = 1e-3

# (x_m, y_m, yaw_rad) -> clearance in metres (<= 0 when the pose penetrates the world)
Clearance = Callable[[float, float, float], float]


@dataclass(slots=True)
class ChassisState:
    """The planar chassis state, updated in place by the drive; sensors read it."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    v_mps: float = 0.0
    w_radps: float = 0.0
    accel_mps2: float = 0.0  # longitudinal acceleration in the body frame
    yaw_accel_radps2: float = 0.0
    in_contact: bool = False


@dataclass(frozen=True, kw_only=True, slots=True)
class KinematicParams:
    """Geometry and limits of the ideal drive."""

    wheel_radius_m: float
    wheel_separation_m: float
    max_wheel_acceleration_mps2: float
    step_s: float
    bounding_radius_m: float = 0.3  # farthest point of the robot's collision shape from base_footprint


class KinematicDrive:
    """Ideal differential drive with an acceleration limit and stop-at-contact."""

    def __init__(self, params: KinematicParams, *, clearance: Clearance | None = None) -> None:
        self.params = params
        self.state = ChassisState()
        self.wheel_angle_rad = [0.0, 0.0]  # left, right
        self.wheel_speed_radps = [0.0, 0.0]
        self._rim = [0.0, 0.0]  # wheel-rim speeds, m/s
        self._target = [0.0, 0.0]
        self._clearance = clearance
        self._blocked = False  # the last move was refused by the world
        self._budget_m = 0.0  # how far any robot point may move before the world must be checked again
        self.contacts = 0

    def reset_pose(self, x_m: float, y_m: float, yaw_rad: float) -> None:
        """Place the robot (at rest) and forget the clearance budget."""
        s = self.state
        s.x_m, s.y_m, s.yaw_rad = x_m, y_m, yaw_rad
        s.v_mps = s.w_radps = s.accel_mps2 = s.yaw_accel_radps2 = 0.0
        self._budget_m = 0.0

    def set_cmd_vel(self, v_mps: float, w_radps: float) -> None:
        """Set the commanded body velocity; it holds until the next command."""
        half = 0.5 * self.params.wheel_separation_m
        self._target[0] = v_mps - w_radps * half
        self._target[1] = v_mps + w_radps * half

    def advance(self, n_steps: int) -> None:
        """Advance `n_steps` physics steps."""
        p = self.params
        dt = p.step_s
        dv_max = p.max_wheel_acceleration_mps2 * dt
        inv_track = 1.0 / p.wheel_separation_m
        rim, target = self._rim, self._target
        s = self.state
        v0, w0 = s.v_mps, s.w_radps
        steps_left = n_steps
        while steps_left > 0:
            n = 1
            if rim[0] == target[0] and rim[1] == target[1]:
                # Steady wheel speeds: move in one exact arc as far as the clearance budget allows.
                n = steps_left
                if self._clearance is not None:
                    per_step = (abs(rim[0]) + abs(rim[1])) * (0.5 + p.bounding_radius_m * inv_track) * dt
                    if per_step > 0.0 and per_step * n >= self._budget_m:
                        n = max(1, min(n, int(self._budget_m / per_step)))
            else:
                for i in (0, 1):
                    err = target[i] - rim[i]
                    rim[i] = target[i] if abs(err) <= dv_max else rim[i] + math.copysign(dv_max, err)
            v = 0.5 * (rim[0] + rim[1])
            w = (rim[1] - rim[0]) * inv_track
            if v != 0.0 or w != 0.0:
                self._move(v, w, n * dt)
                if self._blocked:
                    rim[0] = rim[1] = 0.0
                    v = w = 0.0
            steps_left -= n
            s.v_mps, s.w_radps = v, w
        total_dt = n_steps * dt
        s.accel_mps2 = (s.v_mps - v0) / total_dt
        s.yaw_accel_radps2 = (s.w_radps - w0) / total_dt
        inv_r = 1.0 / p.wheel_radius_m
        self.wheel_speed_radps[0] = rim[0] * inv_r
        self.wheel_speed_radps[1] = rim[1] * inv_r

    def _move(self, v: float, w: float, dt: float) -> None:
        s = self.state
        self._blocked = False
        x, y, yaw = s.x_m, s.y_m, s.yaw_rad
        dyaw = w * dt
        if abs(dyaw) < 1e-9:
            nx = x + v * dt * math.cos(yaw + 0.5 * dyaw)
            ny = y + v * dt * math.sin(yaw + 0.5 * dyaw)
        else:
            radius = v / w
            nx = x + radius * (math.sin(yaw + dyaw) - math.sin(yaw))
            ny = y - radius * (math.cos(yaw + dyaw) - math.cos(yaw))
        nyaw = yaw + dyaw
        if self._clearance is not None:
            travel = abs(v * dt) + abs(dyaw) * self.params.bounding_radius_m
            if travel >= self._budget_m:
                clearance = self._clearance(nx, ny, nyaw)
                if clearance <= 0.0:
                    if not s.in_contact:
                        self.contacts += 1
                    s.in_contact = True
                    self._blocked = True
                    self._budget_m = 0.0
                    return
                self._budget_m = clearance
                if clearance > _RELEASE_M:
                    s.in_contact = False
            else:
                self._budget_m -= travel
        s.x_m, s.y_m, s.yaw_rad = nx, ny, math.atan2(math.sin(nyaw), math.cos(nyaw))
        r = self.params.wheel_radius_m
        half = 0.5 * self.params.wheel_separation_m
        self.wheel_angle_rad[0] += (v - w * half) * dt / r
        self.wheel_angle_rad[1] += (v + w * half) * dt / r
