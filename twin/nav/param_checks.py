"""Nav2 params files and maps as scenario inputs: what `load_nav2_params` and `load_map` cannot check alone.

`load_nav2_params` checks the types and ranges of what AMCL and the costmaps read as it reads them.
This module checks the rest before anything is built, each refusal one line naming the file and
line (or the scenario's `navigation.set` key) and the fix:

- the navigation servers' parameters (controller, planner, velocity smoother, behaviours,
  bt_navigator): types and ranges, as Nav2 Humble's nodes declare them. Values a file leaves out
  take Nav2's code defaults, as Nav2's nodes declare them; but a DWB controller without `critics`
  is refused, as Nav2 Humble refuses it (`DWBLocalPlanner::loadCritics` throws "No critics defined
  for FollowPath" and controller_server fails to configure). An empty params file, or one with
  only `amcl`, is therefore refused on that line, where it used to run a controller that found "No
  valid trajectories out of 0!" (Nav2's code defaults for DWB's velocity limits are all 0);
- rates against the physics rate (a timer fires at most once per physics step);
- memory: a costmap grid, a particle set, AMCL's likelihood field, the inflation tables and a DWB
  sample grid are sized before they are allocated, and one that would not fit in half of the
  memory this process may use (physical memory, or less under an rlimit or a cgroup limit) is
  refused with the size it would take;
- `navigation.set` keys: each must name a parameter the twin reads ("did you mean"); the params
  *file* may hold keys the twin does not read (ROS ignores undeclared parameters too), listed in
  one warning line;
- map files: the YAML's numbers (a resolution the OccupancyGrid's float32 can carry, a finite origin,
  thresholds in 0..1) and the image's size, read from its header before it is decoded.
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import math
import os
import resource
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import yaml

from twin.core import yaml_numbers
from twin.core.errors import ConfigError
from twin.nav.controller.checkers import GOAL_CHECKER_PLUGINS, PROGRESS_CHECKER_PLUGINS
from twin.nav.params import (
    MAX_DISTANCE_M,
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    SET_KEY,
    Nav2Params,
    ParamReader,
    ParamSource,
)

__all__ = [
    "check_map_fields",
    "check_map_image",
    "check_nav2_inputs",
    "memory_budget_bytes",
]

# --- memory ---------------------------------------------------------------------------------------

# Bytes per element at the structures' peak (numpy arrays and C buffers), from the process's peak RSS
# with each structure at scale (TB3's params; 2026-11-27), rounded up about 1.5 to 3 times: a rolling
# costmap took 5.0 bytes a cell, a static one over a 4000 x 4000 map 12.0, AMCL 49 bytes a particle
# (2 million particles, six updates) and 41 bytes a map cell for its likelihood field.
_COSTMAP_CELL_BYTES = 7  # master, composition window and inflation's index buffer (int32), per cell
_COSTMAP_LAYER_CELL_BYTES = 1  # each obstacle layer's own grid
_STATIC_CELL_BYTES = 10  # the static layer's reading of /map (int16 copy, masks, the layer)
_INFLATION_TABLE_BYTES = 48  # the inflation cost table's float64 arrays, per squared cell distance
_PARTICLE_BYTES = 160  # poses, weights, noise, resampling, clusters, KLD tables, per max_particles
_FIELD_CELL_BYTES = 64  # AMCL's likelihood field: distances, heap, marks, the cubed table, per map cell
_DWB_SAMPLE_BYTES = 48  # the C cycle's sample, score, order and heading index per velocity sample
_DWB_STEP_BYTES = 96  # a trajectory's poses and heading tables per time step
_IMAGE_PIXEL_BYTES = 48  # a map image decoded: shades (float64), RGB or alpha, occupancy, per pixel


def _cgroup_limit() -> int | None:
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text(encoding="ascii").strip()
        except (OSError, ValueError):
            continue
        if text.isdigit() and int(text) < 1 << 60:
            return int(text)
    return None


@functools.cache
def _memory_limit_bytes() -> tuple[int, str]:
    """The memory this process may use and what sets it (physical memory, an rlimit, a cgroup)."""
    limits: list[tuple[int, str]] = []
    with contextlib.suppress(OSError, ValueError):
        limits.append((os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "physical memory"))
    for name, what in (("RLIMIT_AS", "address-space limit"), ("RLIMIT_DATA", "data limit")):
        soft = resource.getrlimit(getattr(resource, name))[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            limits.append((soft, f"{what} (ulimit)"))
    cgroup = _cgroup_limit()
    if cgroup is not None:
        limits.append((cgroup, "cgroup memory limit"))
    return min(limits) if limits else (8 << 30, "assumed memory")


def memory_budget_bytes() -> int:
    """Half the memory this process may use: any one structure the twin sizes from user input must fit it."""
    return _memory_limit_bytes()[0] // 2


def _size(n: float) -> str:
    for unit, scale in (("EiB", 1 << 60), ("PiB", 1 << 50), ("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}" if n < 1e3 * (1 << 60) else f"{n:.3g} bytes"
    return f"{n / 1024:.3g} KiB"


Where = str | Callable[[], str]
"""A message's location, or what finds it: a params file's line is found (the file parsed again) only for a message."""


def _text(where: Where) -> str:
    return where if isinstance(where, str) else where()


def _fits(where: Where, what: str, n_bytes: float, fix: str) -> None:
    budget = memory_budget_bytes()
    if n_bytes > budget:
        limit, source = _memory_limit_bytes()
        msg = (
            f"{_text(where)}: {what} would take {_size(n_bytes)}, more than the {_size(budget)} the twin allows one "
            f"structure (half of this machine's {_size(limit)} {source}); {fix}"
        )
        raise ConfigError(msg)


# --- the navigation servers' parameters ------------------------------------------------------------

DWB_PLUGIN = "dwb_core::DWBLocalPlanner"
RPP_PLUGIN = "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController"
_SERVER_NODES = ("controller_server", "planner_server", "bt_navigator", "velocity_smoother", "behavior_server")
_LOOKAHEAD_STEPS = 100_000  # behaviours' collision look-ahead: cycle_frequency x simulate_ahead_time footprints
_D = MAX_DISTANCE_M


class _Collector(ParamReader):
    """A reader that only records which keys are read (the servers' keys when Nav2 does not run)."""

    def number(self, key: str, default: float, **_: object) -> float:
        self.used.add(key)
        value = self.params.get(key, default)
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default

    def integer(self, key: str, default: int, **_: object) -> int:
        self.used.add(key)
        value = self.params.get(key, default)
        return value if isinstance(value, int) and not isinstance(value, bool) else default

    def flag(self, key: str, default: bool) -> bool:
        self.used.add(key)
        return default

    def text(self, key: str, default: str) -> str:
        self.used.add(key)
        value = self.params.get(key, default)
        return value if isinstance(value, str) else default

    def str_list(self, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
        self.used.add(key)
        value = self.params.get(key, list(default))
        if isinstance(value, str):
            return tuple(value.split())
        return tuple(v for v in value if isinstance(v, str)) if isinstance(value, list) else default


def _rate(r: ParamReader, key: str, default: float) -> float:
    return r.number(key, default, low=MIN_RATE_HZ, high=MAX_RATE_HZ, unit="Hz")


def _triple(r: ParamReader, key: str, default: tuple[float, float, float], *, sign: int = 0) -> tuple[float, ...]:
    """velocity_smoother's [x, y, theta] parameters; `sign` +1 / -1: every value must be >= 0 / <= 0."""
    r.used.add(key)
    value = r.params.get(key, list(default))
    if isinstance(r, _Collector):
        return default
    ok = isinstance(value, list) and len(value) == 3
    if (
        not isinstance(value, list)
        or not ok
        or not all(isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= _D for v in value)
    ):
        raise r.fail(key, f"expected [x, y, theta], three finite numbers, got {value!r}")
    if sign and any(v * sign < 0 for v in value):
        words = "not negative (accelerations)" if sign > 0 else "negative or 0 (decelerations slow down)"
        raise r.fail(key, f"must be {words}, got {value!r}", "Nav2 refuses it too; fix the signs")
    return tuple(float(v) for v in value)


def _dwb(r: ParamReader, name: str, controller_hz: float, strict: bool, cells: int) -> None:
    p = f"{name}."
    n = functools.partial
    num, flag = r.number, r.flag
    critics_key = p + "critics"
    if strict and critics_key not in r.params:
        raise r.fail(
            critics_key,
            f'not set: Nav2 Humble\'s DWB refuses to start without it ("No critics defined for {name}")',
            "list critics, e.g. [RotateToGoal, Oscillation, BaseObstacle, GoalAlign, PathAlign, PathDist, "
            "GoalDist] as TurtleBot3's params do",
        )
    r.str_list(critics_key, ())
    r.text(p + "trajectory_generator_name", "dwb_plugins::StandardTrajectoryGenerator")
    for key in ("min_vel_y", "max_vel_y", "acc_lim_y", "decel_lim_y"):
        num(p + key, 0.0, low=-_D, high=_D)
    num(p + "RotateToGoal.lookahead_time", -1.0, low=-_D, high=_D)
    num(p + "Oscillation.oscillation_reset_time", -1.0, low=-_D, high=_D)
    if p + "sim_period" in r.params:
        num(p + "sim_period", 0.05, above=0.0, high=_D, unit="s")
    vel = n(num, low=-_D, high=_D, unit="m/s")
    min_vel_x, max_vel_x = vel(p + "min_vel_x", 0.0), vel(p + "max_vel_x", 0.0)
    max_vel_theta = num(p + "max_vel_theta", 0.0, low=-_D, high=_D, unit="rad/s")
    max_speed_xy = vel(p + "max_speed_xy", 0.0)
    vel(p + "min_speed_xy", 0.0)
    num(p + "min_speed_theta", 0.0, low=-_D, high=_D, unit="rad/s")
    num(p + "acc_lim_x", 0.0, low=0.0, high=_D, unit="m/s^2")
    num(p + "acc_lim_theta", 0.0, low=0.0, high=_D, unit="rad/s^2")
    num(p + "decel_lim_x", 0.0, low=-_D, high=0.0, unit="m/s^2")
    num(p + "decel_lim_theta", 0.0, low=-_D, high=0.0, unit="rad/s^2")
    vx = r.integer(p + "vx_samples", 20, low=1)
    vth = r.integer(p + "vtheta_samples", 20, low=1)
    sim_time = num(p + "sim_time", 1.7, above=0.0, high=_D, unit="s")
    lin_gran = num(p + "linear_granularity", 0.5, above=0.0, high=_D, unit="m")
    ang_gran = num(p + "angular_granularity", 0.025, above=0.0, high=_D, unit="rad")
    flag(p + "include_last_point", True)
    num(p + "xy_goal_tolerance", 0.25, low=0.0, high=_D, unit="m")
    num(p + "trans_stopped_velocity", 0.25, low=0.0, high=_D, unit="m/s")
    flag(p + "prune_plan", True)
    num(p + "prune_distance", 2.0, low=0.0, high=_D, unit="m")
    num(p + "forward_prune_distance", 2.0, low=0.0, high=_D, unit="m")
    flag(p + "shorten_transformed_plan", True)
    for critic in ("BaseObstacle", "PathAlign", "GoalAlign", "PathDist", "GoalDist", "RotateToGoal", "Oscillation"):
        num(f"{p}{critic}.scale", 1.0, low=-_D, high=_D)
    for critic in ("PathAlign", "GoalAlign"):
        num(f"{p}{critic}.forward_point_distance", 0.325, low=-_D, high=_D, unit="m")
    num(p + "RotateToGoal.slowing_factor", 5.0, low=0.0, high=_D)
    num(p + "Oscillation.oscillation_reset_dist", 0.05, low=0.0, high=_D, unit="m")
    num(p + "Oscillation.oscillation_reset_angle", 0.2, low=0.0, high=_D, unit="rad")
    num(p + "Oscillation.x_only_threshold", 0.05, low=0.0, high=_D, unit="m/s")
    if not strict:
        return
    lin = max(abs(min_vel_x), abs(max_vel_x), max_speed_xy)
    steps = max(lin * sim_time / lin_gran, abs(max_vel_theta) * sim_time / ang_gran) + 3
    samples = (max(vx, 2) + 2.0) * (max(vth, 2) + 2.0)
    key = p + ("vx_samples" if steps * _DWB_STEP_BYTES < samples * 8 else "sim_time")
    _fits(
        functools.partial(r.source.locate, r.node, key),
        f"DWB's {vx} x {vth} velocity samples with trajectories of up to {steps:.3g} steps",
        samples * _DWB_SAMPLE_BYTES + steps * _DWB_STEP_BYTES + cells * 8.0,
        "lower vx_samples / vtheta_samples, or sim_time against linear_granularity and angular_granularity",
    )


_RPP_NUMBERS = (
    "desired_linear_vel", "lookahead_dist", "min_lookahead_dist", "max_lookahead_dist", "lookahead_time",
    "rotate_to_heading_angular_vel", "min_approach_linear_velocity", "approach_velocity_scaling_dist",
    "regulated_linear_scaling_min_radius", "regulated_linear_scaling_min_speed", "rotate_to_heading_min_angle",
    "max_angular_accel", "cost_scaling_dist", "cost_scaling_gain", "max_allowed_time_to_collision_up_to_carrot",
    "inflation_cost_scaling_factor", "max_robot_pose_search_dist", "transform_tolerance",
)  # fmt: skip
_RPP_FLAGS = (
    "use_velocity_scaled_lookahead_dist", "use_regulated_linear_velocity_scaling",
    "use_cost_regulated_linear_velocity_scaling", "use_rotate_to_heading", "use_collision_detection",
    "allow_reversing", "use_interpolation",
)  # fmt: skip


def _rpp(r: ParamReader, name: str) -> None:
    for key in _RPP_NUMBERS:
        r.number(f"{name}.{key}", 1.0, low=0.0, high=_D)
    for key in _RPP_FLAGS:
        r.flag(f"{name}.{key}", True)


def _controller_server(r: ParamReader, strict: bool, local_cells: int) -> float:
    hz = _rate(r, "controller_frequency", 20.0)
    r.number("failure_tolerance", 0.0, low=-1.0, high=_D, unit="s")
    r.number("min_x_velocity_threshold", 0.0001, low=0.0, high=_D, unit="m/s")
    r.number("min_theta_velocity_threshold", 0.0001, low=0.0, high=_D, unit="rad/s")
    plugins = r.str_list("controller_plugins", ("FollowPath",))
    for name in plugins:
        plugin = r.text(f"{name}.plugin", DWB_PLUGIN)
        if plugin == DWB_PLUGIN:
            _dwb(r, name, hz, strict, local_cells)
        elif plugin == RPP_PLUGIN:
            _rpp(r, name)
        elif strict:
            raise r.fail(f"{name}.plugin", f"unknown controller plugin {plugin!r}", f"use {DWB_PLUGIN} or {RPP_PLUGIN}")
    checkers = r.str_list("goal_checker_plugins", ()) or (r.text("goal_checker_plugin", "goal_checker"),)
    r.text("goal_checker_plugin", "goal_checker")
    for name in checkers:
        plugin = r.text(f"{name}.plugin", GOAL_CHECKER_PLUGINS[0])
        if strict and plugin not in GOAL_CHECKER_PLUGINS:
            raise r.fail(
                f"{name}.plugin", f"unknown goal checker plugin {plugin!r}", f"use {' or '.join(GOAL_CHECKER_PLUGINS)}"
            )
        r.number(f"{name}.xy_goal_tolerance", 0.25, low=0.0, high=_D, unit="m")
        r.number(f"{name}.yaw_goal_tolerance", 0.25, low=0.0, high=_D, unit="rad")
        r.flag(f"{name}.stateful", True)
        if plugin == GOAL_CHECKER_PLUGINS[1]:
            r.number(f"{name}.trans_stopped_velocity", 0.25, low=0.0, high=_D, unit="m/s")
            r.number(f"{name}.rot_stopped_velocity", 0.25, low=0.0, high=_D, unit="rad/s")
    progress = r.text("progress_checker_plugin", "progress_checker")
    plugin = r.text(f"{progress}.plugin", PROGRESS_CHECKER_PLUGINS[0])
    if strict and plugin not in PROGRESS_CHECKER_PLUGINS:
        fix = f"use {' or '.join(PROGRESS_CHECKER_PLUGINS)}"
        raise r.fail(f"{progress}.plugin", f"unknown progress checker plugin {plugin!r}", fix)
    r.number(f"{progress}.required_movement_radius", 0.5, low=0.0, high=_D, unit="m")
    r.number(f"{progress}.movement_time_allowance", 10.0, low=0.0, high=_D, unit="s")
    if plugin == PROGRESS_CHECKER_PLUGINS[1]:
        r.number(f"{progress}.required_movement_angle", 0.5, low=0.0, high=_D, unit="rad")
    return hz


def _planner_server(r: ParamReader) -> None:
    names = r.str_list("planner_plugins", ("GridBased",))
    for name in names[:1]:  # the twin plans with the first (the navigator's tree names no other)
        r.text(f"{name}.plugin", "nav2_navfn_planner/NavfnPlanner")
        r.number(f"{name}.tolerance", 0.5, low=0.0, high=_D, unit="m")
        r.flag(f"{name}.use_astar", False)
        r.flag(f"{name}.allow_unknown", True)


def _bt_navigator(r: ParamReader) -> float:
    loop_ms = r.number("bt_loop_duration", 10.0, low=1e3 / MAX_RATE_HZ, high=1e3 / MIN_RATE_HZ, unit="ms")
    for key, default in (("global_frame", "map"), ("robot_base_frame", "base_link"), ("odom_topic", "odom")):
        r.text(key, default)
    return 1e3 / loop_ms


def _velocity_smoother(r: ParamReader) -> float:
    hz = _rate(r, "smoothing_frequency", 20.0)
    _triple(r, "max_velocity", (0.5, 0.0, 2.5))
    _triple(r, "min_velocity", (-0.5, 0.0, -2.5))
    _triple(r, "max_accel", (2.5, 0.0, 3.2), sign=1)
    _triple(r, "max_decel", (-2.5, 0.0, -3.2), sign=-1)
    _triple(r, "deadband_velocity", (0.0, 0.0, 0.0), sign=1)
    r.number("velocity_timeout", 1.0, low=0.0, high=_D, unit="s")
    r.text("feedback", "OPEN_LOOP")
    r.number("odom_duration", 0.1, low=0.0, high=_D, unit="s")
    r.flag("scale_velocities", False)
    return hz


def _behavior_server(r: ParamReader) -> float:
    hz = _rate(r, "cycle_frequency", 10.0)
    ahead = r.number("simulate_ahead_time", 2.0, low=0.0, high=_D, unit="s")
    r.number("max_rotational_vel", 1.0, low=0.0, high=_D, unit="rad/s")
    r.number("min_rotational_vel", 0.4, low=0.0, high=_D, unit="rad/s")
    r.number("rotational_acc_lim", 3.2, low=0.0, high=_D, unit="rad/s^2")
    for name in ("backup", "drive_on_heading"):  # Humble flips limits given with the wrong sign
        r.number(f"{name}.acceleration_limit", 0.0, low=-_D, high=_D, unit="m/s^2")
        r.number(f"{name}.deceleration_limit", 0.0, low=-_D, high=_D, unit="m/s^2")
        r.number(f"{name}.minimum_speed", 0.0, low=0.0, high=_D, unit="m/s")
    if not isinstance(r, _Collector) and hz * ahead > _LOOKAHEAD_STEPS:
        raise r.fail(
            "simulate_ahead_time",
            f"{ahead:g} s at cycle_frequency {hz:g} Hz checks {hz * ahead:.3g} footprints per cycle "
            f"(more than {_LOOKAHEAD_STEPS})",
            "a few seconds is what Nav2 uses (2.0)",
        )
    return hz


_SERVERS: Mapping[str, Callable[..., float | None]] = {
    "controller_server": _controller_server,
    "planner_server": _planner_server,
    "bt_navigator": _bt_navigator,
    "velocity_smoother": _velocity_smoother,
    "behavior_server": _behavior_server,
}


def _server_node(params: Nav2Params, short: str) -> str:
    for name in params.raw:
        if name == short or name.rsplit("/", 1)[-1] == short:
            return name
    return short


# --- the whole check -------------------------------------------------------------------------------


class _Grid(Protocol):
    """What the checks need of a map (`OccupancyMap`): its cell size and cell counts."""

    @property
    def resolution_m(self) -> float: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...


@dataclass(frozen=True, kw_only=True, slots=True)
class _Rates:
    where: Where
    rate_hz: float


def _check_whole_file(params: Nav2Params) -> None:
    """Refuse a params file without Nav2's navigation servers (one of a split pair), naming what it holds.

    TurtleBot4's and Clearpath's bringups split Nav2's parameters into a localization file (amcl,
    map_server) and a navigation one; the twin reads one file, as nav2_bringup's `params_file` is one.
    """
    have = {name.rsplit("/", 1)[-1] for name in params.raw}
    missing = [n for n in ("controller_server", "planner_server") if n not in have]
    if len(missing) < 2:  # (one of them alone runs on Nav2's defaults, or is refused for what it lacks)
        return
    holds = ", ".join(sorted(have)) or "no node"
    msg = (
        f"{params.source}: holds no {' and no '.join(missing)} section (it holds {holds}), so Nav2 Humble's "
        'controller_server would not start ("No critics defined for FollowPath"): navigation.params takes '
        "Nav2's whole params file, as nav2_bringup's params_file; merge a split pair (a localization file and "
        "a navigation one) into one file"
    )
    raise ConfigError(msg)


def check_nav2_inputs(
    params: Nav2Params,
    occupancy: _Grid | None = None,
    *,
    map_source: str | None = None,
    amcl: bool = True,
    nav2: bool = True,
    physics_step_s: float | None = None,
) -> None:
    """Check what the run would build from a params file (and its map) before it is built.

    Args:
        params: The loaded params file (with the scenario's `navigation.set`).
        occupancy: The map AMCL and the global costmap use (None: checked without it).
        map_source: The map's YAML file, named when the map's cells make a structure too large.
        amcl: True when AMCL runs (its particle set and likelihood field are sized).
        nav2: True when Nav2's servers run (their parameters are checked and the costmaps sized).
        physics_step_s: The scenario's physics step: no Nav2 rate may exceed its rate.

    Raises:
        ConfigError: The first problem, one line: `FILE:LINE: node.key: problem; fix` or
            `navigation.set.node.key: problem; fix`.
    """
    source = params.origin or ParamSource(Path(params.source))
    if nav2:
        _check_whole_file(params)
    local_cells = _cells(params.local_costmap.width_m, params.local_costmap.height_m, params.local_costmap.resolution_m)
    known: dict[str, set[str]] = {node: set(keys) for node, keys in params.read_keys.items()}
    rates: list[_Rates] = []
    if nav2:  # the costmaps first: DWB's check counts the local costmap's cells too
        for costmap in (params.global_costmap, params.local_costmap):
            node = next((n for n in params.read_keys if n.rsplit("/", 1)[-1] == costmap.name), costmap.name)
            update, publish = costmap.update_frequency_hz, costmap.publish_frequency_hz
            rates.append(_Rates(where=functools.partial(source.locate, node, "update_frequency"), rate_hz=update))
            rates.append(_Rates(where=functools.partial(source.locate, node, "publish_frequency"), rate_hz=publish))
            _check_costmap_memory(params, source, node, occupancy, map_source)
    for short, check in _SERVERS.items():
        node = _server_node(params, short)
        node_params = params.raw.get(node, {})
        reader = ParamReader(source, node, node_params) if nav2 else _Collector(source, node, node_params)
        rate = check(reader, nav2, local_cells) if short == "controller_server" else check(reader)
        known.setdefault(node, set()).update(reader.used)
        if rate is not None and nav2:
            key = {"controller_server": "controller_frequency", "bt_navigator": "bt_loop_duration",
                   "velocity_smoother": "smoothing_frequency", "behavior_server": "cycle_frequency"}[short]  # fmt: skip
            rates.append(_Rates(where=functools.partial(source.locate, node, key), rate_hz=rate))
    _check_set_keys(params, source, known)
    if amcl:
        _check_amcl_memory(params, source, occupancy, map_source)
    if physics_step_s is not None and physics_step_s > 0:
        physics_hz = 1.0 / physics_step_s
        for entry in rates:
            if entry.rate_hz > physics_hz * (1 + 1e-9):
                msg = (
                    f"{_text(entry.where)}: {entry.rate_hz:g} Hz is above the physics rate ({physics_hz:g} Hz, "
                    f"physics.step_s {physics_step_s:g}); lower it or shorten physics.step_s"
                )
                raise ConfigError(msg)


def _cells(width_m: float, height_m: float, resolution_m: float) -> int:
    return max(1, int(width_m / resolution_m)) * max(1, int(height_m / resolution_m))


def _map_where(map_source: str | None, occupancy: _Grid, fallback: Where) -> Where:
    """Where a size that comes from the map's cells is blamed: the map's `resolution`, naming the parameter too."""
    if map_source is None:
        return fallback
    return lambda: (
        f"{map_source}: 'resolution' {occupancy.resolution_m:g} m (with {_text(fallback).rsplit(': ', 1)[-1]})"
    )


def _check_costmap_memory(
    params: Nav2Params, source: ParamSource, node: str, occupancy: _Grid | None, map_source: str | None
) -> None:
    spec = params.global_costmap if node.rsplit("/", 1)[-1] == "global_costmap" else params.local_costmap
    layers = sum(1 for layer in spec.obstacle_layers if layer.enabled)
    per_cell = _COSTMAP_CELL_BYTES + layers * _COSTMAP_LAYER_CELL_BYTES
    cols, rows = max(1, int(spec.width_m / spec.resolution_m)), max(1, int(spec.height_m / spec.resolution_m))
    fix = "make width and height smaller or resolution coarser (TurtleBot3: 3 x 3 m at 0.05 m)"
    key = "resolution" if spec.resolution_m < 1e-3 else ("width" if spec.width_m >= spec.height_m else "height")
    _fits(
        functools.partial(source.locate, node, key),
        f"{spec.name}'s grid of {cols} x {rows} cells at {spec.resolution_m:g} m",
        float(cols) * rows * per_cell,
        fix,
    )
    resolution = spec.resolution_m
    static = spec.static_layer is not None and spec.static_layer.enabled and not spec.rolling_window
    from_map = static and occupancy is not None
    if static and occupancy is not None:  # a static costmap takes the map's size and cells
        resolution = occupancy.resolution_m
        _fits(
            map_source or functools.partial(source.locate, node, "plugins"),
            f"{spec.name}'s grid over the map's {occupancy.width} x {occupancy.height} cells",
            float(occupancy.width) * occupancy.height * (per_cell + _STATIC_CELL_BYTES),
            "use a smaller map (or a coarser one)",
        )
    inflation = spec.inflation
    if inflation is not None and inflation.enabled:
        radius_cells = math.ceil(inflation.inflation_radius_m / resolution)
        where = functools.partial(source.locate, node, f"{inflation.name}.inflation_radius")
        _fits(
            _map_where(map_source, occupancy, where) if from_map and occupancy is not None else where,
            f"{spec.name}'s inflation table for {inflation.inflation_radius_m:g} m over {resolution:g} m cells "
            f"({radius_cells} cells)",
            (float(radius_cells) ** 2 + 2) * _INFLATION_TABLE_BYTES,
            "lower inflation_radius (TurtleBot3: 0.55 m) or use coarser cells",
        )


def _check_amcl_memory(
    params: Nav2Params, source: ParamSource, occupancy: _Grid | None, map_source: str | None
) -> None:
    node = next((n for n in params.read_keys if n.rsplit("/", 1)[-1] == "amcl"), "amcl")
    a = params.amcl
    _fits(
        functools.partial(source.locate, node, "max_particles"),
        f"AMCL's set of {a.max_particles} particles",
        float(a.max_particles) * _PARTICLE_BYTES,
        "lower max_particles (TurtleBot3: 2000)",
    )
    if occupancy is None:
        return
    radius = int(a.laser_likelihood_max_dist_m / occupancy.resolution_m)
    _fits(
        _map_where(map_source, occupancy, functools.partial(source.locate, node, "laser_likelihood_max_dist")),
        f"AMCL's likelihood field over the map's {occupancy.width} x {occupancy.height} cells of "
        f"{occupancy.resolution_m:g} m (distances up to {a.laser_likelihood_max_dist_m:g} m: {radius} cells)",
        float(occupancy.width) * occupancy.height * _FIELD_CELL_BYTES + (float(radius) + 2) ** 2 * 8,
        "use a smaller or coarser map, or lower laser_likelihood_max_dist (TurtleBot3: 1.0 m)",
    )


def _check_set_keys(params: Nav2Params, source: ParamSource, known: Mapping[str, Iterable[str]]) -> None:
    """Every `navigation.set` key must name a parameter the twin reads."""
    nodes = {node.rsplit("/", 1)[-1]: node for node in known}
    for (node, key), written in source.overridden.items():
        short = written.partition(".")[0]
        if node not in known and nodes.get(short) is None:
            close = difflib.get_close_matches(short, sorted(nodes), n=1, cutoff=0.6)
            hint = f"did you mean '{close[0]}'?" if close else "remove it"
            if short == "map_server":
                hint = "the scenario's `map:` names the map the twin serves; set that"
            runs = ", ".join(sorted(nodes))
            msg = f"{SET_KEY}.{written}: the twin runs no Nav2 node {short!r}; {hint} (it runs {runs})"
            raise ConfigError(msg)
        keys = set(known.get(node, known.get(nodes.get(short, node), ())))
        if key in keys:
            continue
        close = difflib.get_close_matches(key, sorted(keys), n=1, cutoff=0.6)
        fix = f"did you mean '{short}.{close[0]}'?" if close else "remove it (the twin reads only what it implements)"
        msg = f"{SET_KEY}.{written}: the twin reads no parameter '{short}.{key}'; {fix}"
        raise ConfigError(msg)


# --- map files -----------------------------------------------------------------------------------

_FLOAT32_TINY = 1.1754943508222875e-38  # the smallest normal float32: OccupancyGrid's resolution is a float32


def _at(where: str, key: str) -> str:
    """`FILE:LINE` of a map YAML's top-level `key` (`FILE` alone when the file does not say)."""
    try:
        node = yaml_numbers.compose(Path(where).read_text(encoding="utf-8"), where)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError):
        return where
    if isinstance(node, yaml.MappingNode):
        for key_node, _ in node.value:
            if key_node.value == key:
                return f"{where}:{key_node.start_mark.line + 1}"
    return where


def check_map_fields(
    where: str, *, resolution_m: float, origin: tuple[float, float, float], occupied: float, free: float, scale: bool
) -> None:
    """Refuse map YAML numbers the map cannot be used with (after their types are checked).

    Args:
        where: The map YAML file (its lines are looked up for the message).
        resolution_m: `resolution`.
        origin: `origin` (x, y, yaw).
        occupied: `occupied_thresh`.
        free: `free_thresh`.
        scale: True in `mode: scale`.

    Raises:
        ConfigError: `FILE:LINE: 'key' problem; fix`.
    """
    if not _FLOAT32_TINY <= resolution_m <= MAX_DISTANCE_M:
        msg = (
            f"{_at(where, 'resolution')}: 'resolution' must be between {_FLOAT32_TINY:.3g} and {MAX_DISTANCE_M:g} m "
            f"(an OccupancyGrid carries it as a float32), got {resolution_m!r}; fix it (TurtleBot3's map: 0.05)"
        )
        raise ConfigError(msg)
    for name, value in zip(("x", "y", "yaw"), origin, strict=True):
        if not (math.isfinite(value) and abs(value) <= MAX_DISTANCE_M):
            bound = f"a finite number within ±{MAX_DISTANCE_M:g}"
            msg = f"{_at(where, 'origin')}: 'origin' {name} must be {bound}, got {value!r}; fix it"
            raise ConfigError(msg)
    for key, value in (("occupied_thresh", occupied), ("free_thresh", free)):
        if not 0.0 <= value <= 1.0:
            fix = "fix it (map_saver writes 0.65 and 0.25)"
            msg = f"{_at(where, key)}: '{key}' must be between 0 and 1, got {value!r}; {fix}"
            raise ConfigError(msg)
    if scale and not free < occupied:
        problem = f"'free_thresh' ({free}) must be below 'occupied_thresh' ({occupied}) in scale mode"
        msg = f"{_at(where, 'free_thresh')}: {problem}; fix them"
        raise ConfigError(msg)


def _pnm_size(head: bytes) -> tuple[int, int] | None:
    """Width and height from a PBM/PGM/PPM header (P1..P6), comments skipped."""
    if len(head) < 2 or head[:1] != b"P" or head[1:2] not in b"123456":
        return None
    numbers: list[int] = []
    i = 2
    while len(numbers) < 2 and i < len(head):
        c = head[i : i + 1]
        if c == b"#":
            while i < len(head) and head[i : i + 1] not in b"\r\n":
                i += 1
        elif c.isdigit():
            j = i
            while j < len(head) and head[j : j + 1].isdigit():
                j += 1
            numbers.append(int(head[i:j]))
            i = j
            continue
        elif not c.isspace():
            return None
        i += 1
    return (numbers[0], numbers[1]) if len(numbers) == 2 else None


def _image_size(path: Path) -> tuple[int, int] | None:
    """Width and height read from a PNM or PNG header, without decoding the image (None: another format)."""
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except OSError:
        return None
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        width, height = struct.unpack(">II", head[16:24])
        return int(width), int(height)
    return _pnm_size(head)


def check_map_image(path: Path, where: str) -> None:
    """Refuse a map image that would not fit in memory once decoded, from its header's size.

    Raises:
        ConfigError: `FILE: map image IMAGE is W x H pixels: ... would take N; fix`.
    """
    size = _image_size(path)
    if size is None:
        return  # another format: PIL's own limit (a decompression-bomb check) applies when it opens it
    width, height = size
    _fits(
        where,
        f"map image {str(path)!r} of {width} x {height} pixels, decoded,",
        float(width) * height * _IMAGE_PIXEL_BYTES,
        "use a smaller image or a coarser map",
    )
