"""A reactive wall follower: keeps a wall on its left at a set distance, from `/scan` alone.

It splits each scan into sectors (ahead, ahead-left, left) and steers on the nearest return in
each. It first drives straight until a wall is ahead; from then on it turns right on the spot when
something is close ahead, bends left around a wall's end when the wall falls away, and otherwise
holds the wall distance with a proportional turn.
"""

from __future__ import annotations

import math

import numpy as np

from twin.msgs import LaserScan, Twist
from twin.node import Node


class WallFollower(Node):
    """Follows the wall on its left."""

    def __init__(self) -> None:
        super().__init__("wall_follower")
        self.distance = self.declare_parameter("distance_m", 0.55).value
        self.speed = self.declare_parameter("speed_mps", 0.22).value
        self.gain = self.declare_parameter("gain", 2.0).value
        self.max_turn = self.declare_parameter("max_turn_radps", 0.9).value
        self.found_wall = False
        self.publisher = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, 10)

    def sector(self, scan: LaserScan, lo_deg: float, hi_deg: float) -> float:
        """The nearest valid return between two bearings (degrees, counter-clockwise from ahead)."""
        ranges = np.asarray(scan.ranges, dtype=float)
        angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
        angles = np.degrees(np.arctan2(np.sin(angles), np.cos(angles)))
        inside = (angles >= lo_deg) & (angles <= hi_deg) & np.isfinite(ranges) & (ranges >= scan.range_min)
        return float(ranges[inside].min()) if inside.any() else math.inf

    def on_scan(self, scan: LaserScan) -> None:
        """Steer on one scan."""
        ahead = self.sector(scan, -25.0, 25.0)
        ahead_left = self.sector(scan, 25.0, 65.0)
        left = min(self.sector(scan, 65.0, 115.0), ahead_left * math.cos(math.radians(45.0)))
        cmd = Twist()
        blocked = ahead < self.distance + 0.25 or ahead_left < 0.9 * self.distance
        if not self.found_wall and not blocked:
            cmd.linear.x = self.speed  # look for a wall straight ahead
        elif blocked:
            if not self.found_wall:
                self.get_logger().info(f"wall found {ahead:.2f} m ahead; following it on the left")
            self.found_wall = True
            cmd.angular.z = -self.max_turn  # blocked: turn right on the spot
        elif left > 2.0 * self.distance:
            cmd.linear.x = self.speed
            cmd.angular.z = self.speed / (1.5 * self.distance)  # the wall fell away: bend left around its end
        else:
            cmd.linear.x = self.speed * min(1.0, (ahead - self.distance) / self.distance)
            turn = self.gain * (left - self.distance)
            cmd.angular.z = max(-self.max_turn, min(self.max_turn, turn))
        self.publisher.publish(cmd)
