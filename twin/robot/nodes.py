"""The robot's nodes: what Gazebo's plugins and robot_state_publisher are in a ROS 2 system.

Each node reads the simulated robot (the drivetrain's chassis and wheels, the lidar's ray caster)
as a Gazebo plugin reads the physics engine, and talks to everything else only over topics:

| node | publishes | subscribes |
|---|---|---|
| `diff_drive` | `/contacts`, `/motor_state` (FMU drives) | `/cmd_vel` |
| `obstacles` (scenario obstacles) | `/obstacles` | |
| `lidar` | `/scan` | |
| `imu` | `/imu` | |
| `joint_states` | `/joint_states` | |
| `gazebo_odometry` (odometry: ground_truth) | `/odom`, `/tf` odom→base | |
| `ground_truth` | `/ground_truth/odom` | |
| `robot_state_publisher` | `/tf_static`, `/robot_description`, `/tf` (wheels) | `/joint_states` |
| `clock` | `/clock` | |

Built-in nodes publish `Encoded` messages: their fast CDR encoder runs once, for the recorder, and
in-process subscribers read `Encoded.data`, documented per topic below. A message object from a user
node's publisher (a `twin.msgs` class) is read field by field instead.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from twin.bag import (
    ClockEncoder,
    ContactEncoder,
    ImuEncoder,
    JointStateEncoder,
    MarkerArrayEncoder,
    MotorStateEncoder,
    OdometryEncoder,
    ScanEncoder,
    StringEncoder,
    TFEncoder,
)
from twin.core.clock import ns_to_s
from twin.core.geometry import Mat4, quat_from_rpy, rpy_from_matrix
from twin.node import PRIORITY_CLOCK, PRIORITY_SENSOR, PRIORITY_STATE, Encoded, Node, QoSProfile
from twin.node.readers import joint_positions, twist_of
from twin.robot.chassis import ChassisState
from twin.robot.drivetrain import Drivetrain, WheelState
from twin.robot.encoders import EncoderModel
from twin.robot.imu import ImuModel
from twin.robot.lidar import Lidar
from twin.world.obstacles import ObstacleField
from twin.world.scene import Contact

__all__ = [
    "ClockNode",
    "ContactTracker",
    "DiffDriveNode",
    "GazeboOdometryNode",
    "GroundTruthNode",
    "ImuNode",
    "JointStateNode",
    "LidarNode",
    "ObstacleNode",
    "RobotStatePublisher",
    "tf_pose",
]


LATCHED = QoSProfile(depth=1, durability="transient_local")
SENSOR_DATA = QoSProfile(depth=5, reliability="best_effort")

# A contact ends once the robot has moved this far from where the world last refused it.
_CONTACT_RELEASE_M = 0.002

_ODOM_COV = (1e-5, 1e-5, 1e12, 1e12, 1e12, 1e-3)  # gazebo_ros_diff_drive's covariance diagonal

Pose7 = tuple[float, float, float, float, float, float, float]


class ContactMonitor(Protocol):
    """The robot's contact check: the contacts at a pose (`CollisionMonitor`, `ObstacleMonitor`, a fleet's)."""

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the contacts at this pose (empty when free)."""
        ...


class ContactTracker:
    """The robot's contact sensor: asks the world whether a pose touches it, and remembers the episode.

    The drivetrain calls `touches` for every pose it would move to; `ObstacleNode` calls
    `touched_by` when an obstacle moves or appears into the robot. `DiffDriveNode` reports an
    episode's beginning and end on `/contacts`.
    """

    def __init__(self, monitor: ContactMonitor) -> None:
        self.monitor = monitor
        # A monitor's yes-or-no check (a fleet's: no contacts built), for the steps of an open episode.
        self._touching: Callable[[float, float, float], object] = getattr(monitor, "touches", monitor.check)
        self.contact: tuple[Contact, ...] = ()
        self.in_contact = False  # a contact episode is open
        self.pending = False  # the node must track the open episode (after each physics advance)
        self.by_obstacle = False  # the open episode began with an obstacle moving into the robot
        self.released = False  # ... and that obstacle no longer touches it

    def touched_by(self, contacts: tuple[Contact, ...]) -> None:
        """An obstacle moved (or appeared) into the robot: open an episode unless one is open."""
        if contacts and not self.in_contact:
            self.in_contact = self.pending = self.by_obstacle = True
            self.released = False
            self.contact = contacts

    def touches(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        """Whether the robot at this pose touches the world (opens an episode when it starts)."""
        if self.in_contact:  # the episode's contacts are known: whether it touches is all that is asked
            return bool(self._touching(x_m, y_m, yaw_rad))
        contacts = self.monitor.check(x_m, y_m, yaw_rad)
        if contacts:
            if not self.in_contact:
                self.in_contact = True
                self.contact = contacts
                self.pending = True
            return True
        return False


class DiffDriveNode(Node):
    """Gazebo's diff-drive plugin: `/cmd_vel` in, the drivetrain stepped by the executor, contacts out.

    Also the motor signals of an FMU drive on `/motor_state` at `motor_rate_hz`.
    """

    def __init__(
        self,
        drive: Drivetrain,
        tracker: ContactTracker,
        *,
        motor_joints: Sequence[str] = (),
        motor_rate_hz: float = 30.0,
        command_topic: str = "cmd_vel",
        limits: tuple[float, float, float, float] | None = None,
    ) -> None:
        super().__init__("diff_drive")
        self.drive = drive
        self.tracker = tracker
        self.contacts = 0
        self._reported = False
        self._release_from = (0.0, 0.0)
        set_cmd_vel = drive.set_cmd_vel

        def on_cmd_vel(msg: Any) -> None:
            if type(msg) is Encoded:
                set_cmd_vel(*msg[2])
            else:
                set_cmd_vel(*twist_of(msg))

        if limits is not None:  # gz-sim DiffDrive's speed limiter: a command beyond the range is clamped to it
            v_low, v_high, w_low, w_high = limits

            def on_cmd_vel(msg: Any) -> None:  # (NaN passes to the drive, which refuses it)
                v, w = msg[2] if type(msg) is Encoded else twist_of(msg)
                set_cmd_vel(min(max(v, v_low), v_high), min(max(w, w_low), w_high))

        self.create_subscription("geometry_msgs/msg/Twist", command_topic, on_cmd_vel, 10, raw=True)
        if command_topic != "cmd_vel":  # the SDF's plugin renames it: say so if the commands go to cmd_vel
            self._check_commands(command_topic)
        self._contact_pub = self.create_publisher(ContactEncoder.msgtype, "contacts", 10)
        self._contact_enc = ContactEncoder("map")
        if motor_joints and hasattr(drive, "command_radps"):
            self._watch_wheels(drive)
        if motor_joints:
            motor_pub = self.create_publisher(MotorStateEncoder.msgtype, "motor_state", 10)
            encode = MotorStateEncoder(list(motor_joints)).encode
            wheel_state = drive.wheel_state

            saturation = getattr(drive, "saturation", None)

            def motors(t_ns: int) -> None:
                ws = wheel_state()
                extra: dict[str, Any] = {}
                if saturation is not None:  # an FMU drive: the commanded wheel speeds and whether they are reachable
                    extra = {
                        "velocity_command_rad_s": drive.command_radps,  # type: ignore[attr-defined]
                        "saturated": (saturation.active,) * 2,
                    }
                args = (t_ns, ws.voltage_v, ws.current_a, ws.effort_nm, ws.speed_radps)
                motor_pub.publish(Encoded((functools.partial(encode, *args, **extra), (), ws)))

            self.create_rate_timer(motor_rate_hz, motors, priority=PRIORITY_STATE)

        # The executor steps the drivetrain `n_steps` physics steps between events.
        self.advance: Callable[[int], None] = drive.advance

    def _watch_wheels(self, drive: Drivetrain) -> None:
        """Until the wheels first turn: warn once when they stay at exactly 0 through 3 s of commands.

        An FMU whose mapping binds wheel_speed to an output that never moves (or the command to an
        input the model ignores) drove nothing, and the run said so only through Nav2's failures.
        """
        seconds = [0]

        def watch() -> None:
            speeds = drive.wheel_state().speed_radps
            if speeds[0] or speeds[1]:  # they turn: nothing more to watch
                timer.cancel()
                return
            asked = max(abs(w) for w in drive.command_radps)  # type: ignore[attr-defined]
            seconds[0] = seconds[0] + 1 if asked > 0.1 else 0
            if seconds[0] >= 3:
                timer.cancel()
                self.get_logger().warning(
                    f"the wheels have stayed at exactly 0 rad/s through 3 s of commands (now {asked:.2f} rad/s): "
                    "the drive FMU's wheel_speed output never moves, or the command reaches no input the model "
                    "reads; check the mapping's roles with `twin fmu check`"
                )

        timer = self.create_timer(1.0, watch)

    def _check_commands(self, command_topic: str) -> None:
        """One second in, warn once if nothing publishes the drive's topic while something publishes `cmd_vel`."""

        def check() -> None:
            timer.cancel()
            if not self.count_publishers(command_topic) and self.count_publishers("cmd_vel"):
                self.get_logger().warning(
                    f"the diff drive listens on {self.resolve_topic_name(command_topic)} (its SDF plugin's "
                    f"topic), which nothing publishes, while {self.resolve_topic_name('cmd_vel')} has "
                    "publishers: the robot will not move; make the plugin's topic cmd_vel or publish the "
                    "commands where it listens"
                )

        timer = self.create_timer(1.0, check)

    def after_advance(self, t_ns: int) -> None:
        """Report a contact's beginning, and its end once the robot is clear of it again."""
        tracker = self.tracker
        s = self.drive.chassis_state()
        if not self._reported:
            self._report(t_ns, begin=True)
            self._reported = True
            self._release_from = (s.x_m, s.y_m)
            return
        if tracker.released:  # the obstacle that walked into the robot has left it
            self._end(t_ns)
            return
        if s.blocked:
            self._release_from = (s.x_m, s.y_m)
            return
        x0, y0 = self._release_from
        if math.hypot(s.x_m - x0, s.y_m - y0) >= _CONTACT_RELEASE_M:
            self._end(t_ns)

    def _end(self, t_ns: int) -> None:
        tracker = self.tracker
        self._report(t_ns, begin=False)
        tracker.in_contact = tracker.pending = self._reported = False
        tracker.by_obstacle = tracker.released = False

    def _report(self, t_ns: int, *, begin: bool) -> None:
        c = self.tracker.contact[0]
        event = ContactEncoder.BEGIN if begin else ContactEncoder.END
        args = (t_ns, event)
        kwargs: dict[str, Any] = {
            "robot_collision": c.robot_link,
            "world_collision": f"{c.link}::{c.collision}",  # c.link is scoped: model::link
            "position_m": c.point,
            "normal": c.normal,
            "depth_m": c.depth_m,
        }
        self._contact_pub.publish(
            Encoded((functools.partial(self._contact_enc.encode, *args, **kwargs), (), (event, c)))
        )
        log = self.get_logger()  # `[robot1.diff_drive]`: a fleet's robot names itself
        if begin:
            self.contacts += 1
            log.warn(f"t={ns_to_s(t_ns):.3f} s: contact with {c.link}; the robot stops")
        else:
            log.info(f"t={ns_to_s(t_ns):.3f} s: contact with {c.link} ended")


class ObstacleNode(Node):
    """The world's moving parts, as a Gazebo world plugin moves models: the scenario's obstacles.

    On a `rate_hz` grid (from t = 0, before the sensors of the same instant), when the field says
    something may change (`ObstacleField.next_update_ns`), it moves the obstacles to their places,
    reports an obstacle that moved or appeared into the robot as a contact (the robot is not pushed)
    and ends that contact once it has left, and publishes the obstacles present as a
    `visualization_msgs/MarkerArray` on `/obstacles` (latched) when the set changes, and at most
    every `marker_period_s` while one moves (unless `markers` is false: a fleet's other robots).
    Data: the `ObstacleMarker`s.
    """

    def __init__(
        self,
        field: ObstacleField,
        tracker: ContactTracker,
        chassis: Callable[[], ChassisState],
        *,
        rate_hz: float,
        marker_period_s: float = 0.1,
        markers: bool = True,
    ) -> None:
        super().__init__("obstacles")
        # A fleet's robots each track their own contacts; one of them shows the obstacles on /obstacles.
        pub = self.create_publisher(MarkerArrayEncoder.msgtype, "/obstacles", LATCHED) if markers else None
        encode = MarkerArrayEncoder("map").encode
        kinds = {"box": MarkerArrayEncoder.CUBE, "cylinder": MarkerArrayEncoder.CYLINDER}
        marker_period_ns = round(marker_period_s * 1e9)
        next_ns: int | None = 0
        next_marker_ns = 0
        shown = -1  # the field's membership count last published

        def robot_pose() -> tuple[float, float, float]:
            s = chassis()
            return s.x_m, s.y_m, s.yaw_rad

        def on_timer(t_ns: int) -> None:
            nonlocal next_ns, next_marker_ns, shown
            if next_ns is None or t_ns < next_ns:  # nothing appears, vanishes or moves before then
                return
            changed, contacts = field.update(t_ns, robot_pose)
            next_ns = field.next_update_ns(t_ns)
            if contacts:
                tracker.touched_by(contacts)
            elif changed and tracker.by_obstacle and tracker.in_contact:
                tracker.released = True
            if pub is not None and (field.membership != shown or (changed and t_ns >= next_marker_ns)):
                shown = field.membership
                next_marker_ns = t_ns + marker_period_ns
                markers = field.markers()
                rows = [(m.id, kinds[m.shape], m.pose, m.scale, m.color_rgba, m.name) for m in markers]
                pub.publish(Encoded((encode, (t_ns, rows), markers)))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_SENSOR - 5)


class LidarNode(Node):
    """Gazebo's ray sensor plugin: a scan of the world at the lidar's rate on `/scan`. Data: the ranges (float32).

    `topic` is the plugin's (`lidar_topic`: TurtleBot3's `scan`), in the robot's namespace.
    """

    def __init__(
        self, lidar: Lidar, frame_id: str, rate_hz: float, chassis: Callable[[], ChassisState], topic: str = "scan"
    ) -> None:
        super().__init__("lidar")
        geo = lidar.geometry
        encode = ScanEncoder(
            frame_id,
            angle_min_rad=geo.angle_min_rad,
            angle_max_rad=geo.angle_max_rad,
            angle_increment_rad=geo.angle_increment_rad,
            time_increment_s=geo.time_increment_s,
            scan_time_s=geo.scan_time_s,
            range_min_m=geo.range_min_m,
            range_max_m=geo.range_max_m,
            samples=geo.num_ranges,
        ).encode
        pub = self.create_publisher(ScanEncoder.msgtype, topic, SENSOR_DATA)
        scan = lidar.scan

        def on_timer(t_ns: int) -> None:
            s = chassis()
            ranges = scan(s.x_m, s.y_m, s.yaw_rad)
            pub.publish(Encoded((encode, (t_ns, ranges), ranges)))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_SENSOR)


class ImuNode(Node):
    """Gazebo's IMU plugin on `/imu`. Data: (t_ns, reading) with the `ImuModel` reading's fields.

    The gyro reports its mean rate over each sample period (an integrating MEMS gyro behind its
    low-pass filter), so its samples add up to the true heading change.
    """

    def __init__(
        self,
        imu: ImuModel,
        chassis: Callable[[], ChassisState],
        initial_yaw_rad: float,
        *,
        chassis_address: int | None = None,
        topic: str = "imu",
    ) -> None:
        """`chassis_address`: where the compiled drive loop keeps the chassis (see `ImuModel.compiled_sampler`).

        `topic`: the plugin's (TurtleBot3's `imu`), in the robot's namespace.
        """
        super().__init__("imu")
        encoder = ImuEncoder(
            imu.spec.frame_id,
            orientation_covariance=imu.orientation_covariance,
            angular_velocity_covariance=imu.angular_velocity_covariance,
            linear_acceleration_covariance=imu.linear_acceleration_covariance,
        )
        encode = encoder.encode
        pub = self.create_publisher(ImuEncoder.msgtype, topic, SENSOR_DATA)
        compiled = None
        if chassis_address is not None:
            compiled = imu.compiled_sampler(chassis_address, initial_yaw_rad, encoder)
        if compiled is not None:  # the sample and its message in one C call; the same numbers
            sample_compiled = compiled

            def compiled_timer(t_ns: int) -> None:
                reading, data = sample_compiled(t_ns)
                pub.publish(Encoded((bytes, (data,), (t_ns, reading))))

            compiled_timer.__name__ = "on_timer"  # one name in profiles and `twin graph`, either path
            self.create_rate_timer(imu.spec.rate_hz, compiled_timer, priority=PRIORITY_SENSOR)
            return
        sample, remainder, tau = imu.sample, math.remainder, math.tau
        last_t_ns, last_yaw = 0, initial_yaw_rad

        def on_timer(t_ns: int) -> None:  # 200 times a simulated second: everything bound to locals
            nonlocal last_t_ns, last_yaw
            _, _, yaw, _, yaw_rate, ax, ay, yaw_accel, _ = chassis()
            dt_ns = t_ns - last_t_ns
            rate = remainder(yaw - last_yaw, tau) * 1e9 / dt_ns if dt_ns > 0 else yaw_rate
            last_t_ns, last_yaw = t_ns, yaw
            r = sample(yaw, rate, yaw_accel, ax, ay)
            pub.publish(Encoded((encode, (t_ns, *r), (t_ns, r))))

        self.create_rate_timer(imu.spec.rate_hz, on_timer, priority=PRIORITY_SENSOR)


class JointStateNode(Node):
    """Gazebo's joint-state publisher on `/joint_states`: the wheels through their encoders, or exact.

    Data: (t_ns, (left, right) positions rad, (left, right) velocities, efforts or None).
    """

    def __init__(
        self,
        names: Sequence[str],
        rate_hz: float,
        wheel_state: Callable[[], WheelState],
        encoders: EncoderModel | None,
        *,
        with_effort: bool,
        topic: str = "joint_states",
        sides: Sequence[int] | None = None,
    ) -> None:
        super().__init__("joint_states")
        encode: Callable[..., bytes] = JointStateEncoder(list(names), with_effort=with_effort).encode
        pub = self.create_publisher(JointStateEncoder.msgtype, topic, 10)
        if sides is not None:  # several wheel pairs: each joint as its side's wheel of the first pair
            encode = functools.partial(_spread, encode, tuple(sides))

        def on_timer(t_ns: int) -> None:
            ws = wheel_state()
            if encoders is None:  # Gazebo's joint states: the exact joint angles and speeds
                positions, velocities = ws.angle_rad, ws.speed_radps
            else:
                js = encoders.read(t_ns, ws.angle_rad[0], ws.angle_rad[1])
                positions = (js.position_left_rad, js.position_right_rad)
                velocities = (js.velocity_left, js.velocity_right)
            if with_effort:
                pub.publish(
                    Encoded((encode, (t_ns, positions, velocities, ws.effort_nm), (t_ns, positions, velocities)))
                )
            else:
                pub.publish(Encoded((encode, (t_ns, positions, velocities), (t_ns, positions, velocities))))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_STATE)


def _spread(encode: Callable[..., bytes], sides: tuple[int, ...], t_ns: int, *pairs: Any) -> bytes:
    """`encode` with each (left, right) pair of values spread over the joints by their `sides`."""
    return encode(t_ns, *(tuple(pair[side] for side in sides) for pair in pairs))


class GazeboOdometryNode(Node):
    """Gazebo diff drive's perfect odometry (`odometry: ground_truth`): `/odom` (the plugin's topic) and odom→base.

    Data: (x, y, yaw, v, yaw rate) in the odom frame.
    """

    def __init__(
        self, base_frame: str, rate_hz: float, chassis: Callable[[], ChassisState], *, topic: str = "odom"
    ) -> None:
        super().__init__("gazebo_odometry")
        cov = np.diag(_ODOM_COV)
        encode_odom = OdometryEncoder("odom", base_frame, pose_covariance=cov, twist_covariance=cov).encode
        encode_tf = TFEncoder([("odom", base_frame)]).encode_planar
        odom_pub = self.create_publisher(OdometryEncoder.msgtype, topic, 10)
        tf_pub = self.create_publisher(TFEncoder.msgtype, "/tf", 10)

        def on_timer(t_ns: int) -> None:
            s = chassis()
            state = (s.x_m, s.y_m, s.yaw_rad, s.v_mps, s.yaw_rate_radps)
            odom_pub.publish(Encoded((encode_odom, (t_ns, *state), state)))
            tf_pub.publish(Encoded((encode_tf, (t_ns, s.x_m, s.y_m, s.yaw_rad), None)))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_STATE)


class GroundTruthNode(Node):
    """Gazebo's p3d plugin: the true pose on `/ground_truth/odom`, map frame. Data: (x, y, yaw, v, yaw rate)."""

    def __init__(self, base_frame: str, rate_hz: float, chassis: Callable[[], ChassisState]) -> None:
        super().__init__("ground_truth")
        encode = OdometryEncoder("map", base_frame).encode
        pub = self.create_publisher(OdometryEncoder.msgtype, "ground_truth/odom", 10)

        def on_timer(t_ns: int) -> None:
            state = chassis()[:5]  # x, y, yaw, v, yaw rate (a plain tuple)
            pub.publish(Encoded((encode, (t_ns, *state), state)))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_STATE)


class ClockNode(Node):
    """Gazebo's `/clock` at its rate. Data: t_ns."""

    def __init__(self, rate_hz: float) -> None:
        super().__init__("clock")
        encode = ClockEncoder().encode
        pub = self.create_publisher(ClockEncoder.msgtype, "/clock", SENSOR_DATA)

        def on_timer(t_ns: int) -> None:
            pub.publish(Encoded((encode, (t_ns,), t_ns)))

        self.create_rate_timer(rate_hz, on_timer, priority=PRIORITY_CLOCK)


class _JointTransform:
    """The transform of a revolving joint at an angle, as (x, y, z, qx, qy, qz, qw), with no matrices per call."""

    __slots__ = ("_ax", "_ay", "_az", "_q", "_t")

    def __init__(self, T_parent: Mat4, axis: tuple[float, float, float]) -> None:
        self._t = (float(T_parent[0, 3]), float(T_parent[1, 3]), float(T_parent[2, 3]))
        self._q = quat_from_rpy(*rpy_from_matrix(T_parent))
        n = math.sqrt(sum(a * a for a in axis)) or 1.0
        self._ax, self._ay, self._az = (a / n for a in axis)

    def at(self, angle_rad: float) -> Pose7:
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


def tf_pose(T: Mat4) -> Pose7:
    """Return a 4x4 transform as (x, y, z, qx, qy, qz, qw)."""
    qx, qy, qz, qw = quat_from_rpy(*rpy_from_matrix(T))
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), qx, qy, qz, qw)


class RobotStatePublisher(Node):
    """robot_state_publisher: the URDF on `/robot_description`, fixed joints on `/tf_static`, wheels on `/tf`.

    `static` holds (parent, child, pose) of every fixed transform (with map→odom while nothing
    localises the robot); `wheels` holds (joint, parent, child, T_parent, axis) of the revolving
    wheel joints, whose transforms follow each `/joint_states` message.
    """

    def __init__(
        self,
        urdf: str,
        static: Sequence[tuple[str, str, Pose7]],
        wheels: Sequence[tuple[str, str, str, Mat4, tuple[float, float, float]]],
        *,
        joint_states_topic: str = "joint_states",
        more_wheels: Sequence[tuple[tuple[str, str, str, Mat4, tuple[float, float, float]], int]] = (),
    ) -> None:
        super().__init__("robot_state_publisher")
        poses = [pose for _, _, pose in static]
        # A robot with no fixed joint (every link on a moving joint) and a localiser publishing map→odom
        # has no fixed transform to send: nothing goes on /tf_static then.
        static_encoder = TFEncoder([(p, c) for p, c, _ in static]) if static else None
        tf_static = self.create_publisher(TFEncoder.msgtype, "/tf_static", LATCHED)
        description = self.create_publisher(StringEncoder.msgtype, "robot_description", LATCHED)

        def publish_static(t_ns: int) -> None:
            if static_encoder is not None:
                tf_static.publish(Encoded((static_encoder.encode, (t_ns, poses), None)))
            description.publish(Encoded((StringEncoder().encode, (urdf,), urdf)))

        self.create_one_shot(publish_static, priority=PRIORITY_STATE)
        if len(wheels) != 2:
            return
        names = [w[0] for w in wheels]
        encode = TFEncoder([(w[1], w[2]) for w in wheels]).encode
        left, right = (_JointTransform(w[3], w[4]) for w in wheels)
        tf_pub = self.create_publisher(TFEncoder.msgtype, "/tf", 10)
        if more_wheels:  # several wheel pairs: each further wheel turns as its side's of the first pair
            encode = TFEncoder([(w[1], w[2]) for w in wheels] + [(w[1], w[2]) for w, _ in more_wheels]).encode
            more = [(_JointTransform(w[3], w[4]), side) for w, side in more_wheels]

        def on_joint_states(msg: Any) -> None:
            if type(msg) is Encoded:
                t_ns, (pl, pr), _ = msg[2]
            else:
                read = joint_positions(msg, names)
                if read is None:
                    return
                t_ns, (pl, pr) = read
            if more_wheels:
                angles = (pl, pr)
                poses = (left.at(pl), right.at(pr), *(joint.at(angles[side]) for joint, side in more))
                tf_pub.publish(Encoded((encode, (t_ns, poses), None)))
                return
            tf_pub.publish(Encoded((encode, (t_ns, (left.at(pl), right.at(pr))), None)))

        self.create_subscription(JointStateEncoder.msgtype, joint_states_topic, on_joint_states, 10, raw=True)
