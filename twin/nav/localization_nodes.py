"""Nav2's localization side as nodes: map_server, an initial-pose publisher, AMCL, the two costmaps.

- `MapServerNode` publishes `/map` once, latched, as map_server does after loading its YAML.
- `InitialPoseNode` publishes one `/initialpose` at start (what the thesis's
  `set_init_amcl_pose.py` does), once AMCL subscribes.
- `AmclNode` runs the particle filter on `/scan` with the odometry pose at the scan's stamp
  (interpolated between the two `/odom` messages around it, as a tf2 lookup would), publishes
  `/amcl_pose` and `/particle_cloud` when the filter updates, and map→odom on `/tf` on every scan,
  stamped scan time + transform_tolerance (TB3_FACTS §4.8).
- `CostmapNode` updates a costmap at its update_frequency from the latest scan and publishes it as
  an OccupancyGrid on `<name>/costmap` at its publish_frequency, with Nav2's 0..100 translation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag import OccupancyGridEncoder, ParticleCloudEncoder, PoseWithCovarianceStampedEncoder, TFEncoder
from twin.core.errors import TwinError
from twin.nav.amcl import Amcl, LaserGeometry
from twin.nav.costmap import Costmap, scan_observation
from twin.nav.frames import Frames, compose
from twin.nav.map_server import OccupancyMap
from twin.node import PRIORITY_STATE, PRIORITY_USER, Encoded, Node, QoSProfile

__all__ = ["AmclNode", "CostmapNode", "InitialPoseNode", "MapServerNode", "costmap_translation"]

Pose = tuple[float, float, float]
LATCHED = QoSProfile(depth=1, durability="transient_local")


def costmap_translation() -> NDArray[np.int8]:
    """Nav2's cost → OccupancyGrid value table: 0 free, 1..98 scaled, 99 inscribed, 100 lethal, -1 unknown."""
    table = np.zeros(256, dtype=np.int16)
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table.astype(np.int8)


class MapServerNode(Node):
    """Publishes the map on `/map` (transient local), once at t = 0."""

    def __init__(self, occupancy: OccupancyMap) -> None:
        super().__init__("map_server")
        encoder = OccupancyGridEncoder(
            occupancy.frame_id,
            occupancy.resolution_m,
            occupancy.width,
            occupancy.height,
            (occupancy.origin_x_m, occupancy.origin_y_m, occupancy.origin_yaw_rad),
        )
        pub = self.create_publisher(OccupancyGridEncoder.msgtype, "map", LATCHED)
        cells = occupancy.data

        def publish(t_ns: int) -> None:
            pub.publish(Encoded((encoder.encode, (t_ns, cells), occupancy)))

        self.create_one_shot(publish, priority=PRIORITY_STATE)


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
            frames.on_odom(t_ns, msg)
            odoms.append((t_ns, frames.odom_pose))
            if len(odoms) > 2:
                del odoms[0]
            if pending and t_ns >= pending[0][0]:
                t_scan, ranges, true_pose = pending.pop()
                process(t_scan, ranges, at(t_scan), true_pose)

        def on_scan(msg: Any) -> None:
            t_ns = now()
            ranges = msg[2] if type(msg) is Encoded else np.asarray(msg.ranges, dtype=np.float64)
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
        self.create_subscription("sensor_msgs/msg/LaserScan", "scan", on_scan, 10, raw=True)
        self.create_subscription(
            "geometry_msgs/msg/PoseWithCovarianceStamped", "initialpose", on_initial_pose, 10, raw=True
        )


class CostmapNode(Node):
    """One Nav2 costmap (global in map, local rolling in odom) on the node graph (see the module docstring).

    Args:
        name: `global_costmap` or `local_costmap` (the node lives in the namespace of the same name).
        costmap: The costmap.
        frames: Shared transforms.
        laser: The lidar's scan geometry and mount.
        odom_frame: True for a costmap in the odom frame (else map).
    """

    def __init__(self, name: str, costmap: Costmap, frames: Frames, laser: LaserGeometry | None) -> None:
        super().__init__(name, namespace=name)
        self.costmap = costmap
        params = costmap.params
        in_odom = params.global_frame != "map"
        table = costmap_translation()
        pub = self.create_publisher(OccupancyGridEncoder.msgtype, "costmap", LATCHED)
        now = self._graph_now
        latest: list[Any] = [None]
        use_scan = laser is not None and any(
            s.data_type == "LaserScan" for layer in params.obstacle_layers for s in layer.sources
        )

        def on_odom(msg: Any) -> None:
            frames.on_odom(now(), msg)

        def on_scan(msg: Any) -> None:
            latest[0] = msg[2] if type(msg) is Encoded else np.asarray(msg.ranges, dtype=np.float64)

        def robot() -> tuple[float, float, float]:
            return frames.odom_pose if in_odom else frames.map_pose()

        def on_update(t_ns: int) -> None:
            if not in_odom and not frames.localized:
                return
            x, y, yaw = robot()
            observations = []
            ranges = latest[0]
            if ranges is not None and laser is not None:
                latest[0] = None
                sx, sy, syaw = compose((x, y, yaw), (laser.mount_x_m, laser.mount_y_m, laser.mount_yaw_rad))
                observations.append(
                    scan_observation(
                        ranges,
                        angle_min_rad=laser.angle_min_rad,
                        angle_increment_rad=laser.angle_increment_rad,
                        range_min_m=laser.range_min_m,
                        range_max_m=laser.range_max_m,
                        sensor_x_m=sx,
                        sensor_y_m=sy,
                        sensor_yaw_rad=syaw,
                    )
                )
            costmap.update(x, y, yaw, observations)

        def on_publish(t_ns: int) -> None:
            grid = costmap.grid
            rows, cols = grid.cost.shape
            encoder = OccupancyGridEncoder(
                grid.frame_id, grid.resolution_m, cols, rows, (grid.origin_x_m, grid.origin_y_m, 0.0)
            )
            cells = table[grid.cost]
            pub.publish(Encoded((encoder.encode, (t_ns, cells), grid)))

        robot_ns = self.get_namespace().rpartition("/")[0]  # the costmap's own namespace is <robot's>/<name>
        self.create_subscription("nav_msgs/msg/Odometry", f"{robot_ns}/odom", on_odom, 10, raw=True)
        if use_scan:
            self.create_subscription("sensor_msgs/msg/LaserScan", f"{robot_ns}/scan", on_scan, 10, raw=True)
        self.create_rate_timer(params.update_frequency_hz, on_update, priority=PRIORITY_USER - 5)
        self.create_rate_timer(params.publish_frequency_hz, on_publish, priority=PRIORITY_USER - 4)
