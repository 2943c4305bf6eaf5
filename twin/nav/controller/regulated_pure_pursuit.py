"""Regulated Pure Pursuit (`nav2_regulated_pure_pursuit_controller`), Humble's parameters and regulation.

Per cycle: the plan is cut around the robot (as DWB does), a carrot is taken `lookahead_dist_m`
along it (or `lookahead_time_s` x speed, clamped, with `use_velocity_scaled_lookahead_dist`); the
command turns at curvature 2 y / L^2 towards it, at `desired_linear_vel` slowed by the path's
curvature (below `regulated_linear_scaling_min_radius_m`), by the cost under the robot, and on the
approach to the goal (down to `min_approach_linear_velocity`). With `use_rotate_to_heading` the robot
first turns in place towards a carrot more than `rotate_to_heading_min_angle_rad` off its heading,
and towards the goal's yaw once at the goal. Angular speed changes are limited by
`max_angular_accel`. A collision found along the arc to the carrot (lethal or inscribed cell within
`max_allowed_time_to_collision_up_to_carrot_s`) raises `NoValidCommand`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["NoValidCommand", "RppController", "RppParams"]


class NoValidCommand(RuntimeError):
    """RPP found a collision ahead or has no plan near the robot."""


@dataclass(frozen=True, kw_only=True, slots=True)
class RppParams:
    """RPP's parameters; defaults are Nav2 Humble's code defaults with TB3's speed (0.22 m/s)."""

    controller_frequency_hz: float = 10.0
    desired_linear_vel: float = 0.22
    lookahead_dist_m: float = 0.6
    min_lookahead_dist_m: float = 0.3
    max_lookahead_dist_m: float = 0.9
    lookahead_time_s: float = 1.5
    use_velocity_scaled_lookahead_dist: bool = False
    rotate_to_heading_angular_vel: float = 1.0
    min_approach_linear_velocity: float = 0.05
    approach_velocity_scaling_dist_m: float = 0.6
    use_regulated_linear_velocity_scaling: bool = True
    use_cost_regulated_linear_velocity_scaling: bool = True
    regulated_linear_scaling_min_radius_m: float = 0.9
    regulated_linear_scaling_min_speed: float = 0.25
    use_rotate_to_heading: bool = True
    rotate_to_heading_min_angle_rad: float = 0.785
    max_angular_accel: float = 3.2
    cost_scaling_dist_m: float = 0.3
    cost_scaling_gain: float = 1.0
    use_collision_detection: bool = True
    max_allowed_time_to_collision_up_to_carrot_s: float = 1.0
    goal_dist_tol_m: float = 0.25
    max_angular_vel: float = 1.0

    @classmethod
    def from_nav2(cls, section: dict[str, object]) -> RppParams:
        """Build from the plugin's params-file section (Nav2 names; unknown keys ignored)."""
        names = {f.name for f in fields(cls)}
        renames = {
            "lookahead_dist": "lookahead_dist_m",
            "min_lookahead_dist": "min_lookahead_dist_m",
            "max_lookahead_dist": "max_lookahead_dist_m",
            "lookahead_time": "lookahead_time_s",
            "approach_velocity_scaling_dist": "approach_velocity_scaling_dist_m",
            "regulated_linear_scaling_min_radius": "regulated_linear_scaling_min_radius_m",
            "rotate_to_heading_min_angle": "rotate_to_heading_min_angle_rad",
            "cost_scaling_dist": "cost_scaling_dist_m",
            "max_allowed_time_to_collision_up_to_carrot": "max_allowed_time_to_collision_up_to_carrot_s",
        }
        kwargs = {renames.get(k, k): v for k, v in section.items() if renames.get(k, k) in names}
        return cls(**kwargs)  # type: ignore[arg-type]


class RppController:
    """Regulated Pure Pursuit; same interface as `DwbController`."""

    def __init__(self, params: RppParams | None = None) -> None:
        self.params = params or RppParams()
        self._plan = np.zeros((0, 3))
        self._last_w = 0.0
        self.plan_to_costmap: tuple[float, float, float] = (0.0, 0.0, 0.0)
        #: The arc to the carrot checked for collisions in the last cycle.
        self.local_plan: NDArray[np.float64] = np.zeros((0, 3))

    def set_plan(self, plan: NDArray[np.float64]) -> None:
        """Take a new global plan (N, 3)."""
        self._plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)

    def compute_velocity(
        self, pose: tuple[float, float, float], velocity: tuple[float, float], costmap: CostGrid
    ) -> tuple[float, float]:
        """Return (vx, wz) for the robot at `pose` (costmap frame).

        Raises:
            NoValidCommand: If the plan has no pose near the robot or a collision lies ahead.
        """
        p = self.params
        lookahead = p.lookahead_dist_m
        if p.use_velocity_scaled_lookahead_dist:
            lookahead = min(max(abs(velocity[0]) * p.lookahead_time_s, p.min_lookahead_dist_m), p.max_lookahead_dist_m)
        local, begin = _prune_and_transform_plan(
            self._plan, pose, plan_to_costmap=self.plan_to_costmap, prune_distance_m=max(lookahead, 2.0), shorten=False
        )
        if len(local) == 0:
            raise NoValidCommand("Resulting plan has 0 poses in it.")
        if begin > 0:
            self._plan = self._plan[begin:]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rel_x = c * (local[:, 0] - pose[0]) + s * (local[:, 1] - pose[1])
        rel_y = -s * (local[:, 0] - pose[0]) + c * (local[:, 1] - pose[1])
        dist = np.hypot(rel_x, rel_y)
        ahead = np.nonzero(dist >= lookahead)[0]
        k = int(ahead[0]) if len(ahead) else len(local) - 1
        cx, cy = float(rel_x[k]), float(rel_y[k])
        carrot_d2 = cx * cx + cy * cy
        curvature = 2.0 * cy / carrot_d2 if carrot_d2 > 1e-9 else 0.0
        goal_rel = math.hypot(float(rel_x[-1]), float(rel_y[-1]))
        dt = 1.0 / p.controller_frequency_hz
        angle_to_carrot = math.atan2(cy, cx)
        if p.use_rotate_to_heading and goal_rel < p.goal_dist_tol_m:
            yaw_err = (float(local[-1, 2]) - pose[2] + math.pi) % (2 * math.pi) - math.pi
            return self._rotate(yaw_err, velocity, dt)
        if p.use_rotate_to_heading and abs(angle_to_carrot) > p.rotate_to_heading_min_angle_rad:
            return self._rotate(angle_to_carrot, velocity, dt)
        v = p.desired_linear_vel
        if p.use_regulated_linear_velocity_scaling and abs(curvature) > 1e-9:
            radius = abs(1.0 / curvature)
            if radius < p.regulated_linear_scaling_min_radius_m:
                v *= radius / p.regulated_linear_scaling_min_radius_m
        if p.use_cost_regulated_linear_velocity_scaling:
            cost = costmap.cost_at(pose[0], pose[1])
            if 0 < cost < 253:
                inscribed_cost = 253.0
                # distance to obstacle from the inflation law cost = 252 exp(-k (d - r)) with k from the params
                d_obs = -math.log(max(cost, 1) / (inscribed_cost - 1.0)) / 3.0
                if d_obs < p.cost_scaling_dist_m:
                    v *= p.cost_scaling_gain * d_obs / p.cost_scaling_dist_m
        v = max(v, p.regulated_linear_scaling_min_speed)
        if goal_rel < p.approach_velocity_scaling_dist_m:
            v = max(v * goal_rel / p.approach_velocity_scaling_dist_m, p.min_approach_linear_velocity)
        v = min(v, p.desired_linear_vel)
        w = max(-p.max_angular_vel, min(p.max_angular_vel, v * curvature))
        if p.use_collision_detection:
            self._check_collision(pose, v, w, math.sqrt(carrot_d2), costmap)
        self._last_w = w
        return v, w

    def _rotate(self, angle: float, velocity: tuple[float, float], dt: float) -> tuple[float, float]:
        p = self.params
        w = math.copysign(p.rotate_to_heading_angular_vel, angle)
        lo, hi = velocity[1] - p.max_angular_accel * dt, velocity[1] + p.max_angular_accel * dt
        w = min(max(w, lo), hi)
        self._last_w = w
        return 0.0, w

    def _check_collision(
        self, pose: tuple[float, float, float], v: float, w: float, carrot_m: float, costmap: CostGrid
    ) -> None:
        p = self.params
        if v <= 0.0:
            return
        horizon = min(p.max_allowed_time_to_collision_up_to_carrot_s, carrot_m / v)
        t = np.linspace(0.0, horizon, max(2, int(horizon * v / costmap.resolution_m) + 2))
        yaw = pose[2] + w * t
        if abs(w) > 1e-9:
            x = pose[0] + v / w * (np.sin(yaw) - math.sin(pose[2]))
            y = pose[1] - v / w * (np.cos(yaw) - math.cos(pose[2]))
        else:
            x = pose[0] + v * t * math.cos(pose[2])
            y = pose[1] + v * t * math.sin(pose[2])
        self.local_plan = np.column_stack([x, y, yaw])
        col = np.floor((x - costmap.origin_x_m) / costmap.resolution_m).astype(np.int64)
        row = np.floor((y - costmap.origin_y_m) / costmap.resolution_m).astype(np.int64)
        inside = (row >= 0) & (row < costmap.rows) & (col >= 0) & (col < costmap.cols)
        costs = costmap.cost[row[inside], col[inside]]
        if ((costs == 253) | (costs == 254)).any():
            raise NoValidCommand("RegulatedPurePursuitController detected collision ahead!")


def _prune_and_transform_plan(
    plan: NDArray[np.float64],
    pose: tuple[float, float, float],
    *,
    plan_to_costmap: tuple[float, float, float] = (0.0, 0.0, 0.0),
    prune_distance_m: float = 2.0,
    forward_prune_distance_m: float = 2.0,
    shorten: bool = True,
    costmap_extent_m: float | None = None,
) -> tuple[NDArray[np.float64], int]:
    """Return the plan in the costmap frame cut around the robot, and the index of its first pose in `plan`.

    As RPP's `transformGlobalPlan`: poses beyond half the costmap's larger side (`costmap_extent_m`)
    are not passed on; the plan starts at the pose nearest the robot within that distance (and
    `prune_distance_m`) and, with `shorten`, ends at the first pose farther than both from the robot.

    Args:
        plan: Global plan poses (N, 3) in the plan's frame.
        pose: Robot pose (x, y, yaw) in the costmap's frame.
        plan_to_costmap: The plan frame's pose in the costmap frame (e.g. map in odom).
        prune_distance_m: Poses farther than this from the robot are not transformed.
        forward_prune_distance_m: Path length kept ahead of the pose nearest the robot.
        shorten: Apply `forward_prune_distance_m`.
        costmap_extent_m: Half the costmap's larger side (None: no costmap limit).
    """
    tx, ty, tyaw = plan_to_costmap
    c, s = math.cos(tyaw), math.sin(tyaw)
    local = np.empty_like(plan)
    local[:, 0] = tx + c * plan[:, 0] - s * plan[:, 1]
    local[:, 1] = ty + s * plan[:, 0] + c * plan[:, 1]
    local[:, 2] = plan[:, 2] + tyaw
    d = np.hypot(local[:, 0] - pose[0], local[:, 1] - pose[1])
    threshold = prune_distance_m if costmap_extent_m is None else min(prune_distance_m, costmap_extent_m)
    near = d <= threshold
    if not near.any():
        return local[:0], len(plan)
    first_near = int(np.argmax(near))
    # the closest pose among the first run of near poses
    run_end = first_near + (
        int(np.argmin(near[first_near:])) if not near[first_near:].all() else len(plan) - first_near
    )
    begin = first_near + int(np.argmin(d[first_near:run_end]))
    end = run_end
    if shorten:
        seg = np.hypot(*np.diff(local[begin:end, :2], axis=0).T)
        along = np.concatenate([[0.0], np.cumsum(seg)])
        end = begin + int(np.searchsorted(along, forward_prune_distance_m, side="right"))
        if costmap_extent_m is not None:
            beyond = np.nonzero(d[begin:end] > threshold)[0]
            if len(beyond):
                end = begin + max(1, int(beyond[0]))
    return local[begin:end], begin
