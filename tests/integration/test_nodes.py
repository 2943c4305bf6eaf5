"""Nodes on the graph, end to end: the shipped example nodes, user-node faults through the CLI, determinism, `twin graph`."""

from __future__ import annotations

import json
import math
import re
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import run_twin
from twin.bag import read_messages
from twin.sim.scenario_file import load_scenario
from twin.world import build_scene, load_robot, load_world

pytestmark = pytest.mark.slow


def _messages(bag: Path, topic: str) -> list[tuple[int, Any]]:
    return [(m.t_ns, m.msg) for m in read_messages(bag, topics=[topic])]


def _all(bag: Path) -> list[tuple[str, int, bytes]]:
    return [(m.topic, m.t_ns, m.msg) for m in read_messages(bag, decode=False)]


def test_the_initial_pose_node_publishes_the_thesis_message_once(repo: Path, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    run = run_twin(
        "simulate", str(repo / "examples" / "nodes" / "init_amcl_pose.yaml"), "--duration", "3", "--out", str(bag)
    )
    assert run.returncode == 0, run.stderr
    poses = _messages(bag, "/initialpose")
    assert len(poses) == 1
    t_ns, msg = poses[0]
    assert t_ns == 100_000_000  # its 0.1 s timer's first firing; the recorder already listens
    assert msg.header.frame_id == "map"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 100_000_000)
    assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == (0.0, 0.0)
    assert msg.pose.pose.orientation.w == 1.0
    cov = np.asarray(msg.pose.covariance).reshape(6, 6)
    assert cov[0, 0] == cov[1, 1] == cov[5, 5] == 0.25
    assert np.count_nonzero(cov) == 3
    logs = [m for _, m in _messages(bag, "/rosout") if m.name == "init_amcl_pose"]
    assert any("initial pose sent" in m.msg for m in logs)


def test_the_wall_follower_drives_the_house_for_a_minute_without_touching(repo: Path, tmp_path: Path) -> None:
    scenario_path = repo / "examples" / "nodes" / "wall_follower.yaml"
    bag = tmp_path / "bag"
    run = run_twin("simulate", str(scenario_path), "--out", str(bag))
    assert run.returncode == 0, run.stderr
    poses = []
    for _, odom in _messages(bag, "/ground_truth/odom"):
        q = odom.pose.pose.orientation
        poses.append(
            (odom.pose.pose.position.x, odom.pose.pose.position.y, math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z))
        )
    assert _messages(bag, "/contacts") == []
    p = np.array(poses)
    assert p.shape[0] > 1700  # 60 s at 30 Hz
    travelled = float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum())
    assert travelled > 5.0
    sc = load_scenario(scenario_path)
    world = load_world(sc.world.sdf, model_path=sc.world.model_path)
    robot = load_robot(sc.robot.model, model_path=sc.world.model_path)
    scene = build_scene(world, exclude_models=(robot.name,))
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    clearance = min(scene.distance(body, *pose) for pose in poses[::2])
    assert clearance > 0.15
    commands = _messages(bag, "/cmd_vel")
    assert len(commands) > 250  # one per scan, 5 Hz


def test_the_same_seed_gives_the_same_messages_to_the_byte(repo: Path, tmp_path: Path) -> None:
    runs = []
    for name in ("a", "b", "c"):
        seed = "9" if name == "c" else "5"
        run = run_twin("simulate", "--duration", "15", "--seed", seed, "--out", str(tmp_path / name))
        assert run.returncode == 0, run.stderr
        runs.append(_all(tmp_path / name))
    assert runs[0] == runs[1]
    scans = [[d for t, _, d in r if t == "/scan"] for r in runs]
    assert scans[0] != scans[2]  # another seed, other lidar noise


def test_recording_topics_exclude_keeps_a_topic_out_while_its_subscribers_still_hear_it(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: no_imu_in_bag\nrecording: {topics: {exclude: [/imu]}}\n")
    bag = tmp_path / "bag"
    run = run_twin("simulate", str(scenario), "--duration", "5", "--out", str(bag))
    assert run.returncode == 0, run.stderr
    topics = {m.topic for m in read_messages(bag, decode=False)}
    assert "/imu" not in topics
    assert {"/odom", "/scan", "/joint_states"} <= topics


def _user_scenario(tmp_path: Path, module: str, nodes: str, *, mission: str = "") -> Path:
    (tmp_path / "my_nodes.py").write_text(textwrap.dedent(module))
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(f"name: user\n{mission}nodes:\n{textwrap.indent(textwrap.dedent(nodes), '  ')}")
    return scenario


_MODULE = """
from twin.msgs import String, Twist
from twin.node import Node

class Spinner(Node):
    def __init__(self):
        super().__init__("spinner")
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        msg = Twist()
        msg.angular.z = 0.5
        self.pub.publish(msg)

class Faulty(Node):
    def __init__(self):
        super().__init__("faulty")
        self.create_timer(0.5, self.on_timer)
        self.n = 0

    def on_timer(self):
        self.n += 1
        if self.n == 3:
            raise KeyError("no such goal")

class ScanAsString(Node):
    def __init__(self):
        super().__init__("liar")
        self.create_publisher(String, "/scan", 10)

class NotANode:
    pass
"""


def test_a_user_node_drives_the_robot_when_the_scenario_has_no_mission(tmp_path: Path) -> None:
    scenario = _user_scenario(tmp_path, _MODULE, "- plugin: my_nodes:Spinner\n", mission="mission: {type: none}\n")
    bag = tmp_path / "bag"
    run = run_twin("simulate", str(scenario), "--duration", "4", "--out", str(bag))
    assert run.returncode == 0, run.stderr
    truth = _messages(bag, "/ground_truth/odom")
    q = truth[-1][1].pose.pose.orientation
    yaw = math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z)
    assert yaw == pytest.approx(0.5 * 3.9, abs=0.1)  # commands from 0.1 s on, at 0.5 rad/s, the wheels' ramp
    assert len(_messages(bag, "/cmd_vel")) == 39


@pytest.mark.parametrize(
    ("nodes", "code", "expected"),
    [
        ("- plugin: my_node:Spinner\n", 2, "module 'my_node' not found.*did you mean 'my_nodes'"),
        ("- plugin: my_nodes:Spiner\n", 2, "has no 'Spiner'.*did you mean 'Spinner'"),
        ("- plugin: wall_folower\n", 2, "no node plugin 'wall_folower'"),
        ("- plugin: my_nodes:NotANode\n", 2, "is not a twin.node.Node subclass"),
        (
            "- plugin: my_nodes:ScanAsString\n",
            2,
            "liar publishes /scan as std_msgs/msg/String, but /scan is sensor_msgs/msg/LaserScan",
        ),
        ("- plugin: my_nodes:Spinner\n  remappings: {/cmd_vel: cmd vel}\n", 2, "remapping /cmd_vel -> cmd vel"),
        ("- plugin: my_nodes:Spinner\n- plugin: my_nodes:Spinner\n", 2, "two nodes are named /spinner"),
    ],
)
def test_bad_user_nodes_are_one_line_config_errors_before_any_bag(
    tmp_path: Path, nodes: str, code: int, expected: str
) -> None:
    scenario = _user_scenario(tmp_path, _MODULE, nodes)
    bag = tmp_path / "bag"
    run = run_twin("simulate", str(scenario), "--duration", "2", "--out", str(bag))
    assert run.returncode == code, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr
    assert lines[0].startswith("twin: error: ")
    assert re.search(expected, lines[0]), lines[0]
    assert not bag.exists()


def test_a_raising_callback_ends_the_run_with_exit_8_and_a_readable_bag(tmp_path: Path) -> None:
    scenario = _user_scenario(tmp_path, _MODULE, "- plugin: my_nodes:Faulty\n")
    bag = tmp_path / "bag"
    run = run_twin("simulate", str(scenario), "--duration", "10", "--out", str(bag))
    assert run.returncode == 8
    line = run.stderr.strip().splitlines()[-1]
    assert "Traceback" not in run.stderr
    assert "node faulty: timer callback Faulty.on_timer raised KeyError: 'no such goal' at t=1.500 s" in line
    clock = [t for t, _ in _messages(bag, "/clock")]
    assert clock[-1] == 1_400_000_000  # everything up to the fault; the clock (10 Hz) publishes after user nodes
    assert max(m.t_ns for m in read_messages(bag, decode=False)) == 1_500_000_000


def test_twin_graph_lists_nodes_topics_types_and_rates() -> None:
    run = run_twin("graph", "--json", "--measure-s", "2")
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    nodes = {n["node"]: n for n in data["nodes"]}
    assert {"/mission", "/diff_drive", "/lidar", "/imu", "/ekf_odometry", "/robot_state_publisher"} <= set(nodes)
    assert {"/amcl", "/bt_navigator", "/controller_server", "/velocity_smoother", "/planner_server"} <= set(nodes)
    topics = {t["topic"]: t for t in data["topics"]}
    # Nav2's chain, as Humble's bringup remaps it: DWB into the smoother, the smoother and the behaviours
    # (not remapped in Humble) to the drive
    assert sorted(topics["/cmd_vel"]["publishers"]) == ["/behavior_server", "/velocity_smoother"]
    assert topics["/cmd_vel"]["subscribers"] == ["/diff_drive"]
    assert topics["/cmd_vel_nav"]["publishers"] == ["/controller_server"]
    assert topics["/cmd_vel_nav"]["subscribers"] == ["/velocity_smoother"]
    assert topics["/imu"]["rate_hz"] == pytest.approx(200.0, rel=0.01)
    assert topics["/scan"]["type"] == "sensor_msgs/msg/LaserScan"
    assert topics["/tf_static"]["latched"] is True
    dot = run_twin("graph", "--dot", "--measure-s", "0")
    assert dot.returncode == 0 and dot.stdout.startswith('digraph "house_waffle"')
    assert '"/velocity_smoother" -> "/cmd_vel";' in dot.stdout
