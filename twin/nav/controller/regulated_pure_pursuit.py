"""Regulated Pure Pursuit (`nav2_regulated_pure_pursuit_controller`), Nav2 Humble's arithmetic.

One cycle is Humble's `computeVelocityCommands`, step by step:

- the plan is cut around the robot (`transformGlobalPlan`): the pose nearest the robot among the
  plan's first `max_robot_pose_search_dist` metres of path (default: half the costmap's larger
  side, Costmap2D's `getSizeInMeters` = (cells - 0.5) x resolution) starts it; it ends before the
  first later pose farther than that half side from the robot; the poses before the start are
  erased from the stored plan (also when what remains is empty: "Resulting plan has 0 poses in it.");
- the lookahead is `lookahead_dist`, or |vx| x `lookahead_time` clamped to [min, max] with
  `use_velocity_scaled_lookahead_dist` (with `allow_reversing`, cut at the path's first cusp);
- the carrot is the first plan pose at least that far from the robot (the last pose when none is),
  or with `use_interpolation` the point where the segment before it crosses the lookahead circle;
- curvature 2 y / d^2 (0 when d^2 <= 0.001);
- the robot turns in place towards the goal's yaw while the carrot is closer than the goal
  checker's `xy_goal_tolerance` (`goal_dist_tol_m`, 0.25 until a goal checker gives one), else
  towards the carrot when it is more than `rotate_to_heading_min_angle` off the heading:
  `rotate_to_heading_angular_vel` limited by `max_angular_accel` around the measured turn rate and
  by sqrt(2 x accel x angle) so as not to overshoot;
- else the speed is the smaller of the curvature-regulated one (x r / `regulated_linear_scaling_min_radius`
  below that radius) and the cost-regulated one (the obstacle distance read back from the cost
  under the robot through the inflation law with `inflation_cost_scaling_factor` and the costmap's
  inscribed radius, below `cost_scaling_dist`), at least `regulated_linear_scaling_min_speed`,
  slowed on the approach (once the remaining path is shorter than `approach_velocity_scaling_dist`,
  by the straight distance to its last pose, down to `min_approach_linear_velocity`), at most
  `desired_linear_vel`; the turn rate is speed x curvature (no angular limit in Humble's RPP);
- with `use_collision_detection`, the robot's footprint is checked at its pose and at poses
  projected forward one costmap cell (or, turning in place, one cell at the footprint's
  circumscribed radius) at a time for `max_allowed_time_to_collision_up_to_carrot`, up to the
  carrot's distance; a footprint cost >= LETHAL (unknown counts unless the costmap tracks
  unknown space) raises "RegulatedPurePursuitController detected collision ahead!"; a projected
  pose off the costmap is not checked.

Held to Nav2 Humble's code by recorded cases (`tests/unit/nav/controller/rpp_cases/`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import ConfigError
from twin.nav.costmap_2d.costmap_2d import FREE_SPACE, LETHAL_OBSTACLE, NO_INFORMATION, CostGrid
from twin.nav.costmap_2d.footprint import footprint_cost, footprint_radii
from twin.nav.params import CostmapParams

__all__ = ["NAV2_PARAMETERS", "NoValidCommand", "RppController", "RppCycle", "RppParams", "in_collision"]

_INSCRIBED_INFLATED_OBSTACLE = 253

MSG_ZERO_LENGTH = "Received plan with zero length"
MSG_ZERO_POSES = "Resulting plan has 0 poses in it."
MSG_COLLISION = "RegulatedPurePursuitController detected collision ahead!"
MSG_COSTMAP_SMALL = (
    "RegulatedPurePursuitController: Dimensions of the costmap are too small to encapsulate the robot "
    "footprint at current speeds!"
)


class NoValidCommand(RuntimeError):
    """RPP found a collision ahead or has no plan near the robot (Nav2's PlannerException)."""


#: Until the controller server hands over the costmap's: TurtleBot3's local costmap (a 0.22 m radius, padded).
_TB3_INSCRIBED, _TB3_CIRCUMSCRIBED, _TB3_FOOTPRINT = footprint_radii(
    CostmapParams(name="local_costmap", robot_radius_m=0.22)
)


@dataclass(frozen=True, kw_only=True, slots=True)
class RppParams:
    """RPP's parameters; defaults are Nav2 Humble's code defaults (`configure`)."""

    controller_frequency_hz: float = 20.0
    desired_linear_vel: float = 0.5
    lookahead_dist_m: float = 0.6
    min_lookahead_dist_m: float = 0.3
    max_lookahead_dist_m: float = 0.9
    lookahead_time_s: float = 1.5
    rotate_to_heading_angular_vel: float = 1.8
    transform_tolerance_s: float = 0.1
    use_velocity_scaled_lookahead_dist: bool = False
    min_approach_linear_velocity: float = 0.05
    approach_velocity_scaling_dist_m: float = 0.6
    max_allowed_time_to_collision_up_to_carrot_s: float = 1.0
    use_collision_detection: bool = True
    use_regulated_linear_velocity_scaling: bool = True
    use_cost_regulated_linear_velocity_scaling: bool = True
    cost_scaling_dist_m: float = 0.6
    cost_scaling_gain: float = 1.0
    inflation_cost_scaling_factor: float = 3.0
    regulated_linear_scaling_min_radius_m: float = 0.9
    regulated_linear_scaling_min_speed: float = 0.25
    use_rotate_to_heading: bool = True
    rotate_to_heading_min_angle_rad: float = 0.785
    max_angular_accel: float = 3.2
    allow_reversing: bool = False
    #: None: half the costmap's larger side, as Nav2's default.
    max_robot_pose_search_dist_m: float | None = None
    use_interpolation: bool = True

    @classmethod
    def from_nav2(
        cls, section: Mapping[str, object], *, controller_frequency_hz: float = 20.0, where: str = "FollowPath"
    ) -> RppParams:
        """Build from the plugin's params-file section (Nav2's names), Nav2 Humble's code defaults for the rest.

        Keys Humble's RPP does not declare (not in `NAV2_PARAMETERS`) are ignored, as Nav2 ignores
        them; the params file's one warning about unused parameters names them (`nav2_config`).

        Raises:
            ConfigError: A value of the wrong type (one line naming `where.key`).
        """
        names = {f.name: f for f in fields(cls)}
        out: dict[str, object] = {"controller_frequency_hz": float(controller_frequency_hz)}
        for key, value in section.items():
            if key not in NAV2_PARAMETERS or key == "plugin":
                continue
            field = names[_RENAMES.get(key, key)]
            if field.type in ("bool",):
                if not isinstance(value, bool):
                    msg = f"{where}.{key}: expected true or false, got {value!r}; fix the params file"
                    raise ConfigError(msg)
                out[field.name] = value
            else:
                if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                    msg = f"{where}.{key}: expected a number, got {value!r}; fix the params file"
                    raise ConfigError(msg)
                out[field.name] = float(value)
        return cls(**out)  # type: ignore[arg-type]


_RENAMES = {
    "lookahead_dist": "lookahead_dist_m",
    "min_lookahead_dist": "min_lookahead_dist_m",
    "max_lookahead_dist": "max_lookahead_dist_m",
    "lookahead_time": "lookahead_time_s",
    "transform_tolerance": "transform_tolerance_s",
    "approach_velocity_scaling_dist": "approach_velocity_scaling_dist_m",
    "regulated_linear_scaling_min_radius": "regulated_linear_scaling_min_radius_m",
    "rotate_to_heading_min_angle": "rotate_to_heading_min_angle_rad",
    "cost_scaling_dist": "cost_scaling_dist_m",
    "max_allowed_time_to_collision_up_to_carrot": "max_allowed_time_to_collision_up_to_carrot_s",
    "max_robot_pose_search_dist": "max_robot_pose_search_dist_m",
}
"""Nav2's parameter names that carry a unit suffix in the twin."""

NAV2_PARAMETERS = frozenset(
    {"plugin"}
    | {next((k for k, v in _RENAMES.items() if v == f.name), f.name) for f in fields(RppParams)}
    - {"controller_frequency_hz"}
)
"""The keys Humble's RPP declares under its plugin name (`configure`), and `plugin`."""


class RppCycle(NamedTuple):
    """What the last cycle computed (for the conformance check and debugging)."""

    erased: int
    """Plan poses erased from the stored plan's front this cycle."""
    transformed: int
    """Poses in the cut plan."""
    branch: int
    """-1 failed before a command, 0 rotate to the goal's yaw, 1 rotate to the path, 2 track."""
    lookahead_m: float
    carrot: tuple[float, float]
    """The carrot in the robot's frame."""
    curvature: float
    arc_poses: int
    """Projected poses checked for collision (after the robot's own)."""


_NO_CYCLE = RppCycle(0, 0, -1, 0.0, (0.0, 0.0), 0.0, 0)


class RppController:
    """Regulated Pure Pursuit; same interface as `DwbController` (see the module docstring).

    The controller server gives it the local costmap's footprint and radii (`use_costmap`), the
    goal checker's tolerance (`goal_dist_tol_m`) and the plan frame's pose in the costmap frame
    (`plan_to_costmap`).
    """

    def __init__(self, params: RppParams | None = None) -> None:
        self.params = params or RppParams()
        self._plan = np.zeros((0, 3))
        self.plan_to_costmap: tuple[float, float, float] = (0.0, 0.0, 0.0)
        #: The goal checker's xy tolerance (Nav2: 0.25 before the first update).
        self.goal_dist_tol_m = 0.25
        self.footprint: tuple[tuple[float, float], ...] = _TB3_FOOTPRINT
        self.inscribed_radius_m = _TB3_INSCRIBED
        self.circumscribed_radius_m = _TB3_CIRCUMSCRIBED
        self.track_unknown = False
        #: The poses projected for the collision check in the last cycle (costmap frame).
        self.local_plan: NDArray[np.float64] = np.zeros((0, 3))
        self.last_cycle = _NO_CYCLE

    def use_costmap(
        self,
        footprint: tuple[tuple[float, float], ...],
        inscribed_radius_m: float,
        circumscribed_radius_m: float,
        track_unknown: bool,
    ) -> None:
        """Take the costmap's padded footprint, its radii and whether it tracks unknown space."""
        self.footprint = tuple(footprint)
        self.inscribed_radius_m = inscribed_radius_m
        self.circumscribed_radius_m = circumscribed_radius_m
        self.track_unknown = track_unknown

    def set_plan(self, plan: NDArray[np.float64]) -> None:
        """Take a new global plan (N, 3)."""
        self._plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)

    def compute_velocity(
        self, pose: tuple[float, float, float], velocity: tuple[float, float], costmap: CostGrid
    ) -> tuple[float, float]:
        """Return (vx, wz) for the robot at `pose` (costmap frame), with its odometry `velocity`.

        Raises:
            NoValidCommand: No plan, no plan pose near the robot, the robot off the costmap, or a
                collision ahead (Nav2's messages).
        """
        p = self.params
        self.last_cycle = _NO_CYCLE
        self.local_plan = np.zeros((0, 3))
        local, goal_yaw, erased = self._transform_plan(pose, costmap)
        lookahead = p.lookahead_dist_m
        if p.use_velocity_scaled_lookahead_dist:
            lookahead = min(max(abs(velocity[0]) * p.lookahead_time_s, p.min_lookahead_dist_m), p.max_lookahead_dist_m)
        allow_reversing = p.allow_reversing and not p.use_rotate_to_heading
        if allow_reversing:
            cusp = _distance_to_cusp(local)
            lookahead = min(lookahead, cusp)
        cx, cy = self._carrot(lookahead, local)
        carrot_d2 = (cx * cx) + (cy * cy)
        curvature = 2.0 * cy / carrot_d2 if carrot_d2 > 0.001 else 0.0
        sign = (1.0 if cx >= 0.0 else -1.0) if allow_reversing else 1.0
        if p.use_rotate_to_heading and math.hypot(cx, cy) < self.goal_dist_tol_m:
            branch = 0
            v, w = self._rotate(goal_yaw, velocity[1])
        elif p.use_rotate_to_heading and abs(angle := math.atan2(cy, cx)) > p.rotate_to_heading_min_angle_rad:
            branch = 1
            v, w = self._rotate(angle, velocity[1])
        else:
            branch = 2
            self.last_cycle = RppCycle(erased, len(local), branch, lookahead, (cx, cy), curvature, 0)
            v = self._constrained_speed(curvature, self._cost_at_pose(pose, costmap), local, sign)
            w = v * curvature
        carrot_dist = math.hypot(cx, cy)
        collided, arc = False, 0
        if p.use_collision_detection:
            collided, arc = self._collision_imminent(pose, v, w, carrot_dist, costmap)
        self.last_cycle = RppCycle(erased, len(local), branch, lookahead, (cx, cy), curvature, arc)
        if collided:
            raise NoValidCommand(MSG_COLLISION)
        return v, w

    # ---------------------------------------------------------------- transformGlobalPlan
    def _transform_plan(
        self, pose: tuple[float, float, float], costmap: CostGrid
    ) -> tuple[NDArray[np.float64], float, int]:
        """The plan near the robot in its frame (x, y), its last pose's yaw there, and the poses erased."""
        plan = self._plan
        if len(plan) == 0:
            raise NoValidCommand(MSG_ZERO_LENGTH)
        tx, ty, tyaw = self.plan_to_costmap
        if (tx, ty, tyaw) == (0.0, 0.0, 0.0):
            rx, ry, ryaw = pose
        else:  # the robot's pose in the plan's frame
            c, s = math.cos(tyaw), math.sin(tyaw)
            dx, dy = pose[0] - tx, pose[1] - ty
            rx, ry, ryaw = c * dx + s * dy, -s * dx + c * dy, pose[2] - tyaw
        extent = max((costmap.cols - 1 + 0.5) * costmap.resolution_m, (costmap.rows - 1 + 0.5) * costmap.resolution_m)
        extent = extent / 2.0
        search = self.params.max_robot_pose_search_dist_m
        if search is None:
            search = extent
        xs, ys = plan[:, 0], plan[:, 1]
        # first_after_integrated_distance: the pose after the first running path length beyond `search`
        upper = len(plan)
        if len(plan) > 1:
            along = np.cumsum(np.hypot(xs[:-1] - xs[1:], ys[:-1] - ys[1:]))
            beyond = np.flatnonzero(along > search)
            if len(beyond):
                upper = int(beyond[0]) + 1
        begin = int(np.argmin(np.hypot(rx - xs[:upper], ry - ys[:upper])))
        far = np.flatnonzero(np.hypot(xs[begin:] - rx, ys[begin:] - ry) > extent)
        end = begin + int(far[0]) if len(far) else len(plan)
        ex, ey = xs[begin:end] - rx, ys[begin:end] - ry
        c, s = math.cos(ryaw), math.sin(ryaw)
        local = np.empty((end - begin, 2))
        local[:, 0] = c * ex + s * ey
        local[:, 1] = -s * ex + c * ey
        if begin:
            self._plan = plan[begin:]
        if end == begin:
            self.last_cycle = RppCycle(begin, 0, -1, 0.0, (0.0, 0.0), 0.0, 0)
            raise NoValidCommand(MSG_ZERO_POSES)
        d = float(plan[end - 1, 2]) - ryaw
        return local, math.atan2(math.sin(d), math.cos(d)), begin

    # ---------------------------------------------------------------- getLookAheadPoint
    def _carrot(self, lookahead: float, local: NDArray[np.float64]) -> tuple[float, float]:
        reach = np.flatnonzero(np.hypot(local[:, 0], local[:, 1]) >= lookahead)
        if not len(reach):
            return float(local[-1, 0]), float(local[-1, 1])
        k = int(reach[0])
        if not self.params.use_interpolation or k == 0:
            return float(local[k, 0]), float(local[k, 1])
        x1, y1 = float(local[k - 1, 0]), float(local[k - 1, 1])
        x2, y2 = float(local[k, 0]), float(local[k, 1])
        # circleSegmentIntersection: the segment's crossing of the circle of radius `lookahead`
        dx = x2 - x1
        dy = y2 - y1
        dr2 = dx * dx + dy * dy
        d = x1 * y2 - x2 * y1
        dd = (x2 * x2 + y2 * y2) - (x1 * x1 + y1 * y1)
        root = math.sqrt(lookahead * lookahead * dr2 - d * d)
        side = math.copysign(1.0, dd)
        return (d * dy + side * dx * root) / dr2, (-d * dx + side * dy * root) / dr2

    # ---------------------------------------------------------------- rotateToHeading
    def _rotate(self, angle: float, turn_rate: float) -> tuple[float, float]:
        p = self.params
        sign = 1.0 if angle > 0.0 else -1.0
        w = sign * p.rotate_to_heading_angular_vel
        dt = 1.0 / p.controller_frequency_hz
        lo = turn_rate - p.max_angular_accel * dt
        hi = turn_rate + p.max_angular_accel * dt
        w = lo if w < lo else (hi if hi < w else w)
        to_stop = math.sqrt(2 * p.max_angular_accel * abs(angle))
        if abs(w) > to_stop:
            w = sign * to_stop
        return 0.0, w

    # ---------------------------------------------------------------- applyConstraints
    def _constrained_speed(self, curvature: float, pose_cost: float, local: NDArray[np.float64], sign: float) -> float:
        p = self.params
        v = p.desired_linear_vel
        curvature_v = cost_v = v
        radius = abs(1.0 / curvature) if curvature != 0.0 else math.inf
        min_rad = p.regulated_linear_scaling_min_radius_m
        if p.use_regulated_linear_velocity_scaling and radius < min_rad:
            curvature_v *= 1.0 - (abs(radius - min_rad) / min_rad)
        if (
            p.use_cost_regulated_linear_velocity_scaling
            and p.inflation_cost_scaling_factor > 0.0
            and pose_cost not in (NO_INFORMATION, FREE_SPACE)
        ):
            obstacle_m = (-1.0 / p.inflation_cost_scaling_factor) * math.log(
                pose_cost / (_INSCRIBED_INFLATED_OBSTACLE - 1)
            ) + self.inscribed_radius_m
            if obstacle_m < p.cost_scaling_dist_m:
                cost_v *= p.cost_scaling_gain * obstacle_m / p.cost_scaling_dist_m
        v = min(cost_v, curvature_v)
        v = max(v, p.regulated_linear_scaling_min_speed)
        # applyApproachVelocityScaling: once the remaining path is short, by the straight distance to its end
        remaining = 0.0
        if len(local) > 1:  # calculate_path_length: summed in order
            remaining = float(np.cumsum(np.hypot(np.diff(local[:, 0]), np.diff(local[:, 1])))[-1])
        scaling = 1.0
        if remaining < p.approach_velocity_scaling_dist_m:
            scaling = math.hypot(float(local[-1, 0]), float(local[-1, 1])) / p.approach_velocity_scaling_dist_m
        approach = v
        if approach * scaling < p.min_approach_linear_velocity:
            approach = p.min_approach_linear_velocity
        else:
            approach *= scaling
        v = min(v, approach)
        v = min(max(abs(v), 0.0), p.desired_linear_vel)
        return sign * v

    def _cost_at_pose(self, pose: tuple[float, float, float], costmap: CostGrid) -> float:
        cell = costmap.world_to_cell(pose[0], pose[1])
        if cell is None:
            raise NoValidCommand(MSG_COSTMAP_SMALL)
        return float(costmap.cost[cell])

    # ---------------------------------------------------------------- isCollisionImminent
    def _in_collision(self, x: float, y: float, yaw: float, costmap: CostGrid) -> bool:
        return in_collision(costmap, self.footprint, (x, y, yaw), track_unknown=self.track_unknown)

    def _collision_imminent(
        self, pose: tuple[float, float, float], v: float, w: float, carrot_dist: float, costmap: CostGrid
    ) -> tuple[bool, int]:
        """Whether the footprint collides at the pose or along the projected arc; how many arc poses were checked."""
        if self._in_collision(pose[0], pose[1], pose[2], costmap):
            return True, 0
        res = costmap.resolution_m
        if abs(v) < 0.01 and abs(w) > 0.01:
            step = 2.0 * math.sin((res / 2) / self.circumscribed_radius_m) / abs(w)
        else:
            step = res / abs(v) if v != 0.0 else math.inf
        limit = self.params.max_allowed_time_to_collision_up_to_carrot_s
        x, y, yaw = pose
        arc: list[tuple[float, float, float]] = []
        collided = False
        i = 1
        while i * step < limit:
            i += 1
            x += step * (v * math.cos(yaw))
            y += step * (v * math.sin(yaw))
            yaw += step * w
            if math.hypot(x - pose[0], y - pose[1]) > carrot_dist:
                break
            arc.append((x, y, yaw))
            if self._in_collision(x, y, yaw, costmap):
                collided = True
                break
        self.local_plan = np.array(arc, dtype=np.float64).reshape(-1, 3)
        return collided, len(arc)


def in_collision(
    costmap: CostGrid,
    footprint: tuple[tuple[float, float], ...],
    pose: tuple[float, float, float],
    *,
    track_unknown: bool,
) -> bool:
    """RPP's `inCollision`: the footprint's cost at `pose` is lethal or unknown (unknown passes when tracked).

    A pose whose centre is off the costmap passes (Nav2 warns that the costmap is too small).
    """
    if costmap.world_to_cell(pose[0], pose[1]) is None:
        return False
    cost = footprint_cost(costmap, footprint, pose)
    if cost == NO_INFORMATION and track_unknown:
        return False
    return cost >= LETHAL_OBSTACLE


def _distance_to_cusp(local: NDArray[np.float64]) -> float:
    """findVelocitySignChange: the distance to the first pose where the path doubles back (else the largest double)."""
    for k in range(1, len(local) - 1):
        oa_x = float(local[k, 0] - local[k - 1, 0])
        oa_y = float(local[k, 1] - local[k - 1, 1])
        ab_x = float(local[k + 1, 0] - local[k, 0])
        ab_y = float(local[k + 1, 1] - local[k, 1])
        if (oa_x * ab_x) + (oa_y * ab_y) < 0.0:
            return math.hypot(float(local[k, 0]), float(local[k, 1]))
    return float(np.finfo(np.float64).max)
