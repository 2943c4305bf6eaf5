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
from twin.node import PRIORITY_USER, Encoded, Node, QoSProfile

__all__ = ["CostmapNode", "costmap_translation"]

LATCHED = QoSProfile(depth=1, durability="transient_local")


def costmap_translation() -> NDArray[np.int8]:
    """Nav2's cost → OccupancyGrid value table: 0 free, 1..98 scaled, 99 inscribed, 100 lethal, -1 unknown."""
    table = np.zeros(256, dtype=np.int16)
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table.astype(np.int8)


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
        prefix = current_frame_prefix()  # the robot's frame prefix, for the encoders made as the grid resizes
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
                        sensor_z_m=laser.mount_z_m,
                        sensor_yaw_rad=syaw,
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

        robot_ns = self.get_namespace().rpartition("/")[0]  # the costmap's own namespace is <robot's>/<name>
        self.create_subscription("nav_msgs/msg/Odometry", f"{robot_ns}/odom", on_odom, 10, raw=True)
        if use_scan:
            self.create_subscription("sensor_msgs/msg/LaserScan", f"{robot_ns}/scan", on_scan, 10, raw=True)
        self.create_rate_timer(params.update_frequency_hz, on_update, priority=PRIORITY_USER - 5)
        self.create_rate_timer(params.publish_frequency_hz, on_publish, priority=PRIORITY_USER - 4)
