"""The Simulation: a Scenario composed into nodes on one executor, as a launch file starts a ROS 2 system.

It loads the world and the robot, builds what the nodes simulate (the drivetrain, the lidar's ray
caster, the IMU and encoder models, the EKF, the mission), creates the nodes in a fixed order and
adds the scenario's own nodes; the executor (`twin.sim.executor`) runs them on the simulation
clock and the recorder records every topic. Nothing here knows what a topic means.

Node order (it fixes which timer fires first among equals, and which subscriber hears first):
rosout, robot_state_publisher, mission, [obstacles], lidar, joint_states, [gazebo_odometry], ground_truth, imu,
diff_drive, ekf_odometry, clock, then the scenario's nodes in their order.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.bag import Recorder
from twin.core.clock import NS_PER_S, s_to_ns
from twin.core.closing import Closing
from twin.core.errors import ConfigError, WorldError
from twin.core.gcpolicy import resume_collection
from twin.estimation import OdometryFilter
from twin.estimation.node import EkfNode
from twin.nav import GridNavigator, GridPlanner, build_grid
from twin.nav.mission_node import MissionNode
from twin.nav.nav2_nodes import Nav2Navigator
from twin.node import Node
from twin.robot.chassis import ChassisParams, SlipModel
from twin.robot.drivetrain import Drivetrain
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.fmu_drive import FmuDrive
from twin.robot.fmu_drivetrain import FmuDrivetrain
from twin.robot.imu import ImuModel, imu_model_spec
from twin.robot.kinematic import KinematicDrivetrain, KinematicParams
from twin.robot.lidar import Lidar
from twin.robot.nodes import (
    ClockNode,
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
from twin.sim.executor import Executor, RecordFilter, Sink
from twin.sim.launch import load_nodes
from twin.sim.mission import BagReplay, CmdVelScript, TreeMission, WaypointFollower
from twin.sim.navigation import NavigationStack
from twin.sim.obstacles import scenario_obstacles
from twin.sim.provenance import fmu_record, run_provenance
from twin.sim.replay import start_moving
from twin.sim.rng import RngStreams
from twin.sim.rosout import RosoutBridge
from twin.sim.scenario import (
    BehaviorTreeMission,
    CmdVelScriptMission,
    InitialPose,
    LidarSection,
    NoMission,
    ReplayMission,
    Scenario,
    WaypointsMission,
    fmu_fallback,
)
from twin.world import RobotModelSpec, build_scene, load_robot, load_world, urdf_from_robot
from twin.world.obstacles import ObstacleField, ObstacleMonitor
from twin.world.scene import CollisionMonitor, RobotBody, Scene
from twin.world.tf_static import static_frames

__all__ = ["RunSummary", "Simulation"]

_log = logging.getLogger(__name__)

# Obstacles appear and vanish on this grid (the /clock period); walkers near the robot step at it (5 mm at 0.5 m/s).
_OBSTACLE_PERIOD_NS = 10_000_000


@dataclass(frozen=True, kw_only=True, slots=True)
class RunSummary:
    """What a run did, for the one-line summary and for scripts (`--json`)."""

    scenario: str
    bag_path: Path | None
    storage: str
    sim_s: float
    wall_s: float
    real_time_factor: float
    messages: int
    topics: dict[str, int]
    contacts: int
    ended_by: str
    mission_result: str
    seed: int
    breakdown_s: dict[str, float]
    drive: str = ""  # the drive that ran, e.g. `fmu xm430_w210_servo (FMI 2, velocity-servo)` or `kinematic`
    drive_notes: str = ""  # e.g. commands clamped to the motors' reach ('' when none)
    localization: dict[str, Any] = field(default_factory=dict)  # AMCL vs the true pose ({} without AMCL)


def _lidar_spec(robot: RobotModelSpec, section: LidarSection) -> RobotModelSpec:
    overrides = {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if not overrides:
        return robot
    if robot.lidar is None:
        msg = f"sensors.lidar: sets {', '.join(overrides)} but robot {robot.name!r} has no lidar in its SDF"
        raise ConfigError(msg)
    return dataclasses.replace(robot, lidar=dataclasses.replace(robot.lidar, **overrides))


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


def scenario_robot(scenario: Scenario) -> RobotModelSpec:
    """Load the scenario's `robot.model` from its `world.model_path` (the project's own models last).

    Raises:
        WorldError: The loader's error, led by the scenario key `robot.model`.
    """
    try:
        return load_robot(scenario.robot.model, model_path=scenario.world.model_path)
    except WorldError as err:
        raise err.with_context(before="robot.model: ") from None


_LOW_OBSTACLE_M = 0.2
"""An obstacle the robot is spawned inside whose top is no higher than this may be a raised floor."""


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
            msg += (
                f", or, if that is the floor (its top is {100 * top:.1f} cm above z = 0), set world.floor_height_m "
                f"to {math.ceil(top * 100 + 0.5) / 100:g} (now {floor_height_m:g}: shapes whose top is at or below "
                "it are floor)"
            )
        raise ConfigError(msg)
    return body, monitor


class Simulation(Closing):
    """One run of a scenario, recording into a new bag. Use as a context manager.

    Args:
        scenario: The scenario to run.
        bag_path: The bag folder to create (must not exist or be empty); None records nothing.
        duration_s: Stop after this much sim time even if the mission goes on (default: the
            mission's end, at most `scenario.max_duration_s`).
        profile: Time each timer callback and the physics (for benchmarks; adds a little overhead).
        write_log: For crash tests: the recorder appends `topic t_ns monotonic_ns` per message here.
        sinks: More places every recorded topic goes to (a live view), after the recorder.

    Raises:
        TwinError: If any input (world, robot, scenario values, nodes) is wrong; nothing is left open.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        bag_path: Path | None,
        duration_s: float | None = None,
        profile: bool = False,
        write_log: Path | None = None,
        sinks: Sequence[Sink] = (),
    ) -> None:
        self.scenario = scenario
        self.step_ns = s_to_ns(scenario.physics.step_s)
        self._profile = profile
        self._rng = RngStreams(scenario.seed)

        t0 = time.perf_counter()
        world = load_world(scenario.world.sdf, model_path=scenario.world.model_path)
        for warning in world.warnings:
            _log.warning("%s", warning)
        robot = _lidar_spec(scenario_robot(scenario), scenario.sensors.lidar)
        if robot.drive is None:
            msg = f"robot {robot.name!r} has no differential drive (wheel joints or a diff-drive plugin) in its SDF"
            raise ConfigError(msg)
        self.robot = robot
        floor_m = scenario.world.floor_height_m
        scene = build_scene(world, exclude_models=(robot.name,), floor_height_m=floor_m)
        body, monitor = spawn_monitor(scene, robot, scenario.robot.initial_pose, floor_height_m=floor_m)
        self.obstacles = self._make_obstacles(body)
        contact: CollisionMonitor | ObstacleMonitor = monitor
        if self.obstacles is not None:
            contact = ObstacleMonitor(monitor, self.obstacles)
        self._tracker = ContactTracker(contact)
        self.lidar = (
            Lidar.from_robot(robot, scene, self._rng.stream("lidar"), obstacles=self.obstacles)
            if robot.lidar is not None
            else None
        )
        self.drive = self._make_drive(body.radius_m, contact)
        self.recorder: Recorder | None = None
        self.executor = Executor(self.step_ns, profile=profile)
        try:  # from here on, a failure must release the drive (FMU instances) it leaves behind
            self._wheels = self._wheel_frames()
            self._imu = self._make_imu()
            self._encoders, self._ekf = self._make_odometry()
            self.navigation = NavigationStack.build(scenario, robot, scene, self._rng.stream("amcl"))
            self.mission = self._make_mission(scene, body)
            user_nodes = load_nodes(scenario)
            self._run_to_limit = duration_s is not None
            limit_ns = s_to_ns(scenario.max_duration_s if duration_s is None else duration_s)
            self.end_k = -(-limit_ns // self.step_ns)
            self._setup_s = time.perf_counter() - t0
            selection = scenario.recording.topics
            keep = RecordFilter(
                include=selection.include,
                include_regex=selection.include_regex,
                exclude=selection.exclude,
                exclude_regex=selection.exclude_regex,
            )
            # Wire the graph once without sinks: a node that cannot join (a duplicate name, a topic of
            # another type) is refused before a bag folder exists.
            scratch = Executor(self.step_ns)
            for node in [RosoutBridge(), *self._builtin_nodes(), *user_nodes]:
                scratch.add_node(node)
            # -- ROS 2 bridge (lane L_ros2) -------------------------------------------------------------
            # A sink that also takes topics from a ROS 2 domain (twin.ros2.Ros2Bridge) adds the node that
            # publishes them into the run, last, typed by the graph just wired (docs/ros2.md).
            for sink in sinks:
                inbound = getattr(sink, "inbound_node", None)
                node_in = inbound(scratch.topics) if inbound is not None else None
                if node_in is not None:
                    user_nodes.append(node_in)
            # -- end ROS 2 bridge ------------------------------------------------------------------------
            if bag_path is not None:
                self.recorder = Recorder(
                    bag_path, storage=scenario.recording.storage, distro=scenario.recording.distro, write_log=write_log
                )
                self.recorder.add_provenance(run_provenance(scenario, duration_s=duration_s, fmus=self._fmu_records()))
            for sink in ([self.recorder] if self.recorder is not None else []) + list(sinks):
                self.executor.add_sink(sink, keep)
            self._rosout = RosoutBridge()
            self.executor.add_node(self._rosout)
            for node in [*self._builtin_nodes(), *user_nodes]:
                self.executor.add_node(node)
            for node in user_nodes:
                unused = node.undeclared_overrides()
                if unused:
                    _log.warning("node %s never declares parameter(s) %s", node.get_name(), ", ".join(unused))
            self.executor.set_physics(self._drive_node.advance, self._drive_node.after_advance, pending=self._tracker)
        except BaseException:
            try:
                self.drive.close()
            finally:
                if self.recorder is not None:
                    self.recorder.close()
            raise

    # -- what the nodes simulate -----------------------------------------------------------------

    def _make_obstacles(self, body: RobotBody) -> ObstacleField | None:
        """The scenario's obstacles and blocks (None without any), refused where they cover the spawn pose."""
        specs = scenario_obstacles(self.scenario, self._rng.stream("blocks"))
        if not specs:
            return None
        period_ns = self.step_ns * max(1, round(_OBSTACLE_PERIOD_NS / self.step_ns))
        field = ObstacleField(specs, body, update_period_ns=period_ns)
        pose = self.scenario.robot.initial_pose
        _, contacts = field.update(0, (pose.x_m, pose.y_m, pose.yaw_rad))
        if contacts:
            c = contacts[0]
            index = next(ob.index for ob in field.obstacles if ob.name == c.model)
            key = f"obstacles[{index}]" if index < len(self.scenario.obstacles) else "blocks"
            msg = (
                f"{key}: {c.model} stands on the robot's spawn pose ({pose.x_m}, {pose.y_m}) at t = 0; "
                "move it, or the robot's initial_pose"
            )
            raise ConfigError(msg)
        return field

    def _make_mission(
        self, scene: Scene, body: RobotBody
    ) -> TreeMission | WaypointFollower | CmdVelScript | BagReplay | None:
        spec = self.scenario.mission
        if isinstance(spec, NoMission):
            return None
        if isinstance(spec, CmdVelScriptMission):
            return CmdVelScript(spec)
        if isinstance(spec, ReplayMission):
            replay = BagReplay(spec)
            start_moving(self.drive, *replay.commands.start_velocity)
            return replay
        if isinstance(spec, WaypointsMission):
            return WaypointFollower(spec)
        nav = self.navigation
        if nav is not None and nav.navigates:
            navigator = Nav2Navigator(lambda: nav.navigator)
            return TreeMission(spec, navigator, clock=lambda: self.executor.now_ns, seed=self.scenario.seed)
        z_lo, z_hi = body.z_range_m
        heights = tuple(float(h) for h in np.linspace(max(z_lo, 0.02), max(z_hi - 0.005, 0.03), 4))
        planner_spec = spec.planner
        grid = build_grid(scene, heights_m=heights, resolution_m=planner_spec.resolution_m)
        planner = GridPlanner(
            grid,
            robot_radius_m=planner_spec.robot_radius_m or body.radius_m,
            inflation_radius_m=planner_spec.inflation_radius_m,
            cost_scaling_factor=planner_spec.cost_scaling_factor,
            tolerance_m=planner_spec.tolerance_m,
        )
        grid_navigator = GridNavigator(planner, spec.follower, spec.progress)
        return TreeMission(spec, grid_navigator, clock=lambda: self.executor.now_ns, seed=self.scenario.seed)

    def _wheel_frames(self) -> list[tuple[str, str, str, np.ndarray, tuple[float, float, float]]]:
        """(joint, parent, child, T_parent, axis) of the left and right wheel joints, in that order."""
        drive = self.robot.drive
        assert drive is not None
        side = {drive.left_joint: 0, drive.right_joint: 1}
        wheels = [(f.joint, f.parent, f.name, f.T_parent, f.axis) for f in self.robot.frames if f.joint in side]
        return sorted(wheels, key=lambda w: side[w[0]])

    def _make_imu(self) -> ImuModel | None:
        spec = self.robot.imu
        if not self.scenario.sensors.imu.enabled:
            return None
        if spec is None:
            _log.info("robot %s has no IMU: /imu is not published and the EKF uses the wheels alone", self.robot.name)
            return None
        model_spec = self.scenario.disturbances.imu.apply(imu_model_spec(spec))
        return ImuModel(model_spec, gyro_rng=self._rng.stream("imu.gyro"), accel_rng=self._rng.stream("imu.accel"))

    def _make_odometry(self) -> tuple[EncoderModel | None, OdometryFilter | None]:
        robot, sc = self.robot, self.scenario
        assert robot.drive is not None
        if len(self._wheels) != 2:
            _log.warning("robot %s: wheel joints not found among its frames; no /joint_states or /odom", robot.name)
            return None, None
        rate = robot.joint_states.rate_hz if robot.joint_states is not None else 30.0
        spec = EncoderSpec(
            rate_hz=rate,
            joint_names=(robot.drive.left_joint, robot.drive.right_joint),
            wheel_radius_m=robot.drive.wheel_radius_m,
        )
        encoders = EncoderModel(spec, sc.disturbances.encoders, self._rng.stream("encoders"))
        if sc.odometry == "ground_truth":
            return encoders, None
        estimation = sc.estimation
        if self._imu is None and estimation.fuse_gyro:
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

    def _fmu_records(self) -> list[dict[str, str]]:
        """Provenance of the FMUs the drive loaded (none for the kinematic drive)."""
        if not isinstance(self.drive, FmuDrivetrain):
            return []
        info = self.drive.fmu_info
        return [fmu_record(self.drive.fmu_path, model_name=info.model_name, guid=info.guid)]

    def _make_drive(self, bounding_radius_m: float, monitor: CollisionMonitor | ObstacleMonitor) -> Drivetrain:
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
                contact=self._tracker.touches,
                free_distance=monitor.free_m,
                slip=sc.disturbances.wheel_slip,
            )
        chassis = ChassisParams(
            wheel_radius_m=robot.drive.wheel_radius_m,
            wheel_separation_m=robot.drive.wheel_separation_m,
            mass_kg=robot.mass_kg,
            yaw_inertia_kgm2=_yaw_inertia(robot),
        )
        return FmuDrivetrain(
            fmu_drive_section(sc),
            chassis,
            step_ns=self.step_ns,
            pose=pose,
            contact=self._tracker.touches,
            free_distance=monitor.free_m,
            bounding_radius_m=bounding_radius_m,
            plugin_wheel_acceleration_mps2=robot.drive.max_wheel_acceleration_mps2,
            robot_name=robot.name,
        )

    # -- the nodes -------------------------------------------------------------------------------

    def _builtin_nodes(self) -> list[Node]:
        """The robot's, the estimator's and the mission's nodes, in the documented order."""
        robot, sc = self.robot, self.scenario
        assert robot.drive is not None
        chassis = self.drive.chassis_state
        nodes: list[Node] = []

        # Latched, once at t = 0: the robot's fixed frames (and map -> odom, which nothing
        # localises yet) and its description; the wheels' transforms on every joint state.
        nav = self.navigation
        localizes = nav is not None and nav.localizes
        # ROS 2 bridge (lane L_ros2): as a simulator (ros2.role), the external stack's AMCL owns map -> odom.
        external = sc.ros2.enabled and sc.ros2.role == "simulator"
        static = [] if localizes or external else [("map", "odom", (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))]
        static += [(parent, child, tf_pose(T)) for parent, child, T in static_frames(robot)]  # casters, optical frames
        nodes.append(RobotStatePublisher(urdf_from_robot(robot), static, self._wheels))
        chassis_now = self.drive.chassis_state

        def truth() -> tuple[float, float, float]:
            c = chassis_now()
            return (c.x_m, c.y_m, c.yaw_rad)

        if nav is not None:
            nodes += nav.nodes(now=lambda: self.executor.now_ns, truth=truth)

        pose = sc.robot.initial_pose
        self.mission_node: MissionNode | None = None
        if self.mission is not None:
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
                bt_log_topic="/mission/behavior_tree_log" if by_nav2 else "/behavior_tree_log",
                pose_source=frames.map_pose if frames is not None and tree else None,
                ready=(lambda: frames.localized) if frames is not None and tree else None,
            )
            nodes.append(self.mission_node)

        if self.obstacles is not None:
            period_s = self.obstacles.update_period_ns / NS_PER_S
            nodes.append(ObstacleNode(self.obstacles, self._tracker, chassis, rate_hz=1.0 / period_s))
        if self.lidar is not None and robot.lidar is not None:
            nodes.append(LidarNode(self.lidar, robot.lidar.frame_id, robot.lidar.rate_hz, chassis))

        names = [w[0] for w in self._wheels]
        fmu = isinstance(self.drive, FmuDrivetrain) and len(self._wheels) == 2
        with_effort = fmu and isinstance(self.drive, FmuDrivetrain) and self.drive.has_effort
        if self._encoders is not None:
            rate = self._encoders.spec.rate_hz
            encoders = self._encoders if self._ekf is not None else None
            nodes.append(JointStateNode(names, rate, self.drive.wheel_state, encoders, with_effort=with_effort))
            if self._ekf is None:
                nodes.append(GazeboOdometryNode(robot.base_frame, rate, chassis))

        nodes.append(GroundTruthNode(robot.base_frame, sc.sensors.ground_truth.rate_hz, chassis))
        if self._imu is not None:
            address = self.drive.chassis_address if isinstance(self.drive, FmuDrivetrain) else None
            nodes.append(ImuNode(self._imu, chassis, pose.yaw_rad, chassis_address=address))

        motor_rate = robot.joint_states.rate_hz if robot.joint_states is not None else 30.0
        self._drive_node = DiffDriveNode(
            self.drive, self._tracker, motor_joints=names if fmu else (), motor_rate_hz=motor_rate
        )
        nodes.append(self._drive_node)
        if self._ekf is not None:
            fuse_gyro = self._imu is not None and sc.estimation.fuse_gyro
            nodes.append(EkfNode(self._ekf, base_frame=robot.base_frame, wheel_joints=names, fuse_gyro=fuse_gyro))
        nodes.append(ClockNode(sc.sensors.clock.rate_hz))
        return nodes

    @property
    def t_s(self) -> float:
        """Sim time reached so far, s."""
        return self.executor.k * self.step_ns / NS_PER_S

    @property
    def contacts(self) -> int:
        """Contacts reported so far."""
        return self._drive_node.contacts

    # -- context manager -------------------------------------------------------------------------

    def close(self) -> None:
        """Close the drive and the bag (idempotent); what was recorded stays a complete, readable bag."""
        logging.getLogger("twin").removeHandler(self._rosout.handler)
        try:
            self.drive.close()
        finally:
            if self.recorder is not None:
                self.recorder.close()

    # -- the loop --------------------------------------------------------------------------------

    def run(
        self,
        *,
        should_stop: Callable[[], bool] = lambda: False,
        progress: Callable[[float, int], None] | None = None,
    ) -> RunSummary:
        """Run until the mission ends, the duration is reached or `should_stop()` turns true.

        Args:
            should_stop: Polled between events (e.g. set by a SIGINT handler).
            progress: Called about every simulated second with (sim seconds, messages so far).

        Raises:
            TwinError: From any node; the bag stays readable (close it with `close`).
        """
        logging.getLogger("twin").addHandler(self._rosout.handler)
        _log.info(
            "scenario %s: world %s, robot %s, seed %d",
            self.scenario.name,
            self.scenario.world.sdf.name,
            self.robot.name,
            self.scenario.seed,
        )
        mission = self.mission_node
        done = None if mission is None or self._run_to_limit else self.mission  # its `done` ends the run
        resume_collection()  # `twin simulate` built all this without the cyclic collector: freeze it, resume
        wall0 = time.perf_counter()
        why = self.executor.spin(self.end_k, done=done, should_stop=should_stop, progress=progress)
        wall_s = time.perf_counter() - wall0
        ended_by = {
            "done": "mission complete",
            "interrupted": "interrupted",
            "duration": "duration"
            if self._run_to_limit or mission is None
            else "max_duration_s reached before the mission ended",
        }[why]
        sim_s = self.t_s
        breakdown = dict(self.executor.timings_s)
        if self._profile:
            breakdown["setup"] = self._setup_s
        _log.info("run ended (%s) at t=%.3f s", ended_by, sim_s)
        return RunSummary(
            scenario=self.scenario.name,
            bag_path=self.recorder.path if self.recorder is not None else None,
            storage=self.scenario.recording.storage,
            sim_s=sim_s,
            wall_s=wall_s,
            real_time_factor=sim_s / wall_s if wall_s > 0 else math.inf,
            messages=self.executor.message_count,
            topics={name: t.count for name, t in self.executor.topics.items() if t.publishers},
            contacts=self.contacts,
            ended_by=ended_by,
            mission_result=self.mission.result if self.mission is not None else "none",
            seed=self.scenario.seed,
            breakdown_s=breakdown,
            drive=self.drive.label,
            drive_notes=self.drive.saturation.describe() if isinstance(self.drive, FmuDrivetrain) else "",
            localization=self.navigation.log.summary() if self.navigation is not None else {},
        )
