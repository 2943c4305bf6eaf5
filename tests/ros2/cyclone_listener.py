"""A second ROS 2 participant (Cyclone DDS, another process) that counts what a twin run sends.

usage: python cyclone_listener.py DOMAIN OUT.json MAX_WALL_S

It subscribes to rt/clock (best effort) and rt/tf_static (reliable, transient local: a late joiner
still gets it), ends when /clock has been silent for 3 s after it was heard, or at MAX_WALL_S, and
writes {"clock": [[sec, nanosec], ...], "tf_static_children": [...]}.
"""

from __future__ import annotations

import json
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from twin.bag.typesys import TypeRegistry
from twin.ros2 import cyclone_config
from twin.ros2.dds_types import struct_type


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
    clocks: list[list[int]] = []
    children: list[str] = []
    start = last = time.monotonic()
    while time.monotonic() - start < max_wall_s and not (clocks and time.monotonic() - last > 3.0):
        for sample in clock_r.take(100):
            if not hasattr(sample, "clock"):  # the writer left (an invalid sample carries no data)
                continue
            clocks.append([sample.clock.sec, sample.clock.nanosec])
            last = time.monotonic()
        for sample in tf_r.take(10):
            if not hasattr(sample, "transforms"):
                continue
            children += [t.child_frame_id for t in sample.transforms]
        time.sleep(0.005)
    with open(out, "w", encoding="utf-8") as f:
        json.dump({"clock": clocks, "tf_static_children": children}, f)
    del tf_r, clock_r, participant, domain
    return 0


if __name__ == "__main__":
    sys.exit(main())
