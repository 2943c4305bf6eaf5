"""Two robots in one world (`robots:`), read back from the bag of a whole run (`twin simulate`).

Two Waffles in the house, each with its own Nav2 stack and its own one-goal mission: both reach
their goals, every robot topic is under the robot's namespace as nav2_bringup's multi-robot launch
names them, each namespace's TF is one tree, and each robot's lidar sees the other's body where the
ground truth puts it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from tests.integration.fleet_helpers import ONE_GOAL_TREE, simulate_and_read, write_goals
from twin.sim.robot_group import scenario_robot
from twin.sim.scenario_file import load_scenario
from twin.world.types import Box, Cylinder

SCENARIO = """
name: two_waffles
max_duration_s: 120
mission: {{tree: {tree}}}
robots:
  - name: robot1
    robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}}}
    mission: {{locations: {goal1}}}
  - name: robot2
    robot: {{initial_pose: {{x_m: 1.5, y_m: -0.2, yaw_rad: 0.0}}}}
    mission: {{locations: {goal2}}}
"""

# robot1 goes back to the thesis's location1, robot2 on to its location3: each its own way.
GOALS = {"robot1": (-1.0, -0.5, -2.25), "robot2": (4.0, 0.5, 1.571)}


@pytest.fixture(scope="module")
def fleet_run(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]], Path]:
    tmp = tmp_path_factory.mktemp("fleet")
    tree, files = write_goals(tmp, GOALS)
    scenario = tmp / "two.yaml"
    scenario.write_text(SCENARIO.format(tree=tree, goal1=files["robot1"], goal2=files["robot2"]))
    decoded = ("/scan", "/tf", "/tf_static", "/ground_truth/odom", "/rosout")
    summary, messages = simulate_and_read(scenario, tmp / "bag", lambda con: con.topic.endswith(decoded))
    return summary, messages, scenario


def test_both_robots_reach_their_own_goals(fleet_run: tuple[dict[str, Any], Any, Path]) -> None:
    summary, messages, _ = fleet_run
    assert summary["robots"] == {"robot1": "SUCCESS", "robot2": "SUCCESS"}, summary
    assert summary["mission_result"] == "SUCCESS"
    assert summary["contacts"] == 0
    for name, (x, y, _) in GOALS.items():
        _, last = messages[f"/{name}/ground_truth/odom"][-1]
        p = last.pose.pose.position
        assert math.hypot(p.x - x, p.y - y) < 0.5, (name, p)


def test_every_robot_topic_is_under_its_namespace(fleet_run: tuple[dict[str, Any], Any, Path]) -> None:
    _, messages, _ = fleet_run
    outside = {t for t in messages if not t.startswith(("/robot1/", "/robot2/"))}
    assert outside == {"/clock", "/rosout"}
    for name in GOALS:
        for topic in ("scan", "cmd_vel", "odom", "tf", "tf_static", "amcl_pose", "plan", "map"):
            assert f"/{name}/{topic}" in messages, (name, topic)
    stamps = [t for t, _ in messages["/clock"]]
    assert len(stamps) == len(set(stamps))  # one clock for the world, not one per robot


def test_each_robots_log_lines_carry_its_namespace_as_ros2_names_a_namespaced_nodes_logger(
    fleet_run: tuple[dict[str, Any], Any, Path],
) -> None:
    # rcl names /robot1/bt_navigator's logger `robot1.bt_navigator`: Nav2's lines, the mission tree's
    # and AMCL's say which robot they are about, in the bag as on the console.
    _, messages, _ = fleet_run
    lines = [(m.name, m.msg) for _, m in messages["/rosout"]]
    for name in GOALS:
        assert (f"{name}.bt_navigator", "Goal succeeded") in lines, lines
        assert any(n == f"{name}.bt_navigator" and t.startswith("Begin navigating") for n, t in lines), lines
        assert any(n == f"{name}.mission" and t.endswith("goal reached") for n, t in lines), lines
        assert any(n == f"{name}.amcl" and t.startswith("Setting pose") for n, t in lines), lines
    # Under no robot: only the twin's own lines (the scenario, the run's end).
    assert {n for n, _ in lines if not n.startswith(("robot1.", "robot2."))} == {"twin"}, lines


def _rosout(bag: Path) -> list[Any]:
    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == "/rosout"]
        return [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=connections)]


def test_each_namespace_holds_one_tf_tree(fleet_run: tuple[dict[str, Any], Any, Path]) -> None:
    _, messages, _ = fleet_run
    for name in GOALS:
        parent: dict[str, str] = {}
        for topic in (f"/{name}/tf_static", f"/{name}/tf"):
            for _, msg in messages[topic]:
                for tf in msg.transforms:
                    parent.setdefault(tf.child_frame_id, tf.header.frame_id)
        assert parent["odom"] == "map" and parent["base_footprint"] == "odom"
        roots = set()
        for child in list(parent):
            top = child
            while top in parent:
                top = parent[top]
            roots.add(top)
        assert roots == {"map"}, (name, parent)


def _pose_at(messages: list[tuple[int, Any]], t_ns: int) -> tuple[float, float, float]:
    stamps = [t for t, _ in messages]
    i = int(np.argmin(np.abs(np.array(stamps) - t_ns)))
    pose = messages[i][1].pose.pose
    q = pose.orientation
    return pose.position.x, pose.position.y, 2.0 * math.atan2(q.z, q.w)


def _robot_lidar_housing(scenario_path: Path) -> tuple[Any, Any, Any]:
    """The fleet's robot model, its lidar and its LDS housing's collision (a cylinder)."""
    robot = scenario_robot(load_scenario(scenario_path).robot_scenarios()[0][1])
    assert robot.lidar is not None
    housing = next(c for c in robot.collisions if c.link.endswith("base_scan"))
    assert isinstance(housing.geometry, Cylinder)
    return robot, robot.lidar, housing


@pytest.mark.parametrize(("me", "other"), [("robot1", "robot2"), ("robot2", "robot1")])
def test_each_lidar_sees_the_other_robot_where_it_truly_is(
    fleet_run: tuple[dict[str, Any], Any, Path], me: str, other: str
) -> None:
    _, messages, scenario_path = fleet_run
    _, lidar, housing = _robot_lidar_housing(scenario_path)
    # The other robot's lidar housing is what stands at lidar height (the Waffle's base is lower).
    hx, hr = float(housing.T_world[0, 3]), housing.geometry.radius_m
    t_ns, scan = messages[f"/{me}/scan"][0]  # both still at their spawn poses
    mx, my, myaw = _pose_at(messages[f"/{me}/ground_truth/odom"], t_ns)
    ox, oy, oyaw = _pose_at(messages[f"/{other}/ground_truth/odom"], t_ns)
    sx, sy = mx + math.cos(myaw) * lidar.mount.x_m, my + math.sin(myaw) * lidar.mount.x_m
    cx, cy = ox + math.cos(oyaw) * hx, oy + math.sin(oyaw) * hx
    distance = math.hypot(cx - sx, cy - sy) - hr
    bearing = math.remainder(math.atan2(cy - sy, cx - sx) - myaw, math.tau)
    beam = round((bearing - scan.angle_min) / scan.angle_increment) % len(scan.ranges)
    near = [float(scan.ranges[(beam + k) % len(scan.ranges)]) for k in (-1, 0, 1)]
    assert min(abs(r - distance) for r in near) < 4 * max(lidar.noise_std_m, 0.005) + 0.01, (near, distance)


def _track(messages: list[tuple[int, Any]]) -> tuple[np.ndarray, ...]:
    """Ground truth as arrays (stamp ns, x, y, unwrapped yaw), to interpolate at a scan's stamp."""
    rows = []
    for _, msg in messages:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        rows.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, p.x, p.y, 2.0 * math.atan2(q.z, q.w)))
    t, x, y, yaw = np.array(rows).T
    return t, x, y, np.unwrap(yaw)


def _ray_circle(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: float) -> np.ndarray:
    """Distance along each unit ray (origin o, directions d: N x 2) to a circle; inf where it misses."""
    f = o - c
    b = d @ f
    disc = b * b - (f @ f - r * r)
    t = -b - np.sqrt(np.where(disc >= 0.0, disc, np.nan))
    return np.where((disc >= 0.0) & (t > 0.0), t, np.inf)


def _ray_square(o: np.ndarray, d: np.ndarray, c: np.ndarray, yaw: float, half: float) -> np.ndarray:
    """Distance along each unit ray to a square of half-side `half` centred at c, turned by yaw."""
    rot = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]])
    p, q = rot @ (o - c), d @ rot.T
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (-half - p) / q, (half - p) / q
    near, far = np.nanmax(np.minimum(a, b), axis=1), np.nanmin(np.maximum(a, b), axis=1)
    return np.where((near <= far) & (near > 0.0), near, np.inf)


@pytest.mark.parametrize(("me", "other"), [("robot1", "robot2"), ("robot2", "robot1")])
def test_every_scan_shows_the_other_waffle_as_its_lidar_housing_not_its_base(
    fleet_run: tuple[dict[str, Any], Any, Path], me: str, other: str
) -> None:
    # Issue 23's explanation of the two-Waffle contacts, from the bag: beams that cross the other
    # robot's LDS housing (placed by ground truth) read its distance within the lidar's noise, and
    # beams that cross its base box but miss the housing pass on beyond the box.
    _, messages, scenario_path = fleet_run
    robot, lidar, housing = _robot_lidar_housing(scenario_path)
    base = next(c for c in robot.collisions if c.name == "base_collision")
    assert isinstance(base.geometry, Box)
    hx, hr = float(housing.T_world[0, 3]), housing.geometry.radius_m
    bx, half = float(base.T_world[0, 3]), base.geometry.size_m[0] / 2
    mine, theirs = _track(messages[f"/{me}/ground_truth/odom"]), _track(messages[f"/{other}/ground_truth/odom"])
    on_housing, past_base = [], []
    for _, scan in messages[f"/{me}/scan"]:
        t = scan.header.stamp.sec * 10**9 + scan.header.stamp.nanosec
        mx, my, myaw = (float(np.interp(t, mine[0], v)) for v in mine[1:])
        ox, oy, oyaw = (float(np.interp(t, theirs[0], v)) for v in theirs[1:])
        if not 0.5 < math.hypot(ox - mx, oy - my) < 3.0:
            continue
        origin = np.array([mx + math.cos(myaw) * lidar.mount.x_m, my + math.sin(myaw) * lidar.mount.x_m])
        angles = myaw + scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
        rays = np.column_stack([np.cos(angles), np.sin(angles)])
        ranges = np.asarray(scan.ranges, dtype=float)
        h = _ray_circle(origin, rays, np.array([ox + math.cos(oyaw) * hx, oy + math.sin(oyaw) * hx]), hr)
        wide = _ray_circle(origin, rays, np.array([ox + math.cos(oyaw) * hx, oy + math.sin(oyaw) * hx]), hr + 0.01)
        b = _ray_square(origin, rays, np.array([ox + math.cos(oyaw) * bx, oy + math.sin(oyaw) * bx]), oyaw, half)
        hit, clear = np.isfinite(h), np.isfinite(b) & ~np.isfinite(wide)  # clear of the housing by 1 cm
        on_housing += list(ranges[hit] - h[hit])
        past_base += list(ranges[clear] - b[clear])
    housing_residual, past = np.array(on_housing), np.array(past_base)
    assert len(housing_residual) >= 20 and len(past) >= 20, (len(housing_residual), len(past))
    assert abs(housing_residual.mean()) < 0.005, housing_residual.mean()
    assert housing_residual.std() < 1.5 * lidar.noise_std_m, housing_residual.std()
    assert (np.abs(housing_residual) < 5 * lidar.noise_std_m).all(), housing_residual
    assert (past > 5 * lidar.noise_std_m).all(), np.sort(past)[:5]  # through where the base stands


def test_a_fleet_scenario_with_an_unknown_per_robot_key_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrobots:\n  - {name: a, robot: {initial_pos: {x_m: 1}}}\n")
    result = run_twin("simulate", str(bad), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"twin: error: {bad}:3: robots[0].robot.initial_pos: unknown key; did you mean 'initial_pose'?"
    ]
    assert not (tmp_path / "bag").exists()


@pytest.mark.parametrize(
    ("second", "message"),
    [
        ("{name: a}", ":5: robots[1].name: robots[0] has the same name 'a'; give each robot its own"),
        ("{name: b, namespace: a}", ":5: robots[1].namespace: robots[0] has the same namespace 'a'"),
        ("{name: b, namespace: 'x-y'}", ":5: robots[1].namespace: namespace 'x-y' is not a ROS namespace"),
        ("{name: 2b}", ":5: robots[1].name: name '2b' must be letters, digits and _"),
        # a robot's own lidar settings are checked as the top level's are (not an internal error at the run)
        (
            "{name: b, robot: {initial_pose: {x_m: 1.5}}, sensors: {lidar: {samples: 0}}}",
            ":5: robots[1].sensors.lidar.samples: must be between 1 and 100000, got 0",
        ),
        (
            "{name: b, robot: {initial_pose: {x_m: 1.5}}, sensors: {lidar: {angle_min_rad: 1.0, angle_max_rad: -1.0}}}",
            ":5: robots[1].sensors.lidar.angle_min_rad: 1.0 is not below angle_max_rad -1.0",
        ),
        (
            "{name: b, robot: {initial_pose: {x_m: 1.5}}, sensors: {lidar: {range_min_m: 50}}}",
            ":5: robots[1].sensors.lidar.range_min_m: the lidar's range would be 50 .. 3.5 m",
        ),
        # the tools take every topic under /a/ for robot a's
        ("{name: b, namespace: a/b}", ":5: robots[1].namespace: namespace 'a/b' is inside robots[0]'s namespace 'a'"),
    ],
)
def test_robot_names_and_namespaces_are_checked_naming_the_entry(tmp_path: Path, second: str, message: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"# a fleet\nname: x\nrobots:\n  - {{name: a}}\n  - {second}\n")  # the second on line 5
    for command in (("simulate", str(bad), "--out", str(tmp_path / "bag")), ("scenario", "check", str(bad))):
        result = run_twin(*command)
        assert result.returncode == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and f"{bad}{message}" in lines[0], lines


@pytest.mark.parametrize(
    ("mission", "code", "message"),
    [
        ("{main_tree: Nope}", 6, "trees/tree.xml:5: no <BehaviorTree ID='Nope'> in the loaded files"),
        ("{locations: broken.yaml}", 2, "broken.yaml:2:1: invalid YAML"),
        ("{locations: one.yaml}", 6, "one.yaml has no location 'location2'; did you mean 'location1'?"),
    ],
)
def test_a_robots_own_tree_or_locations_file_refused_names_its_entry(
    tmp_path: Path, mission: str, code: int, message: str
) -> None:
    # In a fleet of four, "which robot's mission is wrong" is the first thing to know.
    (tmp_path / "broken.yaml").write_text("location1: [1, 2\n")
    (tmp_path / "one.yaml").write_text("location1: [1.0, 0.5, 0.0]\n")
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        f"name: x\nrobots:\n  - {{name: a}}\n  - {{name: b, robot: {{initial_pose: {{x_m: 1.5}}}}, mission: {mission}}}\n"
    )
    for command in (("simulate", str(bad), "--out", str(tmp_path / "bag")), ("scenario", "check", str(bad))):
        result = run_twin(*command)
        assert result.returncode == code, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"twin: error: {bad}:4: robots[1]: "), lines
        assert message in lines[0], lines


def test_robots_spawned_overlapping_are_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrobots:\n  - {name: a}\n  - {name: b, robot: {initial_pose: {x_m: 0.2, y_m: 0.0}}}\n")
    for command in (("simulate", str(bad), "--out", str(tmp_path / "bag")), ("scenario", "check", str(bad))):
        result = run_twin(*command)
        assert result.returncode == 2
        assert result.stderr.strip().splitlines() == [
            f"twin: error: {bad}:4: robots[1].robot.initial_pose: robots[0] (a) and robots[1] (b) are spawned "
            "overlapping (0.200 m apart); move one robot's initial_pose"
        ]
    assert not (tmp_path / "bag").exists()


def test_the_shipped_two_robot_scenario_loads_with_opposite_tours() -> None:
    scenario = load_scenario(REPO / "scenarios" / "house_two_waffles.yaml")
    (ns1, one), (ns2, two) = scenario.robot_scenarios()
    assert (ns1, ns2) == ("robot1", "robot2")
    assert one.mission != two.mission  # the second robot reads the locations in the opposite order
    assert one.robot.model == two.robot.model == "turtlebot3_waffle"


EMPTY_WORLD = REPO.parent / "shared" / "fixtures" / "gazebo_classic" / "worlds" / "empty_world.world"

HEAD_ON = f"""
name: head_on
world: {{sdf: {EMPTY_WORLD}}}
localization: {{type: none}}
drive: {{type: kinematic}}
mission:
  type: cmd_vel_script
  rate_hz: 10
  segments: [{{duration_s: 8.0, linear_mps: 0.15}}]
robots:
  - {{name: robot1, robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}}}}}
  - {{name: robot2, robot: {{initial_pose: {{x_m: 1.2, y_m: 0.0, yaw_rad: 3.141592653589793}}}}}}
"""


def test_robots_driving_head_on_collide_and_the_contact_names_both(tmp_path: Path) -> None:
    scenario = tmp_path / "head_on.yaml"
    scenario.write_text(HEAD_ON)
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["contacts"] >= 1
    contacts: dict[str, list[Any]] = {}
    truth: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([bag]) as reader:
        for con, t_ns, raw in reader.messages():
            if con.topic.endswith("/contacts"):
                contacts.setdefault(con.topic, []).append(reader.deserialize(raw, con.msgtype))
            elif con.topic.endswith("/ground_truth/odom"):
                truth.setdefault(con.topic, []).append((t_ns, reader.deserialize(raw, con.msgtype)))
    first = contacts["/robot1/contacts"][0]
    fields = {name: getattr(first, name) for name in first.__dataclass_fields__}
    text = " ".join(str(v) for v in fields.values())
    assert "robot2::" in text and "turtlebot3_waffle::" in text, fields  # the other robot's link, and its own
    # They stopped against each other: a Waffle's base reaches 0.069 m ahead of its origin (its box,
    # 0.266 m long, centred 0.064 m behind it), so face to face their origins stop about 0.138 m apart.
    gaps = []
    for (_, a), (_, b) in zip(truth["/robot1/ground_truth/odom"], truth["/robot2/ground_truth/odom"], strict=False):
        pa, pb = a.pose.pose.position, b.pose.pose.position
        gaps.append(math.hypot(pa.x - pb.x, pa.y - pb.y))
    assert 0.135 < min(gaps) < 0.2, min(gaps)


def test_a_robot_spawned_in_a_wall_is_named_by_its_entry(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrobots: [{name: a}, {name: b, robot: {initial_pose: {x_m: -1.0, y_m: 1.5}}}]\n")
    result = run_twin("simulate", str(bad), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert (
        len(lines) == 1 and "robots[1].robot.initial_pose: (-1.0, 1.5, 0.0) puts turtlebot3_waffle inside" in lines[0]
    )


def test_a_robot_whose_mission_fails_is_named_and_the_run_exits_1(tmp_path: Path) -> None:
    (tmp_path / "fail.xml").write_text(
        '<root BTCPP_format="4" main_tree_to_execute="MainTree">\n'
        '  <BehaviorTree ID="MainTree"><AlwaysFailure name="give_up"/></BehaviorTree>\n</root>\n'
    )
    (tmp_path / "tree.xml").write_text(ONE_GOAL_TREE)
    (tmp_path / "goal.yaml").write_text("goal: [-1.0, -0.5, -2.25]\n")
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        f"name: one_fails\nmax_duration_s: 120\nmission: {{tree: {tmp_path / 'tree.xml'}, locations: {tmp_path / 'goal.yaml'}}}\n"
        "robots:\n  - {name: robot1}\n"
        f"  - {{name: robot2, robot: {{initial_pose: {{x_m: 1.5, y_m: -0.2}}}}, mission: {{tree: {tmp_path / 'fail.xml'}}}}}\n"
    )
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"), "--json")
    assert result.returncode == 1, result.stderr
    summary = json.loads(result.stdout)
    assert summary["robots"] == {"robot1": "SUCCESS", "robot2": "FAILURE"}  # robot1 went on to its goal
    assert summary["mission_result"] == "FAILURE"
    assert summary["mission_failure"].startswith("robot2: ")
    assert "robot1" not in summary["mission_failure"]
    assert summary["ended_by"] == "mission failed"  # every robot's mission ended, not all well


def test_a_fleet_run_by_a_relative_path_reruns_from_its_bag(tmp_path: Path) -> None:
    first, again = tmp_path / "first", tmp_path / "again"
    ran = run_twin("simulate", "scenarios/house_two_waffles.yaml", "--duration", "2", "--out", str(first), cwd=REPO)
    assert ran.returncode == 0, ran.stderr
    rerun = run_twin("simulate", "--from-bag", str(first), "--out", str(again), cwd=tmp_path)
    assert rerun.returncode == 0, rerun.stderr
    counts = []
    for bag in (first, again):
        with AnyReader([bag]) as reader:
            counts.append({c.topic: c.msgcount for c in reader.connections})
    assert counts[0] == counts[1]
    assert "/robot2/scan" in counts[0]


@pytest.mark.parametrize(
    ("entry", "message", "code"),
    [
        (
            "robot: {model: turtlebot3_wafle, initial_pose: {x_m: 1.5}}",
            "robots[1].robot.model: model 'turtlebot3_wafle' not found",
            3,
        ),
        (
            "robot: {initial_pose: {x_m: 1.5}}, disturbances: {wheel_slip: {left_fraction: 0.05, right_fraction: 0.0}}",
            "robots[1].disturbances.wheel_slip: the FMU chassis slips both wheels alike",
            2,
        ),
    ],
)
def test_a_robots_own_section_refused_by_its_model_or_drive_names_its_entry(
    tmp_path: Path, entry: str, message: str, code: int
) -> None:
    # What the robot's model or its drive refuses is the entry's key, not the top level's (which is valid).
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"name: x\nrobots:\n  - {{name: a}}\n  - {{name: b, {entry}}}\n")
    for command in (("simulate", str(bad), "--out", str(tmp_path / "bag")), ("scenario", "check", str(bad))):
        result = run_twin(*command)
        assert result.returncode == code, result.stderr
        assert result.stderr.strip().splitlines()[0].startswith(f"twin: error: {bad}:4: {message}"), result.stderr


def test_scenario_check_lists_a_fleets_robots_each_with_its_own_spawn_model_and_mission() -> None:
    result = run_twin("scenario", "check", str(REPO / "scenarios" / "turtlebot3_world_four_robots.yaml"))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert "  robots    4, frames namespaced" in lines
    robots = [line.split() for line in lines if line.startswith("    /")]
    assert [r[0] for r in robots] == ["/robot1", "/robot2", "/robot3", "/robot4"]
    scenario = load_scenario(REPO / "scenarios" / "turtlebot3_world_four_robots.yaml")
    for words, (_, sc) in zip(robots, scenario.robot_scenarios(), strict=True):
        pose = sc.robot.initial_pose
        assert " ".join(words[1:]).startswith(f"{sc.robot.model} at ({pose.x_m}, {pose.y_m}, {pose.yaw_rad})")
    assert not any(line.startswith("  robot     ") for line in lines)  # no one robot at the origin


def test_the_run_summary_gives_each_robots_drive_and_localization_when_they_differ(tmp_path: Path) -> None:
    # A Burger and a Waffle: different motors, each robot's AMCL; the summary is not the first robot's alone.
    scenario = tmp_path / "mixed.yaml"
    scenario.write_text(
        "name: mixed\nrobots:\n  - {name: burger1, robot: {model: turtlebot3_burger}}\n"
        "  - {name: waffle1, robot: {initial_pose: {x_m: 1.5, y_m: -0.2}}}\n"
    )
    result = run_twin("simulate", str(scenario), "--duration", "4", "--out", str(tmp_path / "bag"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["drive"].startswith("burger1: fmu xl430_w250_servo")
    assert "; waffle1: fmu xm430_w210_servo" in summary["drive"]
    assert set(summary["localization"]) == {"burger1", "waffle1"}
    assert all(loc["updates"] > 0 for loc in summary["localization"].values()), summary["localization"]


def test_a_fleet_robots_console_warnings_name_the_robot(tmp_path: Path) -> None:
    # Two robots driven head on: alpha's command beyond its motors and the contact each reports.
    scenario = tmp_path / "headon.yaml"
    script = "mission: {{type: cmd_vel_script, segments: [{{duration_s: 8.0, linear_mps: {v}}}]}}"
    scenario.write_text(
        "name: headon\nrobots:\n"
        f"  - {{name: alpha, {script.format(v=0.3)}}}\n"
        f"  - {{name: beta, robot: {{initial_pose: {{x_m: 1.5, yaw_rad: 3.14159}}}}, {script.format(v=0.15)}}}\n"
    )
    result = run_twin("simulate", str(scenario), "--duration", "8", "--out", str(tmp_path / "bag"))
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("twin: WARNING: ")]
    # As ROS 2 prints a namespaced node's lines: `[alpha.diff_drive]`, the logger name rcl gives /alpha/diff_drive.
    drive = "twin: WARNING: [alpha.diff_drive] drive: cmd_vel (0.300 m/s"
    assert any(line.startswith(drive) for line in warnings), "\n".join(warnings)
    assert any("[alpha.diff_drive] t=" in line and "contact with beta::" in line for line in warnings), warnings
    assert any("[beta.diff_drive] t=" in line and "contact with alpha::" in line for line in warnings), warnings
    # The bag's /rosout carries the same names (rcl_interfaces/Log's `name`).
    lines = [(m.name, m.msg) for m in _rosout(tmp_path / "bag")]
    assert any(n == "alpha.diff_drive" and t.startswith("drive: cmd_vel") for n, t in lines), lines
    assert any(n == "beta.diff_drive" and "contact with alpha::" in t for n, t in lines), lines


def test_a_fleet_whose_robots_missions_ended_well_in_different_ways_is_complete(tmp_path: Path) -> None:
    # A script that completes beside a robot with no mission: the run is over, not "running".
    scenario = tmp_path / "mixed.yaml"
    scenario.write_text(
        "name: mixed\nrobots:\n"
        "  - {name: alpha, mission: {type: cmd_vel_script, segments: [{duration_s: 2.0, linear_mps: 0.1}]}}\n"
        "  - {name: beta, robot: {initial_pose: {x_m: 1.5}}, mission: {type: none}}\n"
    )
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["robots"] == {"alpha": "complete", "beta": "none"}
    assert summary["mission_result"] == "complete" and summary["ended_by"] == "mission complete"
