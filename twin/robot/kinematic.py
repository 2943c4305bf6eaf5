"""The ideal drivetrain: wheel speeds follow the command under an acceleration limit; no slip, no motors.

It does to a TurtleBot3 what Gazebo's `gazebo_ros_diff_drive` does (wheel-rim speed changes limited
to `max_wheel_acceleration_mps2`) without the motor dynamics of the FMU drivetrain. It implements
`twin.robot.drivetrain.Drivetrain`. Contact with the world is a pose refusal: a step whose end pose
the `contact` callable reports as penetrating is not taken, and the wheels stop.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from twin.robot.chassis import ChassisState, ContactFn
from twin.robot.disturbances import WheelSlip
from twin.robot.drivetrain import WheelState

__all__ = ["KinematicDrivetrain", "KinematicParams"]

DistanceFn = Callable[[float, float, float], float]

# Longest arc taken in one piece while the wheel speeds are steady: contact is checked at its end.
_MAX_CHUNK_TRAVEL_M = 0.002


@dataclass(frozen=True, kw_only=True, slots=True)
class KinematicParams:
    """Geometry and limits of the ideal drive."""

    wheel_radius_m: float
    wheel_separation_m: float
    max_wheel_acceleration_mps2: float  # math.inf for none
    bounding_radius_m: float = 0.3  # farthest point of the robot's collision shape from its base frame


class KinematicDrivetrain:
    """Ideal differential drive with an acceleration limit and stop-at-contact."""

    def __init__(
        self,
        params: KinematicParams,
        *,
        step_ns: int,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        contact: ContactFn | None = None,
        free_distance: DistanceFn | None = None,
        slip: WheelSlip | None = None,
    ) -> None:
        """Set up at rest at `pose`.

        Args:
            params: Geometry and limits.
            step_ns: The physics step, ns.
            pose: Initial (x_m, y_m, yaw_rad).
            contact: `(x, y, yaw) -> bool`, True if that pose would penetrate the world.
            free_distance: `(x, y, yaw) -> m` the robot may move from there with no contact possible
                (e.g. `CollisionMonitor.free_m`); lets steady motion take longer pieces.
            slip: Wheel slip: each wheel's ground speed is (1 - fraction) times its rim speed, with the
                fractions looked up where the robot is at the start of each piece of motion.
        """
        self.params = params
        self.label = "kinematic"
        no_slip = slip is None or (slip.is_uniform and slip.left_fraction == 0.0 and slip.right_fraction == 0.0)
        self._slip = None if no_slip else slip
        self._free = free_distance
        self.step_ns = step_ns
        self._dt = step_ns * 1e-9
        self._contact = contact
        self.x_m, self.y_m, self.yaw_rad = pose
        self.v_mps = self.w_radps = 0.0
        self._accel = (0.0, 0.0, 0.0)  # longitudinal, lateral, yaw
        self.blocked = False
        self.angle_rad = [0.0, 0.0]  # left, right
        self._rim = [0.0, 0.0]  # wheel-rim speeds, m/s
        self._target = [0.0, 0.0]

    def set_cmd_vel(self, v_mps: float, w_radps: float) -> None:
        """Set the commanded body velocity; it holds until the next command."""
        half = 0.5 * self.params.wheel_separation_m
        self._target[0] = v_mps - w_radps * half
        self._target[1] = v_mps + w_radps * half

    def advance(self, n_steps: int) -> None:
        """Advance `n_steps` physics steps."""
        p = self.params
        dt = self._dt
        dv_max = p.max_wheel_acceleration_mps2 * dt
        inv_track = 1.0 / p.wheel_separation_m
        reach = 0.5 + p.bounding_radius_m * inv_track  # farthest point's travel per unit of |rim| speed
        rim, target = self._rim, self._target
        contact, free = self._contact, self._free
        v0, w0 = self.v_mps, self.w_radps
        # Motion known to be free of contact: no check is needed until it is used up.
        budget = math.inf if contact is None else (free(self.x_m, self.y_m, self.yaw_rad) if free else 0.0)
        used = 0.0
        steps_left = n_steps
        while steps_left > 0:
            n = 1
            if rim[0] == target[0] and rim[1] == target[1]:
                n = steps_left  # steady wheel speeds: one exact arc, in pieces when near the world
                per_step = (abs(rim[0]) + abs(rim[1])) * reach * dt
                if per_step * n > budget - used and per_step * n > _MAX_CHUNK_TRAVEL_M:
                    n = max(1, int(max(budget - used, _MAX_CHUNK_TRAVEL_M) / per_step))
            else:
                for i in (0, 1):
                    err = target[i] - rim[i]
                    rim[i] = target[i] if abs(err) <= dv_max else rim[i] + math.copysign(dv_max, err)
            if self._slip is None:
                v = 0.5 * (rim[0] + rim[1])
                w = (rim[1] - rim[0]) * inv_track
            else:
                slip_left, slip_right = self._slip.fractions_at(self.x_m, self.y_m)
                ground_left, ground_right = (1.0 - slip_left) * rim[0], (1.0 - slip_right) * rim[1]
                v = 0.5 * (ground_left + ground_right)
                w = (ground_right - ground_left) * inv_track
            if v != 0.0 or w != 0.0:
                travel = (abs(rim[0]) + abs(rim[1])) * reach * dt * n
                used += travel
                if used < budget:
                    self._move(v, w, n * dt, None)
                elif self._move(v, w, n * dt, contact):
                    budget, used = (free(self.x_m, self.y_m, self.yaw_rad) if free else 0.0), 0.0
                else:
                    rim[0] = rim[1] = 0.0
                    v = w = 0.0
            steps_left -= n
            self.v_mps, self.w_radps = v, w
        total_dt = n_steps * dt
        self._accel = ((self.v_mps - v0) / total_dt, self.v_mps * self.w_radps, (self.w_radps - w0) / total_dt)

    def _move(self, v: float, w: float, dt: float, contact: ContactFn | None) -> bool:
        """Move along the arc (v, w) for dt; return False (and stay) if `contact` refuses the end pose."""
        x, y, yaw = self.x_m, self.y_m, self.yaw_rad
        dyaw = w * dt
        if abs(dyaw) < 1e-9:
            nx = x + v * dt * math.cos(yaw + 0.5 * dyaw)
            ny = y + v * dt * math.sin(yaw + 0.5 * dyaw)
        else:
            radius = v / w
            nx = x + radius * (math.sin(yaw + dyaw) - math.sin(yaw))
            ny = y - radius * (math.cos(yaw + dyaw) - math.cos(yaw))
        nyaw = yaw + dyaw
        if nyaw > math.pi or nyaw < -math.pi:
            nyaw = math.atan2(math.sin(nyaw), math.cos(nyaw))
        if contact is not None:
            if contact(nx, ny, nyaw):
                self.blocked = True
                return False
            self.blocked = False
        self.x_m, self.y_m, self.yaw_rad = nx, ny, nyaw
        inv_r = 1.0 / self.params.wheel_radius_m
        self.angle_rad[0] += self._rim[0] * dt * inv_r  # the wheels turn with their rims, slip or not
        self.angle_rad[1] += self._rim[1] * dt * inv_r
        return True

    def chassis_state(self) -> ChassisState:
        """Pose, rates and accelerations of the chassis now."""
        ax, ay, alpha = self._accel
        return ChassisState(self.x_m, self.y_m, self.yaw_rad, self.v_mps, self.w_radps, ax, ay, alpha, self.blocked)

    def wheel_state(self) -> WheelState:
        """Wheel angles and speeds now; ideal wheels have no torque, voltage or current (NaN)."""
        inv_r = 1.0 / self.params.wheel_radius_m
        nan = (math.nan, math.nan)
        return WheelState(
            angle_rad=(self.angle_rad[0], self.angle_rad[1]),
            speed_radps=(self._rim[0] * inv_r, self._rim[1] * inv_r),
            effort_nm=nan,
            voltage_v=nan,
            current_a=nan,
        )

    def close(self) -> None:
        """Nothing to release."""
