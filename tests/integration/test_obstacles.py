"""Obstacles that appear, vanish and walk, read back from the bags of whole runs (`twin simulate`).

The world is Gazebo's empty world (shared fixtures), so every finite lidar range comes from an
obstacle and can be computed by hand: each scan is compared beam by beam with the analytic ranges
of the obstacles present at its stamp.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import FIXTURES, REPO, run_twin
from twin.world import load_robot

EMPTY_WORLD = FIXTURES / "gazebo_classic" / "worlds" / "empty_world.world"

LIDAR = f"""
name: obstacles_lidar
world: {{sdf: {EMPTY_WORLD}}}
localization: {{type: none}}
sensors: {{lidar: {{noise_std_m: 0.0}}}}
mission: {{type: none}}
obstacles:
  - {{shape: box, size_m: [0.3, 0.3, 0.4], pose: {{x_m: 2.0, y_m: 0.0, yaw_rad: 0.0}}, appear_s: 1.0, vanish_s: 3.0}}
  - {{shape: cylinder, radius_m: 0.2, height_m: 1.7, path_xy_m: [[-1, 2], [3, 2]], speed_mps: 0.5, loop: true,
     name: walker}}
"""

CONTACT = f"""
name: obstacles_contact
world: {{sdf: {EMPTY_WORLD}}}
localization: {{type: none}}
mission:
  type: cmd_vel_script
  rate_hz: 10
  segments: [{{duration_s: 6.0}}, {{duration_s: 8.0, linear_mps: 0.2}}]
obstacles:
  - {{shape: cylinder, radius_m: 0.15, height_m: 1.7, path_xy_m: [[0, -1.5], [0, 1.5]], speed_mps: 0.5,
     appear_s: 1.0, vanish_s: 6.5, name: walker}}
  - {{shape: box, size_m: [0.3, 0.3, 0.4], pose: {{x_m: 1.2, y_m: 0.0}}, appear_s: 6.0, name: crate}}
"""

BOX = (1.85, 2.15, -0.15, 0.15)  # the box of LIDAR: x_min, x_max, y_min, y_max
WALKER_R_M = 0.2


def _run(tmp: Path, text: str, *extra: str) -> dict[str, list[tuple[int, Any]]]:
    scenario = tmp / "scenario.yaml"
    scenario.write_text(text)
    bag = tmp / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag), *extra)
    assert result.returncode == 0, result.stderr
    messages: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([bag]) as reader:
        for con, t_ns, raw in reader.messages():
            messages.setdefault(con.topic, []).append((t_ns, reader.deserialize(raw, con.msgtype)))
    return messages


@pytest.fixture(scope="module")
def lidar_bag(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[int, Any]]]:
    return _run(tmp_path_factory.mktemp("lidar"), LIDAR, "--duration", "10")


@pytest.fixture(scope="module")
def contact_bag(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[int, Any]]]:
    return _run(tmp_path_factory.mktemp("contact"), CONTACT)


def _walker_xy_yaw(t_s: float) -> tuple[float, float, float]:
    """The walker of LIDAR by hand: 4 m east from (-1, 2) at 0.5 m/s, then back, and so on."""
    walked = (0.5 * t_s) % 8.0
    if walked <= 4.0:
        return -1.0 + walked, 2.0, 0.0
    return 3.0 - (walked - 4.0), 2.0, math.pi


def _circle_hit(ox: float, oy: float, c: float, s: float, cx: float, cy: float, r: float) -> float:
    qx, qy = cx - ox, cy - oy
    b = c * qx + s * qy
    disc = b * b - (qx * qx + qy * qy - r * r)
    if disc < 0.0:
        return math.inf
    t = b - math.sqrt(disc)
    return t if t >= 0.0 else math.inf


def _box_hit(ox: float, oy: float, c: float, s: float) -> float:
    x0, x1, y0, y1 = BOX
    lo, hi = 0.0, math.inf
    for o, d, a, b in ((ox, c, x0, x1), (oy, s, y0, y1)):
        if abs(d) < 1e-15:
            if not a <= o <= b:
                return math.inf
            continue
        t0, t1 = sorted(((a - o) / d, (b - o) / d))
        lo, hi = max(lo, t0), min(hi, t1)
    return lo if lo <= hi else math.inf


def _lidar() -> tuple[float, float, float, float]:
    """The Waffle's lidar: its origin on the base (x, y), first beam and beam step in double precision.

    (LaserScan carries the angles as float32; near a circle's edge a grazing beam's range changes
    fast with its angle, so the expected ranges use the angles the lidar cast.)
    """
    robot = load_robot("turtlebot3_waffle", model_path=(REPO / "sdf" / "models",))
    lidar = robot.lidar
    assert lidar is not None
    step = (lidar.angle_max_rad - lidar.angle_min_rad) / (lidar.samples - 1)
    return lidar.mount.x_m, lidar.mount.y_m, lidar.angle_min_rad, step


def test_box_is_seen_only_between_appear_and_vanish_and_walker_at_its_analytic_ranges(
    lidar_bag: dict[str, list[tuple[int, Any]]],
) -> None:
    ox, oy, angle_min, step = _lidar()  # the robot stands at the origin, facing +x
    scans = lidar_bag["/scan"]
    assert len(scans) == 50
    beam0 = {}
    for t_ns, scan in scans:
        t_s = t_ns / 1e9
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        cx, cy, _ = _walker_xy_yaw(t_s)
        box_present = 1.0 <= t_s < 3.0
        expected = np.full(len(ranges), np.inf)
        for i in range(len(ranges)):
            a = angle_min + i * step
            c, s = math.cos(a), math.sin(a)
            hit = _circle_hit(ox, oy, c, s, cx, cy, WALKER_R_M)
            if box_present:
                hit = min(hit, _box_hit(ox, oy, c, s))
            expected[i] = hit if hit < scan.range_max else math.inf
        np.testing.assert_allclose(ranges, expected, rtol=1e-6, atol=1e-6, err_msg=f"scan at {t_s} s")
        assert np.isfinite(ranges).any(), t_s  # the walker is always in view
        beam0[round(t_s, 1)] = ranges[0]
    # Straight ahead: nothing before 1 s, the box's near face (1.85 m from the base) from 1 s, nothing from 3 s.
    assert all(math.isinf(r) for t, r in beam0.items() if t < 1.0 or t >= 3.0)
    box_face = [r for t, r in beam0.items() if 1.0 <= t < 3.0]
    assert len(box_face) == 10
    assert box_face == pytest.approx([1.85 - ox] * 10, abs=1e-6)


def test_walker_pose_on_obstacles_follows_its_path_and_the_box_shows_while_present(
    lidar_bag: dict[str, list[tuple[int, Any]]],
) -> None:
    arrays = lidar_bag["/obstacles"]
    assert arrays[0][0] == 0
    stamps = [t for t, _ in arrays]
    assert np.diff(stamps).max() <= 100_000_000  # at least every 0.1 s while the walker walks
    for t_ns, array in arrays:
        t_s = t_ns / 1e9
        assert array.markers[0].action == 3  # DELETEALL: each message is the whole set
        shown = {m.text: m for m in array.markers[1:]}
        assert set(shown) == ({"obstacle_0", "walker"} if 1.0 <= t_s < 3.0 else {"walker"}), t_s
        walker = shown["walker"]
        x, y, yaw = _walker_xy_yaw(t_s)
        assert walker.type == 3 and walker.header.frame_id == "map"
        assert (walker.pose.position.x, walker.pose.position.y) == pytest.approx((x, y), abs=1e-9)
        assert walker.pose.position.z == pytest.approx(0.85)  # standing on the floor: half its height
        heading = 2.0 * math.atan2(walker.pose.orientation.z, walker.pose.orientation.w)
        assert math.cos(heading - yaw) == pytest.approx(1.0), t_s
        assert (walker.scale.x, walker.scale.y, walker.scale.z) == pytest.approx((0.4, 0.4, 1.7))
        if "obstacle_0" in shown:
            box = shown["obstacle_0"]
            assert box.type == 1
            assert (box.pose.position.x, box.pose.position.y, box.pose.position.z) == pytest.approx((2.0, 0.0, 0.2))


def test_walker_crossing_a_standing_robot_is_one_contact_and_does_not_push_it(
    contact_bag: dict[str, list[tuple[int, Any]]],
) -> None:
    events = [(t / 1e9, m.event, m.world_collision) for t, m in contact_bag["/contacts"]]
    walker = [(t, e) for t, e, what in events if what.startswith("walker::")]
    assert [e for _, e in walker] == [1, 2]  # BEGIN, END
    # The walker (r 0.15 m) reaches the robot's shapes about 0.3 m before its centre does, at 0.5 m/s from
    # y = -1.5 m at 1 s: it touches at ~3.4 s (y ~ -0.3 m) and leaves ~1.2 s later.
    (begin, _), (end, _) = walker
    assert 3.0 < begin < 3.8 and 4.2 < end < 5.0
    poses = [(t / 1e9, m.pose.pose.position) for t, m in contact_bag["/ground_truth/odom"]]
    standing = [(p.x, p.y) for t, p in poses if t < 6.0]
    assert max(abs(v) for xy in standing for v in xy) < 1e-9  # not pushed


def test_robot_driven_into_a_box_stops_with_a_contact(contact_bag: dict[str, list[tuple[int, Any]]]) -> None:
    events = [(t / 1e9, m.event, m.world_collision) for t, m in contact_bag["/contacts"]]
    crate = [(t, e) for t, e, what in events if what.startswith("crate::")]
    assert [e for _, e in crate] == [1]  # it begins, and never ends: the robot keeps pushing
    begin = crate[0][0]
    assert 6.0 + 0.9 / 0.2 < begin < 14.0
    xs = [(t / 1e9, m.pose.pose.position.x) for t, m in contact_bag["/ground_truth/odom"]]
    after = [x for t, x in xs if t > begin + 0.1]
    assert after and max(after) - min(after) < 0.002  # stopped
    # Its front (the Waffle's base box reaches 0.069 m ahead of the base frame) at the crate's face, 1.05 m.
    assert after[-1] == pytest.approx(1.05 - 0.069, abs=0.01)


COSTMAP = """
name: obstacles_costmap
localization: {type: none}
navigation: {type: nav2}
obstacles:
  - {shape: box, size_m: [0.3, 0.3, 0.5], pose: {x_m: 1.0, y_m: 0.0}, name: crate}
"""


def _cells(grid: Any, x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """The cells of an OccupancyGrid (axis-aligned origin) covering [x0, x1] x [y0, y1] (m, its frame)."""
    info = grid.info
    data = np.asarray(grid.data, dtype=np.int16).reshape(info.height, info.width)
    res, ox, oy = info.resolution, info.origin.position.x, info.origin.position.y
    i0, i1 = int((x0 - ox) // res), int((x1 - ox) // res)
    j0, j1 = int((y0 - oy) // res), int((y1 - oy) // res)
    return data[j0 : j1 + 1, i0 : i1 + 1]


def test_nav2_costmaps_learn_an_obstacle_from_the_scan_and_the_map_does_not_hold_it(tmp_path: Path) -> None:
    """The thesis's mission through Nav2 in the house, a crate 1 m ahead of the spawn pose."""
    messages = _run(tmp_path, COSTMAP, "--duration", "3")
    (_, world_map), *_ = messages["/map"]
    crate = (0.85, 1.15, -0.15, 0.15)
    assert (_cells(world_map, *crate) == 0).all()  # free on the map made from the world
    _, local = messages["/local_costmap/costmap"][-1]
    assert local.header.frame_id == "odom"  # odom = map here (localization: none, spawned at the origin)
    assert _cells(local, *crate).max() == 100  # lethal where the scan hits the crate
    _, global_costmap = messages["/global_costmap/costmap"][-1]
    assert _cells(global_costmap, *crate).max() == 100


def _nested_box_world(folder: Path) -> Path:
    """A world whose model 'shelf' (1.2 m ahead of the origin) includes model://box (link box_link)."""
    box = folder / "models" / "box"
    box.mkdir(parents=True)
    (box / "model.sdf").write_text(
        "<sdf version='1.6'><model name='box'><link name='box_link'><collision name='collision'>"
        "<geometry><box><size>0.3 0.3 0.4</size></box></geometry></collision></link></model></sdf>"
    )
    world = folder / "nested.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='shelf'><static>true</static>"
        "<pose>1.2 0 0.2 0 0 0</pose><include><uri>model://box</uri></include></model></world></sdf>"
    )
    return world


def test_contact_with_a_nested_world_model_names_each_scope_once(tmp_path: Path) -> None:
    world = _nested_box_world(tmp_path)
    text = (
        f"name: nested\nworld: {{sdf: {world}, model_path: [{tmp_path / 'models'}]}}\nlocalization: {{type: none}}\n"
        "mission: {type: cmd_vel_script, segments: [{duration_s: 6.0, linear_mps: 0.2}]}\n"
    )
    contacts = _run(tmp_path, text)["/contacts"]
    assert [m.world_collision for _, m in contacts] == ["shelf::box::box_link::collision"]
