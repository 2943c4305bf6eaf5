"""Topic health on /tf: one topic carries several transform streams, each on its own stamps."""

from __future__ import annotations

import json
from pathlib import Path

from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from tests.conftest import run_twin

STORE = get_typestore(Stores.ROS2_HUMBLE)


def _health(bag: Path, out: Path) -> dict[str, dict]:
    proc = run_twin("analyze", str(bag), "--out", str(out), "--json", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    return {h["topic"]: h for h in json.loads(proc.stdout)["topic_health"]}


def _tf(stamp_ns: int, frame: str, child: str) -> bytes:
    T = STORE.types
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame
    )
    transform = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    msg = T["tf2_msgs/msg/TFMessage"](
        transforms=[T["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=child, transform=transform)]
    )
    return STORE.serialize_cdr(msg, "tf2_msgs/msg/TFMessage")


def test_the_twins_own_tf_streams_all_move_forward(twin_bag: Path, tmp_path: Path) -> None:
    # odom -> base_footprint at 30 Hz, the wheels at 30 Hz, and AMCL's map -> odom stamped 1 s ahead
    assert _health(twin_bag, tmp_path / "r")["/tf"]["non_monotonic_stamps"] == 0


def test_a_tf_stream_going_backwards_is_counted_on_its_own(tmp_path: Path) -> None:
    bag = tmp_path / "tf"
    with Writer(bag, version=8) as writer:
        conn = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=STORE)
        for i in range(100):
            t = i * 50_000_000
            writer.write(conn, t, _tf(t, "odom", "base_footprint"))  # forward at 20 Hz
            if i % 5 == 0:  # map -> odom stamped 1 s ahead, as AMCL does: forward on its own clock
                writer.write(conn, t + 1, _tf(t + 1_000_000_000, "map", "odom"))
            if i in (40, 41):  # a stream whose second stamp is older than its first
                writer.write(conn, t + 2, _tf(t - 100_000_000 * (i - 39), "base_link", "wheel_left_link"))
    assert _health(bag, tmp_path / "r")["/tf"]["non_monotonic_stamps"] == 1


def test_a_burst_of_messages_has_no_rate_and_a_steady_topic_keeps_its_own(gazebo_bag: Path, tmp_path: Path) -> None:
    # The Humble bag's /rosout: its 19 start-up lines within 5 ms are no 1940 Hz topic.
    health = _health(gazebo_bag, tmp_path / "r")
    assert health["/rosout"]["count"] == 19 and health["/rosout"]["rate_hz"] is None
    assert 4.5 < health["/scan"]["rate_hz"] < 5.5  # Gazebo's LDS-01 at 5 Hz
