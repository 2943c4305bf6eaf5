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

What one robot's drive asks of the others each step stays about as cheap with eight robots as with
two: the fleet keeps an odometer (`Fleet.travel_nm`, every robot's motion summed), so a robot's free
distance looks at the robots near it and bounds the far ones by how far
the other robots moved since they were last measured (the odometer less the robot's own share,
`Fleet.own_nm`), instead of measuring every robot at every step.

Nothing here coordinates the robots: each learns of the others from its own sensors only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
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
# A robot's free distance measures the others within this gap (bounding circles) at every call, and
# bounds the farther ones by the fleet's odometer, m.
_NEAR_M = 0.3
# Kept back from a bound made of several measured distances, for their rounding, m.
_ROUNDING_M = 1e-9
# Two robots measured touching stay "no free motion" until they moved this much together since, m.
_STILL_TOUCHING_M = 1e-3
# A robot's free distance, once measured, is answered from its bound (less its own motion and the
# fleet's odometer since) while that stays above this: far more than any robot moves between two
# events, so the drive's compiled loop runs as far as with the measured value, m.
_KEEP_M = 0.02

_Pose = tuple[float, float, float]


class _Monitor(Protocol):
    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]: ...

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float: ...


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
        bodies = tuple(g.body for g in self.groups)
        assert all(b is not None for b in bodies), "spawn every robot before making its fleet"
        self.bodies: tuple[RobotBody, ...] = bodies  # type: ignore[assignment]
        self.radii = tuple(b.radius_m for b in self.bodies)
        # While `advance` steps robot `_moving`, every other robot stands at its entry here (read
        # once per chunk instead of from its drive at every contact check of the moving robot).
        self._standing: list[tuple[float, float, float]] | None = None
        self._moving = -1
        self._last: list[tuple[float, float, float]] | None = None  # every pose when `advance` last ended
        self.travel_nm = 0
        """The fleet's odometer: every robot's motion summed (translation + radius x rotation), nm.

        Any robot's centre moved at most the odometer's increase since a moment: a distance
        measured then, less that increase, bounds the distance now. Whole nanometres, each motion
        rounded up, so the sum has no rounding of its own however long the run."""
        self.own_nm = [0] * len(self.groups)
        """Each robot's share of `travel_nm`: `travel_nm - own_nm[i]` is what the robots other than
        `i` moved, all that can bring them nearer to robot `i` where it stands."""
        # Per (robot, height): its shapes' section placed at a pose, shared by every other robot's
        # lidar view (the lidars of a fleet scan at the same instants, each seeing the same robot).
        self._placed: dict[tuple[int, float], tuple[_Pose, np.ndarray | None, np.ndarray | None]] = {}
        self._bound: tuple[tuple[Callable[[int], None], Callable[[], _Pose]], ...] | None = None  # `_drives`

    def body(self, i: int) -> RobotBody:
        """Robot `i`'s collision body."""
        return self.bodies[i]

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

    def placed_section(self, i: int, height_m: float, pose: _Pose) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Robot `i`'s section at `height_m` (`RobotBody.section`) placed at `pose` (None: nothing of it there).

        Returns:
            Its segments (M, 4) and circles (K, 3) in the world frame, m.
        """
        cached = self._placed.get((i, height_m))
        if cached is not None and cached[0] == pose:
            return cached[1], cached[2]
        x, y, yaw = pose
        segs, circs = self.bodies[i].section(height_m)
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, s], [-s, c]])  # row vectors: p @ rot is R p
        placed_segs = placed_circs = None
        if len(segs):
            placed_segs = np.empty_like(segs)
            placed_segs[:, 0:2] = segs[:, 0:2] @ rot + (x, y)
            placed_segs[:, 2:4] = segs[:, 2:4] @ rot + (x, y)
        if len(circs):
            placed_circs = np.empty_like(circs)
            placed_circs[:, 0:2] = circs[:, 0:2] @ rot + (x, y)
            placed_circs[:, 2] = circs[:, 2]
        self._placed[(i, height_m)] = (pose, placed_segs, placed_circs)
        return placed_segs, placed_circs

    def check_spawn(self) -> None:
        """Refuse two robots spawned touching each other, naming both and their distance.

        Raises:
            ConfigError: If two robots' shapes overlap at their initial poses.
        """
        robots = [(g.namespace, self.pose(i), self.body(i)) for i, g in enumerate(self.groups)]
        problem = overlap_problem(robots)
        if problem is not None:
            raise ConfigError(problem)

    def _drives(self) -> tuple[tuple[Callable[[int], None], Callable[[], _Pose]], ...]:
        """Each robot's drive node's `advance` and its drive's pose reader, bound once (the drives are built)."""
        drives = self._bound
        if drives is None:
            drives = self._bound = tuple((g.drive_node.advance, _pose_reader(g.drive)) for g in self.groups)
        return drives

    def advance(self, n_steps: int) -> None:
        """Step every robot's drive `n_steps` physics steps, one robot after the other."""
        drives = self._drives()
        standing: list[_Pose] = [pose() for _, pose in drives]  # (x, y, yaw) of each
        radii = self.radii
        last = self._last
        own = self.own_nm
        if last is not None and last != standing:  # moved between advances (by hand): on the odometers too
            for i, (a, b, r) in enumerate(zip(last, standing, radii, strict=True)):
                nm = _nm(_moved(a, *b, r))
                self.travel_nm += nm
                own[i] += nm
        self._standing = standing
        hypot, remainder, tau, ceil = math.hypot, math.remainder, math.tau, math.ceil
        try:
            for i, (advance, pose) in enumerate(drives):
                self._moving = i
                advance(n_steps)
                x, y, yaw = pose()
                bx, by, byaw = standing[i]
                if x != bx or y != by or yaw != byaw:
                    standing[i] = (x, y, yaw)
                    # _nm(_moved(...)), inline: this runs for every robot at every event
                    nm = ceil((hypot(x - bx, y - by) + radii[i] * abs(remainder(yaw - byaw, tau))) * 1e9) + 1
                    self.travel_nm += nm
                    own[i] += nm
        finally:
            self._standing = None
            self._moving = -1
            self._last = standing

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
        # after step (`Chassis.update` asks about the refused step and the turn alone); the shapes
        # are rigid, so the same poses give the same contacts, whatever the robots farther away do.
        self._recent: dict[int, dict[tuple[_Pose, _Pose], tuple[Contact, ...]]] = {j: {} for j in self.others}
        # The same for `touches` (whether there is any contact), asked far more often than `check`.
        self._recent_touch: dict[int, dict[tuple[_Pose, _Pose], bool]] = {j: {} for j in self.others}
        # For `free_m`: the pose and odometer of its last full look, the smallest gap of the robots
        # farther than _NEAR_M then (inf: none), and the nearer ones (in index order).
        self._far: tuple[_Pose, int, float, tuple[int, ...]] | None = None
        self.near_m = _NEAR_M
        """The gap within which `free_m` measures another robot at every call (inf: every robot)."""
        # The last measured free distance: the pose and the other robots' odometer then, the
        # distance and its other robots' part. Used only when the world (`inner`) does not move
        # (`static`): the distance less all motion since bounds the world's part too.
        self._measured: tuple[_Pose, int, float, float] | None = None
        self._static = bool(getattr(inner, "static", False))
        # When the last measurement found no free motion because of another robot (its gap, from the
        # exact distances kept, at or below 0): this robot's pose, that robot and its pose then.
        self._touching: tuple[_Pose, int, _Pose] | None = None
        self._stopped_by = -1  # the robot whose gap ended `_free_among`'s last look at 0 or below (-1: none)
        self.keep_m = _KEEP_M
        """`free_m` answers from its last measurement while that bound stays above this (inf: never)."""

    def _where(self, j: int) -> _Pose:
        standing = self.fleet._standing  # the fleet's own reading of who stands where
        return standing[j] if standing is not None and j != self.fleet._moving else self.fleet.pose(j)

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the contacts at this pose: the world's first, else the other robots' (empty when free)."""
        contacts = self.inner.check(x_m, y_m, yaw_rad)
        if contacts:
            return contacts
        fleet, body = self.fleet, self.fleet.body(self.index)
        radius, radii = body.radius_m, fleet.radii
        pose = (x_m, y_m, yaw_rad)
        found: list[Contact] = []
        for j in self.others:
            where = self._where(j)
            if math.hypot(where[0] - x_m, where[1] - y_m) - radius - radii[j] > _MARGIN_M:
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
                    for mine, theirs, point, normal, depth in body.contacts_with(pose, fleet.body(j), where)
                )
                if len(recent) >= _RECENT_POSES:
                    del recent[next(iter(recent))]  # the oldest
                recent[key] = pair
            found += pair
        found.sort(key=lambda c: -c.depth_m)
        return tuple(found)

    def touches(self, x_m: float, y_m: float, yaw_rad: float) -> bool:
        """Whether the robot at this pose touches the world or another robot: `check` as a yes or no.

        The drive asks this at every step while a contact episode is open (the contacts themselves
        matter only when one begins): the same shapes and FCL's same narrow phase, without
        building the contacts, and stopping at the first pair of shapes that touches.
        """
        if self.inner.check(x_m, y_m, yaw_rad):
            return True
        fleet, body = self.fleet, self.fleet.body(self.index)
        radius, radii = body.radius_m, fleet.radii
        pose = (x_m, y_m, yaw_rad)
        for j in self.others:
            where = self._where(j)
            if math.hypot(where[0] - x_m, where[1] - y_m) - radius - radii[j] > _MARGIN_M:
                continue
            key = (pose, where)
            known = self._recent[j].get(key)
            if known is not None:
                if known:
                    return True
                continue
            recent = self._recent_touch[j]
            touching = recent.get(key)
            if touching is None:
                touching = body.touches(pose, fleet.body(j), where)
                if len(recent) >= _RECENT_POSES:
                    del recent[next(iter(recent))]  # the oldest
                recent[key] = touching
            if touching:
                return True
        return False

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return how far the robot may move from this pose touching neither the world nor another robot.

        Sound for one chunk of steps: the others stand still while this robot moves (`Fleet.advance`).
        Near another robot the exact distance (FCL) is measured once and then bounded by how far
        either robot moved since (as `CollisionMonitor` does for the world), asked again only when
        that bound is used up. The robots farther than `_NEAR_M` at the last full look are bounded
        by the fleet's odometer, and looked at again only when that bound could decide the answer:
        the measurement is the same as measuring every robot, at the cost of the near ones. In a
        world that does not move, the other robots' part of a measurement is kept, and answers
        (less this robot's motion and the other robots' since, `Fleet.own_nm`) with the world's
        free distance asked again, while it stays above `keep_m`: far more than a robot moves
        between two events, so the compiled loop runs the same steps as with a new measurement.

        A robot pressed against another is asked again and again at the same pose while that one
        stands still. When the last measurement found no free motion because of one robot's gap,
        the same two poses answer 0 again without a look: that gap is a function of the two poses
        and the exact distance kept for the pair, which only a measurement changes.
        """
        touching = self._touching
        if touching is not None and touching[0] == (x_m, y_m, yaw_rad) and self._where(touching[1]) == touching[2]:
            return 0.0  # pressed against that robot, neither moved: what a measurement answers again
        fleet, i = self.fleet, self.index
        radius = fleet.radii[i]
        measured = self._measured
        if measured is not None:
            (mx, my, myaw), others_nm, value, robots = measured
            moved = math.hypot(x_m - mx, y_m - my) + radius * abs(math.remainder(yaw_rad - myaw, math.tau))
            since = moved + (fleet.travel_nm - fleet.own_nm[i] - others_nm) * 1e-9 + _ROUNDING_M
            keep_m = self.keep_m
            if value - since > keep_m:  # the whole distance still holds: no need to ask the world
                return value - since
            bound = robots - since
            if bound > keep_m:  # the robots' part holds: the world's (its own bound) asked again
                inner = self.inner.free_m(x_m, y_m, yaw_rad)
                return 0.0 if inner <= 0.0 else inner if inner < bound else bound
        free, robots = self._measure(x_m, y_m, yaw_rad, radius)
        keep = self._static and 2.0 * self.keep_m < robots < math.inf
        whole = free if free > 2.0 * self.keep_m else 0.0  # (a world's part as small is asked at each call)
        self._measured = ((x_m, y_m, yaw_rad), fleet.travel_nm - fleet.own_nm[i], whole, robots) if keep else None
        j = self._stopped_by
        pressed = free <= 0.0 and j >= 0 and self.keep_m < math.inf  # keep_m inf: measure at every call
        self._touching = ((x_m, y_m, yaw_rad), j, self._where(j)) if pressed else None
        return free

    def _measure(self, x_m: float, y_m: float, yaw_rad: float, radius: float) -> tuple[float, float]:
        """`free_m` measured: the world's free distance, the near robots' and a bound on the far ones'.

        Returns the free distance and the other robots' part of it alone (a bound on how far this
        robot may move touching none of them; 0 when not looked at), which `free_m` keeps.
        """
        self._stopped_by = -1
        inner = self.inner.free_m(x_m, y_m, yaw_rad)
        if inner <= 0.0:
            return 0.0, 0.0
        fleet = self.fleet
        far = self._far
        if far is not None:
            (ax, ay, ayaw), others_nm, far_gap, near = far
            moved = math.hypot(x_m - ax, y_m - ay) + radius * abs(math.remainder(yaw_rad - ayaw, math.tau))
            others_moved = (fleet.travel_nm - fleet.own_nm[self.index] - others_nm) * 1e-9
            bound = far_gap - moved - others_moved - _ROUNDING_M - _MARGIN_M  # (its own motion: `moved`)
            # When every far robot's gap exceeds `bound`, none can lower the answer or stop the look
            # early: it is what looking at every robot in turn gives.
            if not near:
                if bound > inner:
                    return inner, bound
            else:
                updates: dict[int, tuple[_Pose, _Pose, float]] = {}
                # (Lowered from inf, it stops where lowering `inner` would: at the first gap at or below 0.)
                robots = self._free_among(near, math.inf, x_m, y_m, yaw_rad, measured=updates)
                free = inner if inner < robots else robots
                if bound > max(free, 0.0):
                    self._exact.update(updates)
                    return (free if free > 0.0 else 0.0), (robots if robots < bound else bound)
        radii, near_list, far_gap = fleet.radii, [], math.inf
        for j in self.others:
            where = self._where(j)
            gap = math.hypot(where[0] - x_m, where[1] - y_m) - radius - radii[j]
            if gap > self.near_m:
                far_gap = min(far_gap, gap)
            else:
                near_list.append(j)
        self._far = ((x_m, y_m, yaw_rad), fleet.travel_nm - fleet.own_nm[self.index], far_gap, tuple(near_list))
        robots = self._free_among(self.others, math.inf, x_m, y_m, yaw_rad, measured=self._exact)
        free = inner if inner < robots else robots
        return (free if free > 0.0 else 0.0), robots

    def _free_among(
        self,
        robots: Sequence[int],
        free: float,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        *,
        measured: dict[int, tuple[_Pose, _Pose, float]],
    ) -> float:
        """`free` lowered to each of `robots`' gaps in turn (their order), stopping at 0 or below.

        The exact distances it measures go into `measured` (the monitor's own, or a draft).
        """
        fleet, body, exact = self.fleet, self.fleet.body(self.index), self._exact
        radius, radii = body.radius_m, fleet.radii
        for j in robots:
            where = self._where(j)
            gap = math.hypot(where[0] - x_m, where[1] - y_m) - radius - radii[j]
            if gap > _MARGIN_M:
                gap -= _MARGIN_M
            else:
                other = fleet.body(j)
                known = exact.get(j)
                bound = -1.0
                if known is not None:
                    mine, theirs, distance = known
                    bound = distance - _moved(mine, x_m, y_m, yaw_rad, radius)
                    bound -= _moved(theirs, *where, radii[j])
                if bound > _TOLERANCE_M:  # as sound as a new measurement less the tolerance, and free
                    gap = bound - _TOLERANCE_M
                elif known is not None and known[0] == (x_m, y_m, yaw_rad) and known[1] == where:
                    gap = known[2] - _TOLERANCE_M  # neither moved (stalled against each other)
                elif known is not None and known[2] <= _TOLERANCE_M and known[2] - bound < _STILL_TOUCHING_M:
                    # Measured touching, and moved less than a millimetre since (one sliding along
                    # the other): no free motion, without FCL. The drive checks each step; a new
                    # measurement after the millimetre lets it back into the compiled loop.
                    gap = 0.0
                else:
                    distance = body.distance_to((x_m, y_m, yaw_rad), other, where)
                    measured[j] = ((x_m, y_m, yaw_rad), where, distance)
                    gap = distance - _TOLERANCE_M
            free = min(free, gap)
            if free <= 0.0:
                self._stopped_by = j
                return free
        return free


def overlap_problem(robots: Sequence[tuple[str, _Pose, RobotBody]]) -> str | None:
    """Two robots (namespace, spawn pose, body) spawned touching each other, named with their distance; or None."""
    for i, (ns_a, a, body_a) in enumerate(robots):
        for j in range(i + 1, len(robots)):
            ns_b, b, body_b = robots[j]
            if body_a.distance_to(a, body_b, b) > _TOLERANCE_M:
                continue
            centres = math.hypot(a[0] - b[0], a[1] - b[1])
            return (
                f"robots[{j}].robot.initial_pose: robots[{i}] ({ns_a}) and robots[{j}] ({ns_b}) are spawned "
                f"overlapping ({centres:.3f} m apart); move one robot's initial_pose"
            )
    return None


def _pose_reader(drive: Any) -> Callable[[], _Pose]:
    """A drive's (x, y, yaw) reader: its `pose` where it has one, else from its `chassis_state`."""
    pose = getattr(drive, "pose", None)
    if callable(pose):
        return pose  # type: ignore[no-any-return]
    state = drive.chassis_state
    return lambda: state()[:3]


def _nm(distance_m: float) -> int:
    """A distance in whole nanometres, rounded up (and one more, for the product's own rounding)."""
    return math.ceil(distance_m * 1e9) + 1


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
        placed_section = self.fleet.placed_section
        for j, pose in zip(self.others, poses, strict=True):
            segs, circs = placed_section(j, key, pose)
            if segs is not None:
                segments.append(segs)
            if circs is not None:
                circles.append(circs)
        caster = None
        if segments or circles:
            caster = ObstacleCaster(
                np.concatenate(segments) if segments else np.empty((0, 4)),
                np.concatenate(circles) if circles else np.empty((0, 3)),
                key,
            )
        self._cache[key] = (poses, caster)
        return caster
