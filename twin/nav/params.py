"""Nav2 parameter files as they are: the `ros__parameters` layout, read into the values the twin's nodes use.

A Nav2 params YAML maps node names to `{ros__parameters: {...}}`. A key may be a plain node name
(`amcl`), a path (`/amcl`, `global_costmap/global_costmap`), nested namespaces (`global_costmap:
global_costmap: ros__parameters:`), or the wildcard `/**` whose parameters apply to every node.
Parameters nest as ROS 2 flattens them: `inflation_layer: {inflation_radius: 0.55}` is the
parameter `inflation_layer.inflation_radius`.

`load_nav2_params` reads one file, applies single-value overrides, and returns `Nav2Params`: frozen
specs for the nodes this lane runs (AMCL, the global and local costmaps), the flattened raw
parameters of every node (the navigation lane reads planner, controller, behaviours,
bt_navigator and velocity smoother from there), and the keys nothing in the twin reads. Values a
file leaves out take Nav2 Humble's code defaults. TurtleBot3's Humble files ship in
`twin/data/nav2/` as the default per robot model.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import yaml

from twin.core import yaml_numbers
from twin.core.config import read_text_file
from twin.core.errors import ConfigError

__all__ = [
    "AmclParams",
    "CostmapParams",
    "InflationParams",
    "Nav2Params",
    "ObservationSource",
    "ObstacleLayerParams",
    "ParamReader",
    "ParamSource",
    "StaticLayerParams",
    "default_params_path",
    "is_packaged_params",
    "load_nav2_params",
]

ParamValue = bool | int | float | str | list[Any]

_DATA = Path(__file__).resolve().parent.parent / "data" / "nav2"
_MODELS = {"burger": "burger.yaml", "waffle": "waffle.yaml", "waffle_pi": "waffle_pi.yaml"}

# Nodes whose parameters the navigation lane reads from `Nav2Params.raw` (not listed as unused here).
NAV_LANE_NODES = (
    "planner_server",
    "controller_server",
    "behavior_server",
    "bt_navigator",
    "velocity_smoother",
    "smoother_server",
)
# Parameters every node has and the twin satisfies by construction (it always runs on sim time).
_ALWAYS_USED = frozenset({"use_sim_time"})


def default_params_path(model: str) -> Path:
    """Return the packaged TurtleBot3 Humble params file for a robot model (`burger`, `waffle`, `waffle_pi`).

    A model name with a `turtlebot3_` prefix is accepted.

    Raises:
        ConfigError: If the model has no packaged file.
    """
    key = model.removeprefix("turtlebot3_")
    if key not in _MODELS:
        msg = (
            f"no packaged Nav2 params for robot model {model!r} (the twin ships TurtleBot3's: "
            f"{', '.join(sorted(_MODELS))}); give navigation.params: a Nav2 params file for this robot, e.g. a copy "
            f"of {_DATA / _MODELS['waffle']} with its frames, footprint and speeds"
        )
        raise ConfigError(msg)
    return _DATA / _MODELS[key]


def is_packaged_params(path: Path) -> bool:
    """Whether `path` is one of the packaged TurtleBot3 params files (named by path rather than left null)."""
    try:
        return any(path.resolve() == (_DATA / name).resolve() for name in _MODELS.values())
    except OSError:
        return False


# --- specs ---------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True, slots=True)
class AmclParams:
    """The `amcl` node's parameters (Nav2 Humble names; units added)."""

    alpha1: float = 0.2
    alpha2: float = 0.2
    alpha3: float = 0.2
    alpha4: float = 0.2
    alpha5: float = 0.2
    base_frame_id: str = "base_footprint"
    global_frame_id: str = "map"
    odom_frame_id: str = "odom"
    laser_model_type: str = "likelihood_field"
    robot_model_type: str = "nav2_amcl::DifferentialMotionModel"
    laser_likelihood_max_dist_m: float = 2.0
    laser_max_range_m: float = 100.0
    laser_min_range_m: float = -1.0
    max_beams: int = 60
    min_particles: int = 500
    max_particles: int = 2000
    pf_err: float = 0.05
    pf_z: float = 0.99
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    resample_interval: int = 1
    sigma_hit_m: float = 0.2
    z_hit: float = 0.5
    z_rand: float = 0.5
    z_max: float = 0.05
    z_short: float = 0.05
    lambda_short: float = 0.1
    update_min_d_m: float = 0.25
    update_min_a_rad: float = 0.2
    transform_tolerance_s: float = 1.0
    tf_broadcast: bool = True
    save_pose_rate_hz: float = 0.5
    scan_topic: str = "scan"
    set_initial_pose: bool = False
    initial_pose_x_m: float = 0.0
    initial_pose_y_m: float = 0.0
    initial_pose_yaw_rad: float = 0.0
    do_beamskip: bool = False


@dataclass(frozen=True, kw_only=True, slots=True)
class ObservationSource:
    """One sensor source of an obstacle layer (`observation_sources: scan` and its `scan:` block)."""

    name: str
    topic: str = ""
    data_type: str = "LaserScan"
    marking: bool = True
    clearing: bool = False
    obstacle_max_range_m: float = 2.5
    obstacle_min_range_m: float = 0.0
    raytrace_max_range_m: float = 3.0
    raytrace_min_range_m: float = 0.0
    min_obstacle_height_m: float = 0.0
    max_obstacle_height_m: float = 0.0
    inf_is_valid: bool = False


@dataclass(frozen=True, kw_only=True, slots=True)
class ObstacleLayerParams:
    """An ObstacleLayer or VoxelLayer; the z_* fields and thresholds are the VoxelLayer's (Nav2's defaults)."""

    name: str
    plugin: str
    enabled: bool = True
    footprint_clearing_enabled: bool = True
    min_obstacle_height_m: float = 0.0
    max_obstacle_height_m: float = 2.0
    origin_z_m: float = 0.0
    z_resolution_m: float = 0.2
    z_voxels: int = 10
    unknown_threshold: int = 15
    mark_threshold: int = 0
    sources: tuple[ObservationSource, ...] = ()

    @property
    def voxel(self) -> bool:
        """True for a VoxelLayer."""
        return self.plugin.rsplit("::", 1)[-1].rsplit("/", 1)[-1] == "VoxelLayer"


@dataclass(frozen=True, kw_only=True, slots=True)
class StaticLayerParams:
    """A StaticLayer."""

    name: str
    enabled: bool = True
    map_topic: str = "map"
    map_subscribe_transient_local: bool = True


@dataclass(frozen=True, kw_only=True, slots=True)
class InflationParams:
    """An InflationLayer."""

    name: str
    enabled: bool = True
    inflation_radius_m: float = 0.55
    cost_scaling_factor: float = 10.0
    inflate_unknown: bool = False
    inflate_around_unknown: bool = False


@dataclass(frozen=True, kw_only=True, slots=True)
class CostmapParams:
    """A costmap node's parameters (`global_costmap` or `local_costmap`) and its layers in plugin order."""

    name: str
    update_frequency_hz: float = 5.0
    publish_frequency_hz: float = 1.0
    global_frame: str = "map"
    robot_base_frame: str = "base_link"
    rolling_window: bool = False
    width_m: float = 5.0
    height_m: float = 5.0
    resolution_m: float = 0.1
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    robot_radius_m: float = 0.1
    footprint: tuple[tuple[float, float], ...] = ()
    footprint_padding_m: float = 0.01
    track_unknown_space: bool = False
    lethal_cost_threshold: int = 100
    unknown_cost_value: int = 255
    trinary_costmap: bool = True
    always_send_full_costmap: bool = False
    plugins: tuple[str, ...] = ("static_layer", "obstacle_layer", "inflation_layer")
    static_layer: StaticLayerParams | None = None
    obstacle_layers: tuple[ObstacleLayerParams, ...] = ()
    inflation: InflationParams | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class Nav2Params:
    """One Nav2 params file, read: specs for this lane's nodes, raw parameters of every node, unused keys.

    `raw[node]` holds a node's parameters flattened to ROS 2 names (`inflation_layer.inflation_radius`)
    with the `/**` wildcard's applied; node names are the file's without a leading `/`
    (`global_costmap/global_costmap`, `amcl`).
    """

    source: str
    amcl: AmclParams
    global_costmap: CostmapParams
    local_costmap: CostmapParams
    raw: Mapping[str, Mapping[str, ParamValue]]
    unused_keys: tuple[str, ...] = field(default=())
    #: Where each value came from (file and line, or the scenario's `navigation.set`), for messages.
    origin: ParamSource | None = field(default=None, compare=False)
    #: The parameters the twin read of AMCL and the costmaps (defaults included), per node as in `raw`.
    read_keys: Mapping[str, frozenset[str]] = field(default_factory=dict)

    def node(self, name: str) -> Mapping[str, ParamValue]:
        """Return a node's flattened parameters (empty when the file has none); `name` as in `raw` or its last part."""
        if name in self.raw:
            return self.raw[name]
        for key, params in self.raw.items():
            if key.rsplit("/", 1)[-1] == name:
                return params
        return MappingProxyType({})

    def warning(self, used_elsewhere: Mapping[str, Iterable[str]] | None = None) -> str | None:
        """Return the one warning line listing the keys the twin does not use, or None when all are used.

        Args:
            used_elsewhere: Parameters of the navigation lane's nodes it reads, per node name
                (`{"controller_server": ["controller_frequency", ...]}`); the other keys of those
                nodes are then listed as unused too.
        """
        unused = list(self.unused_keys)
        for node, used in (used_elsewhere or {}).items():
            taken = set(used) | _ALWAYS_USED
            unused.extend(f"{node}.{key}" for key in self.node(node) if key not in taken)
        if not unused:
            return None
        return f"{self.source}: {len(unused)} Nav2 parameter(s) not used by the twin: {', '.join(sorted(unused))}"


# --- reading -------------------------------------------------------------------------------------


def _flatten(prefix: str, value: Any, out: dict[str, ParamValue], where: str) -> None:
    if isinstance(value, Mapping):
        for key, item in value.items():
            _flatten(f"{prefix}.{key}" if prefix else str(key), item, out, where)
        return
    if value is None or not isinstance(value, bool | int | float | str | list):
        msg = f"{where}: parameter {prefix!r} has no usable value ({value!r}); give a number, bool, string or list"
        raise ConfigError(msg)
    out[prefix] = value


def _node_name(raw_key: object, namespace: str) -> str:
    key = str(raw_key).strip("/") if str(raw_key) != "/**" else "**"
    return f"{namespace}/{key}" if namespace else key


def _collect_nodes(
    tree: Mapping[str, Any], namespace: str, nodes: dict[str, dict[str, ParamValue]], where: str
) -> None:
    for raw_key, body in tree.items():
        name = _node_name(raw_key, namespace)
        if not isinstance(body, Mapping):
            msg = (
                f"{where}: {name!r} must be a mapping holding 'ros__parameters' or nested node names, "
                f"got {body!r}; put its parameters under '{raw_key}: ros__parameters:'"
            )
            raise ConfigError(msg)
        for sub_key, sub in body.items():
            if sub_key == "ros__parameters":
                if not isinstance(sub, Mapping):
                    what = "is empty" if sub is None else f"holds {sub!r}"
                    msg = (
                        f"{where}: {name}.ros__parameters {what}, where a mapping of parameter names to values "
                        f"belongs; indent the node's parameters under it, or remove '{raw_key}:' if it has none"
                    )
                    raise ConfigError(msg)
                params = nodes.setdefault(name, {})
                _flatten("", sub, params, f"{where}: node {name}")
            else:
                _collect_nodes({sub_key: sub}, name, nodes, where)


def _read_file(path: Path, substitutions: Mapping[str, str]) -> dict[str, dict[str, ParamValue]]:
    text = read_text_file(path, ConfigError, what="a Nav2 params YAML file")
    for placeholder, value in substitutions.items():  # a launch file's substitutions, made on the text
        text = text.replace(placeholder, value)
    try:
        doc = yaml_numbers.safe_load(text)  # `1e-5` is a number, as ROS 2's parameter parser reads it
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or "invalid YAML"
        msg = f"{path}{line}: malformed Nav2 params YAML ({problem}); fix the YAML syntax"
        raise ConfigError(msg) from None
    except RecursionError:
        msg = f"{path}: Nav2 params YAML nested too deeply; flatten it"
        raise ConfigError(msg) from None
    if isinstance(doc, Mapping):
        doc = _with_repeated_keys_merged(text, str(path), doc)
    if doc is None:
        doc = {}
    if not isinstance(doc, Mapping):
        msg = f"{path}: a Nav2 params file must map node names to 'ros__parameters', got {type(doc).__name__}"
        raise ConfigError(msg)
    if {"image", "resolution", "origin"} <= set(doc):
        msg = (
            f"{path}: is a map_server map YAML (image, resolution, origin), not a Nav2 params file; "
            "name it as the scenario's map:, and the params file as navigation.params"
        )
        raise ConfigError(msg)
    nodes: dict[str, dict[str, ParamValue]] = {}
    _collect_nodes(doc, "", nodes, str(path))
    return nodes


def _with_repeated_keys_merged(text: str, name: str, doc: Any) -> Any:
    """The file's data as ROS 2's parameter parser reads it: a key given twice in one mapping is merged.

    rcl_yaml_param_parser reads the file event by event into one table, so a node's section given
    twice (`amcl:` ... `amcl:`) contributes the parameters of both, and a parameter given twice takes
    the later value. A YAML loader keeps only the later section of the two, dropping the earlier
    one's parameters without a word. `doc` is returned as it is when no key repeats.
    """
    root = yaml_numbers.compose(text, name)
    if root is None or not _repeats_a_key(root):
        return doc
    return yaml_numbers.Loader("").construct_document(_merge_repeated(root))


def _repeats_a_key(node: yaml.Node) -> bool:
    if isinstance(node, yaml.MappingNode):
        keys = [k.value for k, _ in node.value if isinstance(k, yaml.ScalarNode)]
        return len(keys) != len(set(keys)) or any(_repeats_a_key(v) for _, v in node.value)
    if isinstance(node, yaml.SequenceNode):
        return any(_repeats_a_key(v) for v in node.value)
    return False


def _merge_repeated(node: yaml.Node) -> yaml.Node:
    """`node` with each mapping's repeated keys merged: two mappings into one, else the later value."""
    if not isinstance(node, yaml.MappingNode):
        return node
    merged: dict[Any, tuple[yaml.Node, yaml.Node]] = {}
    for key, value in node.value:
        ident = key.value if isinstance(key, yaml.ScalarNode) else id(key)
        earlier = merged.get(ident)
        both = earlier is not None and isinstance(earlier[1], yaml.MappingNode) and isinstance(value, yaml.MappingNode)
        if both:
            assert earlier is not None
            joined = yaml.MappingNode(value.tag, earlier[1].value + value.value, value.start_mark, value.end_mark)
            merged[ident] = (key, joined)
        else:
            merged[ident] = (key, value)
    pairs = [(key, _merge_repeated(value)) for key, value in merged.values()]
    return yaml.MappingNode(node.tag, pairs, node.start_mark, node.end_mark, node.flow_style)


def _key_lines(node: yaml.Node | None, namespace: str, out: dict[tuple[str, str], int]) -> None:
    """Map (node, flattened parameter) to its 1-based line, walking the file as `_collect_nodes` reads it."""
    if not isinstance(node, yaml.MappingNode):
        return
    for key_node, body in node.value:
        name = _node_name(key_node.value, namespace)
        if not isinstance(body, yaml.MappingNode):
            continue
        for sub_key, sub in body.value:
            if sub_key.value == "ros__parameters":
                _param_lines(sub, name, "", out)
            else:
                _key_lines(yaml.MappingNode("tag:yaml.org,2002:map", [(sub_key, sub)]), name, out)


def _param_lines(node: yaml.Node, name: str, prefix: str, out: dict[tuple[str, str], int]) -> None:
    if not isinstance(node, yaml.MappingNode):
        return
    for key_node, value in node.value:
        key = f"{prefix}.{key_node.value}" if prefix else str(key_node.value)
        out.setdefault((name, key), key_node.start_mark.line + 1)
        _param_lines(value, name, key, out)


class ParamSource:
    """Where a node's parameter came from, for messages: the params file and its line, or `navigation.set`.

    Args:
        path: The params file.
        overridden: (node, parameter) -> the `navigation.set` key that gave its value.
    """

    def __init__(self, path: Path, overridden: Mapping[tuple[str, str], str] | None = None) -> None:
        self.path = path
        self.overridden: Mapping[tuple[str, str], str] = overridden or {}
        self._lines: dict[tuple[str, str], int] | None = None

    def line(self, node: str, key: str) -> int | None:
        """The 1-based line of `node`'s `key` in the file (or of the `/**` wildcard's), if the file sets it."""
        if self._lines is None:  # parsed again only when a message needs a line
            self._lines = {}
            try:
                text = self.path.read_text(encoding="utf-8")
                _key_lines(yaml_numbers.compose(text, str(self.path)), "", self._lines)
            except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError):
                pass
        return self._lines.get((node, key), self._lines.get(("**", key)))

    def locate(self, node: str, key: str) -> str:
        """`FILE:LINE: node.key`, or `navigation.set.KEY` when the scenario's overrides set the value.

        A `navigation.set` location holds no file name: `simulate` and `scenario check` put the
        scenario's file in front of it.
        """
        override = self.overridden.get((node, key))
        if override is not None:
            return f"{SET_KEY}.{override}"
        line = self.line(node, key)
        return f"{self.path}{f':{line}' if line is not None else ''}: {node}.{key}"


SET_KEY = "navigation.set"
"""The scenario key holding single-value overrides of a params file."""


class ParamReader:
    """Typed, range-checked access to one node's flattened parameters, recording which keys were read.

    Every read names what it expects; a value of the wrong type or out of range is a `ConfigError`
    naming where the value came from (`FILE:LINE: node.key` or `navigation.set.node.key`) and the fix.
    """

    def __init__(self, source: ParamSource, node: str, params: Mapping[str, ParamValue]) -> None:
        self.source = source
        self.node = node
        self.params = params
        self.used: set[str] = set(_ALWAYS_USED)

    def fail(self, key: str, problem: str, fix: str = "fix the value") -> ConfigError:
        """The error for `key`: `WHERE: problem; fix`."""
        return ConfigError(f"{self.source.locate(self.node, key)}: {problem}; {fix}")

    def _fail(self, key: str, want: str, value: object) -> ConfigError:
        return self.fail(key, f"expected {want}, got {value!r}")

    def has(self, key: str) -> bool:
        """True when the node's parameters hold `key`."""
        return key in self.params

    def number(
        self,
        key: str,
        default: float,
        *,
        above: float | None = None,
        low: float | None = None,
        high: float | None = None,
        unit: str = "",
    ) -> float:
        """A finite number; `above` is an exclusive lower bound, `low` and `high` inclusive bounds."""
        self.used.add(key)
        value = self.params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self._fail(key, "a finite number", value)
        out = float(value)
        _check_range(self, key, out, above=above, low=low, high=high, unit=unit)
        return out

    def integer(self, key: str, default: int, *, low: int | None = None, high: int | None = None) -> int:
        """A whole number (ROS 2 declares these as integers: `20.0` is refused as it would be there)."""
        self.used.add(key)
        value = self.params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._fail(key, "an integer", value)
        _check_range(self, key, value, low=low, high=high)
        return value

    def flag(self, key: str, default: bool) -> bool:
        """A bool (ROS 2 reads `true`/`false`; 1 and 0 are refused as it refuses them)."""
        self.used.add(key)
        value = self.params.get(key, default)
        if not isinstance(value, bool):
            raise self._fail(key, "true or false", value)
        return value

    def text(self, key: str, default: str) -> str:
        """A string."""
        self.used.add(key)
        value = self.params.get(key, default)
        if not isinstance(value, str):
            raise self._fail(key, "a string", value)
        return value

    def str_list(self, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
        """A list of strings (or one space-separated string)."""
        self.used.add(key)
        value = self.params.get(key, list(default))
        if isinstance(value, str):  # `observation_sources: scan bump` is a space-separated list
            return tuple(value.split())
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self._fail(key, "a list of strings", value)
        return tuple(value)

    def unused(self) -> list[str]:
        """The node's keys nothing read, as `node.key`."""
        return [f"{self.node}.{key}" for key in self.params if key not in self.used]


def _check_range(
    r: ParamReader,
    key: str,
    value: float,
    *,
    above: float | None = None,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
) -> None:
    u = f" {unit}" if unit else ""
    if above is not None and not value > above:
        raise r.fail(key, f"must be above {above:g}{u}, got {value!r}")
    if low is not None and not value >= low:
        raise r.fail(key, f"must be at least {low:g}{u}, got {value!r}")
    if high is not None and not value <= high:
        raise r.fail(key, f"must be at most {high:g}{u}, got {value!r}")


# Rates the twin's timers run at: at least once in 16 minutes (as scenario rates), and at most a
# million a second (the physics rate, checked with the scenario, is lower still).
MIN_RATE_HZ = 1e-3
MAX_RATE_HZ = 1e6
# A distance, in metres, beyond any map or sensor the twin handles (1000 km).
MAX_DISTANCE_M = 1e6


def _amcl(r: ParamReader) -> AmclParams:
    model = r.text("laser_model_type", "likelihood_field")
    if model != "likelihood_field":
        problem = f"the twin runs 'likelihood_field' only, got {model!r}"
        raise r.fail("laser_model_type", problem, "use likelihood_field")
    motion = r.text("robot_model_type", "nav2_amcl::DifferentialMotionModel")
    if not motion.endswith("DifferentialMotionModel"):
        raise r.fail(
            "robot_model_type",
            f"the twin runs the differential motion model only, got {motion!r}",
            "use nav2_amcl::DifferentialMotionModel",
        )
    d = MAX_DISTANCE_M
    spec = AmclParams(
        alpha1=r.number("alpha1", 0.2, low=0.0, high=d),
        alpha2=r.number("alpha2", 0.2, low=0.0, high=d),
        alpha3=r.number("alpha3", 0.2, low=0.0, high=d),
        alpha4=r.number("alpha4", 0.2, low=0.0, high=d),
        alpha5=r.number("alpha5", 0.2, low=0.0, high=d),
        base_frame_id=r.text("base_frame_id", "base_footprint"),
        global_frame_id=r.text("global_frame_id", "map"),
        odom_frame_id=r.text("odom_frame_id", "odom"),
        laser_model_type=model,
        robot_model_type=motion,
        laser_likelihood_max_dist_m=r.number("laser_likelihood_max_dist", 2.0, above=0.0, high=d, unit="m"),
        laser_max_range_m=r.number("laser_max_range", 100.0, low=-d, high=d, unit="m"),
        laser_min_range_m=r.number("laser_min_range", -1.0, low=-d, high=d, unit="m"),
        max_beams=r.integer("max_beams", 60, low=1),
        min_particles=r.integer("min_particles", 500, low=1),
        max_particles=r.integer("max_particles", 2000, low=1),
        pf_err=r.number("pf_err", 0.05, above=0.0, high=1.0),
        pf_z=r.number("pf_z", 0.99, low=0.0, high=d),
        recovery_alpha_slow=r.number("recovery_alpha_slow", 0.0, low=0.0, high=1.0),
        recovery_alpha_fast=r.number("recovery_alpha_fast", 0.0, low=0.0, high=1.0),
        resample_interval=r.integer("resample_interval", 1, low=1),
        sigma_hit_m=r.number("sigma_hit", 0.2, above=0.0, high=d, unit="m"),
        z_hit=r.number("z_hit", 0.5, low=0.0, high=d),
        z_rand=r.number("z_rand", 0.5, low=0.0, high=d),
        z_max=r.number("z_max", 0.05, low=0.0, high=d),
        z_short=r.number("z_short", 0.05, low=0.0, high=d),
        lambda_short=r.number("lambda_short", 0.1, low=0.0, high=d),
        update_min_d_m=r.number("update_min_d", 0.25, low=0.0, high=d, unit="m"),
        update_min_a_rad=r.number("update_min_a", 0.2, low=0.0, high=d, unit="rad"),
        transform_tolerance_s=r.number("transform_tolerance", 1.0, low=0.0, high=d, unit="s"),
        tf_broadcast=r.flag("tf_broadcast", True),
        save_pose_rate_hz=r.number("save_pose_rate", 0.5, low=0.0, high=MAX_RATE_HZ, unit="Hz"),
        scan_topic=r.text("scan_topic", "scan"),
        set_initial_pose=r.flag("set_initial_pose", False),
        initial_pose_x_m=r.number("initial_pose.x", 0.0, low=-d, high=d, unit="m"),
        initial_pose_y_m=r.number("initial_pose.y", 0.0, low=-d, high=d, unit="m"),
        initial_pose_yaw_rad=r.number("initial_pose.yaw", 0.0, low=-d, high=d, unit="rad"),
        do_beamskip=r.flag("do_beamskip", False),
    )
    for key in ("initial_pose.z", "z_max", "z_short", "lambda_short"):
        r.used.discard(key)  # beam-model parameters: read for completeness, unused by likelihood_field
    if spec.min_particles > spec.max_particles:
        key = "min_particles" if (r.node, "min_particles") in r.source.overridden else "max_particles"
        raise r.fail(
            key, f"min_particles ({spec.min_particles}) exceeds max_particles ({spec.max_particles})", "swap them"
        )
    return spec


def _footprint(r: ParamReader) -> tuple[tuple[float, float], ...]:
    text = r.text("footprint", "[]")
    try:
        points = yaml_numbers.safe_load(text)
    except (yaml.YAMLError, RecursionError):
        points = None
    if points in (None, []):
        return ()
    ok = isinstance(points, list) and len(points) >= 3
    ok = ok and all(
        isinstance(p, list)
        and len(p) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= MAX_DISTANCE_M for v in p)
        for p in points
    )
    if not ok:
        raise r._fail("footprint", "a string '[[x, y], [x, y], [x, y], ...]' of at least 3 points", text)
    return tuple((float(p[0]), float(p[1])) for p in points)


def _source(r: ParamReader, layer: str, name: str) -> ObservationSource:
    p = f"{layer}.{name}."
    d = MAX_DISTANCE_M
    topic = r.text(p + "topic", "")
    if not topic:  # Nav2's layer would subscribe to "" and fail to configure
        block = f"give it a block ({name}: {{topic: /scan, data_type: LaserScan, marking: true, clearing: true}})"
        if r.has(p + "topic"):
            raise r.fail(p + "topic", f"source {name!r} has an empty topic", "name the topic it reads")
        raise r.fail(
            f"{layer}.observation_sources",
            f"names source {name!r}, but {p}topic is not set",
            f"{block} or remove it from observation_sources",
        )
    data_type = r.text(p + "data_type", "LaserScan")
    if data_type not in ("LaserScan", "PointCloud2"):
        raise r.fail(p + "data_type", f"must be LaserScan or PointCloud2, got {data_type!r}", "fix the value")
    return ObservationSource(
        name=name,
        topic=topic,
        data_type=data_type,
        marking=r.flag(p + "marking", True),
        clearing=r.flag(p + "clearing", False),
        obstacle_max_range_m=r.number(p + "obstacle_max_range", 2.5, low=0.0, high=d, unit="m"),
        obstacle_min_range_m=r.number(p + "obstacle_min_range", 0.0, low=0.0, high=d, unit="m"),
        raytrace_max_range_m=r.number(p + "raytrace_max_range", 3.0, low=0.0, high=d, unit="m"),
        raytrace_min_range_m=r.number(p + "raytrace_min_range", 0.0, low=0.0, high=d, unit="m"),
        min_obstacle_height_m=r.number(p + "min_obstacle_height", 0.0, low=-d, high=d, unit="m"),
        max_obstacle_height_m=r.number(p + "max_obstacle_height", 0.0, low=-d, high=d, unit="m"),
        inf_is_valid=r.flag(p + "inf_is_valid", False),
    )


# Plugin type when a layer names none (`plugin:` missing), from the layer name TB3's files use.
_PLUGIN_BY_NAME = {
    "static_layer": "nav2_costmap_2d::StaticLayer",
    "obstacle_layer": "nav2_costmap_2d::ObstacleLayer",
    "voxel_layer": "nav2_costmap_2d::VoxelLayer",
    "inflation_layer": "nav2_costmap_2d::InflationLayer",
}


def _costmap(r: ParamReader, name: str) -> CostmapParams:
    d = MAX_DISTANCE_M
    plugins = r.str_list("plugins", ("static_layer", "obstacle_layer", "inflation_layer"))
    static: StaticLayerParams | None = None
    obstacles: list[ObstacleLayerParams] = []
    inflation: InflationParams | None = None
    for layer in plugins:
        plugin = r.text(f"{layer}.plugin", _PLUGIN_BY_NAME.get(layer, ""))
        if not plugin:  # a name in `plugins` without a `<name>.plugin`: named where the list was given
            raise r.fail(
                "plugins",
                f"names layer {layer!r}, but {layer}.plugin is not set",
                f"give its type ({layer}: {{plugin: nav2_costmap_2d::ObstacleLayer}}...) or remove it from plugins",
            )
        kind = plugin.rsplit("::", 1)[-1].rsplit("/", 1)[-1]
        if kind == "StaticLayer":
            static = StaticLayerParams(
                name=layer,
                enabled=r.flag(f"{layer}.enabled", True),
                map_topic=r.text(f"{layer}.map_topic", "map"),
                map_subscribe_transient_local=r.flag(f"{layer}.map_subscribe_transient_local", True),
            )
        elif kind in ("ObstacleLayer", "VoxelLayer"):
            sources = r.str_list(f"{layer}.observation_sources", ())
            obstacles.append(
                ObstacleLayerParams(
                    name=layer,
                    plugin=plugin,
                    enabled=r.flag(f"{layer}.enabled", True),
                    footprint_clearing_enabled=r.flag(f"{layer}.footprint_clearing_enabled", True),
                    min_obstacle_height_m=r.number(
                        f"{layer}.min_obstacle_height", 0.0, low=-MAX_DISTANCE_M, high=MAX_DISTANCE_M, unit="m"
                    ),
                    max_obstacle_height_m=r.number(
                        f"{layer}.max_obstacle_height", 2.0, low=-MAX_DISTANCE_M, high=MAX_DISTANCE_M, unit="m"
                    ),
                    origin_z_m=r.number(f"{layer}.origin_z", 0.0, low=-MAX_DISTANCE_M, high=MAX_DISTANCE_M, unit="m"),
                    z_resolution_m=r.number(f"{layer}.z_resolution", 0.2, above=0.0, high=MAX_DISTANCE_M, unit="m"),
                    z_voxels=r.integer(f"{layer}.z_voxels", 10, low=1, high=16),
                    unknown_threshold=r.integer(f"{layer}.unknown_threshold", 15, low=0, high=16),
                    mark_threshold=r.integer(f"{layer}.mark_threshold", 0, low=0, high=16),
                    sources=tuple(_source(r, layer, s) for s in sources),
                )
            )
        elif kind == "InflationLayer":
            inflation = InflationParams(
                name=layer,
                enabled=r.flag(f"{layer}.enabled", True),
                inflation_radius_m=r.number(f"{layer}.inflation_radius", 0.55, low=0.0, high=MAX_DISTANCE_M, unit="m"),
                cost_scaling_factor=r.number(f"{layer}.cost_scaling_factor", 10.0, low=0.0, high=MAX_DISTANCE_M),
                inflate_unknown=r.flag(f"{layer}.inflate_unknown", False),
                inflate_around_unknown=r.flag(f"{layer}.inflate_around_unknown", False),
            )
        else:
            raise r.fail(
                f"{layer}.plugin",
                f"the twin has no costmap layer {plugin!r}",
                "use StaticLayer, ObstacleLayer, VoxelLayer or InflationLayer",
            )
    spec = CostmapParams(
        name=name,
        update_frequency_hz=r.number("update_frequency", 5.0, low=MIN_RATE_HZ, high=MAX_RATE_HZ, unit="Hz"),
        publish_frequency_hz=r.number("publish_frequency", 1.0, low=MIN_RATE_HZ, high=MAX_RATE_HZ, unit="Hz"),
        global_frame=r.text("global_frame", "map"),
        robot_base_frame=r.text("robot_base_frame", "base_link"),
        rolling_window=r.flag("rolling_window", False),
        width_m=r.number("width", 5.0, above=0.0, high=d, unit="m"),
        height_m=r.number("height", 5.0, above=0.0, high=d, unit="m"),
        resolution_m=r.number("resolution", 0.1, above=0.0, high=d, unit="m"),
        origin_x_m=r.number("origin_x", 0.0, low=-d, high=d, unit="m"),
        origin_y_m=r.number("origin_y", 0.0, low=-d, high=d, unit="m"),
        robot_radius_m=r.number("robot_radius", 0.1, low=0.0, high=d, unit="m"),
        footprint=_footprint(r),
        footprint_padding_m=r.number("footprint_padding", 0.01, low=-d, high=d, unit="m"),
        track_unknown_space=r.flag("track_unknown_space", False),
        lethal_cost_threshold=r.integer("lethal_cost_threshold", 100, low=0, high=255),
        unknown_cost_value=r.integer("unknown_cost_value", 255, low=0, high=255),
        trinary_costmap=r.flag("trinary_costmap", True),
        always_send_full_costmap=r.flag("always_send_full_costmap", False),
        plugins=plugins,
        static_layer=static,
        obstacle_layers=tuple(obstacles),
        inflation=inflation,
    )
    return spec


def _costmap_node(nodes: Mapping[str, Any], name: str) -> str:
    for candidate in (f"{name}/{name}", name):
        if candidate in nodes:
            return candidate
    return f"{name}/{name}"


def _set_override(
    nodes: dict[str, dict[str, ParamValue]], key: str, value: Any, overridden: dict[tuple[str, str], str]
) -> None:
    node_short, _, param = key.partition(".")
    if not param:
        msg = f"{SET_KEY}.{key}: an override must name node and parameter ('amcl.max_particles'); fix the key"
        raise ConfigError(msg)
    matches = [n for n in nodes if n == node_short or n.rsplit("/", 1)[-1] == node_short]
    node = matches[0] if matches else (f"{node_short}/{node_short}" if node_short.endswith("costmap") else node_short)
    flat: dict[str, ParamValue] = {}
    _flatten(param, value, flat, f"{SET_KEY}.{key}")
    nodes.setdefault(node, {}).update(flat)
    for name in flat:
        overridden[(node, name)] = f"{node_short}.{name}"


ROBOT_NAMESPACE = "<robot_namespace>"
"""nav2_bringup's placeholder in a params file shared by a fleet, replaced by `/<namespace>` at launch."""


def load_nav2_params(
    path: str | Path, *, overrides: Mapping[str, Any] | None = None, namespace: str = ""
) -> Nav2Params:
    """Read a Nav2 params YAML and apply single-value overrides.

    Values are checked as they are read (types, ranges); `twin.nav.param_checks` checks the rest
    (the navigation servers' parameters, memory, the override keys) once the map is known.

    Args:
        path: The params file (TB3's `param/humble/waffle.yaml`, Nav2's `nav2_params.yaml`, ...).
        overrides: A scenario's `navigation.set`: values that replace the file's, keyed `node.param`
            (`amcl.max_particles`, `local_costmap.inflation_layer.inflation_radius`), or nested
            mappings of the same. A bad value among them is reported as `navigation.set.KEY`.
        namespace: The robot's (a fleet's): `<robot_namespace>` in the file becomes `/<namespace>`,
            as nav2_bringup's multi-robot launch (ReplaceString) writes it; "" for a robot alone.

    Raises:
        ConfigError: If the file cannot be read or parsed, a node's section is not a mapping, or a
            parameter the twin uses has the wrong type or an unusable value (one line naming file,
            line and key, or the override).
    """
    path = Path(path)
    nodes = _read_file(path, {ROBOT_NAMESPACE: f"/{namespace}" if namespace else ""})
    flat_overrides: dict[str, ParamValue] = {}
    if overrides:
        _flatten("", overrides, flat_overrides, SET_KEY)
    overridden: dict[tuple[str, str], str] = {}
    for key, value in flat_overrides.items():
        _set_override(nodes, key, value, overridden)
    source = ParamSource(path, overridden)
    wildcard = nodes.pop("**", {})
    merged = {name: {**wildcard, **params} for name, params in nodes.items()}
    amcl_name = "amcl" if "amcl" in merged else next((n for n in merged if n.endswith("/amcl")), "amcl")
    amcl_reader = ParamReader(source, amcl_name, merged.get(amcl_name, dict(wildcard)))
    amcl = _amcl(amcl_reader)
    readers = [amcl_reader]
    costmaps: dict[str, CostmapParams] = {}
    for short in ("global_costmap", "local_costmap"):
        node = _costmap_node(merged, short)
        reader = ParamReader(source, node, merged.get(node, dict(wildcard)))
        costmaps[short] = _costmap(reader, short)
        readers.append(reader)
    unused: list[str] = []
    for reader in readers:
        unused.extend(reader.unused())
    ran = {reader.node for reader in readers}
    nav_lane = {n for n in merged if n.rsplit("/", 1)[-1] in NAV_LANE_NODES}
    for node, params in merged.items():
        if node in ran or node in nav_lane:
            continue
        if node == "map_server":
            unused.extend(f"{node}.{k}" for k in params if k not in _ALWAYS_USED and k != "yaml_filename")
            continue
        unused.extend(f"{node}.{k}" for k in params if k not in _ALWAYS_USED)
    raw = MappingProxyType({name: MappingProxyType(dict(params)) for name, params in merged.items()})
    return Nav2Params(
        source=str(path),
        amcl=amcl,
        global_costmap=costmaps["global_costmap"],
        local_costmap=costmaps["local_costmap"],
        raw=raw,
        unused_keys=tuple(unused),
        origin=source,
        read_keys=MappingProxyType({r.node: frozenset(r.used) for r in readers}),
    )
