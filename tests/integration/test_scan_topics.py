"""Costmap observation sources and AMCL read the scan topics their params name, resolved as Nav2 Humble does.

The twin used to feed every LaserScan source the robot's lidar, whatever its `topic`. Nav2 Humble's
obstacle layer subscribes to the topic it is given: a relative `scan` resolves in the costmap's own
namespace (`/local_costmap/scan`, which nothing publishes: the layer stays empty, the turtlebot4
users' well-known Humble pitfall), and a laser filter's `/scan_filtered` is read when a node
publishes it. A crate 1 m ahead of the spawn pose shows what each costmap learned. AMCL's
`scan_topic` was ignored the same way.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from twin.nav.costmap_2d.costmap_node import source_topic

SCENARIO = """
name: costmap_sources
localization: {type: none}
navigation:
  type: nav2
  set: {SET}
obstacles:
  - {shape: box, size_m: [0.3, 0.3, 0.5], pose: {x_m: 1.0, y_m: 0.0}, name: crate}
"""

FILTER = """
from twin.msgs import LaserScan
from twin.node import Node

class ScanFilter(Node):
    '''Republishes /scan on /scan_filtered with every range halved: where the costmap marks tells which it read.'''

    def __init__(self):
        super().__init__("scan_filter")
        self.pub = self.create_publisher(LaserScan, "/scan_filtered", 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, 10)

    def on_scan(self, scan):
        scan.ranges = [r / 2.0 for r in scan.ranges]
        self.pub.publish(scan)
"""

CRATE = (0.85, 1.15, -0.15, 0.15)


def _both_layers(topic: str) -> str:
    """`navigation.set` giving both obstacle layers of the (Burger's) local costmap this source topic."""
    keys = [f"local_costmap/local_costmap.{layer}.scan.topic: {topic}" for layer in ("obstacle_layer", "voxel_layer")]
    return "{" + ", ".join(keys) + "}"


def _last_costmaps(tmp: Path, settings: str, *nodes: str) -> tuple[Any, Any, str]:
    scenario = tmp / "scenario.yaml"
    text = SCENARIO.replace("{SET}", settings)
    if nodes:
        (tmp / "scan_filter.py").write_text(FILTER)
        text += "nodes: [" + ", ".join(f"{{plugin: {n}}}" for n in nodes) + "]\n"
    scenario.write_text(text)
    bag = tmp / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", "3")
    assert result.returncode == 0, result.stderr
    last: dict[str, Any] = {}
    with AnyReader([bag]) as reader:
        wanted = [c for c in reader.connections if c.topic.endswith("_costmap/costmap")]
        for connection, _, raw in reader.messages(connections=wanted):
            last[connection.topic] = reader.deserialize(raw, connection.msgtype)
    return last["/local_costmap/costmap"], last["/global_costmap/costmap"], result.stderr


def _crate_cost(grid: Any) -> int:
    info = grid.info
    data = np.asarray(grid.data, dtype=np.int16).reshape(info.height, info.width)
    res, ox, oy = info.resolution, info.origin.position.x, info.origin.position.y
    x0, x1, y0, y1 = CRATE
    return int(
        data[int((y0 - oy) // res) : int((y1 - oy) // res) + 1, int((x0 - ox) // res) : int((x1 - ox) // res) + 1].max()
    )


def test_a_relative_source_topic_reads_nothing_as_in_nav2_humble(tmp_path: Path) -> None:
    local, global_costmap, err = _last_costmaps(tmp_path, _both_layers("scan"))
    assert np.max(local.data) < 99  # the local costmap (no static layer) never saw anything
    assert _crate_cost(global_costmap) == 100  # the global one, reading /scan, did
    assert "[local_costmap.local_costmap] voxel_layer.scan: topic 'scan' is /local_costmap/scan, which nothing" in err
    assert "write /scan" in err


def test_a_filtered_scan_a_node_publishes_is_read(tmp_path: Path) -> None:
    local, global_costmap, err = _last_costmaps(tmp_path, _both_layers("/scan_filtered"), "scan_filter:ScanFilter")
    # Marks where the halved ranges end (nearer than anything is), none where the lidar sees the crate.
    assert np.max(local.data) == 100
    assert _crate_cost(local) < 100  # (inscribed, at most: the marks inflated)
    assert _crate_cost(global_costmap) == 100  # the global costmap reads /scan
    assert "nothing publishes" not in err


def test_source_topics_resolve_as_in_nav2_humble() -> None:
    assert source_topic("/scan", "/local_costmap", "") == "/scan"
    assert source_topic("scan", "/local_costmap", "") == "/local_costmap/scan"
    # a fleet robot: the params' absolute topic is the robot's own, as nav2_bringup's per-robot files write it
    assert source_topic("/scan", "/robot1/local_costmap", "/robot1") == "/robot1/scan"
    assert source_topic("scan", "/robot1/local_costmap", "/robot1") == "/robot1/local_costmap/scan"
    # ... one that names the robot already (a per-robot file, or `<robot_namespace>/scan` filled in) as it is
    assert source_topic("/robot1/scan", "/robot1/local_costmap", "/robot1") == "/robot1/scan"
    assert source_topic("/robot10/scan", "/robot1/local_costmap", "/robot1") == "/robot1/robot10/scan"


def test_a_fleets_shared_params_file_with_robot_namespace_placeholders_reads_each_robots_scans(
    tmp_path: Path,
) -> None:
    # nav2_bringup Humble's nav2_multirobot_params_all.yaml writes `<robot_namespace>/scan`, which its
    # launch fills in per robot: the run failed with "'/global_costmap/<robot_namespace>/scan' is not a topic name"
    waffle = REPO.parent / "shared" / "fixtures" / "nav2" / "turtlebot3_navigation2_humble" / "param" / "humble"
    text = (waffle / "waffle.yaml").read_text()
    assert text.count("topic: /scan") == 4  # both layers of both costmaps
    params = tmp_path / "all.yaml"
    params.write_text(text.replace("topic: /scan", "topic: <robot_namespace>/scan"))
    scenario = tmp_path / "pair.yaml"
    scenario.write_text(
        f"name: pair\nnavigation: {{type: nav2, params: {params}}}\nrobots:\n  - {{name: robot1}}\n"
        "  - {name: robot2, robot: {initial_pose: {x_m: 1.5, y_m: -0.2}}}\n"
    )
    checked = run_twin("scenario", "check", str(scenario))
    assert checked.returncode == 0, checked.stderr
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", "4")
    assert result.returncode == 0, result.stderr
    assert "nothing publishes" not in result.stderr and "<robot_namespace>" not in result.stderr
    last: dict[str, Any] = {}
    with AnyReader([bag]) as reader:
        wanted = [c for c in reader.connections if c.topic.endswith("/local_costmap/costmap")]
        for connection, _, raw in reader.messages(connections=wanted):
            last[connection.topic] = reader.deserialize(raw, connection.msgtype)
    for ns in ("robot1", "robot2"):  # each costmap marked what its own robot's lidar saw
        assert (np.asarray(last[f"/{ns}/local_costmap/costmap"].data) == 100).any(), ns


AMCL_SCENARIO = """
name: amcl_scan_topic
navigation:
  type: nav2
  set: {amcl.scan_topic: TOPIC}
"""

REPUBLISHER = '''
from twin.msgs import LaserScan
from twin.node import Node

class Republisher(Node):
    """Republishes /scan on /scan_copy: as it is, or with its angles shifted by `shift_rad`."""

    def __init__(self):
        super().__init__("republisher")
        self.shift = self.declare_parameter("shift_rad", 0.0).value
        self.pub = self.create_publisher(LaserScan, "/scan_copy", 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, 10)

    def on_scan(self, scan):
        scan.angle_min += self.shift
        scan.angle_max += self.shift
        self.pub.publish(scan)
'''


def _amcl_poses(tmp: Path, topic: str, shift_rad: float | None = None) -> tuple[int, str]:
    tmp.mkdir(parents=True, exist_ok=True)
    scenario = tmp / "scenario.yaml"
    text = AMCL_SCENARIO.replace("TOPIC", topic)
    if shift_rad is not None:
        (tmp / "republisher.py").write_text(REPUBLISHER)
        text += f"nodes: [{{plugin: republisher:Republisher, parameters: {{shift_rad: {shift_rad}}}}}]\n"
    scenario.write_text(text)
    bag = tmp / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", "4")
    assert result.returncode == 0, result.stderr
    with AnyReader([bag]) as reader:
        wanted = [c for c in reader.connections if c.topic == "/amcl_pose"]
        count = sum(1 for _ in reader.messages(connections=wanted))
    return count, result.stderr


def test_amcl_reads_its_scan_topic(tmp_path: Path) -> None:
    default, _ = _amcl_poses(tmp_path / "a", "scan")  # TB3's own value
    assert default > 0
    copied, err = _amcl_poses(tmp_path / "b", "/scan_copy", shift_rad=0.0)
    assert copied == default, err  # the same scans, from another topic
    assert "nothing publishes" not in err


def test_amcl_on_a_topic_nothing_publishes_is_said_and_never_localizes(tmp_path: Path) -> None:
    count, err = _amcl_poses(tmp_path, "/nowhere")
    assert count == 0
    assert "[amcl] scan_topic '/nowhere' is /nowhere, which nothing publishes" in err


def test_amcl_ignores_a_scan_whose_beams_are_not_the_lidars(tmp_path: Path) -> None:
    count, err = _amcl_poses(tmp_path, "/scan_copy", shift_rad=0.1)
    assert count == 0
    assert err.count("[amcl] ignoring scans on /scan_copy whose beams are not the lidar's") == 1


def test_the_lidar_publishes_on_its_sdf_plugins_topic_and_nav2_reads_it_there(tmp_path: Path) -> None:
    # A robot whose ray sensor plugin remaps its output to scan_front, and Nav2 params that name it.
    model = tmp_path / "front_burger"
    shutil.copytree(REPO / "sdf" / "models" / "turtlebot3_burger", model)
    sdf = model / "model.sdf"
    sdf.write_text(sdf.read_text().replace("~/out:=scan<", "~/out:=scan_front<"))
    keys = [f"{c}/{c}.{layer}.scan.topic: /scan_front" for c in ("global_costmap", "local_costmap")
            for layer in ("obstacle_layer", "voxel_layer")]  # fmt: skip
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(
        f"name: scan_front\nrobot: {{model: {sdf}}}\n"
        "navigation: {type: nav2, set: {amcl.scan_topic: scan_front, " + ", ".join(keys) + "}}\n"
        "obstacles:\n  - {shape: box, size_m: [0.3, 0.3, 0.5], pose: {x_m: 1.0, y_m: 0.0}, name: crate}\n"
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", "4")
    assert result.returncode == 0, result.stderr
    assert "nothing publishes" not in result.stderr
    with AnyReader([bag]) as reader:
        topics = {c.topic for c in reader.connections}
        wanted = [c for c in reader.connections if c.topic in ("/amcl_pose", "/local_costmap/costmap")]
        last: dict[str, Any] = {}
        poses = 0
        for connection, _, raw in reader.messages(connections=wanted):
            poses += connection.topic == "/amcl_pose"
            last[connection.topic] = reader.deserialize(raw, connection.msgtype)
    assert "/scan_front" in topics and "/scan" not in topics
    assert poses > 0  # AMCL localized from /scan_front
    assert _crate_cost(last["/local_costmap/costmap"]) == 100  # the costmap saw the crate on /scan_front


def test_the_imu_and_joint_states_go_on_their_plugins_topics_and_the_ekf_reads_them_there(tmp_path: Path) -> None:
    model = tmp_path / "renamed_burger"
    shutil.copytree(REPO / "sdf" / "models" / "turtlebot3_burger", model)
    sdf = model / "model.sdf"
    text = sdf.read_text().replace("~/out:=imu<", "~/out:=imu_raw<").replace("~/out:=joint_states<", "~/out:=wheels<")
    sdf.write_text(text)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(f"name: renamed\nrobot: {{model: {sdf}}}\nlocalization: {{type: none}}\n")
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", "4")
    assert result.returncode == 0, result.stderr
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        odom = [
            reader.deserialize(raw, c.msgtype).pose.pose.position.x
            for c, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic == "/odom"])
        ]
        truth = [
            reader.deserialize(raw, c.msgtype).pose.pose.position.x
            for c, _, raw in reader.messages(
                connections=[c for c in reader.connections if c.topic == "/ground_truth/odom"]
            )
        ]
    assert counts["/imu_raw"] > 0 and counts["/wheels"] > 0
    assert "/imu" not in counts and "/joint_states" not in counts
    assert abs(truth[-1] - truth[0]) > 0.05  # the robot moved
    assert odom[-1] - odom[0] == pytest.approx(truth[-1] - truth[0], abs=0.02)  # and the EKF followed it


def _burger_remapped(tmp_path: Path, remapping: str) -> Path:
    """The project's Burger with its gazebo_ros_diff_drive given this `<ros>` remapping."""
    model = tmp_path / "remapped_burger"
    shutil.copytree(REPO / "sdf" / "models" / "turtlebot3_burger", model)
    sdf = model / "model.sdf"
    ros = f"<ros><remapping>{remapping}</remapping></ros>"
    sdf.write_text(sdf.read_text().replace("<update_rate>30</update_rate>", ros + "<update_rate>30</update_rate>", 1))
    return sdf


def _simulated(tmp_path: Path, text: str, duration: str) -> tuple[str, Path]:
    """Run a scenario of this text for `duration` s; its stderr and bag."""
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(text)
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--duration", duration)
    assert result.returncode == 0, result.stderr
    return result.stderr, bag


def test_a_diff_drive_remapped_away_from_cmd_vel_hears_nothing_as_in_gazebo_and_says_so(tmp_path: Path) -> None:
    # gazebo_ros_diff_drive listening on cmd_vel_raw: Nav2's /cmd_vel reaches nothing, and one line says so.
    sdf = _burger_remapped(tmp_path, "cmd_vel:=cmd_vel_raw")
    stderr, bag = _simulated(tmp_path, f"name: raw\nrobot: {{model: {sdf}}}\n", "4")
    (line,) = [ln for ln in stderr.splitlines() if "nothing publishes" in ln]
    assert "/cmd_vel_raw" in line and "/cmd_vel has publishers" in line
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        truth = [
            reader.deserialize(raw, c.msgtype).pose.pose.position
            for c, _, raw in reader.messages(
                connections=[c for c in reader.connections if c.topic == "/ground_truth/odom"]
            )
        ]
    assert counts["/cmd_vel"] > 20  # Nav2 drove
    assert max(abs(p.x - truth[0].x) + abs(p.y - truth[0].y) for p in truth) < 1e-3  # and the robot never moved


def test_ground_truth_odometry_goes_on_the_diff_drives_remapped_odom_topic(tmp_path: Path) -> None:
    sdf = _burger_remapped(tmp_path, "odom:=wheel_odom")
    text = f"name: wheel_odom\nrobot: {{model: {sdf}}}\nodometry: ground_truth\nmission: {{type: none}}\n"
    _, bag = _simulated(tmp_path, text, "1")
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/wheel_odom"] == 30 and "/odom" not in counts  # its 30 Hz, on its topic
