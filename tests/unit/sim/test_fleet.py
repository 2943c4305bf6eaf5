"""The fleet's contact check and lidar view: what one robot knows of the others, checked against FCL and by hand."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from twin.core.errors import ConfigError
from twin.robot.chassis import ChassisState
from twin.robot.nodes import ContactTracker
from twin.sim.fleet import Fleet, FleetMonitor, FleetView
from twin.sim.robot_group import scenario_robot
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.world.robot_model import load_robot
from twin.world.scene import Contact, RobotBody


class _Still:
    """A drive standing at a pose (what the fleet reads of it)."""

    def __init__(self, x: float, y: float, yaw: float) -> None:
        self.pose = (x, y, yaw)

    def chassis_state(self) -> ChassisState:
        return ChassisState(*self.pose, 0.0, 0.0, 0.0, 0.0, 0.0, False)


class _OpenWorld:
    """No walls: nothing but the other robots limits the robot."""

    static = True

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        return ()

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        return math.inf


def _group(namespace: str, pose: tuple[float, float, float]) -> Any:
    robot = scenario_robot(load_scenario(default_scenario_path()))
    body = RobotBody(robot.collisions, base_height_m=robot.base_height_m)
    return SimpleNamespace(namespace=namespace, body=body, drive=_Still(*pose), scenario=None, robot=robot)


def test_the_free_distance_to_another_robot_never_exceeds_the_true_distance() -> None:
    me, other = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.6, 0.1, 1.0))
    fleet = Fleet([me, other])
    monitor = FleetMonitor(_OpenWorld(), fleet, 0)
    rng = np.random.default_rng(3)
    for _ in range(300):
        pose = (float(rng.uniform(-0.1, 0.5)), float(rng.uniform(-0.3, 0.4)), float(rng.uniform(-math.pi, math.pi)))
        free = monitor.free_m(*pose)
        true = me.body.distance_to(pose, other.body, other.drive.pose)
        assert free <= true + 1e-9, (pose, free, true)
        assert (monitor.check(*pose) != ()) == (true <= 1e-4), (pose, true)  # FCL's contact tolerance


def test_a_contact_with_another_robot_names_its_namespace_and_link() -> None:
    fleet = Fleet([_group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.13, 0.0, math.pi))])
    contacts = FleetMonitor(_OpenWorld(), fleet, 0).check(0.0, 0.0, 0.0)
    assert contacts
    assert contacts[0].model == "robot2"
    assert contacts[0].link == "robot2::turtlebot3_waffle::base_link"
    assert contacts[0].robot_link == "turtlebot3_waffle::base_link"


def test_robots_spawned_apart_pass_and_overlapping_ones_are_named() -> None:
    Fleet([_group("a", (0.0, 0.0, 0.0)), _group("b", (1.0, 0.0, 0.0))]).check_spawn()
    with pytest.raises(ConfigError, match=r"robots\[0\] \(a\) and robots\[1\] \(b\) are spawned overlapping"):
        Fleet([_group("a", (0.0, 0.0, 0.0)), _group("b", (0.1, 0.0, 0.0))]).check_spawn()


def test_the_lidar_view_holds_the_other_robots_lidar_housing_where_it_stands() -> None:
    me, other = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (2.0, 1.0, math.pi / 2))
    view = FleetView(Fleet([me, other]), 0)
    height = me.robot.base_height_m + me.robot.lidar.mount.z_m
    caster = view.caster(height)
    assert caster is not None
    segments, circles = caster.shapes
    assert len(segments) == 0 and len(circles) == 1  # a Waffle's base is below its lidar: only the housing
    cx, cy, r = circles[0]
    # The housing stands 0.052 m behind the base frame's origin; turned by 90 degrees, that is -y.
    assert (cx, cy, r) == pytest.approx((2.0, 1.0 - 0.052, 0.0508), abs=1e-9)
    # Nothing of the robots at 0.3 m: above every shape of a Waffle.
    assert view.caster(0.3) is None
    # The other robot moves: the view follows it.
    other.drive.pose = (3.0, 1.0, math.pi / 2)
    moved = view.caster(height)
    assert moved is not None and moved.shapes[1][0][0] == pytest.approx(3.0)


def test_another_waffles_lidar_sees_of_it_what_gazebos_ray_plane_cuts(fixtures: Path) -> None:
    # Gazebo's ray sensor hits the collision shapes of turtlebot3_gazebo's model.sdf, the robot resting
    # on its wheels: the plane of one Waffle's lidar, above the floor, must cut the same shapes of another.
    gazebo = load_robot(fixtures / "gazebo_classic" / "models" / "turtlebot3_waffle" / "model.sdf")
    assert gazebo.lidar is not None
    gazebo_plane = gazebo.base_height_m + gazebo.lidar.mount.z_m
    gazebo_segments, gazebo_circles = RobotBody(gazebo.collisions, base_height_m=gazebo.base_height_m).section(
        gazebo_plane
    )
    me = _group("robot1", (0.0, 0.0, 0.0))
    plane = me.robot.base_height_m + me.robot.lidar.mount.z_m
    assert plane == pytest.approx(gazebo_plane, abs=0.002)  # the URDF's base_scan against Gazebo's ray pose
    segments, circles = me.body.section(plane)
    assert len(gazebo_segments) == len(segments) == 0  # the 27 cm base is below either plane
    assert circles == pytest.approx(gazebo_circles, abs=1e-9)  # the LDS housing: where, and how wide
    assert circles.shape == (1, 3)


def test_another_burgers_lidar_sees_of_it_what_gazebos_ray_plane_cuts(fixtures: Path) -> None:
    # The same for the Burger: its 14 cm base tops out below either plane, the housing is Gazebo's.
    cuts = []
    for model in (fixtures / "gazebo_classic" / "models" / "turtlebot3_burger" / "model.sdf", "turtlebot3_burger"):
        robot = load_robot(model, model_path=[default_scenario_path().parent.parent / "sdf" / "models"])
        assert robot.lidar is not None
        plane = robot.base_height_m + robot.lidar.mount.z_m
        cuts.append((plane, *RobotBody(robot.collisions, base_height_m=robot.base_height_m).section(plane)))
    (gazebo_plane, gazebo_segments, gazebo_circles), (plane, segments, circles) = cuts
    assert plane == pytest.approx(gazebo_plane, abs=0.002)
    assert len(gazebo_segments) == len(segments) == 0
    assert circles.shape == (1, 3) and circles == pytest.approx(gazebo_circles, abs=1e-9)


def test_a_pose_asked_again_is_answered_as_a_fresh_check_and_follows_the_other_robot() -> None:
    # A robot pressed against another is asked about the same few poses step after step; the answer
    # kept for a pose holds only while the other robot stands where it stood.
    me, other = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.13, 0.0, math.pi))
    fleet = Fleet([me, other])
    monitor = FleetMonitor(_OpenWorld(), fleet, 0)
    touching, apart = (0.0, 0.0, 0.0), (-0.3, 0.0, 0.0)
    for _ in range(3):  # alternating, as `Chassis.update` asks about the step and the turn alone
        assert monitor.check(*touching) == FleetMonitor(_OpenWorld(), fleet, 0).check(*touching) != ()
        assert monitor.check(*apart) == ()
    other.drive.pose = (1.0, 0.0, math.pi)  # the other robot drove away
    assert monitor.check(*touching) == ()
    other.drive.pose = (0.13, 0.0, math.pi)  # and came back
    assert monitor.check(*touching) == FleetMonitor(_OpenWorld(), fleet, 0).check(*touching) != ()


def test_whether_a_robot_touches_another_is_what_its_contacts_say_wherever_either_stands() -> None:
    # `touches` (asked at every step of an open contact episode) against `check` from a fresh
    # monitor, over poses touching, grazing and apart, asked twice each (the second from its cache),
    # and after the other robot moves (a kept answer must not outlive where it stood).
    me, other = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.13, 0.0, math.pi))
    fleet = Fleet([me, other])
    monitor = FleetMonitor(_OpenWorld(), fleet, 0)
    rng = np.random.default_rng(11)
    seen = {True: 0, False: 0}
    for k in range(240):
        if k % 40 == 0:
            other.drive.pose = (float(rng.uniform(0.1, 0.3)), float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-4, 4)))
        pose = (float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-4, 4)))
        first = monitor.touches(*pose)  # asked first: nothing else placed the shapes there
        expected = FleetMonitor(_OpenWorld(), fleet, 0).check(*pose) != ()
        assert first == expected == monitor.touches(*pose), (pose, other.drive.pose)
        seen[expected] += 1
    assert seen[True] > 30 and seen[False] > 30  # both answers were compared


def test_a_drive_in_an_open_contact_episode_keeps_the_contacts_it_began_with() -> None:
    me, other = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.13, 0.0, math.pi))
    tracker = ContactTracker(FleetMonitor(_OpenWorld(), Fleet([me, other]), 0))
    assert tracker.touches(0.0, 0.0, 0.0) and tracker.in_contact and tracker.pending
    first = tracker.contact
    assert first and all(c.model == "robot2" for c in first)
    assert tracker.touches(0.005, 0.0, 0.1)  # pressed deeper, turned: still touching, the same episode
    assert tracker.contact == first
    assert not tracker.touches(-0.3, 0.0, 0.0)  # backed off: free


class _Idle:
    """A drive node that does not move its robot (the test moves it by hand between advances)."""

    def advance(self, n_steps: int) -> None:
        pass


def _moved_to(fleet: Fleet, group: Any, pose: tuple[float, float, float]) -> None:
    """Move a robot by hand, and let the fleet see it (as a run's robots move: in its advance)."""
    group.drive.pose = pose
    fleet.advance(1)


class _Walker:
    """A drive node that walks its robot along a seeded random path (1 cm and a little turn per step)."""

    def __init__(self, drive: _Still, seed: int) -> None:
        self.drive, self.rng = drive, np.random.default_rng(seed)

    def advance(self, n_steps: int) -> None:
        x, y, yaw = self.drive.pose
        yaw += float(self.rng.uniform(-0.3, 0.3))
        self.drive.pose = (x + 0.01 * math.cos(yaw), y + 0.01 * math.sin(yaw), yaw)


def test_the_free_distance_among_many_robots_is_what_measuring_every_robot_gives() -> None:
    # Eight robots walking about a 1.5 m square: the robot's free distance looks at the near ones
    # and bounds the far ones by the fleet's odometer; it must answer, call for call, what a
    # monitor measuring every robot every time answers (the drive's budget, hence its path).
    rng = np.random.default_rng(11)
    groups = []
    for k in range(8):
        g = _group(f"robot{k + 1}", (0.5 * (k % 4) - 0.75, 0.6 * (k // 4) - 0.3, float(rng.uniform(-3, 3))))
        g.drive_node = _Walker(g.drive, k) if k else _Idle()
        groups.append(g)
    fleet = Fleet(groups)
    mine, every = FleetMonitor(_OpenWorld(), fleet, 0), FleetMonitor(_OpenWorld(), fleet, 0)
    mine.keep_m = every.keep_m = every.near_m = math.inf  # measured at every call
    kept = FleetMonitor(_OpenWorld(), fleet, 0)  # and answered from the last measurement while it holds
    me = groups[0].drive
    answers, bounds = [], []
    for step in range(400):
        fleet.advance(1)
        x, y, yaw = me.pose
        me.pose = (x + 0.002 * math.cos(step / 40), y + 0.002 * math.sin(step / 40), yaw + 0.01)
        answer = mine.free_m(*me.pose)
        assert answer == every.free_m(*me.pose), step
        answers.append(answer)
        bounds.append(kept.free_m(*me.pose))
        true = min(groups[0].body.distance_to(me.pose, g.body, g.drive.pose) for g in groups[1:])
        assert bounds[-1] <= true, step  # never more than the robots truly leave free
    assert min(answers) < 0.05 < max(answers)  # others came near and went away
    assert sum(b != a for a, b in zip(answers, bounds, strict=True)) > 50  # often answered from the bound


class _Mover:
    """A robot's drive node that moves its drive 0.01 m per step and notes the fleet's poses as it moves."""

    def __init__(self, fleet_of: list[Fleet], drive: _Still) -> None:
        self.fleet_of, self.drive = fleet_of, drive
        self.seen: list[tuple[tuple[float, float, float], ...]] = []

    def advance(self, n_steps: int) -> None:
        x, y, yaw = self.drive.pose
        self.drive.pose = (x + 0.01 * n_steps, y, yaw)
        fleet = self.fleet_of[0]
        self.seen.append(tuple(fleet.pose(i) for i in range(len(fleet.groups))))


def test_while_one_robot_advances_it_reads_itself_live_and_the_others_where_they_moved_to() -> None:
    groups = [_group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (2.0, 0.0, 0.0))]
    fleet_of: list[Fleet] = []
    for g in groups:
        g.drive_node = _Mover(fleet_of, g.drive)
    fleet = Fleet(groups)
    fleet_of.append(fleet)
    fleet.advance(5)
    # robot1 moved first: it sees itself moved and robot2 not yet; robot2 sees robot1 where it ended.
    assert groups[0].drive_node.seen == [((0.05, 0.0, 0.0), (2.0, 0.0, 0.0))]
    assert groups[1].drive_node.seen == [((0.05, 0.0, 0.0), (2.05, 0.0, 0.0))]
    groups[1].drive.pose = (3.0, 0.0, 0.0)  # between advances every pose is read live
    assert fleet.pose(1) == (3.0, 0.0, 0.0)


def _counting_measures(monitor: FleetMonitor) -> list[int]:
    """Count the monitor's measurements (`_measure`: a look at the world and the robots)."""
    count = [0]
    measure = monitor._measure

    def counted(*args: Any) -> tuple[float, float]:
        count[0] += 1
        return measure(*args)

    monitor._measure = counted  # type: ignore[method-assign,assignment]
    return count


def test_a_robot_moving_among_still_ones_keeps_its_measured_free_distance_for_its_own_motion_alone() -> None:
    # Seven robots stand still 0.3 m to 1 m away; robot1 drives away from them. Its kept free distance
    # is less its own motion and the others' (none): one measurement lasts the whole drive, where
    # the fleet's odometer alone (its own motion counted a second time) would ask for another.
    me = _group("robot1", (0.0, 0.0, 0.0))
    others = [_group(f"robot{k + 2}", (0.55 + 0.1 * k, 0.5 * (-1) ** k, 0.0)) for k in range(7)]
    groups = [me, *others]
    for g in groups:
        g.drive_node = _Idle()
    fleet = Fleet(groups)
    monitor = FleetMonitor(_OpenWorld(), fleet, 0)
    measures = _counting_measures(monitor)
    first = monitor.free_m(*me.drive.pose)
    assert 0.2 < first < 0.4
    for _ in range(60):  # 0.12 m back, away from all of them
        x, y, yaw = me.drive.pose
        _moved_to(fleet, me, (x - 0.002, y, yaw))
        free = monitor.free_m(*me.drive.pose)
        true = min(me.body.distance_to(me.drive.pose, g.body, g.drive.pose) for g in others)
        assert monitor.keep_m < free <= true
    assert measures[0] == 1
    # Another robot moves: its motion comes off the kept distance, down to a new measurement.
    before = monitor.free_m(*me.drive.pose)
    _moved_to(fleet, others[0], (0.5, 0.5, 0.0))
    assert monitor.free_m(*me.drive.pose) == pytest.approx(before - 0.05, abs=1e-6)


def test_a_robot_pressed_against_another_is_answered_as_a_measurement_answers_without_one() -> None:
    # Robot1 pressed against robot2 is asked about the same pose again and again (it creeps below a
    # pose's resolution) while robot3 drives about farther away and robot2 now and then moves.
    # Every answer must be the one a monitor measuring at every call gives; most need no look.
    me, touching = _group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.13, 0.0, math.pi))
    walker = _group("robot3", (-1.0, 0.8, 0.0))
    me.drive_node, touching.drive_node = _Idle(), _Idle()
    walker.drive_node = _Walker(walker.drive, 3)
    fleet = Fleet([me, touching, walker])
    mine, every = FleetMonitor(_OpenWorld(), fleet, 0), FleetMonitor(_OpenWorld(), fleet, 0)
    every.keep_m = every.near_m = math.inf  # measured at every call
    measures = _counting_measures(mine)
    rng = np.random.default_rng(5)
    answers = []
    for step in range(300):
        fleet.advance(1)
        if step % 37 == 36:  # robot2 shifts, pulls away or comes back
            _moved_to(fleet, touching, (0.13 + float(rng.choice([0.0, 1e-4, 3e-3, 0.05])), 0.0, math.pi))
        if step % 50 == 49:  # robot1 turns a little
            x, y, yaw = me.drive.pose
            _moved_to(fleet, me, (x, y, yaw + 0.01))
        poses = [me.drive.pose]
        if step % 10 == 0:  # and now and then a step back, as the drive's contact path asks
            poses.append((me.drive.pose[0] - 0.002, 0.0, me.drive.pose[2]))
        for pose in poses:
            answer = mine.free_m(*pose)
            assert answer == every.free_m(*pose), (step, pose)
            answers.append(answer)
    assert answers.count(0.0) > 200 and max(answers) > 0.0  # pressed most of the time, not always
    assert measures[0] < len(answers) / 2


class _NearWall(_OpenWorld):
    """A wall 3 cm ahead wherever the robot stands: the world's free distance is always small."""

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        return 0.03


def test_near_a_wall_the_free_distance_is_the_walls_and_the_robots_are_not_measured_again() -> None:
    # The world leaves 3 cm; the other robots, about a metre away, leave far more. Each call answers
    # the world's 3 cm (what measuring every robot answers), and the robots' part, measured once, is
    # kept less their motion and robot1's: no new look at them while that bound stays large.
    rng = np.random.default_rng(7)
    me = _group("robot1", (0.0, 0.0, 0.0))
    others = [
        _group(f"robot{k + 2}", (1.2 * math.cos(k), 1.2 * math.sin(k), float(rng.uniform(-3, 3)))) for k in range(5)
    ]
    for g in (me, *others):
        g.drive_node = _Idle()
    fleet = Fleet([me, *others])
    mine, every = FleetMonitor(_NearWall(), fleet, 0), FleetMonitor(_NearWall(), fleet, 0)
    every.keep_m = every.near_m = math.inf  # measured at every call
    measures = _counting_measures(mine)
    for step in range(100):
        fleet.advance(1)
        x, y, yaw = me.drive.pose
        me.drive.pose = (x + 0.001, y, yaw + 0.002)
        assert mine.free_m(*me.drive.pose) == every.free_m(*me.drive.pose) == 0.03, step
    assert measures[0] == 1
    # The robots come near: the kept bound runs out and they are measured again, never overstated.
    for step in range(150):
        for g in others:
            gx, gy, gyaw = g.drive.pose
            g.drive.pose = (gx * 0.995, gy * 0.995, gyaw)
        fleet.advance(1)
        free = mine.free_m(*me.drive.pose)
        true = min(me.body.distance_to(me.drive.pose, g.body, g.drive.pose) for g in others)
        assert free <= min(0.03, true), step
    assert measures[0] > 1


def test_the_lidar_views_of_a_fleet_share_each_robots_placed_section_and_follow_it() -> None:
    # The lidars of a fleet scan at the same instants: robot3's section at the lidar's height is
    # placed once for robot1's and robot2's views, and placed again when robot3 moves.
    groups = [_group("robot1", (0.0, 0.0, 0.0)), _group("robot2", (0.0, 2.0, 0.0)), _group("robot3", (2.0, 1.0, 0.5))]
    fleet = Fleet(groups)
    height = groups[0].robot.base_height_m + groups[0].robot.lidar.mount.z_m
    views = [FleetView(fleet, 0), FleetView(fleet, 1)]
    seen = [v.caster(height) for v in views]
    assert all(c is not None for c in seen)
    housing = [c.shapes[1][-1] for c in seen if c is not None]  # robot3's lidar housing, last in each
    assert housing[0] == pytest.approx(housing[1]) and housing[0][0] == pytest.approx(2.0 - 0.052 * math.cos(0.5))
    key = round(height, 9)
    placed = fleet.placed_section(2, key, groups[2].drive.pose)
    assert fleet.placed_section(2, key, groups[2].drive.pose)[1] is placed[1]  # placed once, then shared
    groups[2].drive.pose = (3.0, 1.0, 0.5)
    moved = [v.caster(height) for v in views]
    assert [c.shapes[1][-1][0] for c in moved if c is not None] == pytest.approx([3.0 - 0.052 * math.cos(0.5)] * 2)
