"""nav2_map_server's map_server on the node graph: `/map` once, latched, as it does after loading its YAML."""

from __future__ import annotations

from twin.bag import OccupancyGridEncoder
from twin.nav.map_server.map_io import OccupancyMap
from twin.node import PRIORITY_STATE, Encoded, Node, QoSProfile

__all__ = ["MapServerNode"]

LATCHED = QoSProfile(depth=1, durability="transient_local")


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
