"""The odometry EKF as a node: `/joint_states` and `/imu` in, `/odom` and odom→base_footprint out.

It steps on each joint-state message (the encoders' rate) with the gyro samples that arrived since
the last one, as a robot_localization-style odometry filter would. Data of its `/odom` messages:
(x, y, yaw, v, yaw rate) in the odom frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from twin.bag import OdometryEncoder, TFEncoder
from twin.estimation.ekf import OdometryFilter
from twin.node import Encoded, Node
from twin.node.readers import imu_yaw_rate, joint_positions

__all__ = ["EkfNode"]


class EkfNode(Node):
    """Fuses wheel encoders (and the gyro, with `fuse_gyro`) into `/odom` and the odom→base transform."""

    def __init__(
        self,
        ekf: OdometryFilter,
        *,
        base_frame: str,
        wheel_joints: Sequence[str],
        fuse_gyro: bool,
        imu_topic: str = "imu",
        joint_states_topic: str = "joint_states",
    ) -> None:
        super().__init__("ekf_odometry")
        names = tuple(wheel_joints)
        encode_odom = OdometryEncoder("odom", base_frame).encode
        encode_tf = TFEncoder([("odom", base_frame)]).encode_planar
        odom_pub = self.create_publisher(OdometryEncoder.msgtype, "odom", 10)
        tf_pub = self.create_publisher(TFEncoder.msgtype, "/tf", 10)
        add_wheel_positions = ekf.add_wheel_positions

        def on_joint_states(msg: Any) -> None:
            if type(msg) is Encoded:
                t_ns, (left, right), _ = msg[2]
            else:
                read = joint_positions(msg, names)
                if read is None:
                    return
                t_ns, (left, right) = read
            _, x, y, yaw, v, yaw_rate, _, pose_cov, twist_cov = add_wheel_positions(t_ns, left, right)
            odom_pub.publish(
                Encoded((encode_odom, (t_ns, x, y, yaw, v, yaw_rate, pose_cov, twist_cov), (x, y, yaw, v, yaw_rate)))
            )
            tf_pub.publish(Encoded((encode_tf, (t_ns, x, y, yaw), None)))

        if fuse_gyro:
            add_gyro = ekf.add_gyro

            def on_imu(msg: Any) -> None:
                if type(msg) is Encoded:
                    t_ns, reading = msg[2]
                    add_gyro(t_ns, reading.angular_velocity_z)
                else:
                    add_gyro(*imu_yaw_rate(msg))

            self.create_subscription("sensor_msgs/msg/Imu", imu_topic, on_imu, 10, raw=True)
        self.create_subscription("sensor_msgs/msg/JointState", joint_states_topic, on_joint_states, 10, raw=True)
