"""A fleet's cameras, read back from the bag: each robot's own camera under its namespace, seeing the others.

Two Waffles face each other in the empty world, robot2 driving towards robot1. Each robot's depth
image shows the other robot's body at the distance the ground truth puts it (at the time of the
frame), its pixels drawn over the background; every camera topic is under its robot's namespace,
its frames as the robot's other messages name them (prefixed with `tf: {mode: frame_prefix}`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from twin.core.errors import ConfigError
from twin.sim.camera import robot_body
from twin.sim.mission import TreeMission
from twin.sim.robot_group import scenario_robot
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation

EMPTY_WORLD = REPO.parent / "shared" / "fixtures" / "gazebo_classic" / "worlds" / "empty_world.world"
W, H = 160, 120
GAP_M = 1.2  # between the robots' origins at the start
SPEED_MPS = 0.2  # robot2 drives towards robot1


def _scenario(tmp_path: Path, **extra: Any) -> Path:
    data: dict[str, Any] = {
        "name": "fleet_camera",
        "world": {"sdf": str(EMPTY_WORLD)},
        "localization": {"type": "none"},
        "drive": {"type": "kinematic"},
        "odometry": "ground_truth",
        "mission": {"type": "none"},
        "sensors": {
            "camera": {"enabled": True, "width": W, "height": H, "rate_hz": 5.0, "depth": True, "noise": False}
        },
        "robots": [
            {"name": "robot1", "robot": {"initial_pose": {"x_m": 0.0, "y_m": 0.0, "yaw_rad": 0.0}}},
            {
                "name": "robot2",
                "robot": {"initial_pose": {"x_m": GAP_M, "y_m": 0.0, "yaw_rad": math.pi}},
                "mission": {
                    "type": "cmd_vel_script",
                    "rate_hz": 10,
                    "segments": [{"duration_s": 3.0, "linear_mps": SPEED_MPS}],
                },
            },
        ],
        **extra,
    }
    path = tmp_path / "fleet_camera.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _record(scenario: Path, bag: Path, duration_s: float) -> dict[str, list[tuple[int, Any]]]:
    with Simulation(load_scenario(scenario), bag_path=bag, duration_s=duration_s) as sim:
        sim.run()
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([bag]) as reader:
        for con, t_ns, raw in reader.messages():
            if "/camera/" in con.topic or con.topic.endswith("/ground_truth/odom"):
                out.setdefault(con.topic, []).append((t_ns, reader.deserialize(raw, con.msgtype)))
    return out


@pytest.fixture(scope="module")
def facing(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[int, Any]]]:
    tmp = tmp_path_factory.mktemp("fleet_camera")
    return _record(_scenario(tmp), tmp / "bag", duration_s=2.5)


def _depth(msg: Any) -> NDArray[np.float32]:
    return np.frombuffer(msg.data, dtype=np.float32).reshape(msg.height, msg.width)


def _rgb(msg: Any) -> NDArray[np.uint8]:
    return np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, 3)


def _truth_at(messages: list[tuple[int, Any]], t_ns: int) -> tuple[float, float]:
    stamp, odom = min(messages, key=lambda m: abs(m[0] - t_ns))
    assert stamp == t_ns  # ground truth at the very time of the frame
    p = odom.pose.pose.position
    return p.x, p.y


def _waffle() -> Any:
    return load_scenario(default_scenario_path())  # the default robot: the Waffle


@pytest.mark.parametrize(("me", "other"), [("robot1", "robot2"), ("robot2", "robot1")])
def test_each_depth_image_shows_the_other_robot_where_the_ground_truth_puts_it(
    facing: dict[str, list[tuple[int, Any]]], me: str, other: str
) -> None:
    robot = scenario_robot(_waffle())
    camera_x_m = float(np.asarray(robot.cameras[0].T_base_sensor)[0, 3])  # the R200 ahead of the origin
    front_m = float(robot_body(robot).vertices[:, 0].max())
    assert 0.06 < front_m < 0.08  # the Waffle's base plate reaches 0.069 m ahead of its origin
    frames = facing[f"/{me}/camera/depth/image_raw"]
    assert len(frames) >= 10
    gaps = []
    for t_ns, msg in frames:
        depth = _depth(msg)
        mx, my = _truth_at(facing[f"/{me}/ground_truth/odom"], t_ns)
        ox, oy = _truth_at(facing[f"/{other}/ground_truth/odom"], t_ns)
        gap = math.hypot(ox - mx, oy - my)
        gaps.append(gap)
        # Below the optical axis, on the axis's column: the other robot's base plate, square to the axis.
        seen = depth[H // 2 + 4 : H // 2 + 12, W // 2]
        expected = gap - camera_x_m - front_m
        assert np.all(np.abs(seen - expected) < 0.02), (t_ns, seen, expected)
    assert gaps[0] - gaps[-1] > 0.3  # robot2 drove: each frame saw it where it was then


def test_the_other_robots_pixels_are_drawn_over_the_background(facing: dict[str, list[tuple[int, Any]]]) -> None:
    for me in ("robot1", "robot2"):
        (_, image), (_, depth) = facing[f"/{me}/camera/image_raw"][0], facing[f"/{me}/camera/depth/image_raw"][0]
        rgb, d = _rgb(image), _depth(depth)
        background = rgb[0, 0]  # the sky: nothing in the empty world stands that high
        assert not np.isfinite(d[0, 0])
        body = np.isfinite(d) & (d < 2.0)
        assert body.sum() > 500  # the other Waffle fills a good part of a 160x120 frame at 1 m
        assert np.all(np.any(rgb[body] != background, axis=1))


def test_every_camera_topic_is_under_its_robots_namespace(facing: dict[str, list[tuple[int, Any]]]) -> None:
    cameras = {topic for topic in facing if "/camera/" in topic}
    assert cameras == {
        f"/{ns}/camera/{name}"
        for ns in ("robot1", "robot2")
        for name in ("image_raw", "camera_info", "depth/image_raw", "points")
    }
    for topic in cameras:
        assert {m.header.frame_id for _, m in facing[topic]} == {"camera_rgb_optical_frame"}, topic
    stamps = [t for t, _ in facing["/robot1/camera/image_raw"]]
    assert stamps == [t for t, _ in facing["/robot2/camera/image_raw"]]  # both at the sensor's rate, in sim time


def test_each_robot_decides_its_own_camera_and_frame_prefix_names_its_frames(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, tf={"mode": "frame_prefix"})
    data = yaml.safe_load(scenario.read_text())
    data["robots"][1]["sensors"] = {"camera": {"enabled": False}}
    scenario.write_text(yaml.safe_dump(data))
    topics = _record(scenario, tmp_path / "bag", duration_s=0.5)
    cameras = {topic for topic in topics if "/camera/" in topic}
    assert cameras == {f"/robot1/camera/{n}" for n in ("image_raw", "camera_info", "depth/image_raw", "points")}
    for topic in cameras:
        assert {m.header.frame_id for _, m in topics[topic]} == {"robot1/camera_rgb_optical_frame"}, topic


def test_each_robots_tree_looks_through_its_own_camera(tmp_path: Path) -> None:
    path = tmp_path / "two.yaml"
    data = yaml.safe_load((REPO / "scenarios" / "house_two_waffles.yaml").read_text())
    data["sensors"] = {"camera": {"enabled": True, "width": W, "height": H}}
    data["robots"][1]["mission"]["locations"] = str(REPO / "trees" / "sim_house_locations_reversed.yaml")
    path.write_text(yaml.safe_dump(data))
    with Simulation(load_scenario(path), bag_path=None, duration_s=0.1) as sim:
        missions = [g.mission for g in sim.groups]
        assert all(isinstance(m, TreeMission) for m in missions)
        sources = [m.images.source for m in missions if isinstance(m, TreeMission)]
        assert all(s is not None for s in sources) and sources[0] is not sources[1]
        for source in sources:
            assert source is not None
            source.want(True)  # as LookForObject does: the camera draws while a reader waits
        sim.run()
        for g, source in zip(sim.groups, sources, strict=True):
            assert source is not None
            frame = source.latest()
            assert frame is not None, g.namespace  # each robot's own camera drew for its own reader


def test_a_camera_on_a_robot_without_one_names_the_fleet_entry(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "name: x\nsensors: {camera: {enabled: true}}\nrobots:\n  - {name: robot1}\n"
        "  - {name: robot2, robot: {model: turtlebot3_burger, initial_pose: {x_m: 1.5, y_m: -0.2}}}\n"
    )
    message = "robots[1].sensors.camera.enabled: robot 'turtlebot3_burger' has no <sensor type=\"camera\">"
    with pytest.raises(ConfigError, match=r"^robots\[1\]\.sensors\.camera\.enabled: robot 'turtlebot3_burger'"):
        Simulation(load_scenario(bad), bag_path=None)
    result = run_twin("simulate", str(bad), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert not (tmp_path / "bag").exists()
