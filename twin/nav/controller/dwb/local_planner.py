"""DWB, Nav2 Humble's default local planner (`dwb_core::DWBLocalPlanner`), with TB3's parameters.

One `compute_velocity` call is one controller_server cycle (10 Hz for TB3), as Humble runs it:

1. **transformGlobalPlan.** In the plan's frame, the plan is searched up to the first pose more than
   `prune_distance_m` along it; the first of those within min(half the costmap, prune distance) of the
   robot begins the part passed on, which ends at the first pose farther than min(half the costmap,
   `forward_prune_distance_m`) from the robot. With `prune_plan` the poses before it are dropped for
   good. The plan's last pose, in the costmap's frame, is the goal.
2. **Critics prepare.** RotateToGoal latches "in the window" within the planner's own
   `xy_goal_tolerance_m` of the goal and "rotating" once also slower than `trans_stopped_velocity`.
   The map-grid critics walk the cut plan at the costmap's resolution (adjustPlanResolution) over
   the known cells on the costmap: PathDist and PathAlign seed every such pose, GoalDist the last
   one, GoalAlign the last one of the plan whose end is moved `forward_point_distance` further along
   the robot's line to the goal; each fills the costmap with Manhattan cell distances to its seeds.
   PathAlign falls silent within its forward point distance of the goal.
3. **Velocity samples** (XYThetaIterator): `vx_samples` x `vtheta_samples` over the velocities
   reachable within `sim_time_s` from the odometry's velocity (StandardTrajectoryGenerator; one
   controller period with LimitedAccelGenerator), x outer, theta inner, a zero inserted where a
   range crosses it, those the speed limits forbid left out.
4. **Trajectories**: `sim_time_s` in steps short enough for `linear_granularity_m` and
   `angular_granularity_rad`, the velocity ramping towards the sample under the acceleration limits
   each step (held at the sample with LimitedAccelGenerator), the pose advancing with the heading
   before the step; the start pose and (include_last_point) the end twice are part of it.
5. **Scores**, in the critics' order, each times its scale (map-grid critics: times half a cell):
   RotateToGoal (0 outside the window; then only slower samples, `slowing_factor` x speed^2 + the
   end's yaw error; once rotating, only turns in place, the yaw error), Oscillation (a sample
   flipping the sign of x, or of theta, after such a flip is illegal), BaseObstacle (any pose off the
   costmap or on a lethal, inscribed or unknown cell is illegal; the score is the last pose's cost),
   PathDist and GoalDist (the end pose's distance; any pose off the costmap is illegal), GoalAlign
   and PathAlign (the distance of a point `forward_point_distance` ahead of the end pose; that point
   off the costmap is illegal). The first sample with the lowest total wins; none legal raises
   `NoValidTrajectory` ("No valid trajectories out of N!").
6. **Debrief**: Oscillation records the chosen command's signs and forgets them once the robot has
   moved `oscillation_reset_dist_m` or turned `oscillation_reset_angle_rad` since the flip. A new
   plan (`set_plan`, each replan) resets RotateToGoal and Oscillation, as DWB's setPlan does.

The cycle runs in C (`dwb_kernel.c`) when a compiler is available; `DwbController(native=
False)` runs the same cycle with numpy (the reference: the tests compare the two).
"""

from __future__ import annotations

import ctypes
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.core.native import CLibrary, load_library
from twin.nav.controller.dwb.critics import (
    CriticState,
    manhattan_distances,
    shortest_angle,
    trajectory_cells,
    walk_plan,
)
from twin.nav.controller.dwb.dwb_params import CRITICS, INVALID_COST, MAP_GRID_CRITICS, DwbParams, NoValidTrajectory
from twin.nav.controller.dwb.trajectory_generator import Trajectories, generate_trajectories, velocity_samples
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["DwbController", "DwbParams", "Evaluation", "NoValidTrajectory"]

F64 = NDArray[np.float64]
Pose = tuple[float, float, float]

# --- the kernel's parameter and state layout (see dwb_kernel.c) ----------------------------------

_P_CRITICS = 29
(_S_X, _S_Y, _S_YAW, _S_VX, _S_VTH, _S_TX, _S_TY, _S_TYAW, _S_IN_WINDOW, _S_ROTATING) = range(10)
_S_OSC = 10  # x positive-only, x negative-only, theta positive-only, theta negative-only
_O_STATUS, _O_VX, _O_VTH, _O_TOTAL, _O_N_SAMPLES, _O_N_LEGAL, _O_BEGIN, _O_END, _O_N_TRAJ = range(9)
_STATUS_OK, _STATUS_NO_LEGAL, _STATUS_EMPTY_TRANSFORMED, _STATUS_EMPTY_PLAN, _STATUS_NO_MEMORY = range(5)

_KERNEL = CLibrary(name="twin_dwb_cycle", files=(Path(__file__).with_name("dwb_kernel.c"),))


@functools.cache
def _kernel() -> Any:
    lib = load_library(_KERNEL)
    if lib is None:
        return None
    dbl = ctypes.POINTER(ctypes.c_double)
    lib.twin_dwb_cycle.argtypes = [
        dbl, dbl, dbl, ctypes.c_long, ctypes.POINTER(ctypes.c_ubyte), ctypes.c_long, ctypes.c_long,
        ctypes.c_double, ctypes.c_double, ctypes.c_double, dbl, dbl, ctypes.c_long,
    ]  # fmt: skip
    lib.twin_dwb_cycle.restype = ctypes.c_int
    return lib


def _parameter_block(p: DwbParams) -> F64:
    values = [
        p.min_vel_x, p.max_vel_x, -p.max_vel_theta, p.max_vel_theta,
        p.acc_lim_x, p.decel_lim_x, p.acc_lim_theta, p.decel_lim_theta,
        p.min_speed_xy, p.max_speed_xy, p.min_speed_theta,
        float(p.vx_samples), float(p.vtheta_samples),
        p.sim_time_s, p.linear_granularity_m, p.angular_granularity_rad,
        p.window_time_s, float(p.limited_accel),
        float(p.prune_plan), p.prune_distance_m, p.forward_prune_distance_m, float(p.shorten_transformed_plan),
        p.xy_goal_tolerance_m, p.trans_stopped_velocity, p.rotate_to_goal_slowing_factor,
        p.path_align_forward_point_distance_m, p.goal_align_forward_point_distance_m,
        float(p.include_last_point), float(len(p.critics)),
    ]  # fmt: skip
    assert len(values) == _P_CRITICS
    for name in p.critics:
        values += [float(CRITICS[name]), p.scale(name)]
    return np.array(values, dtype=np.float64)


def _ptr(array: NDArray[Any], ctype: Any) -> Any:
    return array.ctypes.data_as(ctypes.POINTER(ctype))


class DwbController:
    """DWB's per-cycle velocity choice (see the module docstring); keeps the plan and critics between cycles.

    Args:
        params: DWB's parameters (TB3's by default).
        native: Run the cycle in C when the kernel builds (else numpy, the reference).
    """

    def __init__(self, params: DwbParams | None = None, *, native: bool = True) -> None:
        self.params = params or DwbParams()
        unknown = [c for c in self.params.critics if c not in CRITICS]
        if unknown:
            msg = f"DWB critics the twin lacks: {unknown}; it has {list(CRITICS)}"
            raise ValueError(msg)
        self._kernel = _kernel() if native else None
        self.native = self._kernel is not None
        self._plan: F64 = np.zeros((0, 3))
        #: The plan frame's pose in the costmap's frame (map in odom); set before each cycle.
        self.plan_to_costmap: Pose = (0.0, 0.0, 0.0)
        self._critics = CriticState()
        #: The best trajectory of the last cycle (poses in the costmap frame): `/local_plan`.
        self.local_plan: F64 = np.zeros((0, 3))
        self._par = _parameter_block(self.params)
        self._state = np.zeros(14)
        self._out = np.zeros(9)
        self._traj = np.zeros((self.params.max_steps() + 3, 3))
        self._pointers = (_ptr(self._par, ctypes.c_double), _ptr(self._state, ctypes.c_double))
        self._out_ptr = _ptr(self._out, ctypes.c_double)
        self._traj_ptr = _ptr(self._traj, ctypes.c_double)
        self._plan_ptr: Any = None
        self._cost_key: tuple[int, int] | None = None
        self._cost_ptr: Any = None

    def set_plan(self, plan: F64) -> None:
        """Take a new global plan (N, 3); RotateToGoal and Oscillation reset, as DWB's setPlan resets them."""
        self._plan = np.ascontiguousarray(plan, dtype=np.float64).reshape(-1, 3)
        self._plan_ptr = _ptr(self._plan, ctypes.c_double)
        self._critics.reset()

    def sample(self, velocity: tuple[float, float]) -> Trajectories:
        """The cycle's samples and trajectories from the origin (x, y, yaw = 0) at `velocity` (numpy path)."""
        cmd = velocity_samples(self.params, velocity)
        return generate_trajectories(self.params, cmd, (0.0, 0.0, 0.0), velocity)

    def compute_velocity(self, pose: Pose, velocity: tuple[float, float], costmap: CostGrid) -> tuple[float, float]:
        """Choose (vx m/s, wz rad/s) for the robot at `pose` (costmap frame) moving at `velocity`.

        Raises:
            NoValidTrajectory: No sampled trajectory is legal, or the plan has no pose near the robot.
        """
        if self._kernel is not None:
            return self._compute_native(pose, velocity, costmap)
        return self._compute_numpy(pose, velocity, costmap)

    # -- C ------------------------------------------------------------------------------------------

    def _compute_native(self, pose: Pose, velocity: tuple[float, float], costmap: CostGrid) -> tuple[float, float]:
        st, cr = self._state, self._critics
        st[_S_X], st[_S_Y], st[_S_YAW] = pose
        st[_S_VX], st[_S_VTH] = velocity
        st[_S_TX], st[_S_TY], st[_S_TYAW] = self.plan_to_costmap
        st[_S_IN_WINDOW], st[_S_ROTATING] = cr.in_window, cr.rotating
        st[_S_OSC : _S_OSC + 4] = (
            cr.x.positive_only,
            cr.x.negative_only,
            cr.theta.positive_only,
            cr.theta.negative_only,
        )
        cost = costmap.cost
        key = (id(cost), cost.ctypes.data)
        if key != self._cost_key:
            if not (cost.flags.c_contiguous and cost.dtype == np.uint8):
                msg = "the costmap must be a C-contiguous uint8 array"
                raise ValueError(msg)
            self._cost_key, self._cost_ptr, self._cost_ref = key, _ptr(cost, ctypes.c_ubyte), cost
        par_ptr, st_ptr = self._pointers
        kernel = self._kernel
        assert kernel is not None
        status = kernel.twin_dwb_cycle(
            par_ptr, st_ptr, self._plan_ptr, len(self._plan), self._cost_ptr, cost.shape[0], cost.shape[1],
            costmap.origin_x_m, costmap.origin_y_m, costmap.resolution_m, self._out_ptr, self._traj_ptr,
            len(self._traj),
        )  # fmt: skip
        out = self._out
        cr.in_window, cr.rotating = bool(st[_S_IN_WINDOW]), bool(st[_S_ROTATING])
        if status == _STATUS_EMPTY_PLAN:
            raise NoValidTrajectory("Received plan with zero length")
        begin = int(out[_O_BEGIN])
        if self.params.prune_plan and begin > 0:
            self.set_plan_keeping_critics(self._plan[begin:])
        if status == _STATUS_EMPTY_TRANSFORMED:
            raise NoValidTrajectory("Resulting plan has 0 poses in it.")
        if status == _STATUS_NO_MEMORY:
            raise MemoryError("DWB kernel: out of memory")
        if status == _STATUS_NO_LEGAL:
            cr.debrief((0.0, 0.0), pose, self.params)
            self.local_plan = np.zeros((0, 3))
            raise NoValidTrajectory(f"No valid trajectories out of {int(out[_O_N_SAMPLES])}!")
        cmd = (float(out[_O_VX]), float(out[_O_VTH]))
        self.local_plan = self._traj[: int(out[_O_N_TRAJ])].copy()
        cr.debrief(cmd, pose, self.params)
        return cmd

    def set_plan_keeping_critics(self, plan: F64) -> None:
        """Replace the plan without resetting the critics (the pruning of passed poses)."""
        self._plan = np.ascontiguousarray(plan, dtype=np.float64).reshape(-1, 3)
        self._plan_ptr = _ptr(self._plan, ctypes.c_double)

    # -- numpy (the reference) ----------------------------------------------------------------------

    def evaluate(self, pose: Pose, velocity: tuple[float, float], costmap: CostGrid) -> Evaluation:
        """The numpy cycle's prepare and scoring, every sample kept (`_compute_numpy` chooses from it).

        Runs transformGlobalPlan (pruning the plan as the cycle does) and the critics' prepare (RotateToGoal
        latches); the samples' per-critic raw scores and which critic makes each illegal, in the critics' order.

        Raises:
            NoValidTrajectory: The plan is empty, or no pose of it is near the robot.
        """
        p, cr = self.params, self._critics
        if len(self._plan) == 0:
            raise NoValidTrajectory("Received plan with zero length")
        local, begin, end_index = _transform_global_plan(self._plan, pose, self.plan_to_costmap, p, costmap)
        if p.prune_plan and begin > 0:
            self.set_plan_keeping_critics(self._plan[begin:])
        if len(local) == 0:
            raise NoValidTrajectory("Resulting plan has 0 poses in it.")
        tx, ty, tyaw = self.plan_to_costmap
        c, s = math.cos(tyaw), math.sin(tyaw)
        end = self._plan[-1]
        goal = (tx + c * end[0] - s * end[1], ty + s * end[0] + c * end[1], float(end[2]) + tyaw)
        # prepare
        dxy_sq = (pose[0] - goal[0]) * (pose[0] - goal[0]) + (pose[1] - goal[1]) * (pose[1] - goal[1])
        cur_sq = velocity[0] * velocity[0]
        cr.in_window = cr.in_window or dxy_sq <= p.xy_goal_tolerance_m * p.xy_goal_tolerance_m
        cr.rotating = cr.rotating or (cr.in_window and cur_sq <= p.trans_stopped_velocity * p.trans_stopped_velocity)
        active = [name for name in p.critics if p.scale(name) != 0.0]
        fpd_path, fpd_goal = p.path_align_forward_point_distance_m, p.goal_align_forward_point_distance_m
        if "PathAlign" in active and dxy_sq <= fpd_path * fpd_path:
            active.remove("PathAlign")
        unreachable = float(costmap.rows * costmap.cols + 1)
        maps: dict[str, F64 | None] = {}
        if "PathDist" in active or "PathAlign" in active:
            seeds = walk_plan(local[:, :2], costmap, last_only=False)
            maps["path"] = manhattan_distances(costmap, seeds) if seeds else None
        if "GoalDist" in active:
            seeds = walk_plan(local[:, :2], costmap, last_only=True)
            maps["goal"] = manhattan_distances(costmap, seeds) if seeds else None
        if "GoalAlign" in active:
            shifted = local[:, :2].copy()
            angle = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
            shifted[-1, 0] += fpd_goal * math.cos(angle)
            shifted[-1, 1] += fpd_goal * math.sin(angle)
            seeds = walk_plan(shifted, costmap, last_only=True)
            maps["align"] = manhattan_distances(costmap, seeds) if seeds else None
        commands = velocity_samples(p, velocity)
        traj = generate_trajectories(p, commands, pose, velocity)
        raw, illegal = self._score(
            traj, active=active, maps=maps, goal=goal, cur_sq=cur_sq, costmap=costmap, unreachable=unreachable
        )
        unit = 0.5 * costmap.resolution_m
        scales = np.array(
            [
                0.0 if name not in active else p.scale(name) * unit if name in MAP_GRID_CRITICS else p.scale(name)
                for name in p.critics
            ]
        )
        return Evaluation(
            begin=begin, end=begin + end_index, goal=goal, trajectories=traj, critics=p.critics, scales=scales,
            raw=raw, illegal=illegal,
        )  # fmt: skip

    def _compute_numpy(self, pose: Pose, velocity: tuple[float, float], costmap: CostGrid) -> tuple[float, float]:
        p, cr = self.params, self._critics
        ev = self.evaluate(pose, velocity, costmap)
        commands = ev.trajectories.velocity
        n = len(commands)
        legal = ev.legal
        if not legal.any():
            cr.debrief((0.0, 0.0), pose, p)
            self.local_plan = np.zeros((0, 3))
            raise NoValidTrajectory(f"No valid trajectories out of {n}!")
        best = int(np.argmin(np.where(legal, ev.total, np.inf)))
        one = generate_trajectories(p, commands[best : best + 1], pose, velocity)
        poses = one.poses[0, : int(one.steps[0]) + 1]
        if p.include_last_point:
            poses = np.vstack([poses, poses[-1:]])
        self.local_plan = poses
        cmd = (float(commands[best, 0]), float(commands[best, 1]))
        cr.debrief(cmd, pose, p)
        return cmd

    def _score(
        self,
        traj: Trajectories,
        *,
        active: list[str],
        maps: Mapping[str, F64 | None],
        goal: Pose,
        cur_sq: float,
        costmap: CostGrid,
        unreachable: float,
    ) -> tuple[F64, NDArray[np.bool_]]:
        """Each configured critic's raw score (NaN when it does not score) and illegal flags, per sample."""
        p, cr = self.params, self._critics
        cmd = traj.velocity
        n = len(cmd)
        raw = np.full((n, len(p.critics)), np.nan)
        illegal = np.zeros((n, len(p.critics)), dtype=bool)
        k = np.arange(traj.poses.shape[1])
        live = k[None, :] <= traj.steps[:, None]
        row, col, inside = trajectory_cells(costmap, traj.poses[..., 0], traj.poses[..., 1])
        on_grid = np.where(live, inside, True).all(axis=1)
        cost = np.where(inside, costmap.cost[np.clip(row, 0, costmap.rows - 1), np.clip(col, 0, costmap.cols - 1)], 255)
        ends = traj.poses[np.arange(n), traj.steps]
        end_cost = cost[np.arange(n), traj.steps].astype(np.float64)
        speed_sq = cmd[:, 0] * cmd[:, 0]
        for j, name in enumerate(p.critics):
            if name not in active:
                continue
            if name == "RotateToGoal":
                if not cr.in_window:
                    raw[:, j] = 0.0
                    continue
                rot = np.abs(shortest_angle(ends[:, 2], goal[2]))
                if cr.rotating:
                    illegal[:, j] = np.abs(cmd[:, 0]) > 0.0
                    raw[:, j] = rot
                else:
                    illegal[:, j] = speed_sq >= cur_sq
                    raw[:, j] = speed_sq * p.rotate_to_goal_slowing_factor + rot
            elif name == "Oscillation":
                illegal[:, j] = cr.x.oscillating(cmd[:, 0]) | cr.theta.oscillating(cmd[:, 1])
                raw[:, j] = 0.0
            elif name == "BaseObstacle":
                illegal[:, j] = ~on_grid | ~np.where(live, cost < INVALID_COST, True).all(axis=1)
                raw[:, j] = end_cost
            else:
                fpd = {
                    "GoalAlign": p.goal_align_forward_point_distance_m,
                    "PathAlign": p.path_align_forward_point_distance_m,
                }.get(name, 0.0)
                grid = maps["align" if name == "GoalAlign" else "goal" if name == "GoalDist" else "path"]
                if fpd:
                    px = ends[:, 0] + fpd * np.cos(ends[:, 2])
                    py = ends[:, 1] + fpd * np.sin(ends[:, 2])
                    r, c, ins = trajectory_cells(costmap, px, py)
                    illegal[:, j] = ~ins
                else:  # every pose on the costmap and reachable
                    r, c, ins = trajectory_cells(costmap, ends[:, 0], ends[:, 1])
                    illegal[:, j] = ~on_grid | (grid is None)
                values = (
                    np.full(n, unreachable)
                    if grid is None
                    else grid[np.clip(r, 0, costmap.rows - 1), np.clip(c, 0, costmap.cols - 1)]
                )
                raw[:, j] = np.where(ins, values, 0.0)
        return raw, illegal


@dataclass(frozen=True, kw_only=True, slots=True)
class Evaluation:
    """One cycle's samples scored by every critic (the numpy cycle, before the choice).

    `raw[s, k]` is critic k's raw score of sample s (NaN: the critic does not score this cycle, its scale
    being 0), `illegal[s, k]` whether critic k rejects it; `scales[k]` the factor DWB multiplies the raw
    score by (the map-grid critics' per half cell). Nav2 stops at the first critic, in order, that rejects.
    """

    begin: int
    end: int
    goal: Pose
    trajectories: Trajectories
    critics: tuple[str, ...]
    scales: F64
    raw: F64
    illegal: NDArray[np.bool_]

    @property
    def legal(self) -> NDArray[np.bool_]:
        """The samples no critic rejects."""
        return np.asarray(~self.illegal.any(axis=1))

    @property
    def thrower(self) -> NDArray[np.int64]:
        """The first critic (its index) rejecting each sample; -1 for the legal ones."""
        first = np.argmax(self.illegal, axis=1)
        return np.where(self.illegal.any(axis=1), first, -1).astype(np.int64)

    @property
    def total(self) -> F64:
        """Each sample's total, the critics' scaled scores summed in their order (legal samples)."""
        total = np.zeros(len(self.raw))
        for k in range(self.raw.shape[1]):
            if self.scales[k] != 0.0:
                total = total + np.where(np.isnan(self.raw[:, k]), 0.0, self.raw[:, k]) * self.scales[k]
        return total


# --- the numpy cycle's parts --------------------------------------------------------------------


def _transform_global_plan(
    plan: F64, pose: Pose, plan_to_costmap: Pose, p: DwbParams, costmap: CostGrid
) -> tuple[F64, int, int]:
    """DWB's transformGlobalPlan: the plan's poses passed on (costmap frame), the index of the first, how many."""
    tx, ty, tyaw = plan_to_costmap
    c, s = math.cos(tyaw), math.sin(tyaw)
    rx = c * (pose[0] - tx) + s * (pose[1] - ty)
    ry = -s * (pose[0] - tx) + c * (pose[1] - ty)
    dist_threshold = max(costmap.cols, costmap.rows) * costmap.resolution_m / 2.0
    start_thr = min(dist_threshold, p.prune_distance_m) if p.prune_plan else dist_threshold
    end_thr = min(dist_threshold, p.forward_prune_distance_m) if p.shorten_transformed_plan else dist_threshold
    n = len(plan)
    seg = np.hypot(np.diff(plan[:, 0]), np.diff(plan[:, 1]))
    along = np.cumsum(seg)
    beyond = np.nonzero(along > p.prune_distance_m)[0]
    prune_point = int(beyond[0]) + 1 if len(beyond) else n
    d = np.hypot(rx - plan[:, 0], ry - plan[:, 1])
    near = np.nonzero(d[:prune_point] < start_thr)[0]
    begin = int(near[0]) if len(near) else prune_point
    far = np.nonzero(d[begin:] > end_thr)[0]
    end = begin + int(far[0]) if len(far) else n
    part = plan[begin:end]
    local = np.empty_like(part)
    local[:, 0] = tx + c * part[:, 0] - s * part[:, 1]
    local[:, 1] = ty + s * part[:, 0] + c * part[:, 1]
    local[:, 2] = part[:, 2] + tyaw
    return local, begin, end - begin
