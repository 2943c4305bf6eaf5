"""The navigation servers' parameters, read from a Nav2 params file.

`nav2_config` reads what controller_server (controllers, goal and progress checkers),
planner_server (NavFn), velocity_smoother, behavior_server and bt_navigator take from a params
file (`twin.nav.params.load_nav2_params`), refusing a plugin or value the twin cannot run before the
run starts. Costmaps and AMCL read their own sections in `twin.nav.params`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from twin.core.errors import ConfigError
from twin.nav.behaviors.behavior_server import BEHAVIORS
from twin.nav.behaviors.timed_behavior import BehaviorParams
from twin.nav.controller.checkers import (
    GOAL_CHECKER_PLUGINS,
    PROGRESS_CHECKER_PLUGINS,
    SimpleGoalChecker,
    StoppedGoalChecker,
)
from twin.nav.controller.controller_server import CONTROLLER_PLUGINS, controller_for_plugin
from twin.nav.controller.regulated_pure_pursuit import NAV2_PARAMETERS as RPP_PARAMETERS
from twin.nav.params import Nav2Params
from twin.nav.planner.navfn import NavfnParams
from twin.nav.velocity_smoother.velocity_smoother import Feedback, SmootherParams
from twin.node.node import validate_topic_name

__all__ = ["Nav2Config", "nav2_config"]


@dataclass(frozen=True, kw_only=True, slots=True)
class Nav2Config:
    """What the navigation servers read from a Nav2 params file (TB3 Humble values by default)."""

    controller_frequency_hz: float = 10.0
    failure_tolerance_s: float = 0.3
    velocity_thresholds: tuple[float, float] = (0.001, 0.001)
    controllers: Mapping[str, tuple[str, Mapping[str, object]]] = field(default_factory=dict)
    goal_checkers: Mapping[str, SimpleGoalChecker] = field(default_factory=dict)
    progress_radius_m: float = 0.5
    progress_allowance_s: float = 10.0
    progress_angle_rad: float | None = None  # PoseProgressChecker's required_movement_angle (None: Simple)
    planner: NavfnParams = field(default_factory=NavfnParams)
    behaviors: BehaviorParams = field(default_factory=BehaviorParams)
    #: behavior_server's action servers: name → the behaviour it runs (`spin`, `backup`, `drive_on_heading`,
    #: `wait`; None: AssistedTeleop, which the twin does not simulate), as `behavior_plugins` loads them.
    behavior_servers: Mapping[str, str | None] = field(
        default_factory=lambda: MappingProxyType(dict(zip(BEHAVIORS, BEHAVIORS, strict=True)))
    )
    smoother: SmootherParams = field(default_factory=SmootherParams)
    bt_loop_duration_s: float = 0.01
    used: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


def _num(section: Mapping[str, Any], key: str, default: float, where: str) -> float:
    value = section.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"{where}.{key}: expected a number, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return float(value)


def _flag(section: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
    value = section.get(key, default)
    if not isinstance(value, bool):
        msg = f"{where}.{key}: expected true or false, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return value


def _drive_limits(section: Mapping[str, Any], behavior: str, where: str) -> tuple[float, float, float]:
    """DriveOnHeading's / BackUp's `<behavior>.acceleration_limit`, `.deceleration_limit`, `.minimum_speed` (0 each)."""
    keys = ("acceleration_limit", "deceleration_limit", "minimum_speed")
    accel, decel, minimum = (_num(section, f"{behavior}.{k}", 0.0, where) for k in keys)
    return accel, decel, minimum


# behavior_server's plugin types (Humble), by the behaviour each runs (None: not simulated by the twin).
BEHAVIOR_TYPES: Mapping[str, str | None] = {
    "nav2_behaviors/Spin": "spin",
    "nav2_behaviors/BackUp": "backup",
    "nav2_behaviors/DriveOnHeading": "drive_on_heading",
    "nav2_behaviors/Wait": "wait",
    "nav2_behaviors/AssistedTeleop": None,
}


def _behavior_servers(bs: Mapping[str, Any], where: str) -> dict[str, str | None]:
    """behavior_server's action servers as Humble's loads them: `behavior_plugins` and each one's `<name>.plugin`.

    Without `behavior_plugins` Humble loads spin, backup, drive_on_heading and wait with their own
    types; a name of the list outside those needs its type (Humble's server does not start without).

    Raises:
        ConfigError: A name without a plugin type in a given list, or a type Humble does not have.
    """
    names = _names(bs, "behavior_plugins", BEHAVIORS, where)
    defaults = {"spin": "Spin", "backup": "BackUp", "drive_on_heading": "DriveOnHeading", "wait": "Wait"}
    out: dict[str, str | None] = {}
    for name in names:
        plugin = bs.get(f"{name}.plugin")
        if plugin is None and name in defaults:  # (Humble declares these for its default list)
            plugin = f"nav2_behaviors/{defaults[name]}"
        if plugin is None:
            msg = (
                f"{where}.{name}.plugin: not set, and Humble's behavior_server does not start without a plugin type "
                f"for each name of behavior_plugins; give one of {', '.join(BEHAVIOR_TYPES)}"
            )
            raise ConfigError(msg)
        kind = str(plugin).replace("::", "/")
        if kind not in BEHAVIOR_TYPES:
            msg = f"{where}.{name}.plugin: unknown behaviour {plugin!r}; Humble's are {', '.join(BEHAVIOR_TYPES)}"
            raise ConfigError(msg)
        out[name] = BEHAVIOR_TYPES[kind]
    return out


def _named_kind(servers: Mapping[str, str | None], kind: str) -> str:
    """The name behavior_server loads a behaviour under (its parameters' prefix), or the behaviour's own."""
    return next((name for name, k in servers.items() if k == kind), kind)


def _names(section: Mapping[str, Any], key: str, default: Sequence[str], where: str) -> tuple[str, ...]:
    value = section.get(key, list(default))
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        msg = f"{where}.{key}: expected a list of names, got {value!r}; fix the params file"
        raise ConfigError(msg)
    return tuple(value)


def _plugins(params: Nav2Params, node: str, key: str, default: str) -> tuple[str, ...]:
    """A server's plugin names (`planner_plugins`), refused empty or naming a plugin whose type is not set.

    Nav2 (Humble) gives the default plugin its type only while the list is its default (`[GridBased]`,
    `[FollowPath]`); any other name must say which plugin it is (`<name>.plugin`), or the server fails
    to configure. An empty list loads nothing: every goal the navigator's tree sends it would fail.
    """
    section = params.node(node)
    names = _names(section, key, (default,), f"{params.source}: {node}")

    def at(name: str) -> str:
        origin = params.origin
        return origin.locate(node, name) if origin is not None else f"{params.source}: {node}.{name}"

    if not names:
        msg = f"{at(key)}: is empty, so {node} has no plugin for its goals; name one (e.g. [{default}])"
        raise ConfigError(msg)
    if names != (default,):
        for name in names:
            if f"{name}.plugin" not in section:
                msg = f"{at(key)}: names {name!r}, but {name}.plugin is not set; Nav2 needs each plugin's type"
                raise ConfigError(msg)
    return names


def _sub(section: Mapping[str, Any], prefix: str) -> dict[str, object]:
    return {k[len(prefix) + 1 :]: v for k, v in section.items() if k.startswith(prefix + ".")}


def _triple(
    section: Mapping[str, Any], key: str, default: tuple[float, float, float], where: str
) -> tuple[float, float, float]:
    value = section.get(key)
    if value is None:
        return default
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(v, int | float) for v in value):
        msg = f"{where}.{key}: expected [x, y, theta], got {value!r}; fix the params file"
        raise ConfigError(msg)
    return (float(value[0]), float(value[1]), float(value[2]))


class _Reads(dict[str, object]):
    """A plugin's parameters that note which keys its reader asked for (`get`, `[]`, `in`)."""

    def __init__(self, section: Mapping[str, object]) -> None:
        super().__init__(section)
        self.read: set[str] = set()

    def get(self, key: str, default: object = None) -> object:
        self.read.add(key)
        return super().get(key, default)

    def __getitem__(self, key: str) -> object:
        self.read.add(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        if isinstance(key, str):
            self.read.add(key)
        return super().__contains__(key)


def nav2_config(params: Nav2Params) -> Nav2Config:
    """Read the controller, planner, behaviour, smoother and navigator parameters of a Nav2 params file.

    Raises:
        ConfigError: A value of the wrong type, or a plugin the twin does not implement (its line named).
    """
    try:
        return _nav2_config(params)
    except ConfigError as err:
        raise _with_line(err, params) from None


def _with_line(err: ConfigError, params: Nav2Params) -> ConfigError:
    """`FILE: node.key: problem` as `FILE:LINE: node.key: problem` when the key is in the file (not an override)."""
    text, prefix = str(err), f"{params.source}: "
    if params.origin is None or not text.startswith(prefix):
        return err
    dotted, _, rest = text[len(prefix) :].partition(": ")
    short, _, key = dotted.partition(".")
    node = next((n for n in params.raw if n.rsplit("/", 1)[-1] == short), short)
    line = params.origin.line(node, key) if key and rest else None
    if line is None or (node, key) in params.origin.overridden:
        return err
    return ConfigError(f"{params.source}:{line}: {dotted}: {rest}")


def _nav2_config(params: Nav2Params) -> Nav2Config:
    src = params.source
    cs = params.node("controller_server")
    where = f"{src}: controller_server"
    used: dict[str, list[str]] = {"controller_server": [], "planner_server": [], "bt_navigator": []}
    cu = used["controller_server"]
    plugins = _plugins(params, "controller_server", "controller_plugins", "FollowPath")
    frequency = _num(cs, "controller_frequency", 20.0, where)
    controllers: dict[str, tuple[str, Mapping[str, object]]] = {}
    for name in plugins:
        section = _sub(cs, name)
        plugin = str(section.get("plugin", "dwb_core::DWBLocalPlanner"))
        # refuses unknown plugins, critics and bad values now, before the run
        reads = _Reads(section)
        controller_for_plugin(plugin, reads, where=f"{where}.{name}", controller_frequency_hz=frequency)
        controllers[name] = (plugin, section)
        # RPP: the keys Humble's RPP declares; DWB: the keys the twin's DWB reads (a typo such as
        # max_vel_xx, or a parameter of a critic the list does not name, is not); the others are
        # named in the unused-parameters warning
        taken = RPP_PARAMETERS if plugin == CONTROLLER_PLUGINS[1] else reads.read | {"plugin"}
        cu.extend(f"{name}.{k}" for k in section if k in taken)
    checker_names = _names(cs, "goal_checker_plugins", (), where) or (
        str(cs.get("goal_checker_plugin", "goal_checker")),
    )
    checkers: dict[str, SimpleGoalChecker] = {}
    for name in checker_names:
        section = _sub(cs, name)
        xy = _num(section, "xy_goal_tolerance", 0.25, f"{where}.{name}")
        yaw = _num(section, "yaw_goal_tolerance", 0.25, f"{where}.{name}")
        stateful = bool(section.get("stateful", True))
        keys = ["plugin", "xy_goal_tolerance", "yaw_goal_tolerance", "stateful"]
        if str(section.get("plugin", GOAL_CHECKER_PLUGINS[0])) == GOAL_CHECKER_PLUGINS[1]:
            checkers[name] = StoppedGoalChecker(
                xy_goal_tolerance_m=xy,
                yaw_goal_tolerance_rad=yaw,
                stateful=stateful,
                trans_stopped_velocity_mps=_num(section, "trans_stopped_velocity", 0.25, f"{where}.{name}"),
                rot_stopped_velocity_radps=_num(section, "rot_stopped_velocity", 0.25, f"{where}.{name}"),
            )
            keys += ["trans_stopped_velocity", "rot_stopped_velocity"]
        else:
            checkers[name] = SimpleGoalChecker(xy_goal_tolerance_m=xy, yaw_goal_tolerance_rad=yaw, stateful=stateful)
        cu.extend(f"{name}.{k}" for k in keys if k in section)  # (another's key is named unused)
    progress_name = str(cs.get("progress_checker_plugin", "progress_checker"))
    progress = _sub(cs, progress_name)
    progress_keys = ["plugin", "required_movement_radius", "movement_time_allowance"]
    progress_angle = None
    if str(progress.get("plugin", PROGRESS_CHECKER_PLUGINS[0])) == PROGRESS_CHECKER_PLUGINS[1]:
        progress_angle = _num(progress, "required_movement_angle", 0.5, f"{where}.{progress_name}")
        progress_keys.append("required_movement_angle")
    cu.extend(f"{progress_name}.{k}" for k in progress_keys if k in progress)
    cu += ["controller_frequency", "failure_tolerance", "controller_plugins", "goal_checker_plugins"]
    cu += ["min_x_velocity_threshold", "min_theta_velocity_threshold"]
    cu += ["goal_checker_plugin", "progress_checker_plugin"]
    ps = params.node("planner_server")
    pwhere = f"{src}: planner_server"
    planner_names = _plugins(params, "planner_server", "planner_plugins", "GridBased")
    grid = _sub(ps, planner_names[0])
    plugin = str(grid.get("plugin", "nav2_navfn_planner/NavfnPlanner"))
    if plugin.replace("::", "/") != "nav2_navfn_planner/NavfnPlanner":
        msg = (
            f"{pwhere}.{planner_names[0]}.plugin: unknown planner plugin {plugin!r}; "
            "the twin has nav2_navfn_planner/NavfnPlanner"
        )
        raise ConfigError(msg)
    planner = NavfnParams(
        tolerance_m=_num(grid, "tolerance", 0.5, f"{pwhere}.{planner_names[0]}"),
        use_astar=bool(grid.get("use_astar", False)),
        allow_unknown=bool(grid.get("allow_unknown", True)),
    )
    used["planner_server"] = ["planner_plugins", *(f"{planner_names[0]}.{k}" for k in grid)]
    bt = params.node("bt_navigator")
    loop_ms = _num(bt, "bt_loop_duration", 10.0, f"{src}: bt_navigator")
    used["bt_navigator"] = ["bt_loop_duration", "global_frame", "robot_base_frame", "odom_topic"]
    vs = params.node("velocity_smoother")
    vwhere = f"{src}: velocity_smoother"
    feedback = vs.get("feedback", "OPEN_LOOP")
    if feedback not in ("OPEN_LOOP", "CLOSED_LOOP"):
        msg = f"{vwhere}.feedback: expected OPEN_LOOP or CLOSED_LOOP (as Nav2), got {feedback!r}"
        raise ConfigError(msg)
    defaults = SmootherParams()
    odom_topic = vs.get("odom_topic", defaults.odom_topic)
    if not isinstance(odom_topic, str):
        msg = f"{vwhere}.odom_topic: expected a topic name, got {odom_topic!r}; fix the params file"
        raise ConfigError(msg)
    problem = validate_topic_name(odom_topic)
    if problem is not None:
        msg = f"{vwhere}.odom_topic: {problem}; fix the params file"
        raise ConfigError(msg)
    smoother = SmootherParams(
        smoothing_frequency_hz=_num(vs, "smoothing_frequency", defaults.smoothing_frequency_hz, vwhere),
        feedback=Feedback(feedback),
        odom_topic=odom_topic,
        odom_duration_s=_num(vs, "odom_duration", defaults.odom_duration_s, vwhere),
        max_velocity=_triple(vs, "max_velocity", defaults.max_velocity, vwhere),
        min_velocity=_triple(vs, "min_velocity", defaults.min_velocity, vwhere),
        max_accel=_triple(vs, "max_accel", defaults.max_accel, vwhere),
        max_decel=_triple(vs, "max_decel", defaults.max_decel, vwhere),
        deadband_velocity=_triple(vs, "deadband_velocity", defaults.deadband_velocity, vwhere),
        velocity_timeout_s=_num(vs, "velocity_timeout", defaults.velocity_timeout_s, vwhere),
        scale_velocities=_flag(vs, "scale_velocities", defaults.scale_velocities, vwhere),
    )
    used["velocity_smoother"] = [
        "smoothing_frequency", "max_velocity", "min_velocity", "max_accel", "max_decel",
        "deadband_velocity", "velocity_timeout", "feedback", "scale_velocities", "odom_duration", "odom_topic",
    ]  # fmt: skip
    bs = params.node("behavior_server")
    bwhere = f"{src}: behavior_server"
    servers = _behavior_servers(bs, bwhere)
    bd = BehaviorParams()
    behaviors = BehaviorParams(
        cycle_frequency_hz=_num(bs, "cycle_frequency", bd.cycle_frequency_hz, bwhere),
        simulate_ahead_time_s=_num(bs, "simulate_ahead_time", bd.simulate_ahead_time_s, bwhere),
        max_rotational_vel=_num(bs, "max_rotational_vel", bd.max_rotational_vel, bwhere),
        min_rotational_vel=_num(bs, "min_rotational_vel", bd.min_rotational_vel, bwhere),
        rotational_acc_lim=_num(bs, "rotational_acc_lim", bd.rotational_acc_lim, bwhere),
        backup_limits=_drive_limits(bs, _named_kind(servers, "backup"), bwhere),
        drive_on_heading_limits=_drive_limits(bs, _named_kind(servers, "drive_on_heading"), bwhere),
    )
    used["behavior_server"] = [
        "cycle_frequency", "simulate_ahead_time", "max_rotational_vel", "min_rotational_vel", "rotational_acc_lim",
        "behavior_plugins", *(f"{name}.plugin" for name in servers),
        *(f"{b}.{k}" for b in (_named_kind(servers, "backup"), _named_kind(servers, "drive_on_heading"))
          for k in ("acceleration_limit", "deceleration_limit", "minimum_speed")),
    ]  # fmt: skip
    return Nav2Config(
        controller_frequency_hz=frequency,
        failure_tolerance_s=_num(cs, "failure_tolerance", 0.0, where),
        velocity_thresholds=(
            _num(cs, "min_x_velocity_threshold", 0.0001, where),
            _num(cs, "min_theta_velocity_threshold", 0.0001, where),
        ),
        controllers=controllers,
        goal_checkers=checkers,
        progress_radius_m=_num(progress, "required_movement_radius", 0.5, f"{where}.{progress_name}"),
        progress_allowance_s=_num(progress, "movement_time_allowance", 10.0, f"{where}.{progress_name}"),
        progress_angle_rad=progress_angle,
        planner=planner,
        behaviors=behaviors,
        behavior_servers=MappingProxyType(servers),
        smoother=smoother,
        bt_loop_duration_s=loop_ms / 1000.0,
        used={k: tuple(v) for k, v in used.items()},
    )
