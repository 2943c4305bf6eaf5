"""One robot as a group of nodes under a namespace, as a launch file's `GroupAction` with `PushRosNamespace`.

A `RobotGroup` is made from the robot's sections of a scenario (`robot`, `drive`, `sensors`,
`odometry`, `estimation`, `localization`, `navigation`, `mission`, `disturbances`: a `Scenario`
whose top-level sections are that robot's) and a namespace. The simulation builds the world once
and then, for each robot:

1. `RobotGroup.load`: the robot's model (its name is left out of the world's scene);
2. `spawn(scene)`: its collision body, refused where the spawn pose is not free;
3. `build(...)`: what its nodes simulate: the drive, the lidar, IMU and encoder models, the EKF,
   its localization and Nav2 stack, its mission; only what its sections ask for;
4. `nodes()`: its nodes in launch order, each constructed under the group's namespace: relative
   topic names resolve under it, and `/tf` and `/tf_static` are remapped into it as nav2_bringup's
   multi-robot launch does. With the namespace `""` every name is the single robot's, as before
   groups existed.

Node order within a group (it fixes which timer fires first among equals and which subscriber
hears first): robot_state_publisher, the navigation stack (map_server, initial_pose, amcl,
costmaps, servers, bt_navigator), mission, [obstacles], lidar, joint_states, [gazebo_odometry],
ground_truth, imu, diff_drive, ekf_odometry.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import zlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.bag.frames import frame_prefix
from twin.core.clock import NS_PER_S
from twin.core.errors import ConfigError, WorldError
from twin.node import LaunchArguments, Node, launch_context, logger_name, node_logger
from twin.robot.chassis import ChassisParams, SlipModel
from twin.robot.drivetrain import Drivetrain
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain
from twin.robot.imu import ImuModel, imu_model_spec
from twin.robot.kinematic import KinematicDrivetrain, KinematicParams
from twin.robot.lidar import Lidar, ObstacleSource
from twin.robot.nodes import (
    ContactTracker,
    DiffDriveNode,
    GazeboOdometryNode,
    GroundTruthNode,
    ImuNode,
    JointStateNode,
    LidarNode,
    ObstacleNode,
    RobotStatePublisher,
    tf_pose,
)
from twin.sim.fleet import Fleet, FleetMonitor, FleetView
from twin.sim.obstacles import JoinedSource
from twin.sim.rng import RngStreams
from twin.sim.scenario import (
    BehaviorTreeMission,
    CmdVelScriptMission,
    InitialPose,
    LidarSection,
    NoMission,
    ReplayMission,
    Scenario,
    fmu_fallback,
    runs_amcl,
    runs_nav2,
)
from twin.world import RobotModelSpec, load_robot, urdf_from_robot
from twin.world.obstacles import ObstacleField, ObstacleMonitor
from twin.world.robot_model import DiffDriveSpec, in_namespace
from twin.world.scene import CollisionMonitor, RobotBody, Scene
from twin.world.tf_static import static_frames

if TYPE_CHECKING:
    from twin.estimation import OdometryFilter
    from twin.mission.mission_node import MissionNode
    from twin.sim.mission import BagReplay, CmdVelScript, TreeMission, WaypointFollower
    from twin.sim.navigation import NavigationStack

    Mission = TreeMission | WaypointFollower | CmdVelScript | BagReplay

__all__ = ["RobotGroup", "fmu_drive_section", "scenario_robot", "spawn_monitor"]

_log = logging.getLogger(__name__)

_TF_INTO_NAMESPACE = {"/tf": "tf", "/tf_static": "tf_static"}
"""nav2_bringup's multi-robot remapping: each robot's TF tree on its own `/<ns>/tf`."""

WheelFrame = tuple[str, str, str, np.ndarray, tuple[float, float, float]]


def _lidar_spec(robot: RobotModelSpec, section: LidarSection) -> RobotModelSpec:
    overrides = {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if not overrides:
        return robot
    if robot.lidar is None:
        msg = f"sensors.lidar: sets {', '.join(overrides)} but robot {robot.name!r} has no lidar in its SDF"
        raise ConfigError(msg)
    return dataclasses.replace(robot, lidar=dataclasses.replace(robot.lidar, **overrides))


def _topics_in_own_namespace(robot: RobotModelSpec, namespace: str) -> RobotModelSpec:
    """The robot with a sensor topic that names the robot's own namespace made relative to it.

    `/dolly/laser_scan` of robot `dolly` is `laser_scan`: the group puts every topic in its namespace
    once (as `RobotGroup._drive_topic` does the drive's).
    """
    if not namespace:
        return robot
    changes: dict[str, Any] = {}
    for key in ("lidar", "imu", "joint_states"):
        spec = getattr(robot, key)
        topic = getattr(spec, "topic", None)
        if topic is not None and _outside_own(topic.strip("/"), namespace) != topic.strip("/"):
            changes[key] = dataclasses.replace(spec, topic=_outside_own(topic.strip("/"), namespace))
    return dataclasses.replace(robot, **changes) if changes else robot


def _outside_own(relative: str, namespace: str) -> str:
    """A topic relative to the robot's namespace without that namespace in front (`robot1/scan` of robot1: `scan`)."""
    own = f"{namespace.strip('/')}/" if namespace else ""
    return relative[len(own) :] if own and relative.startswith(own) else relative


def _command_limits(drive: DiffDriveSpec) -> tuple[float, float, float, float] | None:
    """The drive plugin's (v_min, v_max, w_min, w_max) command range (None: it limits nothing)."""
    v, w = drive.linear_velocity_limits_mps, drive.angular_velocity_limits_radps
    if v is None and w is None:
        return None
    inf = math.inf
    return (*(v if v is not None else (-inf, inf)), *(w if w is not None else (-inf, inf)))


def _every_step_sensors(robot: RobotModelSpec, step_s: float) -> RobotModelSpec:
    """The robot with its lidar and IMU at the physics rate where the SDF's `<update_rate>` is 0 or absent.

    SDF's default update rate is 0, which Gazebo (Classic and gz-sim) takes as "every physics step".
    """
    every_hz = 1.0 / step_s
    changes: dict[str, Any] = {}
    sensors = (("lidar", robot.lidar, "sensors.lidar.rate_hz, e.g. 5 for TurtleBot3's LDS"), ("imu", robot.imu, ""))
    for key, spec, override in sensors:
        if spec is None or spec.rate_hz > 0.0:
            continue
        fix = (
            f"give the sensor an <update_rate> (or set {override})" if override else "give the sensor an <update_rate>"
        )
        _log.warning(
            "robot %s: %s %r has no <update_rate> (or 0): it updates at every physics step, %g Hz, as in Gazebo; %s",
            robot.name, key, spec.name, every_hz, fix,
        )  # fmt: skip
        changes[key] = dataclasses.replace(spec, rate_hz=every_hz)
    return dataclasses.replace(robot, **changes) if changes else robot


def fmu_drive_section(sc: Scenario) -> FmuDrive:
    """Return the FMU drive section with `disturbances.wheel_slip` moved into its chassis slip model.

    Raises:
        ConfigError: If slip is set in both places, or in a form the FMU chassis cannot model.
    """
    assert isinstance(sc.drive, FmuDrive)
    slip = sc.disturbances.wheel_slip
    if not slip.regions and slip.left_fraction == 0.0 and slip.right_fraction == 0.0:
        return sc.drive
    if sc.drive.slip != SlipModel():
        msg = "slip is set twice, in disturbances.wheel_slip and in drive.slip; keep one"
        raise ConfigError(msg)
    if slip.regions or slip.left_fraction != slip.right_fraction:
        msg = (
            "disturbances.wheel_slip: the FMU chassis slips both wheels alike; give equal left and right "
            "fractions, use drive.slip for rectangular slippery regions, or the kinematic drive for the rest"
        )
        raise ConfigError(msg)
    return dataclasses.replace(sc.drive, slip=SlipModel(slip=slip.left_fraction))


def _yaw_inertia(robot: RobotModelSpec) -> float:
    """Moment of inertia of the whole robot about the base frame's z axis, kg·m²."""
    total = 0.0
    for part in robot.inertias:
        ixx, iyy, izz, ixy, ixz, iyz = part.inertia_kgm2
        inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        rot = part.T_base_com[:3, :3]
        x, y = float(part.T_base_com[0, 3]), float(part.T_base_com[1, 3])
        total += float((rot @ inertia @ rot.T)[2, 2]) + part.mass_kg * (x * x + y * y)
    return total


def scenario_robot(scenario: Scenario, *, entry: str = "") -> RobotModelSpec:
    """Load the scenario's `robot.model` from its `world.model_path` (the project's own models last).

    Args:
        scenario: The robot's scenario (a fleet's: one robot's view, `Scenario.robot_scenarios`).
        entry: A fleet robot's entry (`robots[1].`), put before the key its errors name.

    Raises:
        WorldError: The loader's error, led by the scenario key (`robot.model`, `robots[1].robot.model`).
    """
    try:
        robot = load_robot(scenario.robot.model, model_path=scenario.world.model_path)
    except WorldError as err:
        raise err.with_context(before=f"{entry}robot.model: ") from None
    for warning in robot.warnings:  # what the model says that the twin reads otherwise (a drive's own numbers...)
        _log.warning("%srobot.model: %s", entry, warning)
    return robot


def driven_robot(scenario: Scenario, *, entry: str = "") -> RobotModelSpec:
    """The scenario's robot as a run drives it, with a differential drive.

    Its model (`scenario_robot`) with the scenario's lidar settings and every sensor whose
    `<update_rate>` is 0 at the physics rate.

    Raises:
        WorldError: The model cannot be loaded, or has no differential drive the twin can run.
        ConfigError: Lidar settings for a robot with no lidar.
    """
    robot = _lidar_spec(scenario_robot(scenario, entry=entry), scenario.sensors.lidar)
    robot = _every_step_sensors(robot, scenario.physics.step_s)
    if robot.drive is None:
        msg = (
            f"{entry}robot.model: {robot.source}: model {robot.name!r} has no differential drive the twin can run: "
            "give it a diff-drive plugin naming its wheel joints (gazebo_ros_diff_drive's or gz-sim's DiffDrive, "
            "<left_joint>/<right_joint>), or two revolute wheel joints whose names hold 'wheel' and 'left'/'right'"
        )
        raise WorldError(msg)
    return robot


_LOW_OBSTACLE_M = 0.2
"""An obstacle the robot is spawned inside whose top is no higher than this may be a raised floor."""

THIN_FLOOR_M = 0.05
"""The highest `world.floor_height_m` that keeps a run true: the robot stands at z = 0 whatever the
floor, so what stands on a floor this far up is that much higher than the robot's lidar sees it in Gazebo."""


def floor_problem(floor_height_m: float) -> str | None:
    """Why a `world.floor_height_m` makes the run untrue (a floor too high to stand the robot under), or None."""
    if floor_height_m <= THIN_FLOOR_M:
        return None
    return (
        f"world.floor_height_m is {floor_height_m:g} m: shapes whose top is at or below it are neither seen nor "
        "touched, and the robot still stands at z = 0, so what stands on a floor that high floats that high above "
        f"the robot's lidar (it is meant for slabs of at most {100 * THIN_FLOOR_M:g} cm); lower the world's "
        "models by the floor's height instead (their <pose> z)"
    )


def spawn_monitor(
    scene: Scene, robot: RobotModelSpec, pose: InitialPose, *, floor_height_m: float = 0.01
) -> tuple[RobotBody, CollisionMonitor]:
    """The robot's collision body and contact monitor, after checking the spawn pose is free.

    Raises:
        ConfigError: If the robot at `pose` overlaps the world (naming the model and link it is inside;
            a low one may be a floor slab standing a little above z = 0: the error names
            `world.floor_height_m` then).
    """
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    monitor = CollisionMonitor(scene, body)
    contacts = monitor.check(pose.x_m, pose.y_m, pose.yaw_rad)
    if contacts:
        c = contacts[0]
        msg = (
            f"robot.initial_pose: ({pose.x_m}, {pose.y_m}, {pose.yaw_rad}) puts {robot.name} inside "
            f"{c.link}; choose a free spawn pose"
        )
        top = scene.top_m(c)
        if top is not None and floor_height_m < top <= _LOW_OBSTACLE_M:
            floor = math.ceil(top * 100 + 0.5) / 100
            if floor <= THIN_FLOOR_M:
                msg += (
                    f", or, if that is the floor (its top is {100 * top:.1f} cm above z = 0), set "
                    f"world.floor_height_m to {floor:g} (now {floor_height_m:g}: shapes whose top is at or below it "
                    "are floor)"
                )
            else:  # the robot would stand that far below what stands on the floor
                msg += (
                    f", or, if that is the floor (its top is {100 * top:.1f} cm above z = 0), lower the world's "
                    f"models by {top:.3f} m (their <pose> z): the robot stands at z = 0, and world.floor_height_m "
                    f"is for slabs of at most {100 * THIN_FLOOR_M:g} cm"
                )
        raise ConfigError(msg)
    return body, monitor


def far_from_world(scene: Scene, robot: RobotModelSpec, pose: InitialPose) -> str | None:
    """Why a spawn pose is likely a mistake: beyond the lidar's reach of every model of the world (None: it is not).

    A robot out there sees nothing of the world, and a map made from the world reaches it only
    across empty space: a Nav2 mission then fails with "no path" goal after goal. Said (a warning)
    once the scenario has passed every check, so a refused one keeps its one line.
    """
    bounds = scene.bounds
    if bounds is None:
        return None
    (x0, y0, _), (x1, y1, _) = bounds
    dx = max(x0 - pose.x_m, 0.0, pose.x_m - x1)
    dy = max(y0 - pose.y_m, 0.0, pose.y_m - y1)
    reach = robot.lidar.range_max_m if robot.lidar is not None else 3.5
    gap = math.hypot(dx, dy)
    if gap <= reach:
        return None
    return (
        f"robot.initial_pose: ({pose.x_m:g}, {pose.y_m:g}) is {gap:.1f} m outside the world's models "
        f"(x {x0:.2f} to {x1:.2f} m, y {y0:.2f} to {y1:.2f} m), beyond the lidar's {reach:g} m: the robot sees "
        "nothing of the world there; did you mean a pose inside it?"
    )


class RobotGroup:
    """One robot's models and nodes under a namespace (see the module docstring for the phases).

    Args:
        scenario: The robot's view of the scenario (its sections at the top level).
        robot: Its model, with the scenario's lidar overrides (`RobotGroup.load` reads it).
        namespace: Pushed onto every node of the group (`""`: none).
    """

    def __init__(self, scenario: Scenario, robot: RobotModelSpec, *, namespace: str = "") -> None:
        self.scenario = scenario
        self.robot = robot
        self.namespace = namespace
        # Gazebo's frame_prefix (`tf: {mode: frame_prefix}`): the robot's frames named `<ns>/odom`... on
        # the shared /tf; else nav2_bringup's remapping of /tf into the namespace.
        self.frame_prefix = namespace if namespace and scenario.tf.mode == "frame_prefix" else ""
        remappings = {} if self.frame_prefix else _TF_INTO_NAMESPACE
        self.launch = LaunchArguments(push_namespace=namespace, remappings=remappings)
        self.body: RobotBody | None = None
        self.monitor: CollisionMonitor | None = None
        self.drive: Drivetrain | None = None
        self.mission_node: MissionNode | None = None

    @classmethod
    def load(cls, scenario: Scenario, *, namespace: str = "", entry: str = "") -> RobotGroup:
        """Read the robot's model.

        Raises:
            WorldError: The robot model cannot be loaded.
            ConfigError: The model has no differential drive, or lidar overrides without a lidar.
        """
        return cls(
            scenario, _topics_in_own_namespace(driven_robot(scenario, entry=entry), namespace), namespace=namespace
        )

    def spawn(self, scene: Scene) -> RobotBody:
        """Make the robot's collision body in the world's scene, checking its spawn pose is free.

        Raises:
            ConfigError: As `spawn_monitor`.
        """
        floor_m = self.scenario.world.floor_height_m
        self.body, self.monitor = spawn_monitor(
            scene, self.robot, self.scenario.robot.initial_pose, floor_height_m=floor_m
        )
        return self.body

    def build(
        self,
        scene: Scene,
        *,
        obstacles: ObstacleField | None,
        rng: RngStreams,
        step_ns: int,
        now: Callable[[], int],
        fleet: Fleet | None = None,
        obstacle_markers: bool = True,
    ) -> None:
        """Build what the robot's nodes simulate; on failure the drive it made is closed again.

        Args:
            scene: The world's static obstacles.
            obstacles: The world's moving and appearing obstacles (None without any).
            rng: The run's seeded streams.
            step_ns: The physics step.
            now: The executor's clock (ns).
            fleet: The run's robots when there are several (this group among them): the robot
                collides with the others and its lidar sees them.
            obstacle_markers: Whether this robot's obstacle node publishes `/obstacles` (one robot of a
                fleet does; every robot tracks its own contacts with its own view of the obstacles).

        Raises:
            TwinError: Any section that cannot be honoured.
        """
        assert self.body is not None and self.monitor is not None
        self.obstacles = obstacles
        self.obstacle_markers = obstacle_markers
        self.step_ns = step_ns
        self._now = now
        contact: CollisionMonitor | ObstacleMonitor | FleetMonitor = self.monitor
        if obstacles is not None:
            contact = ObstacleMonitor(self.monitor, obstacles)
        seen: ObstacleSource | None = obstacles
        if fleet is not None:
            index = fleet.groups.index(self)
            contact = FleetMonitor(contact, fleet, index)
            robots = FleetView(fleet, index)
            seen = robots if obstacles is None else JoinedSource(obstacles, robots)
        self.tracker = ContactTracker(contact)
        robot = self.robot
        self.lidar = (
            Lidar.from_robot(robot, scene, rng.stream("lidar"), obstacles=seen) if robot.lidar is not None else None
        )
        self.drive = self._make_drive(self.body.radius_m, contact)
        if isinstance(self.drive, FmuDrivetrain):
            self.drive.log = node_logger("diff_drive", self.namespace)  # its node's (a fleet's robot's) lines
        try:  # from here on, a failure must release the drive (FMU instances) it leaves behind
            self.wheels = self._wheel_frames()
            self.imu = self._make_imu(rng)
            self.encoders, self.ekf = self._make_odometry(rng)
            self.navigation = self._make_navigation(scene, rng)
            self.mission = self._make_mission()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Release the drive (its FMU instances); idempotent."""
        if self.drive is not None:
            self.drive.close()

    # -- what the nodes simulate -----------------------------------------------------------------

    def _make_navigation(self, scene: Scene, rng: RngStreams) -> NavigationStack | None:
        if not (runs_amcl(self.scenario) or runs_nav2(self.scenario)):
            return None  # no map, AMCL or Nav2 stack: nothing is imported for them either
        from twin.sim.navigation import NavigationStack

        if not self.namespace:
            return NavigationStack.build(self.scenario, self.robot, scene, rng.stream("amcl"))
        log = node_logger("navigation", self.namespace)  # a fleet's robot: its lines name it
        return NavigationStack.build(
            self.scenario, self.robot, scene, rng.stream("amcl"), log=log, namespace=self.namespace
        )

    def _make_mission(self) -> Mission | None:
        spec = self.scenario.mission
        if isinstance(spec, NoMission):
            return None
        from twin.sim import mission

        log = node_logger("mission", self.namespace)  # the mission node's: its tree's lines name the robot
        if isinstance(spec, BehaviorTreeMission):
            from twin.mission.navigate_to_pose import Nav2Navigator

            nav = self.navigation
            assert nav is not None and nav.navigates  # a tree mission always has Nav2's stack (or refused)
            navigator = Nav2Navigator(lambda: nav.navigator)
            return mission.TreeMission(spec, navigator, clock=self._now, seed=self._tree_seed(), log=log)
        if isinstance(spec, CmdVelScriptMission):
            return mission.CmdVelScript(spec)
        if isinstance(spec, ReplayMission):
            from twin.sim.replay import start_moving

            replay = mission.BagReplay(spec, log)
            assert self.drive is not None
            start_moving(self.drive, *replay.commands.start_velocity)
            return replay
        return mission.WaypointFollower(spec)

    def _tree_seed(self) -> int:
        """The seed of the tree's own random draws: the scenario's, and for a namespaced robot its own."""
        seed = self.scenario.seed
        if not self.namespace:
            return seed  # one robot: as before groups existed
        return seed + (zlib.crc32(self.namespace.encode("utf-8")) << 64)

    def _wheel_frames(self) -> list[WheelFrame]:
        """(joint, parent, child, T_parent, axis) of the left and right wheel joints, in that order."""
        drive = self.robot.drive
        assert drive is not None
        side = {drive.left_joint: 0, drive.right_joint: 1}
        wheels = [(f.joint, f.parent, f.name, f.T_parent, f.axis) for f in self.robot.frames if f.joint in side]
        return sorted(wheels, key=lambda w: side[w[0]])

    def _more_wheels(self) -> list[tuple[WheelFrame, int]]:
        """The drive's further wheel pairs' joints (their frames) with their sides, in the plugin's order."""
        drive = self.robot.drive
        assert drive is not None
        frames = {f.joint: f for f in self.robot.frames if f.joint}
        return [
            ((j, frames[j].parent, frames[j].name, frames[j].T_parent, frames[j].axis), side)
            for j, side in drive.more_wheels
            if j in frames
        ]

    def _make_imu(self, rng: RngStreams) -> ImuModel | None:
        spec = self.robot.imu
        if not self.scenario.sensors.imu.enabled:
            return None
        if spec is None:
            _log.info("robot %s has no IMU: /imu is not published and the EKF uses the wheels alone", self.robot.name)
            return None
        model_spec = self.scenario.disturbances.imu.apply(imu_model_spec(spec))
        return ImuModel(model_spec, gyro_rng=rng.stream("imu.gyro"), accel_rng=rng.stream("imu.accel"))

    def _make_odometry(self, rng: RngStreams) -> tuple[EncoderModel | None, OdometryFilter | None]:
        robot, sc = self.robot, self.scenario
        assert robot.drive is not None
        if len(self.wheels) != 2:
            _log.warning("robot %s: wheel joints not found among its frames; no /joint_states or /odom", robot.name)
            return None, None
        rate = robot.joint_states.rate_hz if robot.joint_states is not None else 30.0
        spec = EncoderSpec(
            rate_hz=rate,
            joint_names=(robot.drive.left_joint, robot.drive.right_joint),
            wheel_radius_m=robot.drive.wheel_radius_m,
        )
        encoders = EncoderModel(spec, sc.disturbances.encoders, rng.stream("encoders"))
        if sc.odometry == "ground_truth":
            return encoders, None
        from twin.estimation import OdometryFilter

        estimation = sc.estimation
        if self.imu is None and estimation.fuse_gyro:
            estimation = dataclasses.replace(estimation, fuse_gyro=False)
        pose = sc.robot.initial_pose
        ekf = OdometryFilter(
            estimation,
            wheel_radius_m=robot.drive.wheel_radius_m,
            wheel_separation_m=robot.drive.wheel_separation_m,
            initial_pose=(pose.x_m, pose.y_m, pose.yaw_rad),
            gyro_samples="interval_mean",
        )
        return encoders, ekf

    def _make_drive(
        self, bounding_radius_m: float, monitor: CollisionMonitor | ObstacleMonitor | FleetMonitor
    ) -> Drivetrain:
        sc, robot = self.scenario, self.robot
        assert robot.drive is not None
        pose = (sc.robot.initial_pose.x_m, sc.robot.initial_pose.y_m, sc.robot.initial_pose.yaw_rad)
        drive_spec = sc.drive
        if isinstance(drive_spec, FmuDrive) and (fallback := fmu_fallback(drive_spec)) is not None:
            drive_spec = fallback
        if drive_spec.type == "kinematic":
            accel = drive_spec.max_wheel_acceleration_mps2
            params = KinematicParams(
                wheel_radius_m=robot.drive.wheel_radius_m,
                wheel_separation_m=robot.drive.wheel_separation_m,
                max_wheel_acceleration_mps2=accel if accel > 0.0 else math.inf,
                bounding_radius_m=bounding_radius_m,
            )
            return KinematicDrivetrain(
                params,
                step_ns=self.step_ns,
                pose=pose,
                contact=self.tracker.touches,
                free_distance=monitor.free_m,
                slip=sc.disturbances.wheel_slip,
            )
        chassis = ChassisParams(
            wheel_radius_m=robot.drive.wheel_radius_m,
            wheel_separation_m=robot.drive.wheel_separation_m,
            mass_kg=robot.mass_kg,
            yaw_inertia_kgm2=_yaw_inertia(robot),
        )
        drive_section = fmu_drive_section(sc)
        if drive_section.fmu == "auto" and not robot.name.lower().startswith("turtlebot3"):
            _log.warning(
                "robot %s (%.3g kg) is no TurtleBot3: drive.fmu: auto gives it a TurtleBot3's wheel motors "
                "(Dynamixel %s); give its own motor FMU (drive.fmu_file) or drive: {type: kinematic}",
                robot.name, robot.mass_kg, "XL430-W250" if "burger" in robot.name.lower() else "XM430-W210",
            )  # fmt: skip
        return FmuDrivetrain(
            drive_section,
            chassis,
            step_ns=self.step_ns,
            pose=pose,
            contact=self.tracker.touches,
            free_distance=monitor.free_m,
            probe=monitor.check,
            bounding_radius_m=bounding_radius_m,
            plugin_wheel_acceleration_mps2=robot.drive.max_wheel_acceleration_mps2
            or robot.drive.max_linear_acceleration_mps2,
            robot_name=robot.name,
            log_name=logger_name("fmu", self.namespace),
        )

    # -- the nodes -------------------------------------------------------------------------------

    def nodes(self) -> list[Node]:
        """The group's nodes in launch order, each under the group's namespace (a new set on each call)."""
        with launch_context(self.launch), frame_prefix(self.frame_prefix):
            return self._nodes()

    def _drive_topic(self, topic: str, default: str) -> str:
        """The diff drive plugin's topic in the robot's namespace.

        A plugin `<ros><namespace>` naming the robot's own (`/robot1`, as a fleet's model may) is that
        namespace, not one more under it.
        """
        return _outside_own(in_namespace(topic, default), self.namespace)

    def _nodes(self) -> list[Node]:
        robot, sc, drive = self.robot, self.scenario, self.drive
        assert robot.drive is not None and drive is not None
        chassis = drive.chassis_state
        nodes: list[Node] = []

        # Latched, once at t = 0: the robot's fixed frames (and map -> odom, which nothing
        # localises yet) and its description; the wheels' transforms on every joint state.
        nav = self.navigation
        localizes = nav is not None and nav.localizes
        # As a ROS 2 simulator (ros2.role) the external stack's AMCL owns map -> odom.
        external = self.scenario.ros2.enabled and self.scenario.ros2.role == "simulator"
        static = [] if localizes or external else [("map", "odom", (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))]
        static += [(parent, child, tf_pose(T)) for parent, child, T in static_frames(robot)]  # casters, optical frames
        imu_topic = in_namespace(robot.imu.topic if robot.imu is not None else None, "imu")
        joints_topic = in_namespace(
            robot.joint_states.topic if robot.joint_states is not None else None, "joint_states"
        )
        more = self._more_wheels() if len(self.wheels) == 2 else []
        nodes.append(
            RobotStatePublisher(
                urdf_from_robot(robot), static, self.wheels, joint_states_topic=joints_topic, more_wheels=more
            )
        )

        def truth() -> tuple[float, float, float]:
            c = chassis()
            return (c.x_m, c.y_m, c.yaw_rad)

        if nav is not None:
            nodes += nav.nodes(now=self._now, truth=truth)

        pose = sc.robot.initial_pose
        self.mission_node = None
        if self.mission is not None:
            from twin.mission.mission_node import MissionNode

            spec = sc.mission
            assert not isinstance(spec, NoMission)
            by_nav2 = nav is not None and nav.navigates
            tree = isinstance(spec, BehaviorTreeMission)
            frames = nav.frames if nav is not None and localizes else None
            self.mission_node = MissionNode(
                self.mission,
                initial_pose=(pose.x_m, pose.y_m, pose.yaw_rad),
                command_rate_hz=None
                if by_nav2
                else (spec.controller_rate_hz if isinstance(spec, BehaviorTreeMission) else spec.rate_hz),
                tree_rate_hz=spec.tick_rate_hz if isinstance(spec, BehaviorTreeMission) else None,
                bt_log_topic="mission/behavior_tree_log" if by_nav2 else "behavior_tree_log",
                pose_source=frames.map_pose if frames is not None and tree else None,
                ready=(lambda: frames.localized) if frames is not None and tree else None,
            )
            nodes.append(self.mission_node)

        if self.obstacles is not None:  # the world's; it reports its contacts to this robot
            period_s = self.obstacles.update_period_ns / NS_PER_S
            nodes.append(
                ObstacleNode(
                    self.obstacles, self.tracker, chassis, rate_hz=1.0 / period_s, markers=self.obstacle_markers
                )
            )
        if self.lidar is not None and robot.lidar is not None:
            lidar = robot.lidar
            nodes.append(LidarNode(self.lidar, lidar.frame_id, lidar.rate_hz, chassis, topic=lidar.scan_topic))

        names = [w[0] for w in self.wheels] + [w[0] for w, _ in more]
        sides = [0, 1] + [side for _, side in more] if more else None
        fmu = isinstance(drive, FmuDrivetrain) and len(self.wheels) == 2
        with_effort = fmu and isinstance(drive, FmuDrivetrain) and drive.has_effort
        if self.encoders is not None:
            rate = self.encoders.spec.rate_hz
            encoders = self.encoders if self.ekf is not None else None
            nodes.append(
                JointStateNode(
                    names, rate, drive.wheel_state, encoders, with_effort=with_effort, topic=joints_topic, sides=sides
                )
            )
            if self.ekf is None:
                odom_topic = self._drive_topic(robot.drive.odometry_topic, "odom")
                nodes.append(GazeboOdometryNode(robot.base_frame, rate, chassis, topic=odom_topic))

        nodes.append(GroundTruthNode(robot.base_frame, sc.sensors.ground_truth.rate_hz, chassis))
        if self.imu is not None:
            address = drive.chassis_address if isinstance(drive, FmuDrivetrain) else None
            nodes.append(ImuNode(self.imu, chassis, pose.yaw_rad, chassis_address=address, topic=imu_topic))

        motor_rate = robot.joint_states.rate_hz if robot.joint_states is not None else 30.0
        self.drive_node = DiffDriveNode(
            drive,
            self.tracker,
            motor_joints=names[:2] if fmu else (),  # the drive's two motors (FMUs)
            motor_rate_hz=motor_rate,
            command_topic=self._drive_topic(robot.drive.command_topic, "cmd_vel"),
            limits=_command_limits(robot.drive),
        )
        nodes.append(self.drive_node)
        if self.ekf is not None:
            from twin.estimation.node import EkfNode

            fuse_gyro = self.imu is not None and sc.estimation.fuse_gyro
            nodes.append(
                EkfNode(
                    self.ekf,
                    base_frame=robot.base_frame,
                    wheel_joints=names,
                    fuse_gyro=fuse_gyro,
                    imu_topic=imu_topic,
                    joint_states_topic=joints_topic,
                )
            )
        return nodes
