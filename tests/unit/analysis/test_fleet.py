"""A fleet's bag in the analysis: robots found by namespace, one robot's view, distance and contacts between robots."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from tests.conftest import run_twin
from twin.analysis.collect import ContactEvent, PoseTrack, collect, namespace_view, robot_namespaces
from twin.analysis.compare import compare_bags
from twin.analysis.fleet import pair_contacts, robot_contacts, robot_distance
from twin.bag import LogEncoder, OdometryEncoder, Recorder, TFEncoder

ODOM = "nav_msgs/msg/Odometry"


def _info(*topics: tuple[str, str]) -> Any:
    return SimpleNamespace(topics=tuple(SimpleNamespace(name=n, msgtype=t) for n, t in topics))


def _fleet_info() -> Any:
    return _info(
        ("/robot1/odom", ODOM),
        ("/robot1/ground_truth/odom", ODOM),
        ("/robot1/scan", "sensor_msgs/msg/LaserScan"),
        ("/robot2/odom", ODOM),
        ("/robot2/cmd_vel", "geometry_msgs/msg/Twist"),
        ("/clock", "rosgraph_msgs/msg/Clock"),
        ("/rosout", "rcl_interfaces/msg/Log"),
    )


def test_namespaces_are_the_prefixes_of_robot_odometry() -> None:
    assert robot_namespaces(_fleet_info()) == ["robot1", "robot2"]


def test_nested_namespaces_are_found_whole() -> None:
    info = _info(("/fleet/a/ground_truth/odom", ODOM), ("/fleet/a/tf", "tf2_msgs/msg/TFMessage"))
    assert robot_namespaces(info) == ["fleet/a"]


def test_a_one_robot_bag_has_no_namespaces() -> None:
    # a real robot's /wheel/odom beside its /odom is one robot's odometry source, not a second robot
    info = _info(("/odom", ODOM), ("/wheel/odom", ODOM), ("/ground_truth/odom", ODOM), ("/cmd_vel", "x/msg/Twist"))
    assert robot_namespaces(info) == []


def test_a_robot_view_reads_its_topics_without_the_namespace() -> None:
    view = namespace_view(_fleet_info(), "robot1")
    assert {k: v.name for k, v in view.items()} == {
        "/odom": "/robot1/odom",
        "/ground_truth/odom": "/robot1/ground_truth/odom",
        "/scan": "/robot1/scan",
        "/clock": "/clock",
        "/rosout": "/rosout",
    }
    assert set(namespace_view(_fleet_info(), "/robot2/")) == {"/odom", "/cmd_vel", "/clock", "/rosout"}
    assert set(namespace_view(_fleet_info(), None)) == {t.name for t in _fleet_info().topics}


def _track(topic: str, stamps_s: list[float], xy: list[tuple[float, float]]) -> PoseTrack:
    track = PoseTrack(topic, ODOM)
    for t, (x, y) in zip(stamps_s, xy, strict=True):
        ns = round(t * 1e9)
        track.add(ns, (ns, x, y, 0.0, 0.0, 0.0))
    return track


def test_distance_interpolates_each_robot_at_every_stamp_both_cover() -> None:
    a = _track("/a/ground_truth/odom", [0.0, 1.0, 2.0, 3.0], [(0, 0), (1, 0), (2, 0), (3, 0)])
    b = _track("/b/ground_truth/odom", [0.5, 2.5], [(0.5, 4.0), (2.5, 0.0)])  # moves from y 4 to y 0
    dist = robot_distance({"a": a, "b": b}, 0, "ground truth")
    assert dist is not None
    assert dist.t_s.tolist() == [0.5, 1.0, 2.0, 2.5]  # the union of stamps, inside both spans
    # at 1.0 s: a at (1, 0), b a quarter of the way: (1, 3); at 2.5 s a at (2.5, 0), b at (2.5, 0)
    assert dist.pairs["a", "b"].tolist() == pytest.approx([4.0, 3.0, 1.0, 0.0])
    assert dist.minimum() == (pytest.approx(0.0), 2.5, ("a", "b"))
    assert dist.topics == ("/a/ground_truth/odom", "/b/ground_truth/odom")


def test_distance_of_three_robots_is_the_closest_pair_at_each_time() -> None:
    t = [0.0, 1.0]
    tracks = {
        "r1": _track("/r1/odom", t, [(0, 0), (0, 0)]),
        "r2": _track("/r2/odom", t, [(5, 0), (1, 0)]),
        "r3": _track("/r3/odom", t, [(0, 2), (0, 9)]),
    }
    dist = robot_distance(tracks, 0)
    assert dist is not None
    assert dist.distance_m.tolist() == pytest.approx([2.0, 1.0])
    d, when, pair = dist.minimum()
    assert (d, when, pair) == (pytest.approx(1.0), 1.0, ("r1", "r2"))
    assert dist.pair_minimum(("r1", "r3")) == (pytest.approx(2.0), 0.0)
    assert math.isclose(dist.to_dict()["min_m"], 1.0)


def test_no_distance_without_two_overlapping_tracks() -> None:
    a = _track("/a/odom", [0.0, 1.0], [(0, 0), (1, 0)])
    b = _track("/b/odom", [2.0, 3.0], [(0, 0), (1, 0)])
    assert robot_distance({"a": a, "b": b}, 0) is None
    assert robot_distance({"a": a}, 0) is None
    assert robot_distance({"a": a, "b": _track("/b/odom", [0.5], [(0, 0)])}, 0) is None


def _contact(what: str, t_s: float = 1.0, begin: bool = True) -> ContactEvent:
    return ContactEvent(t_s=t_s, begin=begin, x_m=0.0, y_m=0.0, what=what)


def test_a_contact_both_robots_report_counts_once_for_each() -> None:
    contacts = {
        "robot1": [
            _contact("robot2::turtlebot3_waffle::base_link"),
            _contact("robot2::turtlebot3_waffle::base_link", begin=False),
            _contact("robot2::turtlebot3_waffle::base_link", t_s=4.0),
        ],
        "robot2": [_contact("robot1::turtlebot3_waffle::base_link"), _contact("wall::link::collision", t_s=2.0)],
        "robot3": None,
    }
    # robot2's episode never ends: robot1's second touch falls within it
    assert robot_contacts(contacts) == {"robot1": {"robot2": 2}, "robot2": {"robot1": 1}, "robot3": {}}


def test_a_contact_names_a_nested_namespace_whole() -> None:
    contacts = {"fleet/a": [_contact("fleet/b::m::l")], "fleet/b": [], "b": []}
    assert robot_contacts(contacts) == {"fleet/a": {"fleet/b": 1}, "fleet/b": {"fleet/a": 1}, "b": {}}


def test_a_touch_the_robots_report_a_few_ms_apart_counts_once() -> None:
    # a Burger and a Waffle head on: each finds the touch at a step of its own drive
    contacts = {
        "alpha": [_contact("beta::turtlebot3_waffle::base_link::camera_collision", t_s=4.730)],
        "beta": [_contact("alpha::turtlebot3_burger::base_link::base_collision", t_s=4.7250000000000005)],
    }
    assert robot_contacts(contacts) == {"alpha": {"beta": 1}, "beta": {"alpha": 1}}


def test_repeated_touches_among_three_robots_count_once_each() -> None:
    r1, r2, r3 = "robot1::m::base_link", "robot2::m::base_link", "robot3::m::base_link"
    contacts = {
        # robot1 and robot2 touch twice, each reporting both episodes a few ms apart
        "robot1": [
            _contact(r2, t_s=1.000),
            _contact(r2, t_s=1.500, begin=False),
            _contact(r2, t_s=3.004),
            _contact(r2, t_s=3.200, begin=False),
            _contact(r3, t_s=6.0),  # robot1 runs into robot3, which reports it too
        ],
        "robot2": [
            _contact(r1, t_s=1.005),
            _contact(r1, t_s=1.400, begin=False),
            _contact(r1, t_s=3.000),
            _contact(r1, t_s=3.300, begin=False),
        ],
        # robot3 reports that touch, then runs into robot2, which does not report it
        "robot3": [_contact(r1, t_s=6.002), _contact(r1, t_s=6.5, begin=False), _contact(r2, t_s=8.0)],
    }
    with_robots = robot_contacts(contacts)
    assert with_robots == {
        "robot1": {"robot2": 2, "robot3": 1},
        "robot2": {"robot1": 2, "robot3": 1},
        "robot3": {"robot1": 1, "robot2": 1},
    }
    assert pair_contacts(with_robots) == 4


def test_a_robot_counts_its_own_episodes_when_the_other_s_span_several() -> None:
    # robot2 stays blocked (one episode) while robot1 touches, backs off and touches again
    contacts = {
        "robot1": [
            _contact("robot2::m::l", t_s=1.0),
            _contact("robot2::m::l", t_s=1.2, begin=False),
            _contact("robot2::m::l", t_s=1.6),
        ],
        "robot2": [_contact("robot1::m::l", t_s=1.004)],
    }
    with_robots = robot_contacts(contacts)
    assert with_robots == {"robot1": {"robot2": 2}, "robot2": {"robot1": 1}}
    assert pair_contacts(with_robots) == 2


def test_a_touch_only_the_mover_reports_counts_for_both() -> None:
    # a robot standing still does not report being driven into
    with_robots = robot_contacts({"robot1": [_contact("robot2::m::l")], "robot2": []})
    assert with_robots == {"robot1": {"robot2": 1}, "robot2": {"robot1": 1}}
    assert pair_contacts(with_robots) == 1


def _two_robot_bag(path: Path, *, frame_prefix: bool) -> Path:
    """2 s of two robots' ground truth and TF at 20 Hz (robot1's wheels too, and AMCL's map -> odom at 5 Hz).

    Namespaced TF on `/robot1/tf`, `/robot2/tf`; with `frame_prefix` all of it on one `/tf`, the
    robots' frames named `robot1/odom`..., and a world's transform (`map -> world`) at 1 Hz.
    """
    with Recorder(path) as rec:
        shared = rec.add_topic("/tf", TFEncoder.msgtype) if frame_prefix else None
        for k, ns in enumerate(("robot1", "robot2")):
            odom = rec.add_topic(f"/{ns}/ground_truth/odom", OdometryEncoder.msgtype)
            rec.add_topic(f"/{ns}/cmd_vel", "geometry_msgs/msg/Twist")  # offered: a robot's topic
            tf = shared or rec.add_topic(f"/{ns}/tf", TFEncoder.msgtype)
            p = f"{ns}/" if frame_prefix else ""
            base = TFEncoder([(f"{p}odom", f"{p}base_footprint")])
            wheels = TFEncoder([(f"{p}base_link", f"{p}wheel_left_link"), (f"{p}base_link", f"{p}wheel_right_link")])
            amcl = TFEncoder([("map", f"{p}odom")])
            gt = OdometryEncoder("map", f"{p}base_footprint")
            for i in range(40):
                t_ns = i * 50_000_000 + k  # the robots a nanosecond apart
                x_m = 0.01 * i + k
                rec.write(odom, t_ns, gt.encode(t_ns, x_m, 0.0, 0.0, 0.2, 0.0))
                rec.write(tf, t_ns, base.encode_planar(t_ns, x_m, 0.0, 0.0))
                if ns == "robot1":
                    rec.write(tf, t_ns, wheels.encode(t_ns, [(0, 0.1, 0, 0, 0, 0, 1), (0, -0.1, 0, 0, 0, 0, 1)]))
                if i % 4 == 0:
                    rec.write(tf, t_ns, amcl.encode_planar(t_ns, 0.0, 0.0, 0.0))
        if shared is not None:
            world = TFEncoder([("map", "world")])
            for i in range(2):
                rec.write(shared, i * 1_000_000_000 + 7, world.encode_planar(i * 1_000_000_000 + 7, 0.0, 0.0, 0.0))
    return path


def test_a_robot_reads_only_its_own_transforms_on_a_frame_prefix_fleet_s_shared_tf(tmp_path: Path) -> None:
    bag = _two_robot_bag(tmp_path / "fp", frame_prefix=True)
    tf = {ns: collect(bag, namespace=ns, decoded=False).health["/tf"] for ns in ("robot1", "robot2")}
    # robot1: odom -> base_footprint and its wheels, 40 each, map -> robot1/odom 10; the world's 2
    assert (tf["robot1"].topic, tf["robot1"].count) == ("/tf", 40 + 40 + 10 + 2)
    assert (tf["robot2"].topic, tf["robot2"].count) == ("/tf", 40 + 10 + 2)


def test_a_robot_reads_only_its_own_and_the_worlds_log_lines_on_the_shared_rosout(tmp_path: Path) -> None:
    # rcl names /robot1/amcl's logger `robot1.amcl`: robot1's report counts its lines and the twin's, not robot2's.
    bag = tmp_path / "bag"
    with Recorder(bag) as rec:
        rosout = rec.add_topic("/rosout", LogEncoder.msgtype)
        for ns in ("robot1", "robot2", "fleet/a"):
            rec.add_topic(f"/{ns}/ground_truth/odom", OdometryEncoder.msgtype)
            rec.add_topic(f"/{ns}/cmd_vel", "geometry_msgs/msg/Twist")
        lines = [("twin", 1), ("robot1.amcl", 3), ("robot1.bt_navigator", 2), ("robot2.amcl", 5), ("fleet.a.amcl", 4)]
        t_ns = 0
        for name, n in lines:
            for _ in range(n):
                t_ns += 1_000_000
                rec.write(rosout, t_ns, LogEncoder(name).encode_line(t_ns, 20, "a line", ("f.py", "f", 1)))
        rec.write(rosout, t_ns + 1, b"\x00\x01\x00\x00\x01\x00")  # a damaged line: counted for everyone
    count = {
        ns: collect(bag, namespace=ns, decoded=False).health["/rosout"].count for ns in ("robot1", "robot2", "fleet/a")
    }
    assert count == {"robot1": 1 + 3 + 2 + 1, "robot2": 1 + 5 + 1, "fleet/a": 1 + 4 + 1}
    assert collect(bag, decoded=False).health["/rosout"].count == 16  # the whole bag's, read as one


def test_comparing_a_robot_recorded_with_namespaced_and_prefixed_tf_finds_the_same_tf_rate(tmp_path: Path) -> None:
    ns_bag = _two_robot_bag(tmp_path / "ns", frame_prefix=False)
    fp_bag = _two_robot_bag(tmp_path / "fp", frame_prefix=True)
    result = compare_bags(ns_bag, fp_bag, namespaces=("robot2", "robot2"))
    (rate,) = [r for r in result.rates if r["topic"] == "/tf"]
    assert (rate["count_a"], rate["count_b"]) == (50, 52)  # B: the world's map -> world besides robot2's
    assert rate["rate_b_hz"] == pytest.approx(rate["rate_a_hz"], rel=0.05)
    assert not any("/tf" in line for line in result.summary_lines())


def test_a_one_robot_bag_gets_the_one_robot_report(gazebo_bag: Any, tmp_path: Any) -> None:
    proc = run_twin("analyze", str(gazebo_bag), "--out", str(tmp_path / "r"), "--json", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    keys = {"twin_version", "bag", "summary", "metrics", "mission", "topic_health", "sections", "files"}
    assert set(report) == keys  # no namespace, no robots: the report it always was
    assert (tmp_path / "r" / "report.md").read_text().startswith(f"# Bag report: {gazebo_bag.name}\n")
