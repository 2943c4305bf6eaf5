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

The cycle runs in C (`twin/nav/dwb_kernel.c`) when a compiler is available; `DwbController(native=
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

from twin.core.errors import ConfigError
from twin.core.native import CLibrary, load_library
from twin.nav.costmap_grid import CostGrid

__all__ = [
    "CRITICS",
    "TRAJECTORY_GENERATORS",
    "DwbController",
    "DwbParams",
    "NoValidTrajectory",
    "Trajectories",
]

F64 = NDArray[np.float64]
Pose = tuple[float, float, float]

#: The DWB critics the twin scores, by the name a params file lists them under, and their kernel codes.
CRITICS: Mapping[str, int] = {
    "RotateToGoal": 1,
    "Oscillation": 2,
    "BaseObstacle": 3,
    "GoalAlign": 4,
    "PathAlign": 5,
    "PathDist": 6,
    "GoalDist": 7,
}
TRAJECTORY_GENERATORS = ("dwb_plugins::StandardTrajectoryGenerator", "dwb_plugins::LimitedAccelGenerator")
_MAP_GRID = frozenset({"GoalAlign", "PathAlign", "PathDist", "GoalDist"})
_EPS = 1e-5  # dwb_plugins' EPSILON
_INVALID_COST = 253  # inscribed, lethal and unknown are illegal for BaseObstacle


class NoValidTrajectory(RuntimeError):
    """Every sampled trajectory was illegal (or the plan has no pose near the robot)."""


@dataclass(frozen=True, kw_only=True, slots=True)
class DwbParams:
    """DWB's parameters. `DwbParams()` is TB3's Humble waffle.yaml; `from_nav2` fills gaps with Nav2's defaults."""

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
    include_last_point: bool = True
    trajectory_generator: str = TRAJECTORY_GENERATORS[0]
    sim_period_s: float | None = None  # LimitedAccelGenerator's window; None: one controller period
    xy_goal_tolerance_m: float = 0.05
    trans_stopped_velocity: float = 0.25
    prune_plan: bool = True
    prune_distance_m: float = 2.0
    forward_prune_distance_m: float = 2.0
    shorten_transformed_plan: bool = True
    critics: tuple[str, ...] = (
        "RotateToGoal", "Oscillation", "BaseObstacle", "GoalAlign", "PathAlign", "PathDist", "GoalDist",
    )  # fmt: skip
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
    def from_nav2(
        cls, section: Mapping[str, object], *, controller_frequency_hz: float = 20.0, where: str = "FollowPath"
    ) -> DwbParams:
        """Build from a controller plugin's section of a Nav2 params file, with Nav2 Humble's code defaults.

        Args:
            section: The plugin's keys (`max_vel_x`, `critics`, `PathDist.scale`...); others are ignored.
            controller_frequency_hz: controller_server's `controller_frequency`.
            where: The file and key prefix for error messages.

        Raises:
            ConfigError: A value of the wrong type, a critic or trajectory generator the twin lacks,
                sideways velocities (the twin's robots are differential drive), or RotateToGoal's
                `lookahead_time` / Oscillation's `oscillation_reset_time` (not implemented).
        """
        s = dict(section)

        def num(key: str, default: float) -> float:
            value = s.get(key, default)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                msg = f"{where}.{key}: expected a number, got {value!r}; fix the params file"
                raise ConfigError(msg)
            return float(value)

        def flag(key: str, default: bool) -> bool:
            value = s.get(key, default)
            if not isinstance(value, bool):
                msg = f"{where}.{key}: expected true or false, got {value!r}; fix the params file"
                raise ConfigError(msg)
            return value

        critics = s.get("critics", [])
        if isinstance(critics, str):
            critics = [critics]
        if not isinstance(critics, list | tuple) or not all(isinstance(c, str) for c in critics):
            msg = f"{where}.critics: expected a list of critic names, got {critics!r}; fix the params file"
            raise ConfigError(msg)
        names = [c.removeprefix("dwb_critics::").removesuffix("Critic") for c in critics]
        unknown = [c for c, n in zip(critics, names, strict=True) if n not in CRITICS]
        if unknown:
            msg = (
                f"{where}.critics: the twin has no DWB critic {unknown[0]!r}; "
                f"it has {', '.join(CRITICS)}: remove it or use one of those"
            )
            raise ConfigError(msg)
        generator = str(s.get("trajectory_generator_name", TRAJECTORY_GENERATORS[0]))
        if generator not in TRAJECTORY_GENERATORS:
            msg = (
                f"{where}.trajectory_generator_name: unknown generator {generator!r}; "
                f"the twin has {', '.join(TRAJECTORY_GENERATORS)}"
            )
            raise ConfigError(msg)
        for key in ("min_vel_y", "max_vel_y"):
            if num(key, 0.0) != 0.0:
                msg = f"{where}.{key}: the twin's robots are differential drive; set it to 0.0"
                raise ConfigError(msg)
        if "RotateToGoal" in names and num("RotateToGoal.lookahead_time", -1.0) >= 0.0:
            msg = f"{where}.RotateToGoal.lookahead_time: only -1.0 (the trajectory's end) is implemented; set -1.0"
            raise ConfigError(msg)
        if "Oscillation" in names and num("Oscillation.oscillation_reset_time", -1.0) >= 0.0:
            msg = f"{where}.Oscillation.oscillation_reset_time: not implemented; remove it (the default is -1.0)"
            raise ConfigError(msg)
        sim_period = s.get("sim_period")
        return cls(
            controller_frequency_hz=controller_frequency_hz,
            min_vel_x=num("min_vel_x", 0.0),
            max_vel_x=num("max_vel_x", 0.0),
            max_vel_theta=num("max_vel_theta", 0.0),
            min_speed_xy=num("min_speed_xy", 0.0),
            max_speed_xy=num("max_speed_xy", 0.0),
            min_speed_theta=num("min_speed_theta", 0.0),
            acc_lim_x=num("acc_lim_x", 0.0),
            acc_lim_theta=num("acc_lim_theta", 0.0),
            decel_lim_x=num("decel_lim_x", 0.0),
            decel_lim_theta=num("decel_lim_theta", 0.0),
            vx_samples=int(num("vx_samples", 20)),
            vtheta_samples=int(num("vtheta_samples", 20)),
            sim_time_s=num("sim_time", 1.7),
            linear_granularity_m=num("linear_granularity", 0.5),
            angular_granularity_rad=num("angular_granularity", 0.025),
            include_last_point=flag("include_last_point", True),
            trajectory_generator=generator,
            sim_period_s=None if sim_period is None else num("sim_period", 0.05),
            xy_goal_tolerance_m=num("xy_goal_tolerance", 0.25),
            trans_stopped_velocity=num("trans_stopped_velocity", 0.25),
            prune_plan=flag("prune_plan", True),
            prune_distance_m=num("prune_distance", 2.0),
            forward_prune_distance_m=num("forward_prune_distance", 2.0),
            shorten_transformed_plan=flag("shorten_transformed_plan", True),
            critics=tuple(names),
            base_obstacle_scale=num("BaseObstacle.scale", 1.0),
            path_align_scale=num("PathAlign.scale", 1.0),
            path_align_forward_point_distance_m=num("PathAlign.forward_point_distance", 0.325),
            goal_align_scale=num("GoalAlign.scale", 1.0),
            goal_align_forward_point_distance_m=num("GoalAlign.forward_point_distance", 0.325),
            path_dist_scale=num("PathDist.scale", 1.0),
            goal_dist_scale=num("GoalDist.scale", 1.0),
            rotate_to_goal_scale=num("RotateToGoal.scale", 1.0),
            rotate_to_goal_slowing_factor=num("RotateToGoal.slowing_factor", 5.0),
            oscillation_scale=num("Oscillation.scale", 1.0),
            oscillation_reset_dist_m=num("Oscillation.oscillation_reset_dist", 0.05),
            oscillation_reset_angle_rad=num("Oscillation.oscillation_reset_angle", 0.2),
            x_only_threshold=num("Oscillation.x_only_threshold", 0.05),
        )

    @property
    def limited_accel(self) -> bool:
        """True with LimitedAccelGenerator (the velocity jumps to the sample; the window is one period)."""
        return self.trajectory_generator == TRAJECTORY_GENERATORS[1]

    @property
    def window_time_s(self) -> float:
        """The time the velocity samples may accelerate over (sim_time, or LimitedAccelGenerator's period)."""
        if not self.limited_accel:
            return self.sim_time_s
        if self.sim_period_s is not None:
            return self.sim_period_s
        return 1.0 / self.controller_frequency_hz if self.controller_frequency_hz > 0 else 0.05

    def scale(self, critic: str) -> float:
        """The critic's scale as DWB applies it (map-grid critics' per cell: times half the resolution later)."""
        return {
            "RotateToGoal": self.rotate_to_goal_scale,
            "Oscillation": self.oscillation_scale,
            "BaseObstacle": self.base_obstacle_scale,
            "GoalAlign": self.goal_align_scale,
            "PathAlign": self.path_align_scale,
            "PathDist": self.path_dist_scale,
            "GoalDist": self.goal_dist_scale,
        }[critic]

    def max_steps(self) -> int:
        """The most time steps a trajectory can have."""
        lin = self.max_speed_xy if self.max_speed_xy >= 0 else self.max_vel_x
        lin = max(lin, abs(self.min_vel_x), abs(self.max_vel_x))
        a = lin * self.sim_time_s / self.linear_granularity_m
        b = abs(self.max_vel_theta) * self.sim_time_s / self.angular_granularity_rad
        return max(1, math.ceil(max(a, b)))


@dataclass(frozen=True, kw_only=True, slots=True)
class Trajectories:
    """Sampled trajectories: `velocity[s] = (vx, wz)`, `poses[s, k] = (x, y, yaw)`, `steps[s]` time steps."""

    velocity: F64
    poses: F64
    steps: NDArray[np.int64]


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


# --- critic state kept between cycles ------------------------------------------------------------


@dataclass(slots=True)
class _Trend:
    """Oscillation's CommandTrend for one velocity component."""

    sign: int = 0
    positive_only: bool = False
    negative_only: bool = False

    def update(self, v: float) -> bool:
        flipped = False
        if v < 0.0:
            if self.sign > 0:
                self.negative_only = flipped = True
            self.sign = -1
        elif v > 0.0:
            if self.sign < 0:
                self.positive_only = flipped = True
            self.sign = 1
        return flipped

    def oscillating(self, v: F64) -> NDArray[np.bool_]:
        return np.asarray((self.positive_only & (v < 0.0)) | (self.negative_only & (v > 0.0)), dtype=bool)


class _Critics:
    """RotateToGoal's latches and Oscillation's trends; reset by a new plan."""

    def __init__(self) -> None:
        self.in_window = False
        self.rotating = False
        self.x = _Trend()
        self.theta = _Trend()
        self.stationary: Pose = (0.0, 0.0, 0.0)  # Oscillation's prev_stationary_pose_: kept across resets

    def reset(self) -> None:
        self.in_window = self.rotating = False
        self.x, self.theta = _Trend(), _Trend()

    def debrief(self, cmd: tuple[float, float], pose: Pose, p: DwbParams) -> None:
        """Oscillation's debrief: record the command's signs, forget them after enough motion since a flip."""
        flipped = self.x.update(cmd[0])
        if p.x_only_threshold < 0.0 or abs(cmd[0]) <= p.x_only_threshold:
            flipped = self.theta.update(cmd[1]) or flipped
        if flipped:
            self.stationary = pose
        if self.x.positive_only or self.x.negative_only or self.theta.positive_only or self.theta.negative_only:
            dx, dy = pose[0] - self.stationary[0], pose[1] - self.stationary[1]
            moved = p.oscillation_reset_dist_m >= 0.0 and dx * dx + dy * dy > p.oscillation_reset_dist_m**2
            turned = p.oscillation_reset_angle_rad >= 0.0 and abs(pose[2] - self.stationary[2]) > (
                p.oscillation_reset_angle_rad
            )
            if moved or turned:
                self.x, self.theta = _Trend(), _Trend()


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
        self._critics = _Critics()
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
        cmd = _samples(self.params, velocity)
        return _rollouts(self.params, cmd, (0.0, 0.0, 0.0), velocity)

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

    def _compute_numpy(self, pose: Pose, velocity: tuple[float, float], costmap: CostGrid) -> tuple[float, float]:
        p, cr = self.params, self._critics
        if len(self._plan) == 0:
            raise NoValidTrajectory("Received plan with zero length")
        local, begin = _transform_global_plan(self._plan, pose, self.plan_to_costmap, p, costmap)
        if p.prune_plan and begin > 0:
            self.set_plan_keeping_critics(self._plan[begin:])
        if len(local) == 0:
            raise NoValidTrajectory("Resulting plan has 0 poses in it.")
        tx, ty, tyaw = self.plan_to_costmap
        c, s = math.cos(tyaw), math.sin(tyaw)
        end = self._plan[-1]
        goal = (tx + c * end[0] - s * end[1], ty + s * end[0] + c * end[1], float(end[2]) + tyaw)
        # prepare
        dxy_sq = (pose[0] - goal[0]) ** 2 + (pose[1] - goal[1]) ** 2
        cur_sq = velocity[0] ** 2
        cr.in_window = cr.in_window or dxy_sq <= p.xy_goal_tolerance_m**2
        cr.rotating = cr.rotating or (cr.in_window and cur_sq <= p.trans_stopped_velocity**2)
        active = [name for name in p.critics if p.scale(name) != 0.0]
        fpd_path, fpd_goal = p.path_align_forward_point_distance_m, p.goal_align_forward_point_distance_m
        if "PathAlign" in active and dxy_sq <= fpd_path**2:
            active.remove("PathAlign")
        unreachable = float(costmap.rows * costmap.cols + 1)
        maps: dict[str, F64 | None] = {}
        if "PathDist" in active or "PathAlign" in active:
            seeds = _walk(local[:, :2], costmap, last_only=False)
            maps["path"] = _manhattan(costmap, seeds) if seeds else None
        if "GoalDist" in active:
            seeds = _walk(local[:, :2], costmap, last_only=True)
            maps["goal"] = _manhattan(costmap, seeds) if seeds else None
        if "GoalAlign" in active:
            shifted = local[:, :2].copy()
            angle = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
            shifted[-1, 0] += fpd_goal * math.cos(angle)
            shifted[-1, 1] += fpd_goal * math.sin(angle)
            seeds = _walk(shifted, costmap, last_only=True)
            maps["align"] = _manhattan(costmap, seeds) if seeds else None
        commands = _samples(p, velocity)
        n = len(commands)
        if ("PathDist" in active and maps["path"] is None) or ("GoalDist" in active and maps["goal"] is None):
            legal = np.zeros(n, dtype=bool)
            total = np.zeros(n)
        else:
            traj = _rollouts(p, commands, pose, velocity)
            total, legal = self._score(
                traj, active=active, maps=maps, goal=goal, cur_sq=cur_sq, costmap=costmap, unreachable=unreachable
            )
        if not legal.any():
            cr.debrief((0.0, 0.0), pose, p)
            self.local_plan = np.zeros((0, 3))
            raise NoValidTrajectory(f"No valid trajectories out of {n}!")
        best = int(np.argmin(np.where(legal, total, np.inf)))
        one = _rollouts(p, commands[best : best + 1], pose, velocity)
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
        p, cr = self.params, self._critics
        cmd = traj.velocity
        n = len(cmd)
        k = np.arange(traj.poses.shape[1])
        live = k[None, :] <= traj.steps[:, None]
        row, col, inside = _cells(costmap, traj.poses[..., 0], traj.poses[..., 1])
        on_grid = np.where(live, inside, True).all(axis=1)
        cost = np.where(inside, costmap.cost[np.clip(row, 0, costmap.rows - 1), np.clip(col, 0, costmap.cols - 1)], 255)
        ends = traj.poses[np.arange(n), traj.steps]
        end_cost = cost[np.arange(n), traj.steps].astype(np.float64)
        legal = np.ones(n, dtype=bool)
        total = np.zeros(n)
        if any(c in active for c in ("BaseObstacle", "PathDist", "GoalDist")):
            legal &= on_grid
        if "BaseObstacle" in active:
            legal &= np.where(live, cost < _INVALID_COST, True).all(axis=1)
        if "Oscillation" in active:
            legal &= ~(cr.x.oscillating(cmd[:, 0]) | cr.theta.oscillating(cmd[:, 1]))
        speed_sq = cmd[:, 0] ** 2
        if "RotateToGoal" in active and cr.in_window:
            legal &= (speed_sq < cur_sq) if not cr.rotating else (np.abs(cmd[:, 0]) == 0.0)
        unit = 0.5 * costmap.resolution_m
        for name in active:
            scale = p.scale(name)
            if name == "RotateToGoal":
                if cr.in_window:
                    rot = np.abs(_shortest(ends[:, 2], goal[2]))
                    total += scale * (rot if cr.rotating else speed_sq * p.rotate_to_goal_slowing_factor + rot)
            elif name == "BaseObstacle":
                total += scale * end_cost
            elif name in _MAP_GRID:
                fpd = {
                    "GoalAlign": p.goal_align_forward_point_distance_m,
                    "PathAlign": p.path_align_forward_point_distance_m,
                }.get(name, 0.0)
                grid = maps["align" if name == "GoalAlign" else "goal" if name == "GoalDist" else "path"]
                px = ends[:, 0] + fpd * np.cos(ends[:, 2])
                py = ends[:, 1] + fpd * np.sin(ends[:, 2])
                r, c, ins = _cells(costmap, px, py)
                legal &= ins
                values = (
                    np.full(n, unreachable)
                    if grid is None
                    else grid[np.clip(r, 0, costmap.rows - 1), np.clip(c, 0, costmap.cols - 1)]
                )
                total += scale * unit * np.where(ins, values, 0.0)
        return total, legal


# --- the numpy cycle's parts --------------------------------------------------------------------


def _transform_global_plan(
    plan: F64, pose: Pose, plan_to_costmap: Pose, p: DwbParams, costmap: CostGrid
) -> tuple[F64, int]:
    """DWB's transformGlobalPlan: the plan's poses passed on (costmap frame) and the index of the first."""
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
    return local, begin


def _adjusted(points: F64, resolution_m: float) -> list[tuple[float, float]]:
    """nav_2d_utils::adjustPlanResolution (x, y only): points added where two are more than 2 cells apart."""
    if len(points) == 0:
        return []
    out = [(float(points[0, 0]), float(points[0, 1]))]
    min_sq = resolution_m * resolution_m * 4.0
    lx, ly = out[0]
    for x, y in points[1:].tolist():
        sq = (x - lx) * (x - lx) + (y - ly) * (y - ly)
        if sq > min_sq:
            steps = int((math.sqrt(sq) - math.sqrt(min_sq)) / resolution_m) - 1
            if steps > 1:
                dx, dy = (x - lx) / steps, (y - ly) / steps
                out += [(lx + j * dx, ly + j * dy) for j in range(1, steps)]
        out.append((x, y))
        lx, ly = x, y
    return out


def _world_to_map(costmap: CostGrid, x: float, y: float) -> tuple[int, int] | None:
    """Costmap2D::worldToMap: (row, col), or None left of or below the origin or past the far edges."""
    if x < costmap.origin_x_m or y < costmap.origin_y_m:
        return None
    col = int((x - costmap.origin_x_m) / costmap.resolution_m)
    row = int((y - costmap.origin_y_m) / costmap.resolution_m)
    return (row, col) if row < costmap.rows and col < costmap.cols else None


def _walk(points: F64, costmap: CostGrid, *, last_only: bool) -> list[tuple[int, int]]:
    """The map-grid critics' seeds: every adjusted plan pose on a known cell (or the last), up to the first off it."""
    seeds: list[tuple[int, int]] = []
    for x, y in _adjusted(points, costmap.resolution_m):
        cell = _world_to_map(costmap, x, y)
        if cell is not None and costmap.cost[cell] != 255:
            if last_only:
                seeds[:] = [cell]
            else:
                seeds.append(cell)
        elif seeds:
            break
    return seeds


def _manhattan(costmap: CostGrid, seeds: list[tuple[int, int]]) -> F64:
    """Manhattan cell distance of every cell to the nearest seed (Humble's MapGridCritic propagation)."""
    from scipy.ndimage import distance_transform_cdt

    free = np.ones(costmap.cost.shape, dtype=bool)
    rows, cols = zip(*seeds, strict=True)
    free[list(rows), list(cols)] = False
    return np.asarray(distance_transform_cdt(free, metric="taxicab"), dtype=np.float64)


def _project(v0: float, accel: float, decel: float, dt: float, target: float) -> float:
    if v0 < target:
        return min(target, v0 + accel * dt)
    return max(target, v0 + decel * dt)


class _Iter1D:
    """dwb_plugins::OneDVelocityIterator."""

    def __init__(self, current: float, limits: tuple[float, float, float, float], t: float, n: int) -> None:
        lo, hi, acc, dec = limits
        current = min(max(current, lo), hi)
        self.max_vel = _project(current, acc, dec, t, hi)
        self.min_vel = _project(current, acc, dec, t, lo)
        self.reset()
        if abs(self.min_vel - self.max_vel) < _EPS:
            self.increment = 1.0
            return
        n = max(2, n)
        self.increment = (self.max_vel - self.min_vel) / max(1, n - 1)

    def reset(self) -> None:
        self.current = self.min_vel
        self.return_zero = True
        self.return_zero_now = False

    def velocity(self) -> float:
        return 0.0 if self.return_zero_now else self.current

    def next(self) -> None:
        c = self.current
        if self.return_zero and c < 0.0 and c + self.increment > 0.0 and c + self.increment <= self.max_vel + _EPS:
            self.return_zero_now, self.return_zero = True, False
        else:
            self.current += self.increment
            self.return_zero_now = False

    def finished(self) -> bool:
        return self.current > self.max_vel + _EPS


def _samples(p: DwbParams, velocity: tuple[float, float]) -> F64:
    """XYThetaIterator's samples (n, 2) in its order."""
    t = p.window_time_s
    xi = _Iter1D(velocity[0], (p.min_vel_x, p.max_vel_x, p.acc_lim_x, p.decel_lim_x), t, p.vx_samples)
    th_limits = (-p.max_vel_theta, p.max_vel_theta, p.acc_lim_theta, p.decel_lim_theta)
    ti = _Iter1D(velocity[1], th_limits, t, p.vtheta_samples)

    def valid(x: float, th: float) -> bool:
        sq = x * x
        if p.max_speed_xy >= 0.0 and sq > p.max_speed_xy**2 + _EPS:
            return False
        if (
            p.min_speed_xy >= 0.0
            and sq + _EPS < p.min_speed_xy**2
            and p.min_speed_theta >= 0.0
            and abs(th) + _EPS < p.min_speed_theta
        ):
            return False
        return not (sq == 0.0 and th == 0.0)

    out: list[tuple[float, float]] = []
    ok = valid(xi.velocity(), ti.velocity())
    while True:
        while not ok and not xi.finished():
            ti.next()
            if ti.finished():
                ti.reset()
                xi.next()
            ok = valid(xi.velocity(), ti.velocity())
        if xi.finished():
            break
        out.append((xi.velocity(), ti.velocity()))
        ok = False
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def _rollouts(p: DwbParams, cmd: F64, pose: Pose, velocity: tuple[float, float]) -> Trajectories:
    """Every sample's trajectory, step by step as StandardTrajectoryGenerator (all samples at once)."""
    n = len(cmd)
    lin = np.abs(cmd[:, 0]) * p.sim_time_s / p.linear_granularity_m
    ang = np.abs(cmd[:, 1]) * p.sim_time_s / p.angular_granularity_rad
    steps = np.maximum(np.ceil(np.maximum(lin, ang)), 1).astype(np.int64)
    dt = p.sim_time_s / steps
    n_max = int(steps.max()) if n else 1
    poses = np.empty((n, n_max + 1, 3))
    x = np.full(n, pose[0])
    y = np.full(n, pose[1])
    th = np.full(n, pose[2])
    v = np.full(n, velocity[0])
    w = np.full(n, velocity[1])
    poses[:, 0] = (pose[0], pose[1], pose[2])
    for k in range(1, n_max + 1):
        if p.limited_accel:
            v, w = cmd[:, 0].copy(), cmd[:, 1].copy()
        else:
            v = np.where(
                v < cmd[:, 0],
                np.minimum(cmd[:, 0], v + p.acc_lim_x * dt),
                np.maximum(cmd[:, 0], v + p.decel_lim_x * dt),
            )
            w = np.where(
                w < cmd[:, 1],
                np.minimum(cmd[:, 1], w + p.acc_lim_theta * dt),
                np.maximum(cmd[:, 1], w + p.decel_lim_theta * dt),
            )
        live = k <= steps
        x = np.where(live, x + (v * np.cos(th)) * dt, x)
        y = np.where(live, y + (v * np.sin(th)) * dt, y)
        th = np.where(live, th + w * dt, th)
        poses[:, k, 0], poses[:, k, 1], poses[:, k, 2] = x, y, th
    return Trajectories(velocity=cmd, poses=poses, steps=steps)


def _cells(costmap: CostGrid, x: F64, y: F64) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Cells as worldToMap finds them: (row, col, on the costmap)."""
    fx = (x - costmap.origin_x_m) / costmap.resolution_m
    fy = (y - costmap.origin_y_m) / costmap.resolution_m
    inside = (x >= costmap.origin_x_m) & (y >= costmap.origin_y_m) & (fx < costmap.cols) & (fy < costmap.rows)
    col = np.where(inside, fx, 0).astype(np.int64)
    row = np.where(inside, fy, 0).astype(np.int64)
    inside &= (col < costmap.cols) & (row < costmap.rows)
    return row, col, inside


def _shortest(from_rad: F64, to_rad: float) -> F64:
    """angles::shortest_angular_distance."""
    two_pi = 2.0 * math.pi
    a = np.fmod(np.fmod(to_rad - from_rad, two_pi) + two_pi, two_pi)
    return np.asarray(np.where(a > math.pi, a - two_pi, a))
