"""nav2_amcl on the node graph: AMCL itself, and the initial-pose publisher that starts it.

- `InitialPoseNode` publishes one `/initialpose` at start (what the thesis's
  `set_init_amcl_pose.py` does), once AMCL subscribes.
- `AmclNode` runs the particle filter on `/scan` with the odometry pose at the scan's stamp
  (interpolated between the `/odom` messages around it, as tf2 would) and publishes `/particle_cloud`
  per filter update, `/amcl_pose` when it resampled (and first), map→odom on `/tf` on every scan,
  stamped scan time + transform_tolerance (TB3_FACTS §4.8).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag import ParticleCloudEncoder, PoseWithCovarianceStampedEncoder, TFEncoder
from twin.core.errors import TwinError
from twin.nav.amcl.filter import Amcl
from twin.nav.frames import Frames
from twin.node import Encoded, Node, QoSProfile, in_robot_namespace

__all__ = ["AmclNode", "InitialPoseNode"]

Pose = tuple[float, float, float]
LATCHED = QoSProfile(depth=1, durability="transient_local")


class InitialPoseNode(Node):
    """Publishes one `/initialpose` (frame map) as soon as something subscribes, as the thesis's node does."""

    def __init__(self, pose: tuple[float, float, float], *, xy_variance_m2: float, yaw_variance_rad2: float) -> None:
        super().__init__("initial_pose")
        pub = self.create_publisher(PoseWithCovarianceStampedEncoder.msgtype, "initialpose", 10)
        encode = PoseWithCovarianceStampedEncoder("map").encode
        log = self.get_logger()
        now = self._graph_now
        x, y, yaw = pose

        def on_timer() -> None:
            if pub.get_subscription_count() == 0:
                return
            cov = [0.0] * 36
            cov[0] = cov[7] = xy_variance_m2
            cov[35] = yaw_variance_rad2
            # in process: (x, y, yaw, covariance, frame), as AMCL's subscription reads it
            pub.publish(Encoded((encode, (now(), x, y, yaw, cov), (x, y, yaw, cov, "map"))))
            log.info(f"initial pose sent: x={x:.3f}, y={y:.3f}, yaw={yaw:.3f}")
            timer.cancel()

        timer = self.create_timer(0.1, on_timer)
        self.timer = timer


def _pose_of(msg: Any) -> tuple[float, float, float, list[float], str]:
    if type(msg) is Encoded:
        x, y, yaw, cov, frame = msg[2]
        return x, y, yaw, list(cov), frame
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return float(p.x), float(p.y), yaw, [float(c) for c in msg.pose.covariance], str(msg.header.frame_id)


class AmclNode(Node):
    """Nav2's AMCL on the node graph (see the module docstring)."""

    def __init__(
        self,
        amcl: Amcl,
        frames: Frames,
        *,
        odom_frame: str = "odom",
        global_frame: str = "map",
        transform_tolerance_s: float = 1.0,
        on_estimate: Callable[[int, Pose, Pose], None] | None = None,
        truth: Callable[[], Pose] | None = None,
        lidar_topic: str = "scan",
    ) -> None:
        super().__init__("amcl")
        self.amcl = amcl
        self.updates = 0
        log = self.get_logger()
        pose_encode = PoseWithCovarianceStampedEncoder(global_frame).encode
        cloud_encode = ParticleCloudEncoder(global_frame).encode
        tf_encode = TFEncoder([(global_frame, odom_frame)]).encode_planar
        pose_pub = self.create_publisher(PoseWithCovarianceStampedEncoder.msgtype, "amcl_pose", LATCHED)
        cloud_pub = self.create_publisher(ParticleCloudEncoder.msgtype, "particle_cloud", 10)
        tf_pub = self.create_publisher(TFEncoder.msgtype, "/tf", 10)
        tolerance_ns = round(transform_tolerance_s * 1e9)
        now = self._graph_now
        # (t_ns, pose) of the last two /odom messages, and a scan waiting for the odometry after it.
        odoms: list[tuple[int, tuple[float, float, float]]] = []
        pending: list[tuple[int, NDArray[np.floating], Pose | None]] = []

        def process(t_scan: int, ranges: NDArray[np.floating], odom_pose: Pose, true_pose: Pose | None) -> None:
            estimate = amcl.process_scan(odom_pose, ranges)
            if estimate is not None:
                self.updates += 1
                if on_estimate is not None and true_pose is not None:
                    on_estimate(t_scan, (estimate.x_m, estimate.y_m, estimate.yaw_rad), true_pose)
                frames.map_odom = estimate.map_odom
                frames.localized = True
                pose_pub.publish(
                    Encoded(
                        (
                            pose_encode,
                            (t_scan, estimate.x_m, estimate.y_m, estimate.yaw_rad, estimate.covariance_6x6()),
                            estimate,
                        )
                    )
                )
            if amcl.updated:  # Nav2 publishes the cloud on every filter update, the pose only when it resampled
                poses, weights = amcl.poses.copy(), amcl.weights.copy()
                cloud_pub.publish(Encoded((cloud_encode, (t_scan, poses, weights), (poses, weights))))
            map_odom = amcl.map_odom()
            if map_odom is not None:
                tf_pub.publish(Encoded((tf_encode, (t_scan + tolerance_ns, *map_odom), None)))

        def at(t_ns: int) -> tuple[float, float, float]:
            (t0, p0), (t1, p1) = odoms[0], odoms[-1]
            if t1 <= t0:
                return p1
            f = (t_ns - t0) / (t1 - t0)
            dyaw = (p1[2] - p0[2] + math.pi) % (2.0 * math.pi) - math.pi
            return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * dyaw)

        def on_odom(msg: Any) -> None:
            t_ns = now()
            if unfed[0]:  # every node is on the graph by now
                unfed[0] = False
                if not self.count_publishers(full_topic):
                    log.warn(
                        f"scan_topic {amcl.params.scan_topic!r} is {full_topic}, which nothing publishes (the "
                        f"robot's lidar scans on {lidar_topic}): AMCL gets no scan and never localizes"
                    )
            frames.on_odom(t_ns, msg)
            odoms.append((t_ns, frames.odom_pose))
            if len(odoms) > 2:
                del odoms[0]
            if pending and t_ns >= pending[0][0]:
                t_scan, ranges, true_pose = pending.pop()
                process(t_scan, ranges, at(t_scan), true_pose)

        laser = amcl.laser
        # The params' scan_topic as Nav2 Humble resolves it: relative in AMCL's namespace (TB3's `scan`);
        # absolute as it is, and for a fleet robot under its namespace, as the costmaps' sources.
        scan_topic = amcl.params.scan_topic
        if scan_topic.startswith("/"):
            scan_topic = in_robot_namespace(scan_topic, self.get_namespace().rstrip("/"))
        lidar_topic = self.get_namespace().rstrip("/") + "/" + lidar_topic  # the robot's lidar's scans
        full_topic = self.resolve_topic_name(scan_topic)
        unfed = [full_topic != lidar_topic]  # warn at the first odometry if nothing publishes it
        misfit_warned = [False]

        def fits(msg: Any) -> bool:
            """Whether a node's LaserScan has the lidar's angles (AMCL's beam model takes the lidar's)."""
            if math.isclose(msg.angle_min, laser.angle_min_rad, abs_tol=1e-6) and math.isclose(
                msg.angle_increment, laser.angle_increment_rad, abs_tol=1e-9
            ):
                return True
            if not misfit_warned[0]:
                misfit_warned[0] = True
                log.warn(
                    f"ignoring scans on {full_topic} whose beams are not the lidar's "
                    f"(from {msg.angle_min:g} rad by {msg.angle_increment:g}; the lidar's from "
                    f"{laser.angle_min_rad:g} by {laser.angle_increment_rad:g}): a filter may change ranges, "
                    "not angles"
                )
            return False

        def on_scan(msg: Any) -> None:
            t_ns = now()
            if type(msg) is Encoded:
                ranges = msg[2]
            elif fits(msg):
                ranges = np.asarray(msg.ranges, dtype=np.float64)
            else:
                return
            true_pose = truth() if truth is not None else None
            if odoms and odoms[-1][0] == t_ns:
                process(t_ns, ranges, odoms[-1][1], true_pose)
            else:
                pending[:] = [
                    (t_ns, ranges, true_pose)
                ]  # the filter keeps only the newest scan waiting for its transform

        def on_initial_pose(msg: Any) -> None:
            x, y, yaw, cov, frame = _pose_of(msg)
            if frame not in ("", global_frame):
                log.warn(f"ignoring an initial pose in frame {frame!r}: AMCL takes poses in {global_frame!r}")
                return
            try:
                amcl.set_initial_pose(x, y, yaw, np.asarray(cov))
            except TwinError as err:  # a pose off the map from a user's node: say so, keep running
                log.error(f"initial pose refused: {err}")
                return
            log.info(f"Setting pose ({now() / 1e9:.6f}): {x:.3f} {y:.3f} {yaw:.3f}")
            odoms.clear()
            pending.clear()

        self.create_subscription("nav_msgs/msg/Odometry", "odom", on_odom, 10, raw=True)
        self.create_subscription("sensor_msgs/msg/LaserScan", scan_topic, on_scan, 10, raw=True)
        self.create_subscription(
            "geometry_msgs/msg/PoseWithCovarianceStamped", "initialpose", on_initial_pose, 10, raw=True
        )
