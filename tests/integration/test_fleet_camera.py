"""A fleet's cameras, read back from the bag: each robot's own camera under its namespace, seeing the others.

Two Waffles face each other (in the empty world, and in the house), robot2 driving towards robot1.
Each robot's depth image shows the other robot's body at the distance the ground truth puts it (at
the time of the frame), its pixels drawn over what stands behind it; every camera topic is under
its robot's namespace, its frames as the robot's other messages name them (prefixed with
`tf: {mode: frame_prefix}`); each robot's tree looks through its own camera.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, NamedTuple

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


class Facing(NamedTuple):
    """A run of the two facing Waffles: its scenario file and its camera and ground-truth messages by topic."""

    scenario: Path
    topics: dict[str, list[tuple[int, Any]]]


@pytest.fixture(scope="module", params=["empty_world", "house"])
def facing(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Facing:
    tmp = tmp_path_factory.mktemp("fleet_camera")
    scenario = _scenario(tmp)
    if request.param == "house":  # the default world: the thesis's house, walls behind both robots
        data = yaml.safe_load(scenario.read_text())
        del data["world"]
        scenario.write_text(yaml.safe_dump(data))
    return Facing(scenario, _record(scenario, tmp / "bag", duration_s=2.5))


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
    facing: Facing, me: str, other: str
) -> None:
    robot = scenario_robot(_waffle())
    camera_x_m = float(np.asarray(robot.cameras[0].T_base_sensor)[0, 3])  # the R200 ahead of the origin
    front_m = float(robot_body(robot).vertices[:, 0].max())
    assert 0.06 < front_m < 0.08  # the Waffle's base plate reaches 0.069 m ahead of its origin
    frames = facing.topics[f"/{me}/camera/depth/image_raw"]
    assert len(frames) >= 10
    gaps = []
    for t_ns, msg in frames:
        depth = _depth(msg)
        mx, my = _truth_at(facing.topics[f"/{me}/ground_truth/odom"], t_ns)
        ox, oy = _truth_at(facing.topics[f"/{other}/ground_truth/odom"], t_ns)
        gap = math.hypot(ox - mx, oy - my)
        gaps.append(gap)
        # Below the optical axis, on the axis's column: the other robot's base plate, square to the axis.
        seen = depth[H // 2 + 4 : H // 2 + 12, W // 2]
        expected = gap - camera_x_m - front_m
        assert np.all(np.abs(seen - expected) < 0.02), (t_ns, seen, expected)
    assert gaps[0] - gaps[-1] > 0.3  # robot2 drove: each frame saw it where it was then


def test_the_other_robot_hides_what_the_camera_sees_without_it(facing: Facing, tmp_path: Path) -> None:
    # robot1 alone, where it stands in the fleet, in the same world: what its camera sees without robot2.
    data = yaml.safe_load(facing.scenario.read_text())
    data["robot"] = data.pop("robots")[0]["robot"]
    alone = tmp_path / "alone.yaml"
    alone.write_text(yaml.safe_dump(data))
    topics = _record(alone, tmp_path / "bag", duration_s=0.1)
    (t0, image), (t1, depth) = topics["/camera/image_raw"][0], topics["/camera/depth/image_raw"][0]
    (f0, fleet_image), (f1, fleet_depth) = (
        facing.topics["/robot1/camera/image_raw"][0],
        facing.topics["/robot1/camera/depth/image_raw"][0],
    )
    assert t0 == t1 == f0 == f1 == 0
    rgb, d, fleet_rgb, fleet_d = _rgb(image), _depth(depth), _rgb(fleet_image), _depth(fleet_depth)
    hidden = fleet_d < d  # robot2 stands before what robot1 sees alone
    assert hidden.sum() > 500  # the other Waffle fills a good part of a 160x120 frame at 1.2 m
    assert np.array_equal(fleet_rgb[~hidden], rgb[~hidden])  # elsewhere the same picture
    changed = np.any(fleet_rgb[hidden] != rgb[hidden], axis=1)
    assert changed.mean() > 0.99, changed.mean()  # robot2's own colours, not what stands behind it


def test_every_camera_topic_is_under_its_robots_namespace(facing: Facing) -> None:
    cameras = {topic for topic in facing.topics if "/camera/" in topic}
    assert cameras == {
        f"/{ns}/camera/{name}"
        for ns in ("robot1", "robot2")
        for name in ("image_raw", "camera_info", "depth/image_raw", "points")
    }
    for topic in cameras:
        assert {m.header.frame_id for _, m in facing.topics[topic]} == {"camera_rgb_optical_frame"}, topic
    stamps = [t for t, _ in facing.topics["/robot1/camera/image_raw"]]
    assert stamps == [t for t, _ in facing.topics["/robot2/camera/image_raw"]]  # both at the sensor's rate, in sim time


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
    data["recording"] = {"topics": {"exclude_regex": ".*/camera/.*"}}  # nothing records the images
    data["robots"][1]["mission"]["locations"] = str(REPO / "trees" / "sim_house_locations_reversed.yaml")
    path.write_text(yaml.safe_dump(data))
    with Simulation(load_scenario(path), bag_path=tmp_path / "bag", duration_s=0.5) as sim:
        missions = [g.mission for g in sim.groups]
        assert all(isinstance(m, TreeMission) for m in missions)
        sources = [m.images.source for m in missions if isinstance(m, TreeMission)]
        assert sources[0] is not None and sources[1] is not None and sources[0] is not sources[1]
        sources[0].want(True)  # robot1's LookForObject waits for a frame; robot2's tree asks for none
        sim.run()
        assert sources[0].latest() is not None  # robot1's camera drew for robot1's reader
        assert sources[1].latest() is None  # robot2's camera drew nothing


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


def test_a_robots_camera_draws_only_while_its_own_images_are_taken(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from twin.world.render import Renderer

    drawn: dict[int, int] = {}
    draw = Renderer.render

    def counted(self: Renderer, *args: Any, **kwargs: Any) -> Any:
        drawn[id(self)] = drawn.get(id(self), 0) + 1
        return draw(self, *args, **kwargs)

    monkeypatch.setattr(Renderer, "render", counted)
    scenario = _scenario(tmp_path, recording={"topics": {"exclude_regex": "/robot2/camera/.*"}})
    topics = _record(scenario, tmp_path / "bag", duration_s=1.0)
    assert not any(topic.startswith("/robot2/camera/") for topic in topics)
    assert sorted(drawn.values()) == [5]  # robot1's camera every period at 5 Hz; robot2's, unwatched, never
