"""Gazebo's frame_prefix in the encoders: a robot's frames under its namespace, `map` shared, nothing else changed."""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.unit.bag.test_encoders import T, header, planar, ser, vec
from twin.bag import encoders as E
from twin.bag.frames import current_frame_prefix, frame_prefix, prefixed


def odometry(frame: str, child: str) -> Any:
    twist = T["geometry_msgs/msg/Twist"](linear=vec(0.1, 0.0, 0.0), angular=vec(0.0, 0.0, 0.2))
    return T["nav_msgs/msg/Odometry"](
        header=header(7, frame),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=planar(1.0, 2.0, 0.3), covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def test_an_encoder_made_under_a_prefix_writes_the_prefixed_frames() -> None:
    with frame_prefix("robot1"):
        enc = E.OdometryEncoder("odom", "base_footprint")
    assert enc.encode(7, 1.0, 2.0, 0.3, 0.1, 0.2) == ser(odometry("robot1/odom", "robot1/base_footprint"))


def test_outside_a_prefix_the_bytes_are_as_before() -> None:
    enc = E.OdometryEncoder("odom", "base_footprint")
    assert enc.encode(7, 1.0, 2.0, 0.3, 0.1, 0.2) == ser(odometry("odom", "base_footprint"))
    assert current_frame_prefix() == ""


def test_map_is_shared_and_tf_pairs_are_prefixed() -> None:
    with frame_prefix("/fleet/robot2/"):
        tf = E.TFEncoder([("map", "odom"), ("base_link", "base_scan")])
        scan = E.ScanEncoder(
            "base_scan",
            angle_min_rad=0.0,
            angle_max_rad=1.0,
            angle_increment_rad=0.5,
            time_increment_s=0.0,
            scan_time_s=0.2,
            range_min_m=0.1,
            range_max_m=3.5,
            samples=3,
        )
    assert tf.pairs == (("map", "fleet/robot2/odom"), ("fleet/robot2/base_link", "fleet/robot2/base_scan"))
    got = scan.encode(5, np.array([1.0, 2.0, 3.0], dtype=np.float32))
    assert b"fleet/robot2/base_scan\x00" in got


def test_prefixed_leaves_shared_empty_and_already_prefixed_frames() -> None:
    assert prefixed("odom", "robot1") == "robot1/odom"
    assert prefixed("map", "robot1") == "map"
    assert prefixed("", "robot1") == ""
    assert prefixed("robot1/odom", "robot1") == "robot1/odom"
    assert prefixed("odom", "") == "odom"
