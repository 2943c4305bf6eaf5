"""A fleet's bag on the live server: every namespace served, or one robot alone under a single robot's names."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from tests.foxglove_client import Watch, watch
from twin.bag import QOS_LATCHED, ClockEncoder, Recorder, StringEncoder, TFEncoder
from twin.bag.typesys import TypeRegistry
from twin.live import LiveServer, LiveSink, play_bag
from twin.live.namespace import NamespaceView

ROBOTS = ("robot1", "robot2")


def fleet_bag(path: Path) -> Path:
    """Two robots' TF and descriptions under their namespaces (two /tf_static messages each), and one /clock."""
    with Recorder(path) as rec:
        clock = rec.add_topic("/clock", ClockEncoder.msgtype)
        for i, ns in enumerate(ROBOTS):
            static = rec.add_topic(f"/{ns}/tf_static", TFEncoder.msgtype, qos=[QOS_LATCHED])
            desc = rec.add_topic(f"/{ns}/robot_description", StringEncoder.msgtype, qos=[QOS_LATCHED])
            rec.write(desc, 0, StringEncoder().encode(f"<robot name='{ns}'/>"))
            rec.write(static, 0, TFEncoder([("base_footprint", "base_link")]).encode(0, [(0, 0, 0.01 * i, 0, 0, 0, 1)]))
            rec.write(static, 0, TFEncoder([("base_link", "base_scan")]).encode(0, [(0.1 * i, 0, 0.1, 0, 0, 0, 1)]))
        tf = {ns: rec.add_topic(f"/{ns}/tf", TFEncoder.msgtype) for ns in ROBOTS}
        encoder = ClockEncoder()
        for k in range(10):
            t = k * 10_000_000
            rec.write(clock, t, encoder.encode(t))
            for i, ns in enumerate(ROBOTS):
                rec.write(tf[ns], t, TFEncoder([("odom", "base_footprint")]).encode_planar(t, float(i), 0.01 * k, 0.0))
    return path


def late_client(url: str, topics: list[str]) -> Watch:
    """A client that connects after everything was played: it gets what is latched."""
    return asyncio.run(watch(url, topics, stop=lambda w: all(len(m) >= 2 for m in w.messages.values()), timeout_s=5))


def test_a_fleet_bag_is_served_whole_with_each_robots_static_frames(tmp_path: Path) -> None:
    bag = fleet_bag(tmp_path / "bag")
    with LiveServer(port=0) as server:
        report = play_bag(bag, server, speed=None)
        seen = late_client(server.url, ["/robot1/tf_static", "/robot2/tf_static"])
    assert set(report.topics) == {"/clock"} | {
        f"/{ns}/{t}" for ns in ROBOTS for t in ("tf", "tf_static", "robot_description")
    }
    assert {"/robot1/tf", "/robot2/tf", "/robot1/robot_description"} <= set(seen.channels)
    for ns in ROBOTS:  # both static messages of each namespace, not only the last (each holds its own frames)
        children = [
            seen.decode(f"/{ns}/tf_static", p).transforms[0].child_frame_id
            for _, p in seen.messages[f"/{ns}/tf_static"]
        ]
        assert sorted(children) == ["base_link", "base_scan"], ns


def test_one_robot_is_served_alone_under_a_single_robots_names(tmp_path: Path) -> None:
    bag = fleet_bag(tmp_path / "bag")
    with LiveServer(port=0) as server:
        report = play_bag(bag, server, speed=None, namespace="robot2")
        seen = asyncio.run(
            watch(
                server.url,
                ["/tf_static", "/robot_description"],
                stop=lambda w: len(w.messages["/tf_static"]) >= 2 and bool(w.messages["/robot_description"]),
                timeout_s=5,
            )
        )
    assert set(report.topics) == {"/clock", "/robot2/tf", "/robot2/tf_static", "/robot2/robot_description"}
    assert set(seen.channels) == {"/clock", "/tf", "/tf_static", "/robot_description"}  # nothing of robot1
    assert report.messages == 10 + 10 + 2 + 1
    assert [seen.decode("/robot_description", p).data for _, p in seen.messages["/robot_description"]] == [
        "<robot name='robot2'/>"
    ]
    statics = [seen.decode("/tf_static", p).transforms[0] for _, p in seen.messages["/tf_static"]]
    assert sorted((t.child_frame_id, t.transform.translation.x) for t in statics) == [
        ("base_link", 0.0),
        ("base_scan", 0.1),
    ]


def test_the_view_takes_the_namespace_off_and_keeps_the_worlds_topics() -> None:
    view = NamespaceView("/fleet/robot1/")
    assert view.served_as("/fleet/robot1/scan") == "/scan"
    assert view.served_as("/fleet/robot1/local_costmap/costmap") == "/local_costmap/costmap"
    assert view.served_as("/fleet/robot2/scan") is None
    assert view.served_as("/clock") == "/clock"
    assert view.served_as("/tf") == "/tf"  # a frame_prefix fleet's shared TF
    assert view.served_as("/robot1/scan") is None


def prefixed_fleet_bag(path: Path) -> Path:
    """Two robots as Gazebo's frame_prefix names them: one shared /tf, frames `robotN/...`, topics under /robotN/."""
    from twin.msgs import get_message, serialize

    odometry, scan = get_message("nav_msgs/msg/Odometry"), get_message("sensor_msgs/msg/LaserScan")
    with Recorder(path) as rec:
        clock = rec.add_topic("/clock", ClockEncoder.msgtype)
        tf = rec.add_topic("/tf", TFEncoder.msgtype)
        static = rec.add_topic("/tf_static", TFEncoder.msgtype, qos=[QOS_LATCHED])
        for i, ns in enumerate(ROBOTS):
            rec.write(
                static, 0, TFEncoder([(f"{ns}/base_link", f"{ns}/base_scan")]).encode(0, [(0, 0, 0.1 * i, 0, 0, 0, 1)])
            )
        topics = {
            ns: (rec.add_topic(f"/{ns}/odom", odometry.__msgtype__), rec.add_topic(f"/{ns}/scan", scan.__msgtype__))
            for ns in ROBOTS
        }
        for k in range(5):
            t = k * 10_000_000
            rec.write(clock, t, ClockEncoder().encode(t))
            for i, ns in enumerate(ROBOTS):
                frames = [("map", f"{ns}/odom"), (f"{ns}/odom", f"{ns}/base_footprint")]
                rec.write(
                    tf, t, TFEncoder(frames).encode(t, [(float(i), 0, 0, 0, 0, 0, 1), (0.01 * k, 0, 0, 0, 0, 0, 1)])
                )
                odom = odometry()
                odom.header.frame_id, odom.child_frame_id = f"{ns}/odom", f"{ns}/base_footprint"
                odom.pose.pose.position.x = float(i)
                rec.write(topics[ns][0], t, serialize(odom))
                laser = scan()
                laser.header.frame_id, laser.ranges = f"{ns}/base_scan", [1.0 + i, 2.0]
                rec.write(topics[ns][1], t, serialize(laser))
    return path


def served(bag: Path, **kwargs: Any) -> tuple[Any, dict[str, list[Any]]]:
    """Play the bag (as fast as possible); the report, and each channel's messages as served, decoded."""
    from twin.msgs import deserialize

    names: dict[int, tuple[str, str]] = {}
    out: dict[str, list[Any]] = {}
    with LiveServer(port=0) as server:
        add, publish = server.add_channel, server.publish

        def adding(topic: str, definition: Any, **kw: Any) -> int:
            handle = add(topic, definition, **kw)
            names[handle] = (topic, definition.msgtype)
            return handle

        def publishing(handle: int, t_ns: int, data: bytes) -> None:
            topic, msgtype = names[handle]
            out.setdefault(topic, []).append(deserialize(bytes(data), msgtype))
            publish(handle, t_ns, data)

        server.add_channel, server.publish = adding, publishing  # type: ignore[method-assign]
        report = play_bag(bag, server, speed=None, **kwargs)
    return report, out


def test_a_prefixed_fleets_robot_is_served_with_its_own_frames_unprefixed(tmp_path: Path) -> None:
    # A fleet on one shared /tf (`robot2/odom`...): robot2 alone is served as a one-robot bag is, frames
    # `odom`, `base_footprint`, `base_scan`, so the shipped layout finds them; robot1's transforms are left out.
    bag = prefixed_fleet_bag(tmp_path / "bag")
    report, got = served(bag, namespace="robot2", robots=ROBOTS)
    assert set(report.topics) == {"/clock", "/tf", "/tf_static", "/robot2/odom", "/robot2/scan"}
    assert set(got) == {"/clock", "/tf", "/tf_static", "/odom", "/scan"}
    assert report.messages == 5 + 5 + 1 + 5 + 5  # /tf: robot2's five (robot1's left out); /tf_static: robot2's one
    statics = [t for m in got["/tf_static"] for t in m.transforms]
    assert [(t.header.frame_id, t.child_frame_id, t.transform.translation.z) for t in statics] == [
        ("base_link", "base_scan", 0.1)
    ]
    tfs = [t for m in got["/tf"] for t in m.transforms]
    assert {(t.header.frame_id, t.child_frame_id) for t in tfs} == {("map", "odom"), ("odom", "base_footprint")}
    assert {t.transform.translation.x for t in tfs if t.header.frame_id == "map"} == {1.0}  # robot2's map -> odom
    assert {(o.header.frame_id, o.child_frame_id, o.pose.pose.position.x) for o in got["/odom"]} == {
        ("odom", "base_footprint", 1.0)
    }
    assert {(s.header.frame_id, tuple(s.ranges)) for s in got["/scan"]} == {("base_scan", (2.0, 2.0))}
    # Without the robots named, play_bag finds them in the bag: robot1's transforms stay out all the same.
    _, found = served(bag, namespace="robot2")
    assert {(t.header.frame_id, t.child_frame_id) for m in found["/tf"] for t in m.transforms} == {
        ("map", "odom"),
        ("odom", "base_footprint"),
    }
    # Served whole, the bag keeps every frame as recorded.
    _, whole = served(bag)
    assert {t.child_frame_id for m in whole["/tf"] for t in m.transforms} == {
        "robot1/odom", "robot1/base_footprint", "robot2/odom", "robot2/base_footprint"
    }  # fmt: skip


def test_a_namespaced_fleets_frames_are_served_byte_for_byte() -> None:
    view = NamespaceView("robot1", robots=ROBOTS)
    assert view.rewriter("sensor_msgs/msg/LaserScan", TypeRegistry().store) is None


def test_the_prefix_comes_off_the_robots_own_frames_only() -> None:
    view = NamespaceView("fleet/a", frame_prefix=True, robots=("fleet/a", "fleet/b", "fleet/a/arm"))
    assert view.own_frame("fleet/a/odom") == "odom"
    assert view.own_frame("/fleet/a/base_link") == "base_link"
    assert view.own_frame("map") == "map"
    assert view.own_frame("fleet/b/odom") == "fleet/b/odom"
    assert view.robot_of("fleet/a/arm/link") == "fleet/a/arm"  # a nested robot's frame is its own, not fleet/a's
    assert view.own_frame("fleet/a/arm/link") == "fleet/a/arm/link"


def test_a_live_prefixed_fleet_run_serves_one_robot_with_its_frames_unprefixed() -> None:
    # `twin simulate --live --namespace robot2` with `tf: {mode: frame_prefix}`: what the sink serves.
    from twin.msgs import deserialize, get_message, serialize

    published: list[tuple[int, bytes]] = []
    with LiveServer(port=0) as server:
        server.publish = lambda handle, t_ns, data: published.append((handle, data))  # type: ignore[method-assign]
        sink = LiveSink(server, namespace="robot2", frame_prefix=True, robots=ROBOTS)
        tf = sink.add_topic("/tf", TFEncoder.msgtype)
        scan = sink.add_topic("/robot2/scan", "sensor_msgs/msg/LaserScan")
        assert sink.add_topic("/robot1/scan", "sensor_msgs/msg/LaserScan") == -1  # robot1's: not served
        sink.write(tf, 0, TFEncoder([("map", "robot1/odom")]).encode(0, [(0, 0, 0, 0, 0, 0, 1)]))
        sink.write(tf, 0, TFEncoder([("map", "robot2/odom")]).encode(0, [(1, 0, 0, 0, 0, 0, 1)]))
        laser = get_message("sensor_msgs/msg/LaserScan")()
        laser.header.frame_id = "robot2/base_scan"
        sink.write(scan, 0, serialize(laser))
    assert [h for h, _ in published] == [tf, scan]  # robot1's map -> robot1/odom left out
    (only,) = deserialize(published[0][1], TFEncoder.msgtype).transforms
    assert (only.header.frame_id, only.child_frame_id) == ("map", "odom")
    assert deserialize(published[1][1], "sensor_msgs/msg/LaserScan").header.frame_id == "base_scan"


def test_a_damaged_or_empty_message_of_a_prefixed_fleet_is_served_as_recorded() -> None:
    # A recovered bag may hold a message that does not decode: served as it is, not the end of the playback.
    from twin.msgs import deserialize, get_message, serialize

    view = NamespaceView("robot2", frame_prefix=True, robots=ROBOTS)
    store = TypeRegistry().store
    scan = view.rewriter("sensor_msgs/msg/LaserScan", store)
    assert scan is not None
    assert scan(b"\x00\x01\x00\x00\x07\x00") == b"\x00\x01\x00\x00\x07\x00"
    tf = view.rewriter(TFEncoder.msgtype, store)
    assert tf is not None
    empty = serialize(get_message("tf2_msgs/msg/TFMessage")())
    assert deserialize(tf(empty), TFEncoder.msgtype).transforms == []  # nobody's: served, not dropped
    assert tf(TFEncoder([("map", "robot1/odom")]).encode(0, [(0, 0, 0, 0, 0, 0, 1)])) is None  # robot1's alone
