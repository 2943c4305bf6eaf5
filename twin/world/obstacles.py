"""Obstacles that appear, vanish and move: boxes and cylinders standing on the floor, over time.

A scenario's `obstacles:` (and the behaviour demos' blocks) become `ObstacleSpec`s; an
`ObstacleField` holds them during a run. Each obstacle is present from `appear_s` until `vanish_s`
and stands still at its `pose`, or walks a polyline `path_xy_m` at `speed_mps`, facing where it
goes, from the moment it appears: at the path's end it stops (`loop: false`) or turns and walks
back, back and forth for as long as it is present (`loop: true`).

The field answers what the static `Scene` answers for the world's fixed geometry, for the obstacles
present at the time of its last `update`:

- `caster(height_m)`: an `ObstacleCaster` over the obstacles' horizontal section at a lidar's height
  (boxes give four segments, cylinders a circle: analytic, as the world's upright shapes);
- `check(x, y, yaw)` / `free_m(x, y, yaw)`: contacts of the robot's collision shapes with the
  obstacles (FCL), and the distance the robot may move with none possible, as `CollisionMonitor`
  gives them for the world; `ObstacleMonitor` joins both for the drive.

The field changes only in `update(t_ns, robot_pose)`; between two updates the obstacles stand
still, so the drive's free distance holds over a physics chunk as it does for walls.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import fcl
import numpy as np

from twin.world._native import load_kernel
from twin.world.scene import F64, CollisionMonitor, Contact, RayCaster, RobotBody, _Slice

__all__ = [
    "ObstacleCaster",
    "ObstacleField",
    "ObstacleMarker",
    "ObstacleMonitor",
    "ObstaclePose",
    "ObstacleSpec",
]

_NS_PER_S = 1_000_000_000
# What an FCL distance between the robot's shapes and an obstacle may be off by, m (as for the world).
_DISTANCE_TOLERANCE_M = 1e-4
_GREY = (0.6, 0.6, 0.6, 1.0)
_NEVER = 2**63 - 1


@dataclass(frozen=True, kw_only=True, slots=True)
class ObstaclePose:
    """Where a standing obstacle stands: its centre on the floor and its heading (world frame)."""

    x_m: float
    y_m: float
    yaw_rad: float = 0.0


@dataclass(frozen=True, kw_only=True, slots=True)
class ObstacleSpec:
    """One obstacle: a box or an upright cylinder resting on the floor, present from `appear_s` to `vanish_s`.

    Give either `pose` (it stands there) or `path_xy_m` with `speed_mps` (it walks the polyline from
    its first point, facing its direction of travel, starting when it appears; at the end it stops,
    or with `loop: true` walks back and forth).
    """

    shape: Literal["box", "cylinder"]
    size_m: tuple[float, float, float] | None = None  # box: length (x), width (y), height (z)
    radius_m: float | None = None  # cylinder
    height_m: float | None = None  # cylinder
    pose: ObstaclePose | None = None
    path_xy_m: tuple[tuple[float, float], ...] | None = None
    speed_mps: float | None = None
    loop: bool = False
    appear_s: float = 0.0
    vanish_s: float | None = None  # null: never
    name: str | None = None  # null: obstacle_<index>
    color_rgba: tuple[float, float, float, float] = _GREY

    def __post_init__(self) -> None:
        if self.shape == "box":
            if self.size_m is None:
                raise ValueError("a box needs size_m: [length, width, height] in metres")
            if not all(v > 0.0 for v in self.size_m):
                msg = f"size_m must be three sizes above 0 m, got {list(self.size_m)}"
                raise ValueError(msg)
            if self.radius_m is not None or self.height_m is not None:
                raise ValueError("a box takes size_m, not radius_m or height_m (those are a cylinder's)")
        else:
            if self.radius_m is None or self.height_m is None:
                raise ValueError("a cylinder needs radius_m and height_m in metres")
            if not (self.radius_m > 0.0 and self.height_m > 0.0):
                msg = f"radius_m and height_m must be above 0 m, got {self.radius_m} and {self.height_m}"
                raise ValueError(msg)
            if self.size_m is not None:
                raise ValueError("a cylinder takes radius_m and height_m, not size_m (a box's)")
        if (self.pose is None) == (self.path_xy_m is None):
            raise ValueError("give either pose: {x_m, y_m, yaw_rad} (standing) or path_xy_m with speed_mps (walking)")
        if self.path_xy_m is not None:
            if len(self.path_xy_m) < 2:
                msg = f"path_xy_m needs at least 2 points [x, y], got {len(self.path_xy_m)}"
                raise ValueError(msg)
            if _path_length(self.path_xy_m) <= 0.0:
                raise ValueError("path_xy_m has no length (all its points are the same); give distinct points")
            if self.speed_mps is None or not self.speed_mps > 0.0:
                msg = f"a path needs speed_mps above 0 m/s, got {self.speed_mps}"
                raise ValueError(msg)
        elif self.speed_mps is not None or self.loop:
            raise ValueError("speed_mps and loop are for a path_xy_m; a posed obstacle stands still")
        if not self.appear_s >= 0.0:
            msg = f"appear_s must be 0 s or later, got {self.appear_s}"
            raise ValueError(msg)
        if self.vanish_s is not None and not self.vanish_s > self.appear_s:
            msg = f"vanish_s ({self.vanish_s}) must be after appear_s ({self.appear_s}); make it later or null"
            raise ValueError(msg)
        if not all(0.0 <= c <= 1.0 for c in self.color_rgba):
            msg = f"color_rgba must be four values from 0 to 1, got {list(self.color_rgba)}"
            raise ValueError(msg)

    @property
    def top_m(self) -> float:
        """The obstacle's height above the floor, m."""
        return self.size_m[2] if self.size_m is not None else float(self.height_m or 0.0)


def _path_length(points: Sequence[tuple[float, float]]) -> float:
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points))


_Section = tuple[list[tuple[float, float, float, float]], list[tuple[float, float, float]]]


class ObstacleMarker(NamedTuple):
    """An obstacle as a bag shows it: id, shape, pose (x, y, z, qx, qy, qz, qw), scale (x, y, z), colour, name."""

    id: int
    shape: str
    pose: tuple[float, float, float, float, float, float, float]
    scale: tuple[float, float, float]
    color_rgba: tuple[float, float, float, float]
    name: str


class _Obstacle:
    """One obstacle at run time: its pose over time, its FCL object and its section."""

    def __init__(self, index: int, spec: ObstacleSpec, step_ns: int) -> None:
        self.index = index
        self.spec = spec
        self.name = spec.name or f"obstacle_{index}"
        self.top_m = spec.top_m
        if spec.size_m is not None:
            self.half = (0.5 * spec.size_m[0], 0.5 * spec.size_m[1])
            self.bound_m = math.hypot(*self.half)
            self.geometry: fcl.CollisionGeometry = fcl.Box(*spec.size_m)
        else:
            assert spec.radius_m is not None
            self.half = (spec.radius_m, spec.radius_m)
            self.bound_m = spec.radius_m
            self.geometry = fcl.Cylinder(spec.radius_m, self.top_m)
        self.object = fcl.CollisionObject(self.geometry, fcl.Transform())
        # Present on the update grid: from the first update at or after appear_s, to the first at or after vanish_s.
        self.appear_ns = _ceil_to(round(spec.appear_s * _NS_PER_S), step_ns)
        self.vanish_ns = _ceil_to(round(spec.vanish_s * _NS_PER_S), step_ns) if spec.vanish_s is not None else None
        self.walk_start_ns = round(spec.appear_s * _NS_PER_S)
        if spec.path_xy_m is not None:
            points: list[tuple[float, float]] = []
            for x, y in spec.path_xy_m:
                if not points or (float(x), float(y)) != points[-1]:
                    points.append((float(x), float(y)))  # a repeated point adds no segment
            self.points = points
            self.cumulative = [0.0]
            for a, b in itertools.pairwise(points):
                self.cumulative.append(self.cumulative[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
            self.length_m = self.cumulative[-1]
            assert spec.speed_mps is not None
            self.speed_mps = float(spec.speed_mps)
            # Stops moving here (None: never, it walks back and forth, or its walk outlasts any run).
            walk_ns = self.length_m / self.speed_mps * _NS_PER_S
            self.stop_ns: int | None = (
                None if spec.loop or not walk_ns < _NEVER else self.walk_start_ns + math.ceil(walk_ns)
            )
        else:
            assert spec.pose is not None
            self.stop_ns = self.walk_start_ns
        self.walks = spec.path_xy_m is not None
        self.x = self.y = self.yaw = math.nan
        self.stale = True
        self._section: _Section | None = None

    def present(self, t_ns: int) -> bool:
        return self.appear_ns <= t_ns and (self.vanish_ns is None or t_ns < self.vanish_ns)

    def pose_at(self, t_ns: int) -> tuple[float, float, float]:
        """Return (x, y, yaw) at `t_ns` (its start pose before it appears)."""
        spec = self.spec
        if spec.pose is not None:
            return spec.pose.x_m, spec.pose.y_m, spec.pose.yaw_rad
        walked = max(0, t_ns - self.walk_start_ns) / _NS_PER_S * self.speed_mps
        backwards = False
        length = self.length_m
        if spec.loop:
            walked %= 2.0 * length
            if walked > length:
                walked, backwards = 2.0 * length - walked, True
        else:
            walked = min(walked, length)
        seg = min(max(bisect.bisect_right(self.cumulative, walked) - 1, 0), len(self.points) - 2)
        (x0, y0), (x1, y1) = self.points[seg], self.points[seg + 1]
        span = self.cumulative[seg + 1] - self.cumulative[seg]
        s = min(max((walked - self.cumulative[seg]) / span, 0.0), 1.0)
        yaw = math.atan2(y1 - y0, x1 - x0)
        if backwards:
            yaw = math.remainder(yaw + math.pi, math.tau)
        return x0 + s * (x1 - x0), y0 + s * (y1 - y0), yaw

    def place(self, x: float, y: float, yaw: float) -> None:
        """Move it; its FCL object follows only when a contact check needs it (`sync`)."""
        self.x, self.y, self.yaw = x, y, yaw
        self.stale = True
        self._section = None

    def sync(self) -> None:
        """Put the FCL object where the obstacle is."""
        if self.stale:
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            self.object.setTransform(fcl.Transform(rot, np.array([self.x, self.y, 0.5 * self.top_m])))
            self.stale = False

    def section(self) -> _Section:
        """Its outline on the floor plane: four segments (box) or a circle (cylinder)."""
        if self._section is None:
            self._section = self._outline()
        return self._section

    def _outline(self) -> _Section:
        if self.spec.shape == "cylinder":
            return [], [(self.x, self.y, self.half[0])]
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hx, hy = self.half
        corners = [
            (self.x + c * sx * hx - s * sy * hy, self.y + s * sx * hx + c * sy * hy)
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
        return [(*corners[i], *corners[(i + 1) % 4]) for i in range(4)], []

    def marker(self) -> ObstacleMarker:
        half = 0.5 * self.yaw
        pose = (self.x, self.y, 0.5 * self.top_m, 0.0, 0.0, math.sin(half), math.cos(half))
        if self.spec.size_m is not None:
            scale = (float(self.spec.size_m[0]), float(self.spec.size_m[1]), float(self.spec.size_m[2]))
        else:
            scale = (2.0 * self.half[0], 2.0 * self.half[0], self.top_m)
        return ObstacleMarker(self.index, self.spec.shape, pose, scale, self.spec.color_rgba, self.name)


def _ceil_to(t_ns: int, step_ns: int) -> int:
    return -(-t_ns // step_ns) * step_ns


class ObstacleCaster:
    """Casts rays against a handful of shapes (segments and circles), each against every beam of a fan.

    `RayCaster` indexes a world's thousands of segments in a grid; a few obstacles need no index, and
    a walking one changes the section every update, so this is built per change for a few
    microseconds and answers with the same compiled kernel (or `RayCaster`'s numpy code without it).
    """

    def __init__(
        self,
        segments: Sequence[tuple[float, float, float, float]] | F64,
        circles: Sequence[tuple[float, float, float]] | F64,
        height_m: float,
    ) -> None:
        self.height_m = height_m
        self._seg = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
        self._circ = np.ascontiguousarray(circles, dtype=np.float64).reshape(-1, 3)
        self._lib = load_kernel()
        self._grid: RayCaster | None = None

    @property
    def shapes(self) -> tuple[F64, F64]:
        """Its segments (M, 4) and circles (K, 3), contiguous float64 (for `RayCaster.cast_scan(also=...)`)."""
        return self._seg, self._circ

    def _grid_caster(self) -> RayCaster:
        if self._grid is None:
            section = _Slice(
                segments=self._seg,
                circles=self._circ,
                segment_owner=np.zeros(len(self._seg), dtype=np.int64),
                circle_owner=np.zeros(len(self._circ), dtype=np.int64),
            )
            self._grid = RayCaster(section, self.height_m, ["obstacle"], native=self._lib is not None)
        return self._grid

    def cast_fan(
        self,
        origin_xy: tuple[float, float],
        start_rad: float,
        increment_rad: float,
        count: int,
        max_range_m: float,
        *,
        min_range_m: float = 0.0,
    ) -> F64:
        """Return ranges for `count` beams at `start_rad + i * increment_rad`, as `RayCaster.cast_fan`."""
        lib = self._lib
        if lib is None or increment_rad <= 0.0 or count < 1:
            return self._grid_caster().cast_fan(
                origin_xy, start_rad, increment_rad, count, max_range_m, min_range_m=min_range_m
            )
        out = np.empty(count)
        status = lib.twin_cast_fan(
            self._seg.ctypes.data, np.arange(len(self._seg), dtype=np.int64).ctypes.data, len(self._seg),
            self._circ.ctypes.data, np.arange(len(self._circ), dtype=np.int64).ctypes.data, len(self._circ),
            float(origin_xy[0]), float(origin_xy[1]), float(start_rad), float(increment_rad), int(count),
            min_range_m, max_range_m, out.ctypes.data,
        )  # fmt: skip
        if status != 0:
            raise MemoryError("ray caster kernel could not allocate its beam buffer")
        return out

    def cast_rays(
        self, origin_xy: tuple[float, float], angles_rad: F64, max_range_m: float, *, min_range_m: float = 0.0
    ) -> F64:
        """Return the range along each beam (world-frame angles), as `RayCaster.cast_rays`."""
        return self._grid_caster().cast_rays(origin_xy, angles_rad, max_range_m, min_range_m=min_range_m)


class ObstacleField:
    """The scenario's obstacles over time, for the lidar and the contact check (see the module docstring).

    Args:
        specs: The obstacles, in order (an obstacle's index is its marker id).
        body: The robot's collision body (its shapes are checked against the obstacles).
        update_period_ns: How often `update` is called: appearing and vanishing take effect at the
            first update at or after `appear_s` and `vanish_s`.
        margin_m: Closer than this the exact distance of the robot's shapes is asked (as `CollisionMonitor`).
    """

    def __init__(
        self,
        specs: Sequence[ObstacleSpec],
        body: RobotBody,
        *,
        update_period_ns: int,
        coarse_steps: int = 10,
        robot_speed_bound_mps: float = 1.0,
        margin_m: float = 0.005,
    ) -> None:
        if update_period_ns <= 0 or coarse_steps < 1:
            msg = f"update_period_ns and coarse_steps must be positive, got {update_period_ns}, {coarse_steps}"
            raise ValueError(msg)
        self.body = body
        self.margin_m = margin_m
        self.update_period_ns = update_period_ns
        self.coarse_period_ns = coarse_steps * update_period_ns
        """Walkers far from the robot step at this period (see `next_update_ns`)."""
        self.robot_speed_bound_mps = robot_speed_bound_mps
        """No point of the robot moves faster than this, m/s (a TurtleBot3's reach about 0.6)."""
        self._free_now = 0.0
        self.obstacles = tuple(_Obstacle(i, spec, update_period_ns) for i, spec in enumerate(specs))
        self.active: tuple[_Obstacle, ...] = ()
        self.version = 0
        """Counts the updates that changed anything (what is present, or where)."""
        self.membership = 0
        """Counts the updates that changed what is present."""
        self._casters: dict[float, tuple[int, ObstacleCaster | None]] = {}
        self._t_ns = -1
        vanish = {ob.vanish_ns for ob in self.obstacles if ob.vanish_ns is not None}
        self._events = sorted({ob.appear_ns for ob in self.obstacles} | vanish)
        self._next_event_ns = -1
        self._walking: tuple[_Obstacle, ...] = ()
        self._anchor = (0.0, 0.0, 0.0)
        self._free_m = math.inf  # nothing present yet
        self.queries = 0
        """How many exact (FCL) checks were made (for benchmarks)."""

    # -- time ---------------------------------------------------------------------------------------

    def next_change_ns(self, t_ns: int) -> int | None:
        """The first time at or after `t_ns` when an obstacle may appear, vanish or move (None: never).

        Exact after an `update` at an earlier time (it answers from that update's state).
        """
        if self._walking:
            return t_ns
        following = [e for e in self._events if e >= t_ns]
        return following[0] if following else None

    def next_update_ns(self, t_ns: int) -> int | None:
        """When to call `update` next, after an update at `t_ns` (None: nothing changes any more).

        At the next appearance or vanishing; while obstacles walk, every update period when one
        could reach the robot before a coarser step, otherwise at the next multiple of
        `coarse_period_ns` (walkers far from the robot step every 0.1 s: the same positions at
        every multiple of it, so a 5 Hz lidar sees them where they are, and no contact can be
        missed: the step is shorter than the time a walker and the robot need to close the free
        distance, at the walkers' speeds and `robot_speed_bound_mps`).
        """
        following = self.next_change_ns(t_ns + 1)
        if following is None or not self._walking:
            return following
        period, coarse = self.update_period_ns, self.coarse_period_ns
        reach_s = math.inf
        for ob in self._walking:
            turn_m = 2.0 * ob.bound_m if ob.spec.shape == "box" else 0.0  # a box turning at a corner
            reach_s = min(reach_s, (self._free_now - turn_m) / (ob.speed_mps + self.robot_speed_bound_mps))
        steps = 1
        if reach_s > 0.0:
            steps = max(1, min(coarse // period, int(reach_s * _NS_PER_S) // period))
        grid = (t_ns // coarse + 1) * coarse
        event = next((e for e in self._events if e > t_ns), _NEVER)
        return min(t_ns + steps * period, grid, event)

    def update(
        self, t_ns: int, robot_pose: tuple[float, float, float] | Callable[[], tuple[float, float, float]]
    ) -> tuple[bool, tuple[Contact, ...]]:
        """Move the obstacles to their places at `t_ns`; return whether anything changed and the contacts now.

        The contacts are those of the robot at `robot_pose` (or what the callable returns, asked only
        when needed) with the obstacles: an obstacle walking or appearing into a robot standing still
        touches it. Only walking obstacles are visited between appearances and vanishings, and FCL
        is asked only once their steps have used up the free distance.
        """
        if t_ns == self._t_ns:
            return False, ()
        back_in_time = t_ns < self._t_ns
        self._t_ns = t_ns
        appeared = False  # what is present changed: the free distance is measured again
        moved_m = 0.0  # how far any point of a walker moved: the free distance shrinks by at most this
        if t_ns >= self._next_event_ns or back_in_time:
            active = tuple(ob for ob in self.obstacles if ob.present(t_ns))
            if active != self.active or back_in_time:
                appeared = True
                self.active = active
                self.membership += 1
                for ob in active:
                    ob.place(*ob.pose_at(t_ns))
            self._walking = tuple(ob for ob in active if ob.walks)
            self._next_event_ns = next((e for e in self._events if e > t_ns), _NEVER)
        if self._walking:
            still = []
            for ob in self._walking:
                x, y, yaw = ob.pose_at(t_ns)
                if (x, y, yaw) != (ob.x, ob.y, ob.yaw):
                    step = math.hypot(x - ob.x, y - ob.y) + ob.bound_m * abs(math.remainder(yaw - ob.yaw, math.tau))
                    moved_m = max(moved_m, step)
                    ob.place(x, y, yaw)
                if ob.stop_ns is None or t_ns < ob.stop_ns:
                    still.append(ob)
            self._walking = tuple(still)
        if not appeared and moved_m == 0.0:
            return False, ()
        self.version += 1
        self._free_m -= moved_m
        pose = robot_pose() if callable(robot_pose) else robot_pose
        self._free_now = self.free_m(*pose)
        if appeared or self._free_now <= 0.0:
            contacts = self._query(*pose)
            self._free_now = max(0.0, self._free_m)
            return True, contacts
        return True, ()

    # -- the lidar -------------------------------------------------------------------------------------

    def caster(self, height_m: float) -> ObstacleCaster | None:
        """Return a ray caster over the present obstacles' section at `height_m`, or None when none reach it."""
        key = round(float(height_m), 9)
        cached = self._casters.get(key)
        if cached is not None and cached[0] == self.version:
            return cached[1]
        segments: list[tuple[float, float, float, float]] = []
        circles: list[tuple[float, float, float]] = []
        for ob in self.active:
            if 0.0 <= key <= ob.top_m:
                segs, circs = ob.section()
                segments += segs
                circles += circs
        caster = ObstacleCaster(segments, circles, key) if segments or circles else None
        self._casters[key] = (self.version, caster)
        return caster

    # -- contact ---------------------------------------------------------------------------------------

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return how far the robot may move from this pose with no obstacle contact possible (0 if unknown)."""
        ax, ay, ayaw = self._anchor
        moved = math.hypot(x_m - ax, y_m - ay) + self.body.radius_m * abs(yaw_rad - ayaw)
        free = self._free_m - moved
        return free if free > 0.0 else 0.0

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the robot's contacts with the obstacles at this pose (empty when free)."""
        if not self.active:
            return ()
        ax, ay, ayaw = self._anchor
        moved = math.hypot(x_m - ax, y_m - ay) + self.body.radius_m * abs(yaw_rad - ayaw)
        if moved < self._free_m:
            return ()
        return self._query(x_m, y_m, yaw_rad)

    def _query(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Measure the free distance from this pose (bounding circles first, FCL near), and the contacts."""
        self._anchor = (x_m, y_m, yaw_rad)
        body = self.body
        free = math.inf
        placed = False
        contacts: list[Contact] = []
        for ob in self.active:
            gap = math.hypot(ob.x - x_m, ob.y - y_m) - body.radius_m - ob.bound_m
            if gap > self.margin_m:
                free = min(free, gap - self.margin_m)
                continue
            if not placed:
                body._place(x_m, y_m, yaw_rad)
                placed = True
            self.queries += 1
            ob.sync()
            data = fcl.DistanceData()
            body._manager.distance(ob.object, data, fcl.defaultDistanceCallback)
            distance = max(0.0, float(data.result.min_distance))
            if distance > self.margin_m:
                free = min(free, distance - self.margin_m)
            elif distance > _DISTANCE_TOLERANCE_M:
                free = min(free, distance - _DISTANCE_TOLERANCE_M)
            else:
                free = -1.0
                contacts += self._contacts(ob)
        self._free_m = free
        contacts.sort(key=lambda c: -c.depth_m)
        return tuple(contacts)

    def _contacts(self, ob: _Obstacle) -> list[Contact]:
        body = self.body
        request = fcl.CollisionRequest(num_max_contacts=8, enable_contact=True)
        data = fcl.CollisionData(request=request)
        body._manager.collide(ob.object, data, fcl.defaultCollisionCallback)
        out = []
        for contact in data.result.contacts:
            part = body.owner(contact.o1)
            normal = -np.asarray(contact.normal, dtype=float)  # FCL's points from o1 (the robot) to the obstacle
            if part is None:
                part = body.owner(contact.o2)
                normal = -normal
            if part is None:
                continue
            out.append(
                Contact(
                    model=ob.name,
                    link=f"{ob.name}::link",  # scoped, as the Scene's contacts name links
                    collision=ob.spec.shape,
                    robot_link=part.link,
                    point=(float(contact.pos[0]), float(contact.pos[1]), float(contact.pos[2])),
                    normal=(float(normal[0]), float(normal[1]), float(normal[2])),
                    depth_m=max(0.0, float(contact.penetration_depth)),
                )
            )
        return out

    # -- what a bag shows ------------------------------------------------------------------------------

    def markers(self) -> tuple[ObstacleMarker, ...]:
        """The present obstacles as markers (in index order)."""
        return tuple(ob.marker() for ob in self.active)


class ObstacleMonitor:
    """The world's walls and the obstacles together, with `CollisionMonitor`'s `check` and `free_m`."""

    def __init__(self, walls: CollisionMonitor, field: ObstacleField) -> None:
        self.walls = walls
        self.field = field

    def check(self, x_m: float, y_m: float, yaw_rad: float) -> tuple[Contact, ...]:
        """Return the contacts at this pose: the world's first, else the obstacles' (empty when free)."""
        contacts = self.walls.check(x_m, y_m, yaw_rad)
        return contacts if contacts else self.field.check(x_m, y_m, yaw_rad)

    def free_m(self, x_m: float, y_m: float, yaw_rad: float) -> float:
        """Return how far the robot may move from this pose touching neither the world nor an obstacle."""
        walls = self.walls.free_m(x_m, y_m, yaw_rad)
        if walls <= 0.0 or not self.field.active:
            return walls
        return min(walls, self.field.free_m(x_m, y_m, yaw_rad))
