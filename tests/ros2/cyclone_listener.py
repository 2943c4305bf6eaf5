"""A second ROS 2 participant (Cyclone DDS, another process) that counts what a twin run sends.

usage: python cyclone_listener.py DOMAIN OUT.json MAX_WALL_S [X Y]

It subscribes to rt/clock (best effort), rt/tf_static (reliable, transient local: a late joiner
still gets it) and rt/initialpose, ends when /clock has been silent for 3 s after it was heard, or
at MAX_WALL_S, and writes {"clock": [[sec, nanosec], ...], "tf_static_children": [...],
"initialpose": [[x, y], ...]}. With X Y it also publishes one /initialpose there (frame map), 1 s
after it first hears /clock; it never hears its own.
"""

from __future__ import annotations

import json
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from twin.bag.typesys import TypeRegistry
from twin.ros2 import cyclone_config
from twin.ros2.dds_types import struct_type


def _initial_pose(store: object, made: dict[str, object], x: float, y: float) -> object:
    """A PoseWithCovarianceStamped in the frame map at (x, y), facing +x, with 0.25 variances."""
    msg = struct_type("geometry_msgs/msg/PoseWithCovarianceStamped", store, made)
    header_t = struct_type("std_msgs/msg/Header", store, made)
    time_t = struct_type("builtin_interfaces/msg/Time", store, made)
    cov_t = struct_type("geometry_msgs/msg/PoseWithCovariance", store, made)
    pose_t = struct_type("geometry_msgs/msg/Pose", store, made)
    point_t = struct_type("geometry_msgs/msg/Point", store, made)
    quat_t = struct_type("geometry_msgs/msg/Quaternion", store, made)
    covariance = [0.0] * 36
    covariance[0] = covariance[7] = covariance[35] = 0.25
    pose = pose_t(position=point_t(x=x, y=y, z=0.0), orientation=quat_t(x=0.0, y=0.0, z=0.0, w=1.0))
    header = header_t(stamp=time_t(sec=0, nanosec=0), frame_id="map")
    return msg(header=header, pose=cov_t(pose=pose, covariance=covariance))  # type: ignore[operator]


def main() -> int:
    domain_id, out, max_wall_s = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
    domain = Domain(domain_id, cyclone_config(domain_id))
    participant = DomainParticipant(domain_id)
    store = TypeRegistry().store
    made: dict[str, object] = {}
    clock_t = Topic(participant, "rt/clock", struct_type("rosgraph_msgs/msg/Clock", store, made))
    tf_t = Topic(participant, "rt/tf_static", struct_type("tf2_msgs/msg/TFMessage", store, made))
    clock_r = DataReader(participant, clock_t, Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100)))
    latched = Qos(
        Policy.Reliability.Reliable(100_000_000), Policy.Durability.TransientLocal, Policy.History.KeepLast(10)
    )
    tf_r = DataReader(participant, tf_t, latched)
    pose_type = struct_type("geometry_msgs/msg/PoseWithCovarianceStamped", store, made)
    pose_t = Topic(participant, "rt/initialpose", pose_type)
    reliable = Qos(Policy.Reliability.Reliable(100_000_000), Policy.History.KeepLast(10))
    pose_r = DataReader(participant, pose_t, Qos(*reliable, Policy.IgnoreLocal.Participant))
    pose_w = DataWriter(participant, pose_t, reliable)
    to_send = [float(sys.argv[4]), float(sys.argv[5])] if len(sys.argv) > 5 else None
    poses: list[list[float]] = []
    clocks: list[list[int]] = []
    children: list[str] = []
    start = last = time.monotonic()
    first_clock = 0.0
    while time.monotonic() - start < max_wall_s and not (clocks and time.monotonic() - last > 3.0):
        for sample in clock_r.take(100):
            if not hasattr(sample, "clock"):  # the writer left (an invalid sample carries no data)
                continue
            clocks.append([sample.clock.sec, sample.clock.nanosec])
            last = time.monotonic()
            first_clock = first_clock or last
        if to_send is not None and clocks and time.monotonic() - first_clock > 1.0:
            pose_w.write(_initial_pose(store, made, *to_send))
            to_send = None
        for sample in pose_r.take(10):
            if hasattr(sample, "pose"):
                poses.append([sample.pose.pose.position.x, sample.pose.pose.position.y])
        for sample in tf_r.take(10):
            if not hasattr(sample, "transforms"):
                continue
            children += [t.child_frame_id for t in sample.transforms]
        time.sleep(0.005)
    with open(out, "w", encoding="utf-8") as f:
        json.dump({"clock": clocks, "tf_static_children": children, "initialpose": poses}, f)
    del tf_r, clock_r, pose_r, pose_w, participant, domain
    return 0


if __name__ == "__main__":
    sys.exit(main())
