"""DWB, Nav2 Humble's default local planner (`dwb_core::DWBLocalPlanner`) with TB3's parameters.

One `compute_velocity` call is one controller_server cycle (10 Hz for TB3):

1. The global plan is moved into the local costmap's frame (`plan_to_costmap` transform), pruned
   (poses behind the pose nearest the robot dropped: `prune_plan`) and cut to the poses within
   `prune_distance_m` of the robot, then to `forward_prune_distance_m` of path ahead
   (`shorten_transformed_plan`). Its last pose is the local goal.
2. Velocities are sampled in the dynamic window one controller period (`1 / controller_frequency_hz`)
   of acceleration around the current velocity: `vx_samples` x `vtheta_samples`, x outer, theta
   inner, kept when the speed limits allow them (`min/max_speed_xy`, `min_speed_theta`; not both 0).
3. Each sample becomes a trajectory over `sim_time_s`, accelerating from the current velocity under
   the limits, in steps small enough for `linear_granularity_m` and `angular_granularity_rad`.
4. Seven critics score every trajectory; the lowest weighted sum among the legal ones wins and its
   sampled velocity is the command. No legal trajectory raises `NoValidTrajectory`.

Critics (TB3 scales; Nav2 code defaults where the yaml is silent):
RotateToGoal (32, slowing factor 5, last pose's yaw), Oscillation (1; flips of the x or theta sign
without 0.05 m / 0.2 rad of motion since are illegal), BaseObstacle (0.02; max cost along the
trajectory, illegal on lethal/inscribed/unknown/off-grid), GoalAlign and PathAlign (24 / 32; the
goal/path distance of a point 0.1 m ahead of the trajectory's end, zero within 0.1 m of the goal),
PathDist and GoalDist (32 / 24; the distance in cells of the trajectory's end from the path / the
local goal).

Map-grid distances are Manhattan cell counts from the path's cells (Nav2 propagates them breadth
first around obstacles; here they are taken on the open grid with obstacle cells unreachable, which
differs only where a wall separates a trajectory's end from the path).

All samples are scored at once with numpy (trajectory poses in closed form by cumulative sums).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav._dwb_native import load_dwb_kernel
from twin.nav.costmap_grid import CostGrid

__all__ = [
    "DwbController",
    "DwbParams",
    "NoValidTrajectory",
    "Trajectories",
    "prune_and_transform_plan",
]

_INVALID_COST = 253  # inscribed, lethal and unknown are not valid for BaseObstacle


class NoValidTrajectory(RuntimeError):
    """Every sampled trajectory was illegal; DWB's 'No valid trajectories out of N!'."""


@dataclass(frozen=True, kw_only=True, slots=True)
class DwbParams:
    """DWB's parameters; defaults are TB3's Humble waffle.yaml (burger: `sim_time_s=1.5`)."""

    controller_frequency_hz: float = 10.0
    min_vel_x: float = 0.0
    max_vel_x: float = 0.22
    max_vel_theta: float = 1.0
    min_speed_xy: float = 0.0
    max_speed_xy: float = 0.22
    min_speed_theta: float = 0.0
    acc_lim_x: float = 2.5
    acc_lim_theta: float = 3.2
    decel_lim_x: float = -2.5
    decel_lim_theta: float = -3.2
    vx_samples: int = 20
    vtheta_samples: int = 40
    sim_time_s: float = 2.0
    linear_granularity_m: float = 0.05
    angular_granularity_rad: float = 0.025
    xy_goal_tolerance_m: float = 0.05
    trans_stopped_velocity: float = 0.25
    prune_plan: bool = True
    prune_distance_m: float = 2.0
    forward_prune_distance_m: float = 2.0
    shorten_transformed_plan: bool = True
    base_obstacle_scale: float = 0.02
    path_align_scale: float = 32.0
    path_align_forward_point_distance_m: float = 0.1
    goal_align_scale: float = 24.0
    goal_align_forward_point_distance_m: float = 0.1
    path_dist_scale: float = 32.0
    goal_dist_scale: float = 24.0
    rotate_to_goal_scale: float = 32.0
    rotate_to_goal_slowing_factor: float = 5.0
    oscillation_scale: float = 1.0
    oscillation_reset_dist_m: float = 0.05
    oscillation_reset_angle_rad: float = 0.2
    x_only_threshold: float = 0.05

    @classmethod
    def from_nav2(cls, section: dict[str, object]) -> DwbParams:
        """Build from a controller plugin's section of a Nav2 params file (Nav2 names; unknown keys ignored)."""
        names = {f.name for f in fields(cls)}
        renames = {
            "sim_time": "sim_time_s",
            "linear_granularity": "linear_granularity_m",
            "angular_granularity": "angular_granularity_rad",
            "xy_goal_tolerance": "xy_goal_tolerance_m",
            "prune_distance": "prune_distance_m",
            "forward_prune_distance": "forward_prune_distance_m",
            "BaseObstacle.scale": "base_obstacle_scale",
            "PathAlign.scale": "path_align_scale",
            "PathAlign.forward_point_distance": "path_align_forward_point_distance_m",
            "GoalAlign.scale": "goal_align_scale",
            "GoalAlign.forward_point_distance": "goal_align_forward_point_distance_m",
            "PathDist.scale": "path_dist_scale",
            "GoalDist.scale": "goal_dist_scale",
            "RotateToGoal.scale": "rotate_to_goal_scale",
            "RotateToGoal.slowing_factor": "rotate_to_goal_slowing_factor",
            "Oscillation.scale": "oscillation_scale",
        }
        kwargs: dict[str, object] = {}
        for key, value in section.items():
            name = renames.get(key, key)
            if name in names:
                kwargs[name] = value
        return cls(**kwargs)  # type: ignore[arg-type]


@dataclass(frozen=True, kw_only=True, slots=True)
class Trajectories:
    """The sampled trajectories of one cycle: `poses[s, k] = (x, y, yaw)`, `velocity[s] = (vx, wz)`."""

    velocity: NDArray[np.float64]
    poses: NDArray[np.float64]
    steps: NDArray[np.int64]


def prune_and_transform_plan(
    plan: NDArray[np.float64],
    pose: tuple[float, float, float],
    *,
    plan_to_costmap: tuple[float, float, float] = (0.0, 0.0, 0.0),
    prune_distance_m: float = 2.0,
    forward_prune_distance_m: float = 2.0,
    shorten: bool = True,
    costmap_extent_m: float | None = None,
) -> tuple[NDArray[np.float64], int]:
    """Return the plan in the costmap's frame cut around the robot, and the index of its first pose in `plan`.

    As DWB's `transformGlobalPlan`, poses beyond half the costmap's larger side (`costmap_extent_m`)
    are not passed on: the plan starts at the nearest pose within that distance (and
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


class DwbController:
    """DWB's per-cycle velocity choice; keeps the plan and the critics' state between cycles."""

    def __init__(self, params: DwbParams | None = None, *, native: bool = True) -> None:
        self.params = params or DwbParams()
        #: Roll trajectories out and check obstacles in C when the kernel can be built.
        self.native = native
        self._plan = np.zeros((0, 3))
        self.plan_to_costmap: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._rotate = _RotateState()
        self._osc = _OscillationState()
        #: The best trajectory of the last cycle (poses in the costmap frame): `/local_plan`.
        self.local_plan: NDArray[np.float64] = np.zeros((0, 3))
        #: The plan as transformed and cut in the last cycle (`/transformed_global_plan`).
        self.transformed_plan: NDArray[np.float64] = np.zeros((0, 3))

    def set_plan(self, plan: NDArray[np.float64]) -> None:
        """Take a new global plan (N, 3); critics reset as DWB's `setPlan` resets them."""
        self._plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)
        self._rotate = _RotateState()
        self._osc = _OscillationState()

    def _commands(self, velocity: tuple[float, float]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """The sampled commands (n, 2) and each one's number of time steps."""
        p = self.params
        dt = 1.0 / p.controller_frequency_hz
        vx = _window(
            velocity[0], p.min_vel_x, p.max_vel_x, acc=p.acc_lim_x, decel=p.decel_lim_x, dt=dt, samples=p.vx_samples
        )
        wz = _window(
            velocity[1],
            -p.max_vel_theta,
            p.max_vel_theta,
            acc=p.acc_lim_theta,
            decel=p.decel_lim_theta,
            dt=dt,
            samples=p.vtheta_samples,
        )
        cmd_x = np.repeat(vx, len(wz))
        cmd_w = np.tile(wz, len(vx))
        speed = np.abs(cmd_x)
        eps = 1e-5
        ok = speed <= p.max_speed_xy + eps
        ok &= ~((speed + eps < p.min_speed_xy) & (np.abs(cmd_w) + eps < p.min_speed_theta))
        ok &= ~((cmd_x == 0.0) & (cmd_w == 0.0))
        cmd_x, cmd_w = cmd_x[ok], cmd_w[ok]
        steps = np.maximum(
            np.ceil(
                np.maximum(
                    speed[ok] * p.sim_time_s / p.linear_granularity_m,
                    np.abs(cmd_w) * p.sim_time_s / p.angular_granularity_rad,
                )
                - 1e-9
            ),
            1,
        ).astype(np.int64)
        return np.column_stack([cmd_x, cmd_w]), steps

    def _trajectories(
        self, cmd: NDArray[np.float64], steps: NDArray[np.int64], velocity: tuple[float, float]
    ) -> Trajectories:
        p = self.params
        cmd_x, cmd_w = cmd[:, 0], cmd[:, 1]
        n_max = int(steps.max()) if len(steps) else 1
        k = np.arange(1, n_max + 1)
        step_dt = p.sim_time_s / steps
        live = k[None, :] <= steps[:, None]
        t = k[None, :] * step_dt[:, None]
        v = _ramp(velocity[0], cmd_x, p.acc_lim_x, p.decel_lim_x, t)
        w = _ramp(velocity[1], cmd_w, p.acc_lim_theta, p.decel_lim_theta, t)
        dts = np.where(live, step_dt[:, None], 0.0)
        yaw_after = np.cumsum(w * dts, axis=1)
        yaw_before = yaw_after - w * dts
        x = np.cumsum(v * np.cos(yaw_before) * dts, axis=1)
        y = np.cumsum(v * np.sin(yaw_before) * dts, axis=1)
        poses = np.zeros((len(cmd_x), n_max + 1, 3))
        poses[:, 1:, 0], poses[:, 1:, 1], poses[:, 1:, 2] = x, y, yaw_after
        return Trajectories(velocity=cmd, poses=poses, steps=steps)

    def sample(self, velocity: tuple[float, float]) -> Trajectories:
        """The cycle's trajectories from the robot at the origin (x, y, yaw = 0) moving at `velocity`."""
        cmd, steps = self._commands(velocity)
        return self._trajectories(cmd, steps, velocity)

    def _rollout(
        self,
        cmd: NDArray[np.float64],
        steps: NDArray[np.int64],
        velocity: tuple[float, float],
        pose: tuple[float, float, float],
        costmap: CostGrid,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Each trajectory's end pose (costmap frame), max cost along the way, and whether BaseObstacle allows it."""
        kernel = None if not self.native else load_dwb_kernel()
        n = len(cmd)
        if kernel is not None:
            p = self.params
            ends = np.empty((n, 3))
            max_cost = np.empty(n)
            flags = np.empty(n, dtype=np.uint8)
            cost = np.ascontiguousarray(costmap.cost)
            lim = np.array(
                [p.acc_lim_x, p.decel_lim_x, p.acc_lim_theta, p.decel_lim_theta, p.sim_time_s, velocity[0], velocity[1]]
            )
            geo = np.array([pose[0], pose[1], pose[2], costmap.origin_x_m, costmap.origin_y_m, costmap.resolution_m])
            kernel.twin_dwb_rollout(
                n,
                _ptr(np.ascontiguousarray(cmd), ctypes.c_double),
                _ptr(np.ascontiguousarray(steps), ctypes.c_long),
                _ptr(lim, ctypes.c_double),
                _ptr(geo, ctypes.c_double),
                _ptr(cost, ctypes.c_ubyte),
                costmap.rows,
                costmap.cols,
                _ptr(ends, ctypes.c_double),
                _ptr(max_cost, ctypes.c_double),
                _ptr(flags, ctypes.c_ubyte),
            )
            return ends, max_cost, flags.astype(bool)
        world = _to_frame(self._trajectories(cmd, steps, velocity).poses, pose)
        ends = world[np.arange(n), steps]
        rows, cols, inside = _cells(costmap, world[..., 0], world[..., 1])
        costs = np.where(
            inside, costmap.cost[np.clip(rows, 0, costmap.rows - 1), np.clip(cols, 0, costmap.cols - 1)], 255
        )
        ok = np.asarray(inside.all(axis=1) & (costs < _INVALID_COST).all(axis=1), dtype=bool)
        return ends, costs.max(axis=1).astype(np.float64), ok

    def compute_velocity(
        self, pose: tuple[float, float, float], velocity: tuple[float, float], costmap: CostGrid
    ) -> tuple[float, float]:
        """Choose (vx m/s, wz rad/s) for the robot at `pose` (costmap frame) moving at `velocity`.

        Raises:
            NoValidTrajectory: If no sampled trajectory is legal (or the plan is empty near the robot).
        """
        p = self.params
        local, begin = prune_and_transform_plan(
            self._plan,
            pose,
            plan_to_costmap=self.plan_to_costmap,
            prune_distance_m=p.prune_distance_m,
            forward_prune_distance_m=p.forward_prune_distance_m,
            shorten=p.shorten_transformed_plan,
            costmap_extent_m=max(costmap.cost.shape) * costmap.resolution_m / 2.0,
        )
        if len(local) == 0:
            raise NoValidTrajectory("Resulting plan has 0 poses in it.")
        if p.prune_plan and begin > 0:
            self._plan = self._plan[begin:]
        self.transformed_plan = local
        commands, steps = self._commands(velocity)
        ends, max_cost, obstacle_ok = self._rollout(commands, steps, velocity, pose, costmap)
        # The critics' goal is the global plan's end in the costmap frame (RotateToGoal, PathAlign's quiet
        # zone, GoalAlign's direction); GoalDist and GoalAlign seed from the last plan pose on the costmap.
        tx, ty, tyaw = self.plan_to_costmap
        end = self._plan[-1]
        c, s = math.cos(tyaw), math.sin(tyaw)
        goal = np.array([tx + c * end[0] - s * end[1], ty + s * end[0] + c * end[1], end[2] + tyaw])
        total, legal = self._score(
            commands=commands,
            ends=ends,
            max_cost=max_cost,
            obstacle_ok=obstacle_ok,
            local=local,
            goal=goal,
            pose=pose,
            velocity=velocity,
            costmap=costmap,
        )
        if not legal.any():
            raise NoValidTrajectory(f"No valid trajectories out of {len(legal)}!")
        best = int(np.argmin(np.where(legal, total, np.inf)))
        best_traj = self._trajectories(commands[best : best + 1], steps[best : best + 1], velocity)
        self.local_plan = _to_frame(best_traj.poses, pose)[0]
        cmd = (float(commands[best, 0]), float(commands[best, 1]))
        self._osc.debrief(cmd, pose, p)
        return cmd

    def _score(
        self,
        *,
        commands: NDArray[np.float64],
        ends: NDArray[np.float64],
        max_cost: NDArray[np.float64],
        obstacle_ok: NDArray[np.bool_],
        local: NDArray[np.float64],
        goal: NDArray[np.float64],
        pose: tuple[float, float, float],
        velocity: tuple[float, float],
        costmap: CostGrid,
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        p = self.params
        n = len(commands)
        legal = np.ones(n, dtype=bool)
        total = np.zeros(n)
        # RotateToGoal
        rot = self._rotate
        d_goal = math.hypot(pose[0] - goal[0], pose[1] - goal[1])
        rot.in_window = rot.in_window or d_goal <= p.xy_goal_tolerance_m
        speed_sq = velocity[0] ** 2
        rot.rotating = rot.rotating or (rot.in_window and speed_sq <= p.trans_stopped_velocity**2)
        if rot.in_window:
            yaw_err = np.abs(_wrap(ends[:, 2] - goal[2]))
            cmd_sq = commands[:, 0] ** 2
            if not rot.rotating:
                legal &= cmd_sq < speed_sq
                total += p.rotate_to_goal_scale * (cmd_sq * p.rotate_to_goal_slowing_factor + yaw_err)
            else:
                legal &= commands[:, 0] == 0.0
                total += p.rotate_to_goal_scale * yaw_err
        # Oscillation
        legal &= ~self._osc.oscillating(commands, pose, p)
        # BaseObstacle
        legal &= obstacle_ok
        total += p.base_obstacle_scale * max_cost
        # Map-grid critics (Humble's MapGridCritic): Manhattan cell distances from the plan's cells (PathDist,
        # PathAlign) or the goal's cell (GoalDist, GoalAlign), propagated over the whole costmap (obstacles are
        # BaseObstacle's business), scored at the trajectory's last pose (the aligns: a point `fpd` ahead of
        # it); a pose off the costmap makes the trajectory illegal. Each scale counts `0.5 * resolution` per
        # unit, as MapGridCritic::getScale. PathAlign goes quiet within `fpd` of the goal; GoalAlign draws the
        # nose to a point `fpd` beyond the goal along the robot's line to it.
        unit = 0.5 * costmap.resolution_m
        free = np.zeros(costmap.cost.shape, dtype=bool)
        path_map = _distance_map(costmap, local[:, :2], free)
        goal_map = _distance_map(costmap, _last_pose_on_costmap(local, costmap)[None, :2], free)
        to_goal = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
        fpd_goal = p.goal_align_forward_point_distance_m
        shifted = local.copy()
        shifted[-1, 0] += fpd_goal * math.cos(to_goal)
        shifted[-1, 1] += fpd_goal * math.sin(to_goal)
        nose_map = _distance_map(costmap, _last_pose_on_costmap(shifted, costmap)[None, :2], free)
        for scale, dist_map, fpd in (
            (p.path_dist_scale, path_map, 0.0),
            (p.goal_dist_scale, goal_map, 0.0),
            (p.path_align_scale, path_map, p.path_align_forward_point_distance_m),
            (p.goal_align_scale, nose_map, fpd_goal),
        ):
            if dist_map is path_map and fpd > 0.0 and d_goal <= fpd:
                continue  # PathAlign goes quiet near the goal
            px = ends[:, 0] + fpd * np.cos(ends[:, 2])
            py = ends[:, 1] + fpd * np.sin(ends[:, 2])
            r, c, ins = _cells(costmap, px, py)
            score = np.where(ins, dist_map.ravel()[np.where(ins, r * costmap.cols + c, 0)], np.inf)
            finite = np.isfinite(score)
            legal &= finite
            total += scale * unit * np.where(finite, score, 0.0)
        return total, legal


@dataclass(slots=True)
class _RotateState:
    in_window: bool = False
    rotating: bool = False


@dataclass(slots=True)
class _Trend:
    sign: int = 0
    positive_only: bool = False
    negative_only: bool = False

    def flagged(self, v: NDArray[np.float64]) -> NDArray[np.bool_]:
        if self.positive_only:
            return v < 0.0
        if self.negative_only:
            return v > 0.0
        return np.zeros(v.shape, dtype=bool)

    def update(self, v: float) -> bool:
        if v < 0.0:
            if self.sign > 0:
                self.negative_only = True
                return True
            self.sign = -1
        elif v > 0.0:
            if self.sign < 0:
                self.positive_only = True
                return True
            self.sign = 1
        return False


@dataclass(slots=True)
class _OscillationState:
    x: _Trend = field(default_factory=_Trend)
    theta: _Trend = field(default_factory=_Trend)
    flip_pose: tuple[float, float, float] | None = None

    def _maybe_reset(self, pose: tuple[float, float, float], p: DwbParams) -> None:
        if self.flip_pose is None:
            return
        moved = math.hypot(pose[0] - self.flip_pose[0], pose[1] - self.flip_pose[1])
        turned = abs(_wrap(pose[2] - self.flip_pose[2]))
        if moved > p.oscillation_reset_dist_m or turned > p.oscillation_reset_angle_rad:
            self.x, self.theta, self.flip_pose = _Trend(), _Trend(), None

    def oscillating(
        self, velocity: NDArray[np.float64], pose: tuple[float, float, float], p: DwbParams
    ) -> NDArray[np.bool_]:
        self._maybe_reset(pose, p)
        osc = self.x.flagged(velocity[:, 0])
        x_only = np.abs(velocity[:, 0]) <= p.x_only_threshold
        return osc | (x_only & self.theta.flagged(velocity[:, 1]))

    def debrief(self, cmd: tuple[float, float], pose: tuple[float, float, float], p: DwbParams) -> None:
        flipped = self.x.update(cmd[0])
        if abs(cmd[0]) <= p.x_only_threshold:
            flipped = self.theta.update(cmd[1]) or flipped
        if flipped:
            self.flip_pose = pose


def _last_pose_on_costmap(local: NDArray[np.float64], costmap: CostGrid) -> NDArray[np.float64]:
    """The goal the critics aim at: the last plan pose inside the costmap (DWB's getLastPoseOnCostmap)."""
    _, _, inside = _cells(costmap, local[:, 0], local[:, 1])
    idx = np.nonzero(inside)[0]
    return np.asarray(local[int(idx[-1])] if len(idx) else local[-1], dtype=np.float64)


def _window(
    v0: float, v_min: float, v_max: float, *, acc: float, decel: float, dt: float, samples: int
) -> NDArray[np.float64]:
    """DWB's one-dimensional velocity iterator: `samples` values over the reachable window."""

    def project(target: float) -> float:
        return max(target, v0 + decel * dt) if target < v0 else min(target, v0 + acc * dt)

    hi = min(v_max, project(v_max))
    lo = max(v_min, project(v_min))
    if samples <= 1 or hi <= lo:
        return np.array([min(max(v0, lo), hi) if hi >= lo else lo])
    return np.linspace(lo, hi, samples)


def _ramp(
    v0: float, target: NDArray[np.float64], acc: float, decel: float, t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Velocity after time t when accelerating from v0 towards each target under the limits."""
    up = np.minimum(target[:, None], v0 + acc * t)
    down = np.maximum(target[:, None], v0 + decel * t)
    return np.where((target >= v0)[:, None], up, down)


def _to_frame(poses: NDArray[np.float64], pose: tuple[float, float, float]) -> NDArray[np.float64]:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = np.empty_like(poses)
    out[..., 0] = pose[0] + c * poses[..., 0] - s * poses[..., 1]
    out[..., 1] = pose[1] + s * poses[..., 0] + c * poses[..., 1]
    out[..., 2] = pose[2] + poses[..., 2]
    return out


def _wrap(a: NDArray[np.float64] | float) -> NDArray[np.float64]:
    return np.asarray((np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi)


def _cells(
    costmap: CostGrid, x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    col = np.floor((x - costmap.origin_x_m) / costmap.resolution_m).astype(np.int64)
    row = np.floor((y - costmap.origin_y_m) / costmap.resolution_m).astype(np.int64)
    inside = (row >= 0) & (row < costmap.rows) & (col >= 0) & (col < costmap.cols)
    return row, col, inside


def _distance_map(costmap: CostGrid, points: NDArray[np.float64], blocked: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Manhattan cell distance to the cells the points fall in; inf on blocked cells (and everywhere if none inside)."""
    from scipy.ndimage import distance_transform_cdt

    rows, cols, inside = _cells(costmap, points[:, 0], points[:, 1])
    if not inside.any():
        return np.full(costmap.cost.shape, np.inf)
    seeds = np.ones(costmap.cost.shape, dtype=bool)
    seeds[rows[inside], cols[inside]] = False
    dist: NDArray[np.float64] = np.asarray(distance_transform_cdt(seeds, metric="taxicab"), dtype=np.float64)
    dist[blocked] = np.inf
    return dist


def _ptr(array: NDArray[Any], ctype: Any) -> Any:
    return array.ctypes.data_as(ctypes.POINTER(ctype))
