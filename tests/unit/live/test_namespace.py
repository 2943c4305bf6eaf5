"""A fleet's bag on the live server: every namespace served, or one robot alone under a single robot's names."""

from __future__ import annotations

import asyncio
from pathlib import Path

from tests.foxglove_client import Watch, watch
from twin.bag import QOS_LATCHED, ClockEncoder, Recorder, StringEncoder, TFEncoder
from twin.live import LiveServer, play_bag
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
