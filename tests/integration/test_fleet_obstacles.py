"""`obstacles:` with several robots, read back from the bag: each robot's lidar sees them, each robot hits its own.

Two Waffles side by side in an empty world drive straight ahead, each towards a box standing in
its lane; a person (a cylinder) walks across far ahead of both. Every robot's scan shows both
boxes and the person where they are, each robot's contacts name the box it ran into, and the
world's `/obstacles` is published once, not once per robot.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import REPO, run_twin
from tests.integration.fleet_helpers import simulate_and_read
from twin.sim.robot_group import scenario_robot
from twin.sim.scenario_file import load_scenario

EMPTY_WORLD = REPO.parent / "shared" / "fixtures" / "gazebo_classic" / "worlds" / "empty_world.world"

LANES = {"robot1": 0.0, "robot2": 1.5}  # y of each robot's lane
FACE_X = 0.7  # each box's near face (boxes 0.2 m deep, 0.6 m wide, centred at x 0.8)
# The person walks towards the robots between their lanes, seen past the boxes' edges by both.
WALKER_X0, WALKER_Y, WALKER_SPEED, WALKER_R = 1.6, 0.75, 0.2, 0.15

SCENARIO = f"""
name: fleet_boxes
world: {{sdf: {EMPTY_WORLD}}}
localization: {{type: none}}
drive: {{type: kinematic}}
max_duration_s: 8
mission:
  type: cmd_vel_script
  rate_hz: 10
  segments: [{{duration_s: 6.0, linear_mps: 0.15}}]
obstacles:
  - {{shape: box, size_m: [0.2, 0.6, 0.4], pose: {{x_m: 0.8, y_m: 0.0, yaw_rad: 0.0}}, name: box_a}}
  - {{shape: box, size_m: [0.2, 0.6, 0.4], pose: {{x_m: 0.8, y_m: 1.5, yaw_rad: 0.0}}, name: box_b}}
  - {{shape: cylinder, radius_m: {WALKER_R}, height_m: 1.7, path_xy_m: [[{WALKER_X0}, {WALKER_Y}], [1.0, {WALKER_Y}]],
     speed_mps: {WALKER_SPEED}, name: person}}
robots:
  - {{name: robot1, robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}}}}}
  - {{name: robot2, robot: {{initial_pose: {{x_m: 0.0, y_m: 1.5, yaw_rad: 0.0}}}}}}
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]], Path]:
    tmp = tmp_path_factory.mktemp("fleet_obstacles")
    scenario = tmp / "boxes.yaml"
    scenario.write_text(SCENARIO)
    decoded = ("/scan", "/contacts", "/ground_truth/odom", "/obstacles")
    summary, messages = simulate_and_read(scenario, tmp / "bag", lambda con: con.topic.endswith(decoded))
    return summary, messages, scenario


def _scan_origin(
    messages: dict[str, list[tuple[int, Any]]], ns: str, t_ns: int, mount_x: float
) -> tuple[float, float, float]:
    truth = messages[f"/{ns}/ground_truth/odom"]
    i = int(np.argmin([abs(t - t_ns) for t, _ in truth]))
    pose = truth[i][1].pose.pose
    yaw = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
    return pose.position.x + math.cos(yaw) * mount_x, pose.position.y + math.sin(yaw) * mount_x, yaw


@pytest.mark.parametrize("ns", list(LANES))
def test_each_robots_lidar_sees_both_boxes_where_they_stand(run: tuple[Any, Any, Path], ns: str) -> None:
    _, messages, scenario = run
    lidar = scenario_robot(load_scenario(scenario).robot_scenarios()[0][1]).lidar
    assert lidar is not None
    t_ns, scan = messages[f"/{ns}/scan"][0]  # at the spawn pose
    sx, sy, yaw = _scan_origin(messages, ns, t_ns, lidar.mount.x_m)
    tolerance = 4 * max(lidar.noise_std_m, 0.005) + 0.01
    n = len(scan.ranges)
    for box_y in LANES.values():  # its own box ahead, and the other robot's, off to one side
        # The beam towards the middle of the box's near face, and what that face is along it.
        bearing = math.atan2(box_y - sy, FACE_X - sx) - yaw
        beam = round((math.remainder(bearing, math.tau) - scan.angle_min) / scan.angle_increment) % n
        angle = yaw + scan.angle_min + beam * scan.angle_increment
        expected = (FACE_X - sx) / math.cos(angle)
        assert abs(box_y - (sy + expected * math.sin(angle))) < 0.3  # the beam hits the face, not a side
        assert abs(float(scan.ranges[beam]) - expected) < tolerance, (ns, box_y, float(scan.ranges[beam]), expected)


@pytest.mark.parametrize("ns", list(LANES))
def test_each_robots_lidar_sees_the_walking_person(run: tuple[Any, Any, Path], ns: str) -> None:
    _, messages, scenario = run
    lidar = scenario_robot(load_scenario(scenario).robot_scenarios()[0][1]).lidar
    assert lidar is not None
    n_seen = 0
    for t_ns, scan in messages[f"/{ns}/scan"][:6]:  # the first 1.2 s
        sx, sy, yaw = _scan_origin(messages, ns, t_ns, lidar.mount.x_m)
        px = WALKER_X0 - WALKER_SPEED * t_ns / 1e9
        bearing = math.atan2(WALKER_Y - sy, px - sx) - yaw
        beam = round((math.remainder(bearing, math.tau) - scan.angle_min) / scan.angle_increment) % len(scan.ranges)
        expected = math.hypot(px - sx, WALKER_Y - sy) - WALKER_R
        near = [float(scan.ranges[(beam + k) % len(scan.ranges)]) for k in (-1, 0, 1)]
        # The person is where its path puts it at the scan's time (within a 10 ms update step).
        if min(abs(r - expected) for r in near) < 0.03:
            n_seen += 1
    assert n_seen == 6, ns


def test_each_robot_runs_into_its_own_box_and_its_contacts_name_it(run: tuple[Any, Any, Path]) -> None:
    summary, messages, _ = run
    assert summary["contacts"] >= 2
    for ns, box in (("robot1", "box_a"), ("robot2", "box_b")):
        contacts = messages.get(f"/{ns}/contacts", [])
        assert contacts, ns
        text = " ".join(str(getattr(m, f)) for _, m in contacts for f in m.__dataclass_fields__)
        assert f"{box}::link" in text and ("box_b" if box == "box_a" else "box_a") not in text, (ns, text[:300])
        _, last = messages[f"/{ns}/ground_truth/odom"][-1]
        assert last.pose.pose.position.x < FACE_X  # stopped at its box (its front 0.069 m ahead of its origin)


def test_the_obstacles_are_published_once_for_the_world(run: tuple[Any, Any, Path]) -> None:
    _, messages, _ = run
    assert not [t for t in messages if t.endswith("/obstacles") and t != "/obstacles"]
    stamps = [t for t, _ in messages["/obstacles"]]
    assert stamps and len(stamps) == len(set(stamps))  # one publisher, not one per robot
    names = {m.ns + str(m.id) for m in messages["/obstacles"][0][1].markers}
    assert len(names) == 3


def test_an_obstacle_on_a_fleet_robots_spawn_pose_names_the_robot(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(SCENARIO.replace("x_m: 0.0, y_m: 1.5", "x_m: 0.8, y_m: 1.5"))
    for command in (("simulate", str(bad), "--out", str(tmp_path / "bag")), ("scenario", "check", str(bad))):
        result = run_twin(*command)
        assert result.returncode == 2
        line = next(i for i, text in enumerate(bad.read_text().splitlines(), 1) if "name: box_b" in text)
        assert result.stderr.strip().splitlines() == [
            f"twin: error: {bad}:{line}: obstacles[1]: box_b stands on robots[1] (robot2)'s spawn pose (0.8, 1.5) "
            "at t = 0; move it, or the robot's initial_pose"
        ]


def test_with_obstacles_each_lidar_still_sees_the_other_robot(run: tuple[Any, Any, Path]) -> None:
    _, messages, scenario = run
    robot = scenario_robot(load_scenario(scenario).robot_scenarios()[0][1])
    lidar = robot.lidar
    assert lidar is not None
    housing = next(c for c in robot.collisions if c.link.endswith("base_scan"))
    hr = float(housing.geometry.radius_m)  # type: ignore[attr-defined]
    for me, other in (("robot1", "robot2"), ("robot2", "robot1")):
        t_ns, scan = messages[f"/{me}/scan"][0]
        sx, sy, yaw = _scan_origin(messages, me, t_ns, lidar.mount.x_m)
        ox, oy, _ = _scan_origin(messages, other, t_ns, lidar.mount.x_m)  # its lidar housing's centre
        bearing = math.remainder(math.atan2(oy - sy, ox - sx) - yaw, math.tau)
        beam = round((bearing - scan.angle_min) / scan.angle_increment) % len(scan.ranges)
        expected = math.hypot(ox - sx, oy - sy) - hr
        assert abs(float(scan.ranges[beam]) - expected) < 4 * max(lidar.noise_std_m, 0.005) + 0.01, me
