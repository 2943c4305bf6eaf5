"""Publish the robot's initial pose once, as the thesis's `set_init_amcl_pose.py` does for AMCL.

Written as a ROS 2 user writes it with rclpy: porting the original means changing the imports
(`rclpy.node` -> `twin.node`, `geometry_msgs.msg` -> `twin.msgs`) and dropping `rclpy.init`/`spin`,
which the twin's launcher does. It waits until something subscribes to `/initialpose` (AMCL, or
the bag recorder, as `ros2 bag record` does in a ROS system), then publishes one
PoseWithCovarianceStamped in frame `map`: the pose from the parameters x, y, theta and the
variance `cov` on x, y and yaw.
"""

from __future__ import annotations

import math

from twin.msgs import PoseWithCovarianceStamped
from twin.node import Node


class InitAmclPose(Node):
    """Sends one initial pose to AMCL."""

    def __init__(self) -> None:
        super().__init__("init_amcl_pose")
        # The thesis's launch file sets x = -2.0, y = -0.5 (turtlebot3_world's spawn pose).
        self.x = self.declare_parameter("x", -2.0).value
        self.y = self.declare_parameter("y", -0.5).value
        self.theta = self.declare_parameter("theta", 0.0).value
        self.cov = self.declare_parameter("cov", 0.5**2).value
        self.publisher = self.create_publisher(PoseWithCovarianceStamped, "/initialpose", 10)
        self.timer = self.create_timer(0.1, self.on_timer)

    def on_timer(self) -> None:
        """Send the pose once somebody listens, then stop the timer."""
        if self.publisher.get_subscription_count() == 0:
            self.get_logger().info("waiting for a subscriber on /initialpose", once=True)
            return
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = "map"
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.pose.pose.position.x = self.x
        msg.pose.pose.position.y = self.y
        msg.pose.pose.orientation.z = math.sin(self.theta / 2.0)
        msg.pose.pose.orientation.w = math.cos(self.theta / 2.0)
        covariance = [0.0] * 36
        covariance[0] = covariance[7] = covariance[35] = self.cov  # x, y, yaw
        msg.pose.covariance = covariance
        self.publisher.publish(msg)
        self.get_logger().info(f"initial pose sent: x={self.x}, y={self.y}, theta={self.theta}, cov={self.cov}")
        self.timer.cancel()
