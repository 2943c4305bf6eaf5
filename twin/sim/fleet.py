"""Several robots in one world: each steps on the one executor, sees the others and collides with them.

A `Fleet` holds the robot groups of a run with more than one robot (`robots:` in the scenario):

- `advance(n)` steps every robot's drive `n` physics steps, one robot after the other: while one
  moves, the others stand where they are, so each robot's free distance (`FleetMonitor.free_m`),
  measured to the others where they stand, holds for its whole chunk.
- `FleetMonitor` is one robot's contact check: the world (and its obstacles) first, then the other
  robots' collision shapes at their current poses (FCL, only when their bounding circles are near).
  A contact names the other robot's namespace and link (`robot2::turtlebot3_waffle::base_link`).
- `FleetView` is what one robot's lidar sees besides the world: the section of every other robot's
  shapes at the lidar's height, where that robot is at the time of the scan.

Nothing here coordinates the robots: each learns of the others from its own sensors only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from twin.core.errors import ConfigError
from twin.world.obstacles import ObstacleCaster
from twin.world.scene import Contact, RobotBody

__all__ = ["AllDone", "Fleet", "FleetMonitor", "FleetView"]

# Closer than this (bounding circles' gap) the exact distance between two robots' shapes is asked, m.
_MARGIN_M = 0.005
# What an FCL distance between two robots' shapes may be off by, m (as for the world).
_TOLERANCE_M = 1e-4
# How many pairs of poses' contacts a robot's check keeps per other robot.
_RECENT_POSES = 8

_Pose = tuple[float, float, float]


class _Monitor(Protocol):
    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]: ...

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float: ...

    def repeats_free(self, x_m: float, y_m: float, yaw_rad: float) -> bool: ...


class _Group(Protocol):
    """What the fleet reads of a robot group (`twin.sim.robot_group.RobotGroup`)."""

    namespace: str
    body: RobotBody | None
    drive: Any
    scenario: Any
    drive_node: Any
    tracker: Any


class _Done(Protocol):
    @property
    def done(self) -> bool: ...


class AllDone:
    """Done when every one of the missions is (the run of a fleet ends with its last mission)."""

    def __init__(self, missions: Sequence[_Done]) -> None:
        self._missions = tuple(missions)

    @property
    def done(self) -> bool:
        """Whether every mission has ended."""
        return all(m.done for m in self._missions)


class Fleet:
    """The robots of one run (see the module docstring).

    Args:
        groups: The robot groups, spawned (each has its body) and not yet built.
    """

    def __init__(self, groups: Sequence[_Group]) -> None:
        self.groups = tuple(groups)
        # While `advance` steps robot `_moving`, every other robot stands at its entry here (read
        # once per chunk instead of from its drive at every contact check of the moving robot).
        self._standing: list[tuple[float, float, float]] | None = None
        self._moving = -1

    def body(self, i: int) -> RobotBody:
        """Robot `i`'s collision body."""
        body = self.groups[i].body
        assert body is not None
        return body

    def pose(self, i: int) -> tuple[float, float, float]:
        """Robot `i`'s pose now (x, y, yaw), its spawn pose before its drive exists."""
        standing = self._standing
        if standing is not None and i != self._moving:
            return standing[i]
        drive = self.groups[i].drive
        if drive is None:
            p = self.groups[i].scenario.robot.initial_pose
            return (p.x_m, p.y_m, p.yaw_rad)
        s = drive.chassis_state()
        return (s.x_m, s.y_m, s.yaw_rad)

    def check_spawn(self) -> None:
        """Refuse two robots spawned touching each other, naming both and their distance.

        Raises:
            ConfigError: If two robots' shapes overlap at their initial poses.
        """
        n = len(self.groups)
        for i in range(n):
            for j in range(i + 1, n):
                a, b = self.pose(i), self.pose(j)
                if self.body(i).distance_to(a, self.body(j), b) > _TOLERANCE_M:
                    continue
                centres = math.hypot(a[0] - b[0], a[1] - b[1])
                msg = (
                    f"robots[{i}] ({self.groups[i].namespace}) and robots[{j}] ({self.groups[j].namespace}) are "
                    f"spawned overlapping ({centres:.3f} m apart); move one robot's initial_pose"
                )
                raise ConfigError(msg)

    def advance(self, n_steps: int) -> None:
        """Step every robot's drive `n_steps` physics steps, one robot after the other."""
        standing = [self.pose(i) for i in range(len(self.groups))]
        self._standing = standing
        try:
            for i, g in enumerate(self.groups):
                self._moving = i
                g.drive_node.advance(n_steps)
                standing[i] = self.pose(i)
        finally:
            self._standing = None
            self._moving = -1

    def after_advance(self, t_ns: int) -> None:
        """Let each robot with an open contact episode track it (report its end)."""
        for g in self.groups:
            if g.tracker.pending:
                g.drive_node.after_advance(t_ns)

    @property
    def pending(self) -> bool:
        """Whether any robot has a contact episode to track."""
        return any(g.tracker.pending for g in self.groups)


class FleetMonitor:
    """One robot's contact check against the world (`inner`) and the fleet's other robots.

    Args:
        inner: The robot's check against the world and its obstacles.
        fleet: The run's robots.
        index: This robot's index in the fleet.
    """

    def __init__(self, inner: _Monitor, fleet: Fleet, index: int) -> None:
        self.inner = inner
        self.fleet = fleet
        self.index = index
        self.others = tuple(j for j in range(len(fleet.groups)) if j != index)
        # Per other robot: (this robot's pose, the other's pose, their exact distance there).
        self._exact: dict[int, tuple[tuple[float, float, float], tuple[float, float, float], float]] = {}
        # Per other robot: (this robot's pose, the other's) -> their contacts, for the last few pairs
        # of poses asked. A robot pressed against another is asked about the same few poses step
        # after step (its motion is below a float's resolution, and `Chassis.update` asks about the
        # refused step and the turn alone); the shapes are rigid, so the same poses give the same
        # contacts, whatever the robots farther away do.
        self._recent: dict[int, dict[tuple[_Pose, _Pose], tuple[Contact, ...]]] = {j: {} for j in self.others}
        # The last check, when it found its pose free: that pose and where the others stood.
        self._last_free: tuple[_Pose, tuple[_Pose, ...]] | None = None

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the contacts at this pose: the world's first, else the other robots' (empty when free)."""
        contacts = self.inner.check(x_m, y_m, yaw_rad)
        if contacts:
            self._last_free = None
            return contacts
        fleet, body = self.fleet, self.fleet.body(self.index)
        pose = (x_m, y_m, yaw_rad)
        found: list[Contact] = []
        wheres: list[_Pose] = []
        for j in self.others:
            other, where = fleet.body(j), fleet.pose(j)
            wheres.append(where)
            gap = math.hypot(where[0] - x_m, where[1] - y_m) - body.radius_m - other.radius_m
            if gap > _MARGIN_M:
                continue
            recent = self._recent[j]
            key = (pose, where)
            pair = recent.get(key)
            if pair is None:
                ns = fleet.groups[j].namespace
                pair = tuple(
                    Contact(
                        model=ns,
                        link=f"{ns}::{theirs.link}",
                        collision=theirs.name,
                        robot_link=mine.link,
                        point=point,
                        normal=normal,
                        depth_m=depth,
                    )
                    for mine, theirs, point, normal, depth in body.contacts_with(pose, other, where)
                )
                if len(recent) >= _RECENT_POSES:
                    del recent[next(iter(recent))]  # the oldest
                recent[key] = pair
            found += pair
        self._last_free = None if found else (pose, tuple(wheres))
        found.sort(key=lambda c: -c.depth_m)
        return tuple(found)

    def repeats_free(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        """Whether the last check was at this pose and found it free, and would find it free again now.

        It would when the world's check repeats its answer (`inner.repeats_free`) and every other
        robot either stands where it stood then, or was and is too far from the pose to be asked
        about: the check's answer is a function of the pose and where the robots near it stand.
        """
        last = self._last_free
        if last is None or last[0] != (x_m, y_m, yaw_rad) or not self.inner.repeats_free(x_m, y_m, yaw_rad):
            return False
        fleet, radius = self.fleet, self.fleet.body(self.index).radius_m
        for j, then in zip(self.others, last[1], strict=True):
            now = fleet.pose(j)
            if now == then:
                continue
            theirs = fleet.body(j).radius_m  # the gaps as `check` computes them, so "far" is bit for bit its own
            if math.hypot(then[0] - x_m, then[1] - y_m) - radius - theirs <= _MARGIN_M:
                return False
            if math.hypot(now[0] - x_m, now[1] - y_m) - radius - theirs <= _MARGIN_M:
                return False
        return True

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return how far the robot may move from this pose touching neither the world nor another robot.

        Sound for one chunk of steps: the others stand still while this robot moves (`Fleet.advance`).
        Near another robot the exact distance (FCL) is measured once and then bounded by how far
        either robot moved since (as `CollisionMonitor` does for the world), asked again only when
        that bound is used up.
        """
        free = self.inner.free_m(x_m, y_m, yaw_rad)
        if free <= 0.0:
            return 0.0
        fleet, body, exact = self.fleet, self.fleet.body(self.index), self._exact
        for j in self.others:
            other, where = fleet.body(j), fleet.pose(j)
            gap = math.hypot(where[0] - x_m, where[1] - y_m) - body.radius_m - other.radius_m
            if gap > _MARGIN_M:
                gap -= _MARGIN_M
            else:
                known = exact.get(j)
                bound = -1.0
                if known is not None:
                    mine, theirs, distance = known
                    bound = distance - _moved(mine, x_m, y_m, yaw_rad, body.radius_m)
                    bound -= _moved(theirs, *where, other.radius_m)
                if bound > _MARGIN_M:
                    gap = bound - _MARGIN_M
                elif known is not None and known[0] == (x_m, y_m, yaw_rad) and known[1] == where:
                    gap = known[2] - _TOLERANCE_M  # neither moved (stalled against each other)
                else:
                    distance = body.distance_to((x_m, y_m, yaw_rad), other, where)
                    exact[j] = ((x_m, y_m, yaw_rad), where, distance)
                    gap = distance - _TOLERANCE_M
            free = min(free, gap)
            if free <= 0.0:
                return 0.0
        return free


def _moved(anchor: tuple[float, float, float], x_m: float, y_m: float, yaw_rad: float, radius_m: float) -> float:
    """How far any point of a body of `radius_m` may have moved from `anchor` to this pose, at most, m."""
    return math.hypot(x_m - anchor[0], y_m - anchor[1]) + radius_m * abs(math.remainder(yaw_rad - anchor[2], math.tau))


class FleetView:
    """What one robot's lidar sees of the other robots: their shapes' section at its height, where they are.

    It answers as an `ObstacleField` does for the lidar (`caster(height_m)`), and joins the world's
    obstacles (`field`, when the run has some) to the robots.

    Args:
        fleet: The run's robots.
        index: The robot whose lidar looks.
    """

    def __init__(self, fleet: Fleet, index: int) -> None:
        self.fleet = fleet
        self.others = tuple(j for j in range(len(fleet.groups)) if j != index)
        self._cache: dict[float, tuple[tuple[tuple[float, float, float], ...], ObstacleCaster | None]] = {}

    def caster(self, height_m: float) -> ObstacleCaster | None:
        """Return a ray caster over the other robots as they stand now at `height_m` (None: none reaches it)."""
        key = round(float(height_m), 9)
        poses = tuple(self.fleet.pose(j) for j in self.others)
        cached = self._cache.get(key)
        if cached is not None and cached[0] == poses:
            return cached[1]
        segments: list[np.ndarray] = []
        circles: list[np.ndarray] = []
        for j, (x, y, yaw) in zip(self.others, poses, strict=True):
            segs, circs = self.fleet.body(j).section(key)
            c, s = math.cos(yaw), math.sin(yaw)
            rot = np.array([[c, s], [-s, c]])  # row vectors: p @ rot is R p
            if len(segs):
                a = segs[:, 0:2] @ rot + (x, y)
                b = segs[:, 2:4] @ rot + (x, y)
                segments.append(np.hstack([a, b]))
            if len(circs):
                centres = circs[:, 0:2] @ rot + (x, y)
                circles.append(np.hstack([centres, circs[:, 2:3]]))
        caster = None
        if segments or circles:
            seg_rows = [(float(r[0]), float(r[1]), float(r[2]), float(r[3])) for arr in segments for r in arr]
            circ_rows = [(float(r[0]), float(r[1]), float(r[2])) for arr in circles for r in arr]
            caster = ObstacleCaster(seg_rows, circ_rows, key)
        self._cache[key] = (poses, caster)
        return caster
