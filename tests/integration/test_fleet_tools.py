"""The analysis tools on a fleet's bag: `twin analyze`, `analyze compare` and `replay` by namespace.

One bag of the two Waffles in the house (20 s of `scenarios/house_two_waffles.yaml`), read back
with rosbags independently of the twin's readers: each robot's numbers and the distance between
the robots are recomputed here from the bag's own ground truth.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from tests.integration.fleet_helpers import ONE_GOAL_TREE

ROBOTS = ("robot1", "robot2")


@pytest.fixture(scope="module")
def fleet_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("fleet_tools") / "bag"
    proc = run_twin(
        "simulate", str(REPO / "scenarios" / "house_two_waffles.yaml"), "--duration", "20", "--out", str(bag)
    )
    assert proc.returncode == 0, proc.stderr
    return bag


# Head on: each robot's goal is behind the other, 1.5 m apart; they meet in the middle and touch.
HEAD_ON = """
name: head_on
max_duration_s: 12
mission: {{tree: {tree}}}
robots:
  - name: robot1
    robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}}}
    mission: {{locations: {goal1}}}
  - name: robot2
    robot: {{initial_pose: {{x_m: 1.5, y_m: 0.0, yaw_rad: 3.14159}}}}
    mission: {{locations: {goal2}}}
"""


@pytest.fixture(scope="module")
def head_on_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("head_on")
    (tmp / "tree.xml").write_text(ONE_GOAL_TREE)
    (tmp / "g1.yaml").write_text("goal: [2.0, 0.0, 0.0]\n")
    (tmp / "g2.yaml").write_text("goal: [-0.5, 0.0, 3.14]\n")
    scenario = tmp / "head_on.yaml"
    scenario.write_text(HEAD_ON.format(tree=tmp / "tree.xml", goal1=tmp / "g1.yaml", goal2=tmp / "g2.yaml"))
    bag = tmp / "bag"
    proc = run_twin("simulate", str(scenario), "--out", str(bag))
    assert proc.returncode in (0, 1), proc.stderr  # 1: a mission failed (they may block each other)
    return bag


def _read_truth(bag: Path) -> dict[str, Any]:
    """What a bag holds, read with rosbags: ground truth per robot, tree-log goal results, contacts."""
    gt: dict[str, dict[int, tuple[float, float, float]]] = {ns: {} for ns in ROBOTS}
    goals: dict[str, list[tuple[str, str]]] = {ns: [] for ns in ROBOTS}
    contacts = {ns: 0 for ns in ROBOTS}
    touching: dict[str, list[tuple[int, str]]] = {ns: [] for ns in ROBOTS}  # (t ns, what) of each contact begun
    with AnyReader([bag]) as reader:
        for con, _t, raw in reader.messages():
            ns = con.topic.split("/")[1]
            if con.topic.endswith("/ground_truth/odom"):
                msg = reader.deserialize(raw, con.msgtype)
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                p = msg.pose.pose.position
                gt[ns][stamp] = (p.x, p.y, msg.twist.twist.linear.x)
            elif con.topic.endswith("/mission/behavior_tree_log"):
                msg = reader.deserialize(raw, con.msgtype)
                for e in msg.event_log:
                    if e.node_name.startswith("go_to") and e.current_status in ("SUCCESS", "FAILURE"):
                        goals[ns].append((e.node_name, e.current_status))
            elif con.topic.endswith("/contacts"):
                msg = reader.deserialize(raw, con.msgtype)
                if msg.event == 1:
                    contacts[ns] += 1
                    touching[ns].append((_t, msg.world_collision))
    return {"gt": gt, "goals": goals, "contacts": contacts, "touching": touching}


@pytest.fixture(scope="module")
def truth(fleet_bag: Path) -> dict[str, Any]:
    return _read_truth(fleet_bag)


@pytest.fixture(scope="module")
def fleet_report(fleet_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path]:
    out = tmp_path_factory.mktemp("fleet_report") / "r"
    proc = run_twin("analyze", str(fleet_bag), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), out


def _path_length(track: dict[int, tuple[float, float, float]]) -> float:
    xy = [track[s][:2] for s in sorted(track)]
    return sum(math.dist(a, b) for a, b in itertools.pairwise(xy))


def _distance(truth: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(t s, distance m) between the robots at the stamps both ground truths share."""
    a, b = truth["gt"]["robot1"], truth["gt"]["robot2"]
    stamps = sorted(set(a) & set(b))
    d = np.array([math.dist(a[s][:2], b[s][:2]) for s in stamps])
    return np.array(stamps, dtype=np.float64) * 1e-9, d


def _one_error_line(proc: Any, *words: str) -> None:
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_analyze_finds_both_robots_by_namespace(fleet_report: tuple[dict[str, Any], Path]) -> None:
    report, _ = fleet_report
    assert report["namespaces"] == list(ROBOTS)
    assert set(report["robots"]) == set(ROBOTS)


@pytest.mark.parametrize("ns", ROBOTS)
def test_each_robot_is_reported_from_its_own_topics(
    ns: str, fleet_report: tuple[dict[str, Any], Path], truth: dict[str, Any]
) -> None:
    robot = fleet_report[0]["robots"][ns]
    m = robot["metrics"]
    track = truth["gt"][ns]
    assert m["pose_source"] == f"/{ns}/ground_truth/odom"
    assert m["path_length_m"] == pytest.approx(_path_length(track), rel=1e-9)
    assert m["max_speed_mps"] == pytest.approx(max(abs(v[2]) for v in track.values()), rel=1e-9)
    assert m["localization_source"] == f"/{ns}/amcl_pose"
    assert m["localization_error_median_m"] is not None
    assert m["contacts"] == truth["contacts"][ns]
    ended = [(g["name"], g["result"]) for g in m["goals"] if g["end_s"] is not None]
    assert ended == truth["goals"][ns]
    assert m["goals_succeeded"] == sum(r == "SUCCESS" for _, r in truth["goals"][ns])
    other = next(o for o in ROBOTS if o != ns)
    topics = {h["topic"] for h in robot["topic_health"]}
    assert f"/{ns}/scan" in topics and "/clock" in topics
    assert not any(t.startswith(f"/{other}/") for t in topics)


def test_the_robots_are_told_apart(fleet_report: tuple[dict[str, Any], Path], truth: dict[str, Any]) -> None:
    # robot2 tours in the opposite order: in 20 s the two have ended different numbers of goals
    r = fleet_report[0]["robots"]
    assert len(truth["goals"]["robot1"]) != len(truth["goals"]["robot2"])
    assert r["robot1"]["metrics"]["goals"] != r["robot2"]["metrics"]["goals"]
    assert r["robot1"]["metrics"]["path_length_m"] != r["robot2"]["metrics"]["path_length_m"]


def test_inter_robot_distance_matches_the_ground_truth(
    fleet_report: tuple[dict[str, Any], Path], truth: dict[str, Any]
) -> None:
    dist = fleet_report[0]["inter_robot_distance"]
    t_s, d = _distance(truth)
    assert dist["source"] == "ground truth"
    assert dist["topics"] == ["/robot1/ground_truth/odom", "/robot2/ground_truth/odom"]
    assert dist["samples"] == len(d)
    i = int(np.argmin(d))
    assert dist["min_m"] == pytest.approx(float(d[i]), abs=1e-12)
    assert dist["min_t_s"] == pytest.approx(float(t_s[i]), abs=1e-9)  # the bag starts at sim time 0
    assert dist["min_pair"] == ["robot1", "robot2"]
    for mark in dist["each_s"]:
        assert mark["min_m"] == pytest.approx(float(np.interp(mark["t_s"], t_s, d)), abs=1e-9)
    assert len(dist["each_s"]) >= 19


def test_fleet_report_files_have_a_section_per_robot(fleet_report: tuple[dict[str, Any], Path]) -> None:
    report, out = fleet_report
    md = (out / "report.md").read_text()
    assert "## Robot /robot1" in md and "## Robot /robot2" in md
    assert "## Inter-robot distance" in md and "from ground truth" in md
    assert (out / "inter_robot_distance.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for ns in ROBOTS:
        assert f"![map]({ns}_map.png)" in md
        assert (out / f"{ns}_map.png").exists()
    html = (out / "report.html").read_text()
    assert html.count("<h2>Robot /robot") == 2
    assert json.loads((out / "report.json").read_text())["namespaces"] == list(ROBOTS)
    assert {Path(f).name for f in report["files"]} >= {"report.md", "report.html", "inter_robot_distance.png"}


def test_fleet_summary_on_the_terminal(fleet_bag: Path, tmp_path: Path, truth: dict[str, Any]) -> None:
    proc = run_twin("analyze", str(fleet_bag), "--out", str(tmp_path / "r"), "--no-plots")
    assert proc.returncode == 0, proc.stderr
    _, d = _distance(truth)
    assert "2 robots: robot1, robot2" in proc.stdout
    assert f"Inter-robot minimum distance {d.min():.3f} m" in proc.stdout


def test_namespace_restricts_analyze_to_one_robot(fleet_bag: Path, tmp_path: Path, truth: dict[str, Any]) -> None:
    proc = run_twin("analyze", str(fleet_bag), "--namespace", "robot2", "--out", str(tmp_path / "r"), "--json")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["namespace"] == "robot2"
    assert report["metrics"]["path_length_m"] == pytest.approx(_path_length(truth["gt"]["robot2"]), rel=1e-9)
    assert not any(h["topic"].startswith("/robot1/") for h in report["topic_health"])
    assert "# Bag report: bag, robot /robot2" in (tmp_path / "r" / "report.md").read_text()


def test_analyze_refuses_a_namespace_the_bag_lacks(fleet_bag: Path, tmp_path: Path) -> None:
    proc = run_twin("analyze", str(fleet_bag), "--namespace", "robot3", "--out", str(tmp_path / "r"))
    _one_error_line(proc, "--namespace", "robot3", "robot1, robot2", str(fleet_bag))


def test_compare_on_a_fleet_bag_asks_for_a_namespace(fleet_bag: Path) -> None:
    proc = run_twin("analyze", "compare", str(fleet_bag), str(fleet_bag))
    _one_error_line(proc, "--namespace", "robot1, robot2", str(fleet_bag))


def test_compare_two_robots_of_one_bag(fleet_bag: Path, truth: dict[str, Any]) -> None:
    proc = run_twin("analyze", "compare", str(fleet_bag), str(fleet_bag), "--namespace", "robot1", "robot2", "--json")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert (result["topic_a"], result["topic_b"]) == ("/robot1/ground_truth/odom", "/robot2/ground_truth/odom")
    # one bag, one clock: robot2's position error against robot1 is the distance between them
    _, d = _distance(truth)
    assert result["matched_poses"] == len(d)
    assert result["position_error_max_m"] == pytest.approx(float(d.max()), abs=1e-9)
    assert result["position_error_final_m"] == pytest.approx(float(d[-1]), abs=1e-9)


def test_compare_one_robot_with_itself_by_namespace(fleet_bag: Path) -> None:
    proc = run_twin(
        "analyze", "compare", str(fleet_bag), str(fleet_bag), "--namespace", "robot2", "--topic", "/odom", "--json"
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["topic_a"] == result["topic_b"] == "/robot2/odom"
    assert result["position_error_max_m"] == 0.0


def test_replay_needs_a_namespace_on_a_fleet_bag(fleet_bag: Path, tmp_path: Path) -> None:
    world = REPO / "sdf" / "worlds" / "house.sdf"
    proc = run_twin("replay", str(fleet_bag), "--world", str(world), "--out", str(tmp_path / "r"))
    _one_error_line(proc, "--namespace", "robot1, robot2")


def test_replay_one_robot_of_a_fleet(fleet_bag: Path, tmp_path: Path, truth: dict[str, Any]) -> None:
    world = REPO / "sdf" / "worlds" / "house.sdf"
    out = tmp_path / "r"
    proc = run_twin(
        "replay", str(fleet_bag), "--world", str(world), "--namespace", "robot2", "--out", str(out), "--json"
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["topic_a"] == "/robot2/ground_truth/odom"
    assert result["robot"] == "turtlebot3_waffle"
    scenario = (out / "scenario.yaml").read_text()
    assert '"/robot2/cmd_vel"' in scenario and '"/robot2/ground_truth/odom"' in scenario
    # it starts where robot2 started (1.5 m from robot1's start) and follows robot2's commands
    first = result["position_error_each_s"][0]
    assert first["t_s"] == 0.0 and first["error_m"] < 0.01
    assert result["position_error_max_m"] < 0.1
    assert _path_length(truth["gt"]["robot2"]) > 1.0  # robot2 moved: the small error says something


def test_a_bag_of_one_namespaced_robot_needs_no_namespace(tmp_path: Path) -> None:
    # One robot under a namespace (nav2_bringup's multi-robot launch with one robot): the tools take it.
    scenario = tmp_path / "one.yaml"
    scenario.write_text(
        "name: one_ns\nmax_duration_s: 6\nrobots:\n  - name: tb3_0\n"
        "    robot: {initial_pose: {x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}\n"
    )
    bag = tmp_path / "bag"
    assert run_twin("simulate", str(scenario), "--out", str(bag)).returncode == 0
    world = REPO / "sdf" / "worlds" / "house.sdf"
    proc = run_twin("replay", str(bag), "--world", str(world), "--out", str(tmp_path / "r"), "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["topic_a"] == "/tb3_0/ground_truth/odom"
    proc = run_twin("analyze", "compare", str(bag), str(bag), "--json")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["topic_a"] == result["topic_b"] == "/tb3_0/ground_truth/odom"
    assert result["position_error_max_m"] == 0.0


def test_graph_groups_a_fleet_by_namespace() -> None:
    scenario = str(REPO / "scenarios" / "house_two_waffles.yaml")
    proc = run_twin("graph", scenario, "--measure-s", "1", "--json")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    groups = {g["namespace"]: g for g in data["namespaces"]}
    assert list(groups) == ["/robot1", "/robot2", ""]
    for ns in ("/robot1", "/robot2"):
        assert groups[ns]["nodes"] and all(n.startswith(ns + "/") for n in groups[ns]["nodes"])
        assert f"{ns}/amcl" in groups[ns]["nodes"] and f"{ns}/scan" in groups[ns]["topics"]
    assert set(groups[""]["topics"]) == {"/clock", "/rosout"}
    # the groups split the graph: every node and topic in exactly one
    assert sorted(n for g in groups.values() for n in g["nodes"]) == sorted(n["node"] for n in data["nodes"])
    assert sorted(t for g in groups.values() for t in g["topics"]) == sorted(t["topic"] for t in data["topics"])
    text = run_twin("graph", scenario, "--measure-s", "1").stdout
    assert "namespace /robot1: " in text and "namespace /robot2: " in text
    assert "outside the robots' namespaces: " in text
    dot = run_twin("graph", scenario, "--measure-s", "1", "--dot").stdout
    assert dot.count("subgraph cluster_") == 2 and 'label="/robot2";' in dot


def test_graph_of_one_robot_has_no_groups() -> None:
    proc = run_twin("graph", "--measure-s", "1", "--json")
    assert proc.returncode == 0, proc.stderr
    assert "namespaces" not in json.loads(proc.stdout)


def test_head_on_contacts_and_closest_approach(head_on_bag: Path, tmp_path: Path) -> None:
    truth = _read_truth(head_on_bag)
    # the robots touched: each robot's own contacts name the other (robot2::turtlebot3_waffle::...)
    own = {
        ns: sum(1 for _t, what in truth["touching"][ns] if what.startswith(f"{other}::"))
        for ns, other in (("robot1", "robot2"), ("robot2", "robot1"))
    }
    assert all(own.values()), truth["touching"]
    proc = run_twin("analyze", str(head_on_bag), "--out", str(tmp_path / "r"), "--json", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    for ns in ROBOTS:
        assert report["robots"][ns]["metrics"]["contacts"] == truth["contacts"][ns]
    # both robots report their touches (some ms apart): each counts its own, the other's once in them
    assert report["robot_contacts"] == {"robot1": {"robot2": own["robot1"]}, "robot2": {"robot1": own["robot2"]}}
    t_s, d = _distance(truth)
    i = int(np.argmin(d))
    dist = report["inter_robot_distance"]
    assert dist["min_m"] == pytest.approx(float(d[i]), abs=1e-12)
    assert dist["min_t_s"] == pytest.approx(float(t_s[i]), abs=1e-9)
    assert dist["min_t_s"] > 1.0  # they closed in from 1.5 m: the minimum is not the start
    assert dist["min_m"] < 1.0


# A Burger and a Waffle driven head on by their commands alone (no Nav2): they touch at about 4.7 s.
MIXED_HEAD_ON = """
name: mixed_head_on
robots:
  - name: robot1
    robot: {model: turtlebot3_burger, initial_pose: {x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}
    mission: {type: cmd_vel_script, rate_hz: 10.0, segments: [{duration_s: 10.0, linear_mps: 0.15, angular_radps: 0.0}]}
  - name: robot2
    robot: {initial_pose: {x_m: 1.5, y_m: 0.0, yaw_rad: 3.14159}}
    mission: {type: cmd_vel_script, rate_hz: 10.0, segments: [{duration_s: 10.0, linear_mps: 0.15, angular_radps: 0.0}]}
"""


def test_a_touch_the_robots_report_ms_apart_counts_once(tmp_path: Path) -> None:
    scenario = tmp_path / "mixed_head_on.yaml"
    scenario.write_text(MIXED_HEAD_ON)
    bag = tmp_path / "bag"
    proc = run_twin("simulate", str(scenario), "--duration", "8", "--out", str(bag))
    assert proc.returncode == 0, proc.stderr
    truth = _read_truth(bag)
    # each robot reports the touch, at a step of its own drive: not at one time
    (t1, what1), (t2, what2) = truth["touching"]["robot1"] + truth["touching"]["robot2"]
    assert what1.startswith("robot2::") and what2.startswith("robot1::")
    assert t1 != t2 and abs(t1 - t2) < 50_000_000, (t1, t2)
    proc = run_twin("analyze", str(bag), "--out", str(tmp_path / "r"), "--json", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["robot_contacts"] == {"robot1": {"robot2": 1}, "robot2": {"robot1": 1}}
    for ns in ROBOTS:
        assert report["robots"][ns]["metrics"]["contacts"] == 1


def test_without_ground_truth_the_distance_comes_from_amcl(fleet_bag: Path, tmp_path: Path) -> None:
    """A fleet's bag as a real multi-robot run records it: no ground truth, AMCL in the shared map frame."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    bag = tmp_path / "no_truth"
    amcl: dict[str, dict[int, tuple[float, float]]] = {ns: {} for ns in ROBOTS}
    with (
        Reader(fleet_bag) as reader,
        AnyReader([fleet_bag]) as decoder,
        Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as writer,
    ):
        out = {}
        for con in reader.connections:
            if con.topic.endswith("/ground_truth/odom"):
                continue
            out[con.id] = writer.add_connection(
                con.topic, con.msgtype, msgdef=con.msgdef.data, rihs01=con.digest, serialization_format="cdr"
            )
        kept = [c for c in reader.connections if c.id in out]
        for con, t_ns, raw in reader.messages(connections=kept):
            writer.write(out[con.id], t_ns, raw)
            if con.topic.endswith("/amcl_pose"):
                msg = decoder.deserialize(raw, con.msgtype)
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                amcl[con.topic.split("/")[1]][stamp] = (msg.pose.pose.position.x, msg.pose.pose.position.y)
    proc = run_twin("analyze", str(bag), "--out", str(tmp_path / "r"), "--json", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    dist = json.loads(proc.stdout)["inter_robot_distance"]
    assert dist["source"] == "AMCL estimates in the map frame"
    assert dist["topics"] == ["/robot1/amcl_pose", "/robot2/amcl_pose"]
    # recomputed: both estimates interpolated at every stamp of either, over the span both cover
    tracks = {
        ns: (np.array(sorted(a), dtype=np.float64), np.array([a[s] for s in sorted(a)])) for ns, a in amcl.items()
    }
    lo = max(t[0] for t, _ in tracks.values())
    hi = min(t[-1] for t, _ in tracks.values())
    at = np.unique(np.concatenate([t for t, _ in tracks.values()]))
    at = at[(at >= lo) & (at <= hi)]
    xy = {ns: np.stack([np.interp(at, t, p[:, 0]), np.interp(at, t, p[:, 1])], 1) for ns, (t, p) in tracks.items()}
    d = np.hypot(*(xy["robot1"] - xy["robot2"]).T)
    assert dist["samples"] == len(at)
    assert dist["min_m"] == pytest.approx(float(d.min()), abs=1e-9)
    assert dist["min_t_s"] == pytest.approx(float(at[int(np.argmin(d))]) * 1e-9, abs=1e-9)
