"""The scenario: what one run is made of, as the frozen dataclasses a scenario file is loaded into.

`twin.sim.scenario_file.load_scenario` reads a file into them, laid over the packaged defaults
(`DEFAULTS_PATH`). Paths in a scenario are relative to the file that names them. `recording.out_dir` is relative to
the working directory, like a shell's output path.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar

from twin.core.config import FieldError, NameOrPath
from twin.core.errors import TwinError
from twin.core.native import compiler_candidates, find_compiler
from twin.core.numbers import number_problem
from twin.estimation import EstimationSection
from twin.mission.path_follower import FollowerParams
from twin.robot.disturbances import Disturbances
from twin.robot.fmu_drive import FmuDrive
from twin.world.obstacles import ObstacleSpec

__all__ = [
    "ROBOT_SECTIONS",
    "NodeSpec",
    "ReplayMission",
    "RobotEntry",
    "Ros2Section",
    "Scenario",
    "TfSection",
    "default_scenario_path",
    "fmu_fallback",
    "for_ros2_role",
    "in_entry",
    "names_a_key",
    "runs_amcl",
    "runs_nav2",
]

TwinErrorT = TypeVar("TwinErrorT", bound=TwinError)

_log = logging.getLogger(__name__)

_DATA = Path(__file__).resolve().parent.parent / "data"
DEFAULTS_PATH = _DATA / "scenario_defaults.yaml"
#: The project's own robot models (turtlebot3_waffle, turtlebot3_burger), in a source checkout.
PACKAGED_MODELS = _DATA.parent.parent / "sdf" / "models"


@dataclass(frozen=True, kw_only=True, slots=True)
class WorldSection:
    """Which world to load and where `model://` URIs resolve.

    `model_path` always ends with the project's own `sdf/models` (when it exists): a scenario that
    names its own folders still finds `robot.model: turtlebot3_waffle`, after them.
    """

    sdf: Path
    model_path: tuple[Path, ...] = ()
    floor_height_m: float = 0.01
    missing_includes: Literal["error", "warn"] = "error"
    """A `model://` include not on the model path: refuse the world, or skip it with a warning (as Gazebo Classic)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.floor_height_m <= 0.5:
            msg = f"floor_height_m must be between 0 and 0.5 m, got {self.floor_height_m}"
            raise ValueError(msg)
        if PACKAGED_MODELS not in self.model_path and PACKAGED_MODELS.is_dir():
            object.__setattr__(self, "model_path", (*self.model_path, PACKAGED_MODELS))


@dataclass(frozen=True, kw_only=True, slots=True)
class InitialPose:
    """The robot's spawn pose in the world frame."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0


@dataclass(frozen=True, kw_only=True, slots=True)
class RobotSection:
    """The robot: an SDF model by name (`model://NAME` on the model path) or a file, and its spawn pose."""

    model: NameOrPath
    initial_pose: InitialPose = field(default_factory=InitialPose)


@dataclass(frozen=True, kw_only=True, slots=True)
class LidarSection:
    """Lidar settings; a null value keeps what the robot's SDF says."""

    rate_hz: float | None = None
    samples: int | None = None
    angle_min_rad: float | None = None
    angle_max_rad: float | None = None
    range_min_m: float | None = None
    range_max_m: float | None = None
    noise_std_m: float | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class RateSection:
    """A publication rate."""

    rate_hz: float

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            msg = f"rate_hz must be a positive number, got {self.rate_hz}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class ImuSection:
    """The IMU of the robot's SDF (rate, frame, mount and noise come from there)."""

    enabled: bool = True


@dataclass(frozen=True, kw_only=True, slots=True)
class CameraSection:
    """The robot SDF's camera; off unless enabled (each frame costs milliseconds). Null keeps the SDF's value."""

    enabled: bool = False
    width: int | None = None
    height: int | None = None
    rate_hz: float | None = None
    depth: bool = False  # also /camera/depth/image_raw (a depth sensor in the SDF publishes it anyway)
    noise: bool = True  # the SDF's <noise>; false draws clean images
    compressed: bool = False  # also <image_topic>/compressed (JPEG, as image_transport's compressed plugin)

    def __post_init__(self) -> None:
        for key, side in (("width", self.width), ("height", self.height)):
            if side is not None and not 1 <= side <= 8192:
                msg = f"{key} must be from 1 to 8192 pixels, got {side}"
                raise ValueError(msg)
        if self.rate_hz is not None and not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            msg = f"rate_hz must be a positive number, got {self.rate_hz}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class SensorsSection:
    """Sensor and publication rates."""

    lidar: LidarSection = field(default_factory=LidarSection)
    imu: ImuSection = field(default_factory=ImuSection)
    camera: CameraSection = field(default_factory=CameraSection)
    ground_truth: RateSection = field(default_factory=lambda: RateSection(rate_hz=30.0))
    # gazebo_ros_init publishes /clock at its `publish_rate`, 10 Hz by default (throttled on real time:
    # 10 per simulated second when Gazebo runs at real time, as the Humble TB3 bag records, 282 in 29.8 s)
    clock: RateSection = field(default_factory=lambda: RateSection(rate_hz=10.0))


@dataclass(frozen=True, kw_only=True, slots=True)
class PhysicsSection:
    """The fixed physics step."""

    step_s: float = 0.001

    def __post_init__(self) -> None:
        if not 1e-5 <= self.step_s <= 0.05:
            msg = f"step_s must be between 1e-05 and 0.05 s, got {self.step_s}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class KinematicDrive:
    """Ideal wheels: wheel speeds follow the command, limited in acceleration like Gazebo's diff drive."""

    type: Literal["kinematic"] = "kinematic"
    max_wheel_acceleration_mps2: float = 1.0


def fmu_fallback(drive: FmuDrive) -> KinematicDrive | None:
    """The drive to run instead of a built-in FMU that cannot be built here (no C compiler), else None.

    Says so once, as a warning naming the fallback. A drive given as an `fmu_file` needs no compiler.
    """
    if drive.fmu_file is not None or find_compiler() is not None:
        return None
    accel = drive.max_wheel_acceleration_mps2
    fallback = KinematicDrive() if accel is None else KinematicDrive(max_wheel_acceleration_mps2=accel)
    _log.warning(
        "drive: no C compiler to build %s (tried %s; install one, e.g. apt-get install gcc, or set CC): "
        "running the kinematic drive instead (ideal wheels, %g m/s^2 wheel acceleration)",
        "the robot's motor FMUs" if drive.fmu == "auto" else drive.fmu,
        ", ".join(compiler_candidates()),
        fallback.max_wheel_acceleration_mps2,
    )
    return fallback


@dataclass(frozen=True, kw_only=True, slots=True)
class CmdVelSegment:
    """Hold one velocity command for a duration."""

    duration_s: float
    linear_mps: float = 0.0
    angular_radps: float = 0.0

    def __post_init__(self) -> None:
        if not (self.duration_s > 0.0 and math.isfinite(self.duration_s)):
            msg = f"duration_s must be a positive number of seconds, got {self.duration_s}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class CmdVelScriptMission:
    """A scripted list of timed `cmd_vel` segments, published at `rate_hz`; the run ends after the last."""

    type: Literal["cmd_vel_script"] = "cmd_vel_script"
    rate_hz: float = 10.0
    segments: tuple[CmdVelSegment, ...] = ()

    def __post_init__(self) -> None:
        if not self.segments:  # (ran 0 ms and called it a complete mission)
            msg = "segments is empty: give at least one {duration_s, linear_mps, angular_radps}, or mission type none"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class WaypointsMission:
    """Drive through points `[x, y]` or `[x, y, yaw]` (world frame) with the path follower; ends at the last.

    No planner: the points must be joined by free straight lines.
    """

    type: Literal["waypoints"] = "waypoints"
    rate_hz: float = 10.0
    points: tuple[tuple[float, ...], ...] = ()
    follower: FollowerParams = field(default_factory=FollowerParams)

    def __post_init__(self) -> None:
        if not self.points:  # (ran 0 ms and called it a complete mission)
            msg = "points is empty: give at least one [x, y] to drive to, or mission type none"
            raise ValueError(msg)
        for i, point in enumerate(self.points):
            if len(point) not in (2, 3):
                msg = f"points[{i}] must be [x, y] or [x, y, yaw], got {list(point)}"
                raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class ReplayMission:
    """Drive with the velocity commands recorded in a bag, each at its recorded sim time.

    Sim time 0 is the bag's first pose on `pose_topic` (its header stamp); a command's time is its
    header stamp (TwistStamped), else its record time mapped through the bag's `/clock`. The robot
    starts at that first pose (`initial_pose: bag`, replacing `robot.initial_pose`) and the run
    ends at the bag's last pose.
    """

    type: Literal["replay"] = "replay"
    bag: Path
    topic: str = "/cmd_vel"
    pose_topic: str | None = None  # null: /ground_truth/odom, else /odom
    initial_pose: Literal["bag", "scenario"] = "bag"
    rate_hz: float = 200.0  # how often the loop asks; a recorded command takes effect at most 1/rate late

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            msg = f"rate_hz must be a positive number, got {self.rate_hz}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class BehaviorTreeMission:
    """A BehaviorTree.CPP mission (v3 or v4 XML) ticked like the thesis's autonomy node.

    `GoToPose` goals go to Nav2's bt_navigator as NavigateToPose goals (`navigation:`). The run ends
    when the tree returns SUCCESS or FAILURE.
    """

    type: Literal["behavior_tree"] = "behavior_tree"
    tree: Path
    main_tree: str | None = None
    locations: Path | None = None  # set as `location_file` on the blackboard
    tick_rate_hz: float = 2.0  # the thesis's 500 ms timer
    controller_rate_hz: float = 10.0  # TB3 Nav2 controller_frequency
    target_color: Literal["red", "green", "blue"] = "blue"  # LookForObject's (the demos' node parameter)


@dataclass(frozen=True, kw_only=True, slots=True)
class NoMission:
    """No mission: the robot does what nodes on `/cmd_vel` tell it (a user's node drives it)."""

    type: Literal["none"] = "none"


@dataclass(frozen=True, kw_only=True, slots=True)
class TopicSelection:
    """Which topics the bag records, as `ros2 bag record` takes them; empty `include`: every topic."""

    include: tuple[str, ...] = ()
    include_regex: str = ""
    exclude: tuple[str, ...] = ()
    exclude_regex: str = ""

    def __post_init__(self) -> None:
        for key in ("include_regex", "exclude_regex"):
            pattern = getattr(self, key)
            try:
                re.compile(pattern)
            except re.error as err:
                msg = f"{key}: {pattern!r} is not a regular expression: {err}"
                raise ValueError(msg) from None


@dataclass(frozen=True, kw_only=True, slots=True)
class RecordingSection:
    """Where and how the bag is written."""

    out_dir: str = "bags"
    storage: Literal["mcap", "sqlite3"] = "mcap"
    distro: Literal["humble", "iron", "jazzy", "kilted", "rolling"] = "humble"
    topics: TopicSelection = field(default_factory=TopicSelection)


@dataclass(frozen=True, kw_only=True, slots=True)
class NodeSpec:
    """A node to run beside the robot, as a launch file lists one.

    `plugin` is `module:Class` (a module beside the scenario file is importable) or the name of an
    entry point in the `twin.nodes` group of an installed package.
    """

    plugin: str
    name: str | None = None  # overrides the node's own name
    namespace: str = ""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    remappings: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Every number a user gives is checked (docs/hardening.md): a parameter's too, where it lies
        stack: list[tuple[str, Any]] = [(f"parameters.{k}", v) for k, v in self.parameters.items()]
        while stack:
            key, value = stack.pop()
            if isinstance(value, Mapping):
                stack += [(f"{key}.{k}", v) for k, v in value.items()]
            elif isinstance(value, list | tuple):
                stack += [(f"{key}[{i}]", v) for i, v in enumerate(value)]
            elif isinstance(value, float | int) and not isinstance(value, bool):
                problem = number_problem(value, key)
                if problem is not None:
                    msg = f"{key}: {problem}"
                    raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class InitialPoseEstimate:
    """The pose published once on `/initialpose` at start (null coordinates: the spawn pose)."""

    x_m: float | None = None
    y_m: float | None = None
    yaw_rad: float | None = None
    xy_variance_m2: float = 0.25  # the thesis's set_init_amcl_pose.py: 0.25 on x, y and yaw
    yaw_variance_rad2: float = 0.25

    def __post_init__(self) -> None:
        for key in ("x_m", "y_m", "yaw_rad"):
            value = getattr(self, key)
            if value is not None and not math.isfinite(value):
                msg = f"{key} must be a finite number, got {value}"
                raise ValueError(msg)
        for key in ("xy_variance_m2", "yaw_variance_rad2"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                msg = f"{key} must be a variance >= 0, got {value}"
                raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class LocalizationSection:
    """AMCL on the map (Nav2's), or none: map→odom stays the identity and the robot steers on `/odom`.

    auto (the default): AMCL when the mission navigates on the map (a behaviour tree), none otherwise.
    """

    type: Literal["auto", "amcl", "none"] = "auto"
    initial_pose: InitialPoseEstimate | None = field(default_factory=InitialPoseEstimate)  # null: a node sends it
    map_offset_m: tuple[float, float] = (0.0, 0.0)  # the map drawn this far off the world (a misaligned SLAM map)

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) and abs(v) <= 100.0 for v in self.map_offset_m):
            msg = f"map_offset_m must be two finite numbers of metres (at most 100), got {list(self.map_offset_m)}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class NavigationSection:
    """How `GoToPose` goals are carried out: Nav2's stack (the only navigator; the grid stand-in is retired)."""

    type: str = "nav2"
    params: Path | None = None  # a Nav2 params YAML; null: TurtleBot3's Humble file for the robot model
    bt_xml: Path | None = None  # null: Nav2 Humble's navigate_to_pose_w_replanning_and_recovery.xml
    set: Mapping[str, Any] = field(default_factory=dict)  # single values over the params file, `node.param: value`

    def __post_init__(self) -> None:
        if self.type == "grid":
            msg = "type 'grid': the grid stand-in is gone, Nav2's stack is the navigator; remove `type: grid`"
            raise ValueError(msg)
        if self.type != "nav2":
            msg = f"type {self.type!r} is not allowed; the navigator is 'nav2' (Nav2's stack)"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class BlocksSection:
    """The TurtleBot3 behaviour demos' blocks: red, green, blue cubes before `count` of the mission's locations.

    Each stands `offset_m` along its location's heading theta, turned to theta, resting on the floor;
    which locations get one is drawn from the scenario seed (its own stream, `blocks`).
    """

    count: int = 0  # 0: no blocks; 3: the demos'
    offset_m: float = 0.6  # block_spawner.py's block_spawn_offset
    size_m: float = 0.1  # the demos' cubes

    def __post_init__(self) -> None:
        if self.count < 0:
            msg = f"count must be 0 (no blocks) or more, got {self.count}"
            raise ValueError(msg)
        if not self.size_m > 0.0:
            msg = f"size_m must be above 0 m, got {self.size_m}"
            raise ValueError(msg)


#: The ROS 2 domain ids a participant may join (the range ROS 2 allows on Linux: ports stay below 32768).
ROS2_DOMAIN_IDS = range(233)


@dataclass(frozen=True, kw_only=True, slots=True)
class Ros2Section:
    """The run as a participant of a ROS 2 domain (`twin.ros2`, docs/ros2.md); off unless enabled or `--ros2`.

    `role: simulator` is Gazebo's part alone (world, robot, sensors, drive, TF, /clock): the twin runs
    none of its own localization, navigation or mission, so a ROS 2 stack drives the robot.
    """

    enabled: bool = False
    domain_id: int = 0
    role: Literal["full", "simulator"] = "full"
    publish: tuple[str, ...] | None = None  # null: every topic the run publishes
    subscribe: tuple[str, ...] = ("/cmd_vel", "/initialpose")  # taken from the domain into the run
    interface: str = "lo"  # loopback only; any other interface reaches the network

    def __post_init__(self) -> None:
        if self.domain_id not in ROS2_DOMAIN_IDS:
            msg = f"domain_id must be a whole number from 0 to 232, got {self.domain_id}"
            raise ValueError(msg)
        for key in ("publish", "subscribe"):
            for name in getattr(self, key) or ():
                if not _is_ros_topic_name(name):
                    msg = f"{key}: {name!r} is not an absolute ROS 2 topic name (e.g. /scan, /robot1/cmd_vel)"
                    raise ValueError(msg)
        if not re.fullmatch(r"[A-Za-z0-9_.:-]{1,64}", self.interface):
            msg = f"interface must name a network interface (lo, eth0) or an address, got {self.interface!r}"
            raise ValueError(msg)


def _is_ros_topic_name(name: str) -> bool:
    """Whether `name` is an absolute ROS 2 topic name: `/`-separated tokens of letters, digits and `_`."""
    if not name.startswith("/") or name.endswith("/"):
        return False
    return all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", part) and "__" not in part for part in name[1:].split("/"))


@dataclass(frozen=True, kw_only=True, slots=True)
class TfSection:
    """How a fleet's robots publish TF (docs/fleet.md, "Two ways to name a fleet's frames").

    `namespaced` (nav2_bringup's multi-robot launch): each robot's TF on `/<ns>/tf` and
    `/<ns>/tf_static` with the usual frame names. `frame_prefix` (Gazebo's and robot_state_publisher's
    `frame_prefix`): every robot's TF on one shared `/tf` and `/tf_static`, its frames named
    `<ns>/odom`, `<ns>/base_footprint`..., under one shared `map`.
    """

    mode: Literal["namespaced", "frame_prefix"] = "namespaced"


#: The sections of a scenario that belong to one robot: a `robots:` entry may set each of them.
ROBOT_SECTIONS = (
    "robot",
    "drive",
    "sensors",
    "odometry",
    "estimation",
    "localization",
    "navigation",
    "mission",
    "disturbances",
)

_ROS_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True, kw_only=True, slots=True)
class RobotEntry:
    """One robot of a fleet (`robots:`): its name, its namespace, and its sections.

    The loader lays the entry's sections over the scenario's top-level ones (`ROBOT_SECTIONS`), so
    each holds the robot's whole section here.
    """

    name: str
    namespace: str | None = None  # null: the name
    robot: RobotSection
    mission: BehaviorTreeMission | CmdVelScriptMission | WaypointsMission | ReplayMission | NoMission
    sensors: SensorsSection = field(default_factory=SensorsSection)
    drive: KinematicDrive | FmuDrive = field(default_factory=lambda: FmuDrive(fmu="auto", profile="velocity-servo"))
    odometry: Literal["ekf", "ground_truth"] = "ekf"
    estimation: EstimationSection = field(default_factory=EstimationSection)
    disturbances: Disturbances = field(default_factory=Disturbances)
    localization: LocalizationSection = field(default_factory=LocalizationSection)
    navigation: NavigationSection = field(default_factory=NavigationSection)

    def __post_init__(self) -> None:
        if not _ROS_TOKEN.match(self.name):
            msg = f"name {self.name!r} must be letters, digits and _ (not starting with a digit)"
            raise FieldError(("name",), msg)
        ns = self.ns
        if not all(_ROS_TOKEN.match(token) for token in ns.split("/")):
            msg = (
                f"namespace {self.namespace!r} is not a ROS namespace: tokens of letters, digits and _ "
                "(not starting with a digit) joined by /"
            )
            raise FieldError(("namespace",) if self.namespace is not None else ("name",), msg)

    @property
    def ns(self) -> str:
        """The namespace without its leading and trailing `/` (the name when none is given)."""
        return (self.namespace if self.namespace is not None else self.name).strip("/")


@dataclass(frozen=True, kw_only=True, slots=True)
class Scenario:
    """One run: world, robot, sensors, drive, mission, recording, seed and maximum duration.

    `robots:` makes a fleet: each entry is one robot under its namespace (`RobotEntry`); without it
    the top-level sections are the one robot's, with no namespace.
    """

    name: str
    world: WorldSection
    robot: RobotSection
    mission: BehaviorTreeMission | CmdVelScriptMission | WaypointsMission | ReplayMission | NoMission
    sensors: SensorsSection = field(default_factory=SensorsSection)
    physics: PhysicsSection = field(default_factory=PhysicsSection)
    # The robot's own motors as FMUs in velocity mode (the TB3's DYNAMIXELs); {type: kinematic}: ideal wheels.
    drive: KinematicDrive | FmuDrive = field(default_factory=lambda: FmuDrive(fmu="auto", profile="velocity-servo"))
    odometry: Literal["ekf", "ground_truth"] = "ekf"
    estimation: EstimationSection = field(default_factory=EstimationSection)
    disturbances: Disturbances = field(default_factory=Disturbances)
    recording: RecordingSection = field(default_factory=RecordingSection)
    nodes: tuple[NodeSpec, ...] = ()
    map: Literal["from_world"] | Path = "from_world"  # a map_server YAML, or rasterised from the world
    localization: LocalizationSection = field(default_factory=LocalizationSection)
    navigation: NavigationSection = field(default_factory=NavigationSection)
    obstacles: tuple[ObstacleSpec, ...] = ()  # boxes and cylinders that appear, vanish and walk (docs/obstacles.md)
    blocks: BlocksSection = field(default_factory=BlocksSection)
    ros2: Ros2Section = field(default_factory=Ros2Section)  # the run on a ROS 2 domain (docs/ros2.md)
    seed: int = 0
    max_duration_s: float = 600.0
    # A user node's NaN or infinity in a field the twin's nodes read (`/cmd_vel`, `/initialpose`...):
    # drop (refused, warned once, counted in the summary) or error (the run ends, exit 8).
    non_finite_messages: Literal["drop", "error"] = "drop"
    source_path: Path | None = None  # the scenario file (set by the loader; user modules are found beside it)
    robots: tuple[RobotEntry, ...] = ()  # a fleet, each under its namespace; empty: the one robot above
    tf: TfSection = field(default_factory=TfSection)  # how a fleet's robots name their frames

    def __post_init__(self) -> None:
        if not _SCENARIO_NAME.fullmatch(self.name):
            msg = (
                f"{self.name[:60]!r}{'...' if len(self.name) > 60 else ''} cannot name the bag folder "
                "(<recording.out_dir>/<name>_<time>): use letters, digits, _, -, . (not first) and spaces "
                "(not last), at most 100"
            )
            raise FieldError(("name",), msg)
        for key, attr in (("name", "name"), ("namespace", "ns")):
            seen: dict[str, int] = {}
            for i, entry in enumerate(self.robots):
                value = getattr(entry, attr)
                if value in seen:
                    msg = f"robots[{seen[value]}] has the same {key} {value!r}; give each robot its own"
                    raise FieldError(("robots", i, key), msg)
                seen[value] = i
        for i, outer in enumerate(self.robots):
            for j, inner in enumerate(self.robots):
                if inner.ns.startswith(f"{outer.ns}/"):
                    # The tools take everything under /<ns>/ for that robot's (analyze, play, replay).
                    msg = (
                        f"namespace {inner.ns!r} is inside robots[{i}]'s namespace {outer.ns!r}; give each "
                        f"robot a namespace of its own beside the others (e.g. {outer.ns!r} and "
                        f"{inner.ns.rsplit('/', 1)[0] + '_' + inner.ns.rsplit('/', 1)[1]!r})"
                    )
                    raise FieldError(("robots", j, "namespace"), msg)
        names: dict[str, int] = {}  # an obstacle's name is its model in /contacts and its marker
        for i, spec in enumerate(self.obstacles):
            name = spec.name or f"obstacle_{i}"
            if name in names:
                msg = f"obstacles[{names[name]}] has the same name {name!r}; give each obstacle its own"
                raise FieldError(("obstacles", i, "name"), msg)
            names[name] = i

    def robot_scenarios(self) -> list[tuple[str, Scenario]]:
        """Each robot's (namespace, its view of the scenario: its sections at the top level, no `robots`).

        Without `robots:` the one robot, namespace `""`.
        """
        if not self.robots:
            return [("", self)]
        out = []
        for entry in self.robots:
            sections = {name: getattr(entry, name) for name in ROBOT_SECTIONS}
            out.append((entry.ns, dataclasses.replace(self, robots=(), **sections)))
        return out


def for_ros2_role(scenario: Scenario) -> Scenario:
    """The scenario a `ros2.role` runs: `full` as it is; `simulator` Gazebo's part alone.

    As a simulator the run keeps the world, robot, sensors, drive, odometry, TF, robot_state_publisher
    and /clock, and drops its mission, AMCL and Nav2 (and so its map and map→odom): an external
    stack brings its own and drives the robot on /cmd_vel. In a fleet every robot is so, and the
    topics taken by default are each robot's (`/robot1/cmd_vel`, `/robot1/initialpose`...), as a
    multi-robot Nav2 publishes them.
    """
    if not scenario.ros2.enabled:
        return scenario
    ros2 = scenario.ros2
    if scenario.robots and ros2.subscribe == Ros2Section().subscribe:
        each = tuple(f"/{entry.ns}{topic}" for entry in scenario.robots for topic in ros2.subscribe)
        scenario = dataclasses.replace(scenario, ros2=dataclasses.replace(ros2, subscribe=each))
    if ros2.role == "full":
        return scenario

    def simulated(localization: LocalizationSection) -> LocalizationSection:
        return dataclasses.replace(localization, type="none", initial_pose=None)

    robots = tuple(
        dataclasses.replace(entry, mission=NoMission(), localization=simulated(entry.localization))
        for entry in scenario.robots
    )
    return dataclasses.replace(
        scenario, mission=NoMission(), localization=simulated(scenario.localization), robots=robots
    )


def in_entry(err: TwinErrorT, entry: str) -> TwinErrorT:
    """A fleet robot's error naming its entry (`robots[1].`): before its key, else before the whole line.

    `robots[1].robot.model: ...` for an error about a key; `robots[1]: trees/tree.xml:5: ...` for one
    that names a file of the robot's (its tree, its locations, its Nav2 params). No entry: `err` as it is.
    """
    if not entry or str(err).startswith(entry.rstrip(".")):
        return err
    text = str(err)
    return err.with_context(before=entry if names_a_key(text) else f"{entry.rstrip('.')}: ")


# A scenario's name leads its bag folder's: a file name, never a path (`../x`, `a/b`) or too long for one.
_SCENARIO_NAME = re.compile(r"[A-Za-z0-9_\-]([A-Za-z0-9_. \-]{0,98}[A-Za-z0-9_.\-])?")

_KEY_PATH = re.compile(r"[A-Za-z_]\w*(\[\d+\])*(\.[A-Za-z_]\w*(\[\d+\])*)*:")


_FILE_ENDINGS = tuple(
    f".{ext}:"
    for ext in ("yaml", "yml", "xml", "pgm", "png", "sdf", "world", "urdf", "fmu", "csv", "json", "mcap", "db3")
)


def names_a_key(text: str) -> bool:
    """Whether an error starts with a scenario key (`robot.model: ...`), not a file or a sentence.

    A key is dotted names with list indexes (`robots[1].sensors.lidar.samples:`); a file
    (`maps/map.pgm:`, `nav2.yaml:3:`) or a URI (`model://x:`) is not.
    """
    head = text.split(" ", 1)[0]
    return bool(_KEY_PATH.fullmatch(head)) and not head.endswith(_FILE_ENDINGS)


def default_scenario_path() -> Path:
    """Return the shipped default scenario (the thesis's house mission)."""
    return Path(__file__).resolve().parent.parent.parent / "scenarios" / "default.yaml"


def runs_nav2(sc: Scenario) -> bool:
    """Whether the robot runs Nav2's stack (costmaps, servers, bt_navigator): a behaviour-tree mission sends goals."""
    return isinstance(sc.mission, BehaviorTreeMission)


def runs_amcl(sc: Scenario) -> bool:
    """Whether the robot runs AMCL: `localization.type` amcl, or auto (the default) with a mission that navigates."""
    kind = sc.localization.type
    return kind == "amcl" or (kind == "auto" and runs_nav2(sc))
