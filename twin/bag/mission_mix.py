"""A synthetic recording with the default mission's topics, types and rates.

The values are plausible but made up (a TurtleBot3 driving a slow circle in a square room); what
matters is that every topic type the twin records is there at its real rate and size. Reader
checks, the kill test and the recording benchmark use it; it also makes a handy sample bag:

```python
with Recorder("/tmp/sample_bag") as rec:
    MissionMix(rec).run(10_000_000_000)  # 10 simulated seconds
```
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from twin.bag import encoders as enc
from twin.bag.recorder import Recorder, TopicHandle

__all__ = ["MIX_RATES_HZ", "MissionMix", "lds01_scan_encoder"]

_NS = 1_000_000_000

#: Publications per simulated second in the default mission (TB3_FACTS §7.4 and ARCHITECTURE).
MIX_RATES_HZ: dict[str, float] = {
    "/clock": 100.0,
    "/imu": 200.0,
    "/tf": 30.0,  # odom -> base_footprint
    "/tf#wheels": 30.0,  # robot_state_publisher's wheel transforms, also on /tf
    "/odom": 30.0,
    "/ground_truth/odom": 30.0,
    "/joint_states": 30.0,
    "/motor_state": 30.0,
    "/scan": 5.0,
    "/amcl_pose": 2.0,  # per filter update: every 0.25 m or 0.2 rad of motion (TB3_FACTS §4.1)
    "/particle_cloud": 2.0,  # likewise; 500 to 2000 particles
    "/tf#amcl": 5.0,  # map -> odom on every scan, also on /tf
    "/cmd_vel": 10.0,
    "/plan": 1.0,
    "/behavior_tree_log": 2.0,
    "/rosout": 0.5,
}

_URDF = """<?xml version="1.0"?>
<robot name="turtlebot3_waffle">
  <link name="base_footprint"/>
  <link name="base_link"/>
  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>
    <origin xyz="0 0 0.010" rpy="0 0 0"/></joint>
</robot>
"""


def lds01_scan_encoder() -> enc.ScanEncoder:
    """A scan encoder with the TurtleBot3 LDS-01 geometry as Gazebo publishes it (TB3_FACTS §2.1)."""
    return enc.ScanEncoder(
        "base_scan",
        angle_min_rad=0.0,
        angle_max_rad=6.28,
        angle_increment_rad=0.0175,
        time_increment_s=0.0,
        scan_time_s=0.0,
        range_min_m=0.12,
        range_max_m=3.5,
        samples=360,
    )


@dataclass(frozen=True, kw_only=True, slots=True)
class _Emitter:
    topic: str
    period_ns: int
    emit: Callable[[int], None]


class MissionMix:
    """Registers the mission's topics on a recorder and writes them at their rates.

    Args:
        recorder: An open recorder.
        particles: Particles per `/particle_cloud` message.
        path_poses: Poses per `/plan`.
        on_write: Called with `(topic, t_ns)` after each message is handed to the recorder.
    """

    def __init__(
        self,
        recorder: Recorder,
        *,
        particles: int = 500,
        path_poses: int = 120,
        on_write: Callable[[str, int], None] | None = None,
    ) -> None:
        self.recorder = recorder
        self._on_write = on_write
        self._rng = np.random.default_rng(0)
        self.counts: dict[str, int] = {}
        rec = recorder
        add = rec.add_topic
        self.handles: dict[str, TopicHandle] = {
            "/clock": add("/clock", enc.ClockEncoder.msgtype),
            "/tf": add("/tf", enc.TFEncoder.msgtype),
            "/tf_static": add("/tf_static", enc.TFEncoder.msgtype),
            "/robot_description": add("/robot_description", enc.StringEncoder.msgtype),
            "/map": add("/map", enc.OccupancyGridEncoder.msgtype),
            "/imu": add("/imu", enc.ImuEncoder.msgtype),
            "/odom": add("/odom", enc.OdometryEncoder.msgtype),
            "/ground_truth/odom": add("/ground_truth/odom", enc.OdometryEncoder.msgtype),
            "/joint_states": add("/joint_states", enc.JointStateEncoder.msgtype),
            "/motor_state": add("/motor_state", enc.MotorStateEncoder.msgtype),
            "/scan": add("/scan", enc.ScanEncoder.msgtype),
            "/amcl_pose": add("/amcl_pose", enc.PoseWithCovarianceStampedEncoder.msgtype),
            "/particle_cloud": add("/particle_cloud", enc.ParticleCloudEncoder.msgtype),
            "/cmd_vel": add("/cmd_vel", enc.TwistEncoder.msgtype),
            "/plan": add("/plan", enc.PathEncoder.msgtype),
            "/goal_pose": add("/goal_pose", enc.PoseStampedEncoder.msgtype),
            "/behavior_tree_log": add("/behavior_tree_log", enc.BehaviorTreeLogEncoder.msgtype),
            "/rosout": add("/rosout", enc.LogEncoder.msgtype),
            "/contact": add("/contact", enc.ContactEncoder.msgtype),
        }
        wheels = ("wheel_left_joint", "wheel_right_joint")
        self._clock = enc.ClockEncoder()
        self._tf_odom = enc.TFEncoder([("odom", "base_footprint")])
        self._tf_map = enc.TFEncoder([("map", "odom")])
        self._tf_wheels = enc.TFEncoder([("base_link", "wheel_left_link"), ("base_link", "wheel_right_link")])
        self._tf_static = enc.TFEncoder(
            [("base_footprint", "base_link"), ("base_link", "imu_link"), ("base_link", "base_scan")]
        )
        self._imu = enc.ImuEncoder(
            "imu_link",
            orientation_covariance=np.diag([1e-6] * 3),
            angular_velocity_covariance=np.diag([4e-8] * 3),
            linear_acceleration_covariance=np.diag([2.89e-4] * 3),
        )
        odom_cov = np.diag([1e-5, 1e-5, 1e12, 1e12, 1e12, 1e-3])
        self._odom = enc.OdometryEncoder("odom", "base_footprint", pose_covariance=odom_cov, twist_covariance=odom_cov)
        self._truth = enc.OdometryEncoder("world", "base_footprint")
        self._joints = enc.JointStateEncoder(wheels)
        self._motors = enc.MotorStateEncoder(wheels)
        self._scan = lds01_scan_encoder()
        self._amcl = enc.PoseWithCovarianceStampedEncoder("map", covariance=np.diag([0.05, 0.05, 0, 0, 0, 0.02]))
        self._cloud = enc.ParticleCloudEncoder("map")
        self._twist = enc.TwistEncoder()
        self._path = enc.PathEncoder("map")
        self._goal = enc.PoseStampedEncoder("map")
        self._bt = enc.BehaviorTreeLogEncoder()
        self._log = enc.LogEncoder("twin")
        self._contact = enc.ContactEncoder("odom")
        self._string = enc.StringEncoder()
        self._grid = enc.OccupancyGridEncoder("map", 0.05, 200, 160, (-5.0, -4.0, 0.0))
        self._particles = particles
        self._path_poses = path_poses
        self._beam_angles = np.arange(360, dtype=np.float64) * 0.0175
        self._emitters = [
            _Emitter(topic=topic.split("#")[0], period_ns=round(_NS / rate), emit=getattr(self, _EMITTERS[topic]))
            for topic, rate in MIX_RATES_HZ.items()
        ]

    # -- values: a robot circling at 0.2 m/s with a 1 m radius -------------------------------------

    @staticmethod
    def pose_at(t_ns: int) -> tuple[float, float, float]:
        """`(x, y, yaw)` of the robot at `t_ns`."""
        angle = 0.2 * t_ns / _NS
        return math.cos(angle), math.sin(angle), angle + math.pi / 2

    def _write(self, topic: str, t_ns: int, data: bytes) -> None:
        self.recorder.write(self.handles[topic], t_ns, data)
        self.counts[topic] = self.counts.get(topic, 0) + 1
        if self._on_write is not None:
            self._on_write(topic, t_ns)

    def _emit_clock(self, t: int) -> None:
        self._write("/clock", t, self._clock.encode(t))

    def _emit_imu(self, t: int) -> None:
        _, _, yaw = self.pose_at(t)
        self._write(
            "/imu",
            t,
            self._imu.encode(t, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2), 0.0, 0.0, 0.2, 0.0, 0.04, 9.81),
        )

    def _emit_tf(self, t: int) -> None:
        x, y, yaw = self.pose_at(t)
        self._write("/tf", t, self._tf_odom.encode_planar(t, x, y, yaw))

    def _emit_tf_wheels(self, t: int) -> None:
        a = 0.2 * t / _NS / 0.033
        s, c = math.sin(a / 2), math.cos(a / 2)
        poses = ((0.0, 0.144, 0.023, 0.0, s, 0.0, c), (0.0, -0.144, 0.023, 0.0, s, 0.0, c))
        self._write("/tf", t, self._tf_wheels.encode(t, poses))

    def _emit_tf_amcl(self, t: int) -> None:
        self._write("/tf", t, self._tf_map.encode(t, ((0.01, -0.02, 0.0, 0.0, 0.0, 0.0, 1.0),)))

    def _emit_odom(self, t: int) -> None:
        x, y, yaw = self.pose_at(t)
        self._write("/odom", t, self._odom.encode(t, x, y, yaw, 0.2, 0.2))

    def _emit_truth(self, t: int) -> None:
        x, y, yaw = self.pose_at(t)
        self._write("/ground_truth/odom", t, self._truth.encode(t, x, y, yaw, 0.2, 0.2))

    def _emit_joints(self, t: int) -> None:
        a = 0.2 * t / _NS / 0.033
        self._write("/joint_states", t, self._joints.encode(t, (a * 0.9, a * 1.1), (5.45, 6.66)))

    def _emit_motors(self, t: int) -> None:
        self._write("/motor_state", t, self._motors.encode(t, (4.1, 4.9), (0.31, 0.35), (0.021, 0.024), (5.45, 6.66)))

    def _emit_scan(self, t: int) -> None:
        ranges = (2.0 + 0.5 * np.cos(self._beam_angles + 0.2 * t / _NS)).astype(np.float32)
        ranges[::37] = np.inf
        self._write("/scan", t, self._scan.encode(t, ranges))

    def _emit_amcl(self, t: int) -> None:
        x, y, yaw = self.pose_at(t)
        self._write("/amcl_pose", t, self._amcl.encode(t, x + 0.01, y - 0.02, yaw))

    def _emit_cloud(self, t: int) -> None:
        x, y, yaw = self.pose_at(t)
        spread = self._rng.normal(0.0, 0.05, size=(self._particles, 3))
        poses = spread + np.array([x, y, yaw])
        self._write("/particle_cloud", t, self._cloud.encode(t, poses, np.full(self._particles, 1 / self._particles)))

    def _emit_cmd_vel(self, t: int) -> None:
        self._write("/cmd_vel", t, self._twist.encode(0.2, 0.2))

    def _emit_plan(self, t: int) -> None:
        s = np.linspace(0.0, 1.0, self._path_poses)
        angle = 0.2 * t / _NS + s
        poses = np.column_stack((np.cos(angle), np.sin(angle), angle + math.pi / 2))
        self._write("/plan", t, self._path.encode(t, poses))

    def _emit_bt(self, t: int) -> None:
        events = [(t, "GoToPose", "IDLE", "RUNNING"), (t, "NavigateToPose", "RUNNING", "SUCCESS")]
        self._write("/behavior_tree_log", t, self._bt.encode(t, events))

    def _emit_rosout(self, t: int) -> None:
        text = f"reached waypoint {t // (2 * _NS)}"
        self._write(
            "/rosout", t, self._log.encode(t, enc.LogEncoder.INFO, text, file="mission.py", function="tick", line=42)
        )

    def _emit_once(self, t: int) -> None:
        """The latched and one-off messages, at the start."""
        self._write("/robot_description", t, self._string.encode(_URDF))
        static = ((0.0, 0.0, 0.010, 0.0, 0.0, 0.0, 1.0), (-0.032, 0.0, 0.068, 0.0, 0.0, 0.0, 1.0))
        self._write("/tf_static", t, self._tf_static.encode(t, (*static, (-0.064, 0.0, 0.122, 0.0, 0.0, 0.0, 1.0))))
        cells = np.zeros((160, 200), dtype=np.int8)
        cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
        cells[40:60, 50:70] = -1
        self._write("/map", t, self._grid.encode(t, cells))
        self._write("/goal_pose", t, self._goal.encode(t, 1.5, 0.5, 0.0))

    def _emit_contact(self, t: int) -> None:
        x, y, _ = self.pose_at(t)
        data = self._contact.encode(
            t,
            enc.ContactEncoder.BEGIN,
            robot_collision="base_footprint",
            world_collision="wall::link::collision",
            position_m=(x, y, 0.05),
            normal=(-1.0, 0.0, 0.0),
            depth_m=0.002,
        )
        self._write("/contact", t, data)

    # -- scheduling -------------------------------------------------------------------------------

    def schedule(self, duration_ns: int) -> Iterator[tuple[int, Callable[[int], None]]]:
        """`(t_ns, emit)` for every publication in `[0, duration_ns)`, in time order."""
        yield 0, self._emit_once
        if duration_ns > _NS:
            yield _NS, self._emit_contact
        heap = [(0, i) for i in range(len(self._emitters))]
        heapq.heapify(heap)
        counters = [0] * len(self._emitters)
        while heap:
            t, i = heapq.heappop(heap)
            if t >= duration_ns:
                continue
            yield t, self._emitters[i].emit
            counters[i] += 1
            heapq.heappush(heap, (counters[i] * self._emitters[i].period_ns, i))

    def run(self, duration_ns: int) -> int:
        """Write every publication of `[0, duration_ns)`; return the number of messages."""
        before = sum(self.counts.values())
        for t, emit in self.schedule(duration_ns):
            emit(t)
        return sum(self.counts.values()) - before


_EMITTERS = {
    "/clock": "_emit_clock",
    "/imu": "_emit_imu",
    "/tf": "_emit_tf",
    "/tf#wheels": "_emit_tf_wheels",
    "/odom": "_emit_odom",
    "/ground_truth/odom": "_emit_truth",
    "/joint_states": "_emit_joints",
    "/motor_state": "_emit_motors",
    "/scan": "_emit_scan",
    "/amcl_pose": "_emit_amcl",
    "/particle_cloud": "_emit_cloud",
    "/tf#amcl": "_emit_tf_amcl",
    "/cmd_vel": "_emit_cmd_vel",
    "/plan": "_emit_plan",
    "/behavior_tree_log": "_emit_bt",
    "/rosout": "_emit_rosout",
}
