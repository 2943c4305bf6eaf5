"""The Simulation: a Scenario assembled into a world, a robot, a mission and a bag, and the loop that runs them.

One step of the loop (ARCHITECTURE.md): the drive advances whole physics steps between events;
at each event time the scheduler fires the tasks due, in priority order: the mission's command,
then the sensors, then the publications. Time is `k * step_ns`, never an accumulated float.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Self

import numpy as np

from twin.bag import (
    BehaviorTreeLogEncoder,
    ClockEncoder,
    ContactEncoder,
    ImuEncoder,
    JointStateEncoder,
    LogEncoder,
    MotorStateEncoder,
    OdometryEncoder,
    PathEncoder,
    Recorder,
    ScanEncoder,
    StringEncoder,
    TFEncoder,
    TwistEncoder,
)
from twin.core.clock import NS_PER_S, ns_to_s, s_to_ns
from twin.core.errors import ConfigError, TwinError
from twin.core.geometry import Mat4, quat_from_rpy, rpy_from_matrix
from twin.estimation import OdometryFilter
from twin.nav import GridNavigator, GridPlanner, build_grid
from twin.robot.chassis import ChassisParams, SlipModel
from twin.robot.drivetrain import Drivetrain, FmuDrive, FmuDrivetrain, WheelState
from twin.robot.encoders import EncoderModel, EncoderSpec
from twin.robot.imu import ImuModel, imu_model_spec
from twin.robot.kinematic import KinematicDrivetrain, KinematicParams
from twin.robot.lidar import Lidar
from twin.sim.bus import Bus, Publisher
from twin.sim.mission import CmdVelScript, TreeMission, WaypointFollower
from twin.sim.rng import RngStreams
from twin.sim.scenario import (
    BehaviorTreeMission,
    CmdVelScriptMission,
    LidarSection,
    Scenario,
    WaypointsMission,
    fmu_fallback,
)
from twin.sim.scheduler import Scheduler
from twin.world import RobotModelSpec, build_scene, load_robot, load_world, urdf_from_robot
from twin.world.scene import CollisionMonitor, Contact, RobotBody, Scene
from twin.world.types import JointType

__all__ = ["RunSummary", "Simulation"]

_log = logging.getLogger(__name__)

# Task priorities within one step: commands first, then sensors, then what reports state.
_P_MISSION = 10
_P_SENSOR = 40
_P_STATE = 60
_P_CLOCK = 90

# A contact ends once the robot has moved this far from where the world last refused it.
_CONTACT_RELEASE_M = 0.002

_ODOM_COV = (1e-5, 1e-5, 1e12, 1e12, 1e12, 1e-3)  # gazebo_ros_diff_drive's covariance diagonal


@dataclass(frozen=True, kw_only=True, slots=True)
class RunSummary:
    """What a run did, for the one-line summary and for scripts (`--json`)."""

    scenario: str
    bag_path: Path
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


def _lidar_spec(robot: RobotModelSpec, section: LidarSection) -> RobotModelSpec:
    overrides = {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if not overrides:
        return robot
    if robot.lidar is None:
        msg = f"sensors.lidar: sets {', '.join(overrides)} but robot {robot.name!r} has no lidar in its SDF"
        raise ConfigError(msg)
    return dataclasses.replace(robot, lidar=dataclasses.replace(robot.lidar, **overrides))


def _fmu_slip(sc: Scenario) -> FmuDrive:
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


class _JointTransform:
    """The transform of a revolving joint at an angle, as (x, y, z, qx, qy, qz, qw), with no matrices per call."""

    __slots__ = ("_ax", "_ay", "_az", "_q", "_t")

    def __init__(self, T_parent: Mat4, axis: tuple[float, float, float]) -> None:
        self._t = (float(T_parent[0, 3]), float(T_parent[1, 3]), float(T_parent[2, 3]))
        self._q = quat_from_rpy(*rpy_from_matrix(T_parent))
        n = math.sqrt(sum(a * a for a in axis)) or 1.0
        self._ax, self._ay, self._az = (a / n for a in axis)

    def at(self, angle_rad: float) -> tuple[float, float, float, float, float, float, float]:
        """Return the parent-to-child pose with the joint at `angle_rad`: q_parent * q_axis(angle)."""
        s, c = math.sin(0.5 * angle_rad), math.cos(0.5 * angle_rad)
        bx, by, bz, bw = self._ax * s, self._ay * s, self._az * s, c
        ax, ay, az, aw = self._q
        return (
            *self._t,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        )


def _tf_pose(T: Mat4) -> tuple[float, float, float, float, float, float, float]:
    qx, qy, qz, qw = quat_from_rpy(*rpy_from_matrix(T))
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), qx, qy, qz, qw)


class _RosoutHandler(logging.Handler):
    """Copies the twin's log records into the bag's /rosout, stamped with sim time."""

    _LEVELS = ((logging.CRITICAL, 50), (logging.ERROR, 40), (logging.WARNING, 30), (logging.INFO, 20))

    def __init__(self, publisher: Publisher, clock: Callable[[], int]) -> None:
        super().__init__(level=logging.INFO)
        self._pub = publisher
        self._clock = clock
        self._encoder = LogEncoder("twin")

    def emit(self, record: logging.LogRecord) -> None:
        level = next((ros for py, ros in self._LEVELS if record.levelno >= py), 10)
        try:
            data = self._encoder.encode(
                self._clock(),
                level,
                record.getMessage(),
                file=record.pathname,
                function=record.funcName,
                line=record.lineno,
            )
            self._pub.publish(self._clock(), data)
        except TwinError:
            self.handleError(record)


class Simulation:
    """One run of a scenario, recording into a new bag. Use as a context manager.

    Args:
        scenario: The scenario to run.
        bag_path: The bag folder to create (must not exist or be empty).
        duration_s: Stop after this much sim time even if the mission goes on (default: the
            mission's end, at most `scenario.max_duration_s`).
        profile: Time each subsystem (for benchmarks; adds a little overhead).
        write_log: For crash tests: the recorder appends `topic t_ns monotonic_ns` per message here.

    Raises:
        TwinError: If any input (world, robot, scenario values) is wrong; nothing is left open.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        bag_path: Path,
        duration_s: float | None = None,
        profile: bool = False,
        write_log: Path | None = None,
    ) -> None:
        self.scenario = scenario
        self.step_ns = s_to_ns(scenario.physics.step_s)
        self._profile = profile
        self._timers: dict[str, float] = {}
        self._rng = RngStreams(scenario.seed)
        self._k = 0
        self.contacts = 0
        self._contact: tuple[Contact, ...] = ()
        self._in_contact = False  # a contact episode is open
        self._touching = False  # the loop must track the open episode
        self._reported = False
        self._release_from = (0.0, 0.0)

        t0 = time.perf_counter()
        world = load_world(scenario.world.sdf, model_path=scenario.world.model_path)
        for warning in world.warnings:
            _log.warning("%s", warning)
        robot = load_robot(scenario.robot.model, model_path=scenario.world.model_path)
        robot = _lidar_spec(robot, scenario.sensors.lidar)
        if robot.drive is None:
            msg = f"robot {robot.name!r} has no differential drive (wheel joints or a diff-drive plugin) in its SDF"
            raise ConfigError(msg)
        self.robot = robot
        scene = build_scene(world, exclude_models=(robot.name,))
        body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
        self._monitor = CollisionMonitor(scene, body)
        pose = scenario.robot.initial_pose
        spawn_contacts = self._monitor.check(pose.x_m, pose.y_m, pose.yaw_rad)
        if spawn_contacts:
            c = spawn_contacts[0]
            msg = (
                f"robot.initial_pose: ({pose.x_m}, {pose.y_m}, {pose.yaw_rad}) puts {robot.name} inside "
                f"{c.model}::{c.link}; choose a free spawn pose"
            )
            raise ConfigError(msg)
        self.lidar = Lidar.from_robot(robot, scene, self._rng.stream("lidar")) if robot.lidar is not None else None
        self.drive = self._make_drive(body.radius_m)
        try:  # from here on, a failure must release the drive (FMU instances) it leaves behind
            self._wheels = self._wheel_frames()
            self._imu = self._make_imu()
            self._encoders, self._ekf = self._make_odometry()
            self.mission = self._make_mission(scene, body)
            self._run_to_limit = duration_s is not None
            limit_ns = s_to_ns(scenario.max_duration_s if duration_s is None else duration_s)
            self.end_k = -(-limit_ns // self.step_ns)
            self._setup_s = time.perf_counter() - t0
            self.recorder = Recorder(
                bag_path, storage=scenario.recording.storage, distro=scenario.recording.distro, write_log=write_log
            )
        except BaseException:
            self.drive.close()
            raise
        try:
            self.bus = Bus(self.recorder)
            self.scheduler = Scheduler(self.step_ns)
            self._rosout = _RosoutHandler(
                self.bus.advertise("/rosout", LogEncoder.msgtype), lambda: self._k * self.step_ns
            )
            self._setup_publishers()
        except BaseException:
            self.recorder.close()
            self.drive.close()
            raise

    def _make_mission(self, scene: Scene, body: RobotBody) -> TreeMission | WaypointFollower | CmdVelScript:
        spec = self.scenario.mission
        if isinstance(spec, CmdVelScriptMission):
            return CmdVelScript(spec)
        if isinstance(spec, WaypointsMission):
            return WaypointFollower(spec)
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
        navigator = GridNavigator(planner, spec.follower, spec.progress)
        return TreeMission(spec, navigator, clock=lambda: self._k * self.step_ns, seed=self.scenario.seed)

    def _wheel_frames(self) -> list[tuple[str, str, str, Mat4, tuple[float, float, float]]]:
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

    def _make_drive(self, bounding_radius_m: float) -> Drivetrain:
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
                contact=self._touches,
                free_distance=self._monitor.free_m,
                slip=sc.disturbances.wheel_slip,
            )
        chassis = ChassisParams(
            wheel_radius_m=robot.drive.wheel_radius_m,
            wheel_separation_m=robot.drive.wheel_separation_m,
            mass_kg=robot.mass_kg,
            yaw_inertia_kgm2=_yaw_inertia(robot),
        )
        return FmuDrivetrain(
            _fmu_slip(sc),
            chassis,
            step_ns=self.step_ns,
            pose=pose,
            contact=self._touches,
            free_distance=self._monitor.free_m,
            bounding_radius_m=bounding_radius_m,
            plugin_wheel_acceleration_mps2=robot.drive.max_wheel_acceleration_mps2,
            robot_name=robot.name,
        )

    @property
    def t_s(self) -> float:
        """Sim time reached so far, s."""
        return self._k * self.step_ns / NS_PER_S

    # -- context manager -------------------------------------------------------------------------

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close the drive and the bag (idempotent); what was recorded stays a complete, readable bag."""
        logging.getLogger("twin").removeHandler(self._rosout)
        try:
            self.drive.close()
        finally:
            self.recorder.close()

    # -- setup -----------------------------------------------------------------------------------

    def _timed(self, name: str, fn: Callable[[int], None]) -> Callable[[int], None]:
        if not self._profile:
            return fn
        timers = self._timers
        timers.setdefault(name, 0.0)
        clock = time.perf_counter

        def wrapper(t_ns: int) -> None:
            start = clock()
            fn(t_ns)
            timers[name] += clock() - start

        return wrapper

    def _setup_publishers(self) -> None:
        robot, sc, bus = self.robot, self.scenario, self.bus
        assert robot.drive is not None
        add = self.scheduler.add

        # Latched, once at t = 0: the robot's fixed frames and its description.
        static_pairs = [("map", "odom")]
        static_poses = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)]
        for frame in robot.frames:
            if frame.joint_type is JointType.FIXED:
                static_pairs.append((frame.parent, frame.name))
                static_poses.append(_tf_pose(frame.T_parent))
        tf_static = bus.advertise("/tf_static", TFEncoder.msgtype)
        description = bus.advertise("/robot_description", StringEncoder.msgtype)
        static_encoder = TFEncoder(static_pairs)
        urdf = urdf_from_robot(robot)

        def publish_static(t_ns: int) -> None:
            tf_static.publish(t_ns, static_encoder.encode(t_ns, static_poses))
            description.publish(t_ns, StringEncoder().encode(urdf))

        self.scheduler.once("static", publish_static, at_k=0, priority=_P_STATE)

        # Mission: the tree at its rate, the controller's cmd_vel at its rate. The mission steers on
        # the pose the robot believes (the EKF's, odom = map here; the ground truth without EKF).
        cmd_pub = bus.advertise("/cmd_vel", TwistEncoder.msgtype)
        twist = TwistEncoder()
        chassis_now, ekf, mission_obj = self.drive.chassis_state, self._ekf, self.mission
        if isinstance(mission_obj, TreeMission):
            self._setup_tree(mission_obj)

        def mission(t_ns: int) -> None:
            if ekf is not None:
                e = ekf.estimate
                v, w = mission_obj.command(t_ns, e.x_m, e.y_m, e.yaw_rad)
            else:
                s = chassis_now()
                v, w = mission_obj.command(t_ns, s.x_m, s.y_m, s.yaw_rad)
            self.drive.set_cmd_vel(v, w)
            cmd_pub.publish(t_ns, twist.encode(v, w))

        rate = sc.mission.controller_rate_hz if isinstance(sc.mission, BehaviorTreeMission) else sc.mission.rate_hz
        add("mission", rate, self._timed("mission", mission), priority=_P_MISSION)

        # Lidar.
        if self.lidar is not None and robot.lidar is not None:
            geo = self.lidar.geometry
            scan_pub = bus.advertise("/scan", ScanEncoder.msgtype)
            scan_enc = ScanEncoder(
                robot.lidar.frame_id,
                angle_min_rad=geo.angle_min_rad,
                angle_max_rad=geo.angle_max_rad,
                angle_increment_rad=geo.angle_increment_rad,
                time_increment_s=geo.time_increment_s,
                scan_time_s=geo.scan_time_s,
                range_min_m=geo.range_min_m,
                range_max_m=geo.range_max_m,
                samples=geo.num_ranges,
            )
            lidar, chassis = self.lidar, self.drive.chassis_state

            def scan(t_ns: int) -> None:
                s = chassis()
                scan_pub.publish(t_ns, scan_enc.encode(t_ns, lidar.scan(s.x_m, s.y_m, s.yaw_rad)))

            add("lidar", robot.lidar.rate_hz, self._timed("lidar", scan), priority=_P_SENSOR)

        # Wheel encoders -> /joint_states and the wheels' transforms (robot_state_publisher publishes
        # them on each), then the EKF fuses them with the gyro into /odom and odom -> base_footprint.
        if len(self._wheels) == 2:
            self._setup_odometry()

        # Ground truth, in the world (= map) frame, for analysis.
        truth_pub = bus.advertise("/ground_truth/odom", OdometryEncoder.msgtype)
        truth_enc = OdometryEncoder("map", robot.base_frame)
        chassis = self.drive.chassis_state

        def ground_truth(t_ns: int) -> None:
            s = chassis()
            truth_pub.publish(t_ns, truth_enc.encode(t_ns, s.x_m, s.y_m, s.yaw_rad, s.v_mps, s.yaw_rate_radps))

        add(
            "ground_truth",
            sc.sensors.ground_truth.rate_hz,
            self._timed("ground_truth", ground_truth),
            priority=_P_STATE,
        )

        # IMU -> /imu, and its yaw rate to the EKF.
        if self._imu is not None:
            imu, ekf = self._imu, self._ekf
            imu_pub = bus.advertise("/imu", ImuEncoder.msgtype)
            imu_enc = ImuEncoder(
                imu.spec.frame_id,
                orientation_covariance=imu.orientation_covariance,
                angular_velocity_covariance=imu.angular_velocity_covariance,
                linear_acceleration_covariance=imu.linear_acceleration_covariance,
            )
            add_gyro = ekf.add_gyro if ekf is not None and sc.estimation.fuse_gyro else None
            sample, encode_imu, publish_imu = imu.sample, imu_enc.encode, imu_pub.publish

            # The gyro reports its mean rate over each sample period (an integrating MEMS gyro behind
            # its low-pass filter), so its samples add up to the true heading change; the EKF
            # integrates them by the rectangle rule (`gyro_samples="interval_mean"`).
            last_t_ns, last_yaw = 0, self.scenario.robot.initial_pose.yaw_rad

            def imu_sample(t_ns: int) -> None:
                nonlocal last_t_ns, last_yaw
                s = chassis()
                yaw, dt_ns = s.yaw_rad, t_ns - last_t_ns
                rate = math.remainder(yaw - last_yaw, math.tau) * 1e9 / dt_ns if dt_ns > 0 else s.yaw_rate_radps
                last_t_ns, last_yaw = t_ns, yaw
                r = sample(yaw, rate, s.yaw_accel_radps2, s.ax_mps2, s.ay_mps2)
                publish_imu(t_ns, encode_imu(t_ns, *r))
                if add_gyro is not None:
                    add_gyro(t_ns, r.angular_velocity_z)

            add("imu", imu.spec.rate_hz, self._timed("imu", imu_sample), priority=_P_SENSOR)

        # Motor signals of an FMU drive: voltage, current, torque and speed per wheel.
        if isinstance(self.drive, FmuDrivetrain) and len(self._wheels) == 2:
            motor_pub = bus.advertise("/motor_state", MotorStateEncoder.msgtype)
            motor_enc = MotorStateEncoder([w[0] for w in self._wheels])
            wheel_signals = self.drive.wheel_state
            fmu_drive = self.drive

            def motors(t_ns: int) -> None:
                ws = wheel_signals()
                saturated = (fmu_drive.saturation.active,) * 2
                motor_pub.publish(
                    t_ns,
                    motor_enc.encode(
                        t_ns,
                        ws.voltage_v,
                        ws.current_a,
                        ws.effort_nm,
                        ws.speed_radps,
                        velocity_command_rad_s=fmu_drive.command_radps,
                        saturated=saturated,
                    ),
                )

            rate = robot.joint_states.rate_hz if robot.joint_states is not None else 30.0
            add("motor_state", rate, self._timed("motor_state", motors), priority=_P_STATE)

        # Contacts, as events when they begin and end.
        self._contact_pub = bus.advertise("/contacts", ContactEncoder.msgtype)
        self._contact_enc = ContactEncoder("map")

        # Clock.
        clock_pub = bus.advertise("/clock", ClockEncoder.msgtype)
        clock_enc = ClockEncoder()

        def clock(t_ns: int) -> None:
            clock_pub.publish(t_ns, clock_enc.encode(t_ns))

        add("clock", sc.sensors.clock.rate_hz, self._timed("clock", clock), priority=_P_CLOCK)

    def _setup_tree(self, mission: TreeMission) -> None:
        bt_pub = self.bus.advertise("/behavior_tree_log", BehaviorTreeLogEncoder.msgtype)
        bt_enc = BehaviorTreeLogEncoder()
        plan_pub = self.bus.advertise("/plan", PathEncoder.msgtype)
        plan_enc = PathEncoder("map")
        navigator = mission.navigator
        plans = [0]

        def tick(t_ns: int) -> None:
            changes = mission.tick(t_ns)
            if changes:
                events = [(c.t_ns, mission.node_name(c.uid), c.prev.name, c.new.name) for c in changes]
                bt_pub.publish(t_ns, bt_enc.encode(t_ns, events))
            if navigator.plans != plans[0]:
                plans[0] = navigator.plans
                if navigator.path:
                    plan_pub.publish(t_ns, plan_enc.encode(t_ns, [(x, y, 0.0) for x, y in navigator.path]))

        assert isinstance(self.scenario.mission, BehaviorTreeMission)
        self.scheduler.add(
            "tree", self.scenario.mission.tick_rate_hz, self._timed("tree", tick), priority=_P_MISSION - 5
        )

    def _setup_odometry(self) -> None:
        robot, bus = self.robot, self.bus
        assert robot.drive is not None and self._encoders is not None
        names = [w[0] for w in self._wheels]
        with_effort = isinstance(self.drive, FmuDrivetrain)
        joint_pub = bus.advertise("/joint_states", JointStateEncoder.msgtype)
        joint_enc = JointStateEncoder(names, with_effort=with_effort)
        tf_pub = bus.advertise("/tf", TFEncoder.msgtype)
        wheel_tf = TFEncoder([(w[1], w[2]) for w in self._wheels])
        left, right = (_JointTransform(w[3], w[4]) for w in self._wheels)
        odom_pub = bus.advertise("/odom", OdometryEncoder.msgtype)
        odom_enc = OdometryEncoder("odom", robot.base_frame)
        odom_tf = TFEncoder([("odom", robot.base_frame)])
        wheel_state, encoders, ekf = self.drive.wheel_state, self._encoders, self._ekf

        def joints(t_ns: int, ws: WheelState) -> tuple[float, float]:
            if ekf is None:  # Gazebo's joint states: the exact joint angles and speeds
                positions, velocities = ws.angle_rad, ws.speed_radps
            else:
                js = encoders.read(t_ns, ws.angle_rad[0], ws.angle_rad[1])
                positions = (js.position_left_rad, js.position_right_rad)
                velocities = (js.velocity_left, js.velocity_right)
            if with_effort:
                joint_pub.publish(t_ns, joint_enc.encode(t_ns, positions, velocities, ws.effort_nm))
            else:
                joint_pub.publish(t_ns, joint_enc.encode(t_ns, positions, velocities))
            tf_pub.publish(t_ns, wheel_tf.encode(t_ns, (left.at(positions[0]), right.at(positions[1]))))
            return positions[0], positions[1]

        if ekf is None:
            cov = np.diag(_ODOM_COV)
            truth_enc = OdometryEncoder("odom", robot.base_frame, pose_covariance=cov, twist_covariance=cov)
            chassis = self.drive.chassis_state

            def odometry(t_ns: int) -> None:
                joints(t_ns, wheel_state())
                s = chassis()
                odom_pub.publish(t_ns, truth_enc.encode(t_ns, s.x_m, s.y_m, s.yaw_rad, s.v_mps, s.yaw_rate_radps))
                tf_pub.publish(t_ns, odom_tf.encode_planar(t_ns, s.x_m, s.y_m, s.yaw_rad))

        else:
            add_wheel_positions, encode_odom, encode_tf = (
                ekf.add_wheel_positions,
                odom_enc.encode,
                odom_tf.encode_planar,
            )

            def odometry(t_ns: int) -> None:
                _, x, y, yaw, v, yaw_rate, _, pose_cov, twist_cov = add_wheel_positions(
                    t_ns, *joints(t_ns, wheel_state())
                )
                odom_pub.publish(t_ns, encode_odom(t_ns, x, y, yaw, v, yaw_rate, pose_cov, twist_cov))
                tf_pub.publish(t_ns, encode_tf(t_ns, x, y, yaw))

        self.scheduler.add(
            "odometry", self._encoders.spec.rate_hz, self._timed("odometry", odometry), priority=_P_STATE
        )

    # -- contact ---------------------------------------------------------------------------------

    def _touches(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        contacts = self._monitor.check(x_m, y_m, yaw_rad)
        if contacts:
            if not self._in_contact:
                self._in_contact = True
                self._contact = contacts
                self._touching = True
            return True
        return False

    def _track_contact(self, t_ns: int) -> None:
        """Report a contact's beginning, and its end once the robot is clear of it again."""
        s = self.drive.chassis_state()
        if not self._reported:
            self._report_contact(t_ns, begin=True)
            self._reported = True
            self._release_from = (s.x_m, s.y_m)
            return
        if s.blocked:
            self._release_from = (s.x_m, s.y_m)
            return
        x0, y0 = self._release_from
        if math.hypot(s.x_m - x0, s.y_m - y0) >= _CONTACT_RELEASE_M:
            self._report_contact(t_ns, begin=False)
            self._in_contact = self._touching = self._reported = False

    def _report_contact(self, t_ns: int, *, begin: bool) -> None:
        c = self._contact[0]
        event = ContactEncoder.BEGIN if begin else ContactEncoder.END
        self._contact_pub.publish(
            t_ns,
            self._contact_enc.encode(
                t_ns,
                event,
                robot_collision=c.robot_link,
                world_collision=f"{c.model}::{c.link}::{c.collision}",
                position_m=c.point,
                normal=c.normal,
                depth_m=c.depth_m,
            ),
        )
        if begin:
            self.contacts += 1
            _log.warning("t=%.3f s: contact with %s::%s; the robot stops", ns_to_s(t_ns), c.model, c.link)
        else:
            _log.info("t=%.3f s: contact with %s::%s ended", ns_to_s(t_ns), c.model, c.link)

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
            TwinError: From any subsystem; the bag stays readable (close it with `close`).
        """
        logging.getLogger("twin").addHandler(self._rosout)
        _log.info(
            "scenario %s: world %s, robot %s, seed %d",
            self.scenario.name,
            self.scenario.world.sdf.name,
            self.robot.name,
            self.scenario.seed,
        )
        scheduler, drive, end_k = self.scheduler, self.drive, self.end_k
        mission, run_to_limit = self.mission, self._run_to_limit
        advance = drive.advance
        steps_per_s = NS_PER_S // self.step_ns
        next_report = 0
        ended_by = "duration" if run_to_limit else "max_duration_s reached before the mission ended"
        timers = self._timers
        clock = time.perf_counter
        drive_s = 0.0
        wall0 = clock()
        k = 0
        while True:
            due = scheduler.next_due()
            due = min(due, end_k)
            if due > k:
                if self._profile:
                    start = clock()
                    advance(due - k)
                    drive_s += clock() - start
                else:
                    advance(due - k)
                k = due
                self._k = k
                if self._touching:
                    self._track_contact(k * self.step_ns)
            if k >= end_k:
                break
            scheduler.fire_due(k)
            if mission.done and not run_to_limit:
                end_k = k  # the mission is over: this step's publications are the last
                ended_by = "mission complete"
            if k >= next_report:
                if should_stop():
                    ended_by = "interrupted"
                    break
                if progress is not None:
                    progress(k / steps_per_s, self.bus.message_count)
                next_report = k + steps_per_s
        wall_s = clock() - wall0
        sim_s = k * self.step_ns / NS_PER_S
        breakdown = dict(timers)
        if self._profile:
            breakdown["drive"] = drive_s
            breakdown["setup"] = self._setup_s
        _log.info("run ended (%s) at t=%.3f s", ended_by, sim_s)
        return RunSummary(
            scenario=self.scenario.name,
            bag_path=self.recorder.path,
            storage=self.scenario.recording.storage,
            sim_s=sim_s,
            wall_s=wall_s,
            real_time_factor=sim_s / wall_s if wall_s > 0 else math.inf,
            messages=self.bus.message_count,
            topics={name: pub.count for name, pub in self.bus.publishers.items()},
            contacts=self.contacts,
            ended_by=ended_by,
            mission_result=self.mission.result,
            seed=self.scenario.seed,
            breakdown_s=breakdown,
            drive=self.drive.label,
            drive_notes=self.drive.saturation.describe() if isinstance(self.drive, FmuDrivetrain) else "",
        )
