"""nav2_costmap_2d's costmap node: one costmap on the node graph.

`CostmapNode` updates a costmap at its update_frequency from the latest scan and publishes it as
an OccupancyGrid on `<name>/costmap` at its publish_frequency, with Nav2's 0..100 translation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag import OccupancyGridEncoder
from twin.bag.frames import current_frame_prefix, prefixed
from twin.nav.costmap_2d.layered_costmap import Costmap, scan_observation
from twin.nav.frames import Frames, LaserGeometry, compose
from twin.node import PRIORITY_USER, Encoded, Node, QoSProfile, in_robot_namespace

__all__ = ["CostmapNode", "costmap_translation", "source_topic"]

LATCHED = QoSProfile(depth=1, durability="transient_local")


def costmap_translation() -> NDArray[np.int8]:
    """Nav2's cost → OccupancyGrid value table: 0 free, 1..98 scaled, 99 inscribed, 100 lethal, -1 unknown."""
    table = np.zeros(256, dtype=np.int16)
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table.astype(np.int8)


def source_topic(topic: str, costmap_namespace: str, robot_namespace: str) -> str:
    """An observation source's topic as Nav2 Humble's costmap subscribes to it, on the twin's graph.

    A relative topic is resolved in the costmap node's own namespace (`scan` in `/local_costmap` is
    `/local_costmap/scan`: Humble's layers have no `joinWithParentNamespace`, which came later). An
    absolute one is taken as it is; for a fleet robot (`robot_namespace` `/robot1`) it is read under
    the robot's namespace (`/scan` is `/robot1/scan`), as nav2_bringup's multi-robot params files
    write each robot's topics, since the twin's robots share one params file; one that names the
    robot's namespace already (`/robot1/scan`, or `<robot_namespace>/scan` as the launch fills it in)
    is taken as it is.
    """
    if topic.startswith("/"):
        return in_robot_namespace(topic, robot_namespace)
    return f"{costmap_namespace.rstrip('/')}/{topic}"


class CostmapNode(Node):
    """One Nav2 costmap (global in map, local rolling in odom) on the node graph (see the module docstring).

    Args:
        name: `global_costmap` or `local_costmap` (the node lives in the namespace of the same name).
        costmap: The costmap.
        frames: Shared transforms.
        laser: The lidar's scan geometry and mount.
        lidar_topic: The lidar's scan topic in the robot's namespace (its SDF plugin's; TurtleBot3's `scan`).
    """

    def __init__(
        self, name: str, costmap: Costmap, frames: Frames, laser: LaserGeometry | None, *, lidar_topic: str = "scan"
    ) -> None:
        super().__init__(name, namespace=name)
        self.costmap = costmap
        params = costmap.params
        in_odom = params.global_frame != "map"
        table = costmap_translation()
        pub = self.create_publisher(OccupancyGridEncoder.msgtype, "costmap", LATCHED)
        prefix = current_frame_prefix()  # the robot's frame prefix, for the encoders made as the grid resizes
        now = self._graph_now
        robot_ns = self.get_namespace().rpartition("/")[0]  # the costmap's own namespace is <robot's>/<name>
        lidar_topic = f"{robot_ns}/{lidar_topic}"  # the robot's lidar's scans
        # Each LaserScan source's topic as Nav2 Humble resolves it, and the sources reading it.
        readers: dict[str, list[str]] = {}
        unfed: list[tuple[str, str]] = []  # (topic, what to say if nothing publishes it) for a topic not the lidar's
        if laser is not None:
            for layer in params.obstacle_layers:
                for source in layer.sources:
                    if source.data_type != "LaserScan":
                        continue
                    topic = source_topic(source.topic, self.get_namespace(), robot_ns)
                    readers.setdefault(topic, []).append(f"{layer.name}.{source.name}")
                    if topic != lidar_topic:
                        hint = (
                            ""
                            if source.topic.startswith("/")
                            else (
                                " (Nav2 Humble resolves a relative topic in the costmap's own namespace: write /"
                                f"{source.topic})"
                            )
                        )
                        unfed.append((
                            topic,
                            f"{layer.name}.{source.name}: topic {source.topic!r} is {topic}, which nothing publishes "
                            f"(the robot's lidar scans on {lidar_topic}): the layer marks nothing from it{hint}",
                        ))  # fmt: skip
        # (topic, the sources it feeds: None for every source) and its latest scan: one topic, as usual,
        # feeds every source; several feed each its own (`<layer>.<source>`).
        feeds = [(topic, None if len(readers) == 1 else names) for topic, names in readers.items()]
        latest: dict[str, Any] = {}
        lidar_geometry: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # (no lidar: no scan to read)
        if laser is not None:
            lidar_geometry = (laser.angle_min_rad, laser.angle_increment_rad, laser.range_min_m, laser.range_max_m)

        def on_odom(msg: Any) -> None:
            frames.on_odom(now(), msg)

        def receiver(topic: str) -> Any:
            def on_scan(msg: Any) -> None:
                latest[topic] = msg

            return on_scan

        def robot() -> tuple[float, float, float]:
            return frames.odom_pose if in_odom else frames.map_pose()

        def on_update(t_ns: int) -> None:
            if unfed:  # the first update: every node is on the graph by now
                for topic, line in unfed:
                    if not self.count_publishers(topic):
                        self.get_logger().warning(line)
                unfed.clear()
            if not in_odom and not frames.localized:
                return
            x, y, yaw = robot()
            observations = []
            if latest and laser is not None:
                sx, sy, syaw = compose((x, y, yaw), (laser.mount_x_m, laser.mount_y_m, laser.mount_yaw_rad))
                for topic, names in feeds:
                    msg = latest.pop(topic, None)
                    if msg is None:
                        continue
                    if type(msg) is Encoded:  # the lidar's own scan: its ranges, its geometry
                        ranges, geometry = msg[2], lidar_geometry
                    else:  # a node's LaserScan: its own angles and limits, in the lidar's mount
                        ranges = np.asarray(msg.ranges, dtype=np.float64)
                        geometry = (
                            float(msg.angle_min),
                            float(msg.angle_increment),
                            float(msg.range_min),
                            float(msg.range_max),
                        )
                    angle_min, angle_increment, range_min, range_max = geometry
                    for source_name in names or (None,):
                        observations.append(
                            scan_observation(
                                ranges,
                                angle_min_rad=angle_min,
                                angle_increment_rad=angle_increment,
                                range_min_m=range_min,
                                range_max_m=range_max,
                                sensor_x_m=sx,
                                sensor_y_m=sy,
                                sensor_z_m=laser.mount_z_m,
                                sensor_yaw_rad=syaw,
                                source=source_name,
                            )
                        )
            costmap.update(x, y, yaw, observations)

        def on_publish(t_ns: int) -> None:
            grid = costmap.grid
            rows, cols = grid.cost.shape
            encoder = OccupancyGridEncoder(
                prefixed(grid.frame_id, prefix), grid.resolution_m, cols, rows, (grid.origin_x_m, grid.origin_y_m, 0.0)
            )
            cells = table[grid.cost]
            pub.publish(Encoded((encoder.encode, (t_ns, cells), grid)))

        self.create_subscription("nav_msgs/msg/Odometry", f"{robot_ns}/odom", on_odom, 10, raw=True)
        for topic in readers:
            self.create_subscription("sensor_msgs/msg/LaserScan", topic, receiver(topic), 10, raw=True)
        self.create_rate_timer(params.update_frequency_hz, on_update, priority=PRIORITY_USER - 5)
        self.create_rate_timer(params.publish_frequency_hz, on_publish, priority=PRIORITY_USER - 4)
