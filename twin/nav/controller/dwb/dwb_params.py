"""DWB's parameters as a Nav2 params file gives them (`DwbParams.from_nav2`), and the names it accepts."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from twin.core.errors import ConfigError

__all__ = [
    "CRITICS",
    "EPS",
    "INVALID_COST",
    "MAP_GRID_CRITICS",
    "TRAJECTORY_GENERATORS",
    "DwbParams",
    "NoValidTrajectory",
]


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
MAP_GRID_CRITICS = frozenset({"GoalAlign", "PathAlign", "PathDist", "GoalDist"})
EPS = 1e-5  # dwb_plugins' EPSILON
INVALID_COST = 253  # inscribed, lethal and unknown are illegal for BaseObstacle


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
        s = section  # (read, not copied: a caller may note which keys were read)

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
        # A critic reads its parameters under its name as listed (`dwb_critics::RotateToGoalCritic.scale`
        # for that entry), as DWB passes each critic the list's name; an unlisted critic's are not read.
        listed = dict(zip(names, critics, strict=True))

        def key(critic: str, name: str) -> str:
            return f"{listed.get(critic, critic)}.{name}"

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
        for sideways in ("min_vel_y", "max_vel_y"):
            if num(sideways, 0.0) != 0.0:
                msg = f"{where}.{sideways}: the twin's robots are differential drive; set it to 0.0"
                raise ConfigError(msg)
        for sideways in ("acc_lim_y", "decel_lim_y"):  # (read as Nav2 reads them: no sideways speed to limit)
            num(sideways, 0.0)
        if "RotateToGoal" in names and num(key("RotateToGoal", "lookahead_time"), -1.0) >= 0.0:
            at = key("RotateToGoal", "lookahead_time")
            msg = f"{where}.{at}: only -1.0 (the trajectory's end) is implemented; set -1.0"
            raise ConfigError(msg)
        if "Oscillation" in names and num(key("Oscillation", "oscillation_reset_time"), -1.0) >= 0.0:
            at = key("Oscillation", "oscillation_reset_time")
            msg = f"{where}.{at}: not implemented; remove it (the default is -1.0)"
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
            base_obstacle_scale=num(key("BaseObstacle", "scale"), 1.0),
            path_align_scale=num(key("PathAlign", "scale"), 1.0),
            path_align_forward_point_distance_m=num(key("PathAlign", "forward_point_distance"), 0.325),
            goal_align_scale=num(key("GoalAlign", "scale"), 1.0),
            goal_align_forward_point_distance_m=num(key("GoalAlign", "forward_point_distance"), 0.325),
            path_dist_scale=num(key("PathDist", "scale"), 1.0),
            goal_dist_scale=num(key("GoalDist", "scale"), 1.0),
            rotate_to_goal_scale=num(key("RotateToGoal", "scale"), 1.0),
            rotate_to_goal_slowing_factor=num(key("RotateToGoal", "slowing_factor"), 5.0),
            oscillation_scale=num(key("Oscillation", "scale"), 1.0),
            oscillation_reset_dist_m=num(key("Oscillation", "oscillation_reset_dist"), 0.05),
            oscillation_reset_angle_rad=num(key("Oscillation", "oscillation_reset_angle"), 0.2),
            x_only_threshold=num(key("Oscillation", "x_only_threshold"), 0.05),
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
