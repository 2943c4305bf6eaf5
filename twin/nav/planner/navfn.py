"""NavFn as Nav2 Humble's planner_server runs it (`nav2_navfn_planner/NavfnPlanner`).

What carries over from Nav2 (facts in TB3_FACTS §4.3 and §4.8):

- Costs: a costmap cost c < 253 becomes 50 + 0.8 c (COST_NEUTRAL, COST_FACTOR; truncated to an
  integer as NavFn stores it); 253 (inscribed) and 254 (lethal) are forbidden; 255 (unknown) costs
  253 when `allow_unknown`, else is forbidden. The outermost ring of cells is forbidden too.
- Potential: from the robot's cell outward, each cell's potential from its two lowest neighbours
  by NavFn's quadratic interpolation of the Eikonal update; Dijkstra order (`use_astar: false`),
  or A* with a heuristic of 50 per cell of Euclidean distance. The robot's own cell is cleared first
  (Nav2's `clearRobotCell`). Propagation stops when the goal cell is settled.
- Tolerance: when the goal cell has no potential, the reachable node nearest the goal within
  `tolerance_m` (scanned on a grid of one cell) becomes the path's end.
- Path: NavFn's calcPath: gradient descent on the potential from the end back to the robot in
  half-cell steps (a lowest-neighbour step where the potential is not defined around the point or
  the path oscillates), done when the nearest node has a potential below 50 (the robot's node is
  then the last point), at most 4 x the costmap's larger side steps; reversed; the goal replaces
  the last point if it is closer to the one before, else is appended.
  Middle poses carry identity orientation (yaw 0), the last pose the goal's yaw.
- Grid nodes: as Humble's NavfnPlanner, world -> node by rounding (x - origin) / resolution and
  node -> world as origin + node * resolution (a node sits on a cell's corner, not its centre).

The two loops (potential, trace) run in C (`_native`, `navfn_kernels.c`); `_potential_py` and `_trace_py` are
the same algorithm in Python (a fallback used only without a C compiler, and the tests' reference).
"""

from __future__ import annotations

import enum
import heapq
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.nav.costmap_2d.costmap_2d import INSCRIBED_INFLATED_OBSTACLE, NO_INFORMATION, CostGrid
from twin.nav.planner._native import load_navfn_kernel

__all__ = [
    "COST_FACTOR",
    "COST_NEUTRAL",
    "NavfnParams",
    "NavfnPlanner",
    "Plan",
    "PlanFailure",
    "PlanFailureReason",
    "navfn_costs",
]

COST_NEUTRAL = 50
COST_FACTOR = 0.8
COST_OBS = 254
POT_HIGH = 1.0e10


@dataclass(frozen=True, kw_only=True, slots=True)
class NavfnParams:
    """The `GridBased` planner's parameters (TB3 and Nav2 Humble yaml values as defaults).

    Attributes:
        tolerance_m: How far from an unreachable goal the path may end.
        use_astar: A* instead of Dijkstra.
        allow_unknown: Plan through unknown (255) cells, at cost 253.
    """

    tolerance_m: float = 0.5
    use_astar: bool = False
    allow_unknown: bool = True


@dataclass(frozen=True, kw_only=True, slots=True)
class Plan:
    """A path in the costmap's frame: `poses[i] = (x_m, y_m, yaw_rad)`, robot first, goal last."""

    frame_id: str
    poses: NDArray[np.float64]

    @property
    def length_m(self) -> float:
        """Length of the polyline through the poses."""
        if len(self.poses) < 2:
            return 0.0
        return float(np.sum(np.hypot(*np.diff(self.poses[:, :2], axis=0).T)))


class PlanFailureReason(enum.Enum):
    """Why NavFn returned no path (Nav2's planner_server logs and fails the action)."""

    START_OUTSIDE_MAP = "start outside the costmap"
    GOAL_OUTSIDE_MAP = "goal outside the costmap"
    NO_VALID_PATH = "no valid path"


@dataclass(frozen=True, kw_only=True, slots=True)
class PlanFailure:
    """A planning failure: the reason and a one-line message."""

    reason: PlanFailureReason
    message: str


def navfn_costs(cost: NDArray[np.uint8], *, allow_unknown: bool) -> NDArray[np.uint8]:
    """Map Nav2 costmap costs to NavFn's (50 + 0.8 c; 253/254 forbidden; unknown 253 or forbidden; border forbidden)."""
    table = np.empty(256, dtype=np.uint8)
    table[:INSCRIBED_INFLATED_OBSTACLE] = (COST_NEUTRAL + COST_FACTOR * np.arange(INSCRIBED_INFLATED_OBSTACLE)).astype(
        np.uint8
    )
    table[INSCRIBED_INFLATED_OBSTACLE:] = COST_OBS
    if allow_unknown:
        table[NO_INFORMATION] = COST_OBS - 1
    out = table[cost]
    out[0, :] = COST_OBS
    out[-1, :] = COST_OBS
    out[:, 0] = COST_OBS
    out[:, -1] = COST_OBS
    return out


class NavfnPlanner:
    """NavFn over a `CostGrid` (the global costmap); one planner per costmap, reusable across calls.

    Args:
        params: The planner's parameters.
        native: Use the C kernel when it can be built (False: the Python reference path).
    """

    def __init__(self, params: NavfnParams | None = None, *, native: bool = True) -> None:
        self.params = params or NavfnParams()
        self._kernel = load_navfn_kernel() if native else None
        #: The potential of the last plan (rows x cols, POT_HIGH where unreached), for inspection.
        self.potential: NDArray[np.float64] = np.zeros((0, 0))

    @property
    def native(self) -> bool:
        """True when plans are computed by the C kernel."""
        return self._kernel is not None

    def make_plan(
        self, costmap: CostGrid, start: tuple[float, float, float], goal: tuple[float, float, float]
    ) -> Plan | PlanFailure:
        """Plan from `start` to `goal` ((x_m, y_m, yaw_rad) in the costmap's frame).

        Returns:
            The plan, or a `PlanFailure` (start or goal outside the costmap, or no path within tolerance).
        """
        res = costmap.resolution_m
        ny, nx = costmap.cost.shape
        s_node = self._node(costmap, start[0], start[1])
        if s_node is None:
            return PlanFailure(
                reason=PlanFailureReason.START_OUTSIDE_MAP,
                message=f"start ({start[0]:.2f}, {start[1]:.2f}) is outside the costmap",
            )
        if self._node(costmap, goal[0], goal[1]) is None:
            return PlanFailure(
                reason=PlanFailureReason.GOAL_OUTSIDE_MAP,
                message=f"goal ({goal[0]:.2f}, {goal[1]:.2f}) is outside the costmap",
            )
        grid = costmap.cost.copy()
        grid[s_node[1], s_node[0]] = 0  # Nav2's clearRobotCell
        cost = navfn_costs(grid, allow_unknown=self.params.allow_unknown)
        g_node = self._node(costmap, goal[0], goal[1])
        assert g_node is not None
        if s_node == g_node:
            return Plan(frame_id=costmap.frame_id, poses=np.array([[goal[0], goal[1], goal[2]]]))
        source = s_node[1] * nx + s_node[0]
        target = g_node[1] * nx + g_node[0]
        pot = self._potential(cost, nx, ny, source, target)
        self.potential = pot.reshape(ny, nx)
        end = self._best_end(costmap, pot, nx, ny, goal)
        if end is None:
            return PlanFailure(
                reason=PlanFailureReason.NO_VALID_PATH,
                message=f"no path to ({goal[0]:.2f}, {goal[1]:.2f}) within {self.params.tolerance_m} m",
            )
        ex, ey = end
        max_cycles = 4 * max(nx, ny)
        trace = self._trace(
            pot, cost, nx=nx, ny=ny, start=self._node_index(costmap, ex, ey, nx), goal=source, max_cycles=max_cycles
        )
        if trace is None:
            return PlanFailure(
                reason=PlanFailureReason.NO_VALID_PATH,
                message=f"the path to ({goal[0]:.2f}, {goal[1]:.2f}) could not be traced on the potential",
            )
        cells = trace[::-1]  # from the robot's node to the plan's end
        xy = np.column_stack([costmap.origin_x_m + cells[:, 0] * res, costmap.origin_y_m + cells[:, 1] * res])
        xy = _approach(xy, np.array([ex, ey]))
        poses = np.zeros((len(xy), 3))
        poses[:, :2] = xy
        poses[-1, 2] = goal[2]
        return Plan(frame_id=costmap.frame_id, poses=poses)

    # -- internals -------------------------------------------------------------------------

    @staticmethod
    def _node(costmap: CostGrid, x_m: float, y_m: float) -> tuple[int, int] | None:
        if x_m < costmap.origin_x_m or y_m < costmap.origin_y_m:
            return None
        mx = round((x_m - costmap.origin_x_m) / costmap.resolution_m)
        my = round((y_m - costmap.origin_y_m) / costmap.resolution_m)
        return (mx, my) if mx < costmap.cols and my < costmap.rows else None

    def _node_index(self, costmap: CostGrid, x_m: float, y_m: float, nx: int) -> int:
        node = self._node(costmap, x_m, y_m)
        assert node is not None
        return node[1] * nx + node[0]

    def _best_end(
        self, costmap: CostGrid, pot: NDArray[np.float64], nx: int, ny: int, goal: tuple[float, float, float]
    ) -> tuple[float, float] | None:
        """The goal if it has a potential, else the nearest point within tolerance that has one."""
        g_node = self._node(costmap, goal[0], goal[1])
        if g_node is not None and pot[g_node[1] * nx + g_node[0]] < POT_HIGH:
            return goal[0], goal[1]
        res = costmap.resolution_m
        tol = self.params.tolerance_m
        steps = np.arange(-tol, tol + 1e-9, res)
        xs = goal[0] + steps
        ys = goal[1] + steps
        gx, gy = np.meshgrid(xs, ys)
        mx = np.rint((gx - costmap.origin_x_m) / res).astype(np.int64)
        my = np.rint((gy - costmap.origin_y_m) / res).astype(np.int64)
        inside = (gx >= costmap.origin_x_m) & (gy >= costmap.origin_y_m) & (mx < nx) & (my < ny)
        d2 = (gx - goal[0]) ** 2 + (gy - goal[1]) ** 2
        idx = np.where(inside, my * nx + mx, 0)
        ok = inside & (pot[idx] < POT_HIGH) & (d2 <= tol * tol + 1e-12)
        if not ok.any():
            return None
        flat = np.where(ok, d2, np.inf).ravel()
        k = int(np.argmin(flat))
        return float(gx.ravel()[k]), float(gy.ravel()[k])

    def _potential(self, cost: NDArray[np.uint8], nx: int, ny: int, source: int, target: int) -> NDArray[np.float64]:
        pot = np.full(nx * ny, POT_HIGH)
        astar = int(self.params.use_astar)
        if self._kernel is None:
            _potential_py(cost.ravel(), pot, nx=nx, source=source, target=target, astar=astar)
            return pot
        import ctypes

        flat = np.ascontiguousarray(cost.ravel())
        heap_cells = np.empty(4 * nx * ny, dtype=np.int32)
        heap_keys = np.empty(4 * nx * ny, dtype=np.float64)
        self._kernel.twin_navfn_potential(
            flat.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
            nx,
            ny,
            source,
            target,
            astar,
            pot.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            heap_cells.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
            heap_keys.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            np.zeros(nx * ny, dtype=np.uint8).ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
        )
        return pot

    def _trace(
        self,
        pot: NDArray[np.float64],
        cost: NDArray[np.uint8],
        *,
        nx: int,
        ny: int,
        start: int,
        goal: int,
        max_cycles: int,
    ) -> NDArray[np.float64] | None:
        if self._kernel is None:
            return _trace_py(pot, nx=nx, ny=ny, start=start, goal=goal, max_cycles=max_cycles)
        import ctypes

        out = np.empty((max_cycles, 2))
        flat = np.ascontiguousarray(cost.ravel())
        n = self._kernel.twin_navfn_trace(
            pot.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            flat.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
            nx,
            ny,
            start,
            goal,
            max_cycles,
            out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            max_cycles,
        )
        return None if n < 0 else out[:n]


def _approach(xy: NDArray[np.float64], end: NDArray[np.float64]) -> NDArray[np.float64]:
    """Nav2's smoothApproachToGoal: the end replaces the last point if nearer the one before, else is appended."""
    if len(xy) >= 2:
        before = xy[-2]
        if float(np.sum((xy[-1] - before) ** 2)) > float(np.sum((end - before) ** 2)):
            out = xy.copy()
            out[-1] = end
            return out
    return np.vstack([xy, end])


# -- the Python reference of the C kernel (same arithmetic, same order) -------------------------


def _cell_update(cost: NDArray[np.uint8], pot: NDArray[np.float64], nx: int, n: int) -> float:
    left, right, up, down = float(pot[n - 1]), float(pot[n + 1]), float(pot[n - nx]), float(pot[n + nx])
    ta = left if left < right else right
    tc = up if up < down else down
    hf = float(cost[n])
    if tc < ta:
        ta, tc = tc, ta
    dc = tc - ta
    if dc >= hf:
        return ta + hf
    q = dc / hf
    v = -0.2301 * q * q + 0.5307 * q + 0.7040
    return ta + hf * v


def _potential_py(
    cost: NDArray[np.uint8], pot: NDArray[np.float64], *, nx: int, source: int, target: int, astar: int
) -> int:
    tx, ty = (target % nx, target // nx) if target >= 0 else (0, 0)

    def heuristic(n: int) -> float:
        if not astar:
            return 0.0
        dx, dy = float(n % nx - tx), float(n // nx - ty)
        return COST_NEUTRAL * math.sqrt(dx * dx + dy * dy)

    pot[source] = 0.0
    done = np.zeros(len(pot), dtype=bool)
    heap: list[tuple[float, int]] = [(0.0, source)]
    settled = 0
    offsets = (1, -1, nx, -nx)
    while heap:
        key, n = heapq.heappop(heap)
        if done[n] or key > pot[n] + heuristic(n):
            continue
        done[n] = True
        settled += 1
        if n == target:
            break
        for off in offsets:
            m = n + off
            if cost[m] >= COST_OBS or done[m]:
                continue
            p = _cell_update(cost, pot, nx, m)
            if p < pot[m]:
                pot[m] = p
                heapq.heappush(heap, (p + heuristic(m), m))
    return settled


def _gradient(pot: NDArray[np.float64], nx: int, n: int) -> tuple[float, float]:
    """NavFn's gradCell: the normalised descent direction at a cell (0 on the grid's first and last rows)."""
    if n < nx or n > len(pot) - nx:
        return 0.0, 0.0
    cv = float(pot[n])
    dx = dy = 0.0
    if cv >= POT_HIGH:
        if pot[n - 1] < POT_HIGH:
            dx = -COST_OBS
        elif pot[n + 1] < POT_HIGH:
            dx = COST_OBS
        if pot[n - nx] < POT_HIGH:
            dy = -COST_OBS
        elif pot[n + nx] < POT_HIGH:
            dy = COST_OBS
    else:
        if pot[n - 1] < POT_HIGH:
            dx += float(pot[n - 1]) - cv
        if pot[n + 1] < POT_HIGH:
            dx += cv - float(pot[n + 1])
        if pot[n - nx] < POT_HIGH:
            dy += float(pot[n - nx]) - cv
        if pot[n + nx] < POT_HIGH:
            dy += cv - float(pot[n + nx])
    norm = math.sqrt(dx * dx + dy * dy)
    if norm > 0.0:
        norm = 1.0 / norm
        dx *= norm
        dy *= norm
    return dx, dy


def _trace_py(
    pot: NDArray[np.float64], *, nx: int, ny: int, start: int, goal: int, max_cycles: int
) -> NDArray[np.float64] | None:
    """NavFn's calcPath (see the C kernel): the points from `start` down to the source node `goal`."""
    ns = nx * ny
    stc = start
    dx = dy = 0.0
    points: list[tuple[float, float]] = []
    ring = (-nx - 1, -nx, -nx + 1, -1, 1, nx - 1, nx, nx + 1)
    for _ in range(max_cycles):
        near = min(max(stc + round(dx) + int(nx * round(dy)), 0), ns - 1)
        if pot[near] < COST_NEUTRAL:
            points.append((float(goal % nx), float(goal // nx)))
            return np.array(points)
        if stc < nx or stc > ns - nx:
            return None
        points.append((stc % nx + dx, stc // nx + dy))
        oscillating = len(points) > 2 and points[-1] == points[-3]
        high = pot[stc] >= POT_HIGH or any(pot[stc + r] >= POT_HIGH for r in ring)
        if high or oscillating:
            best, bp = stc, float(int(pot[stc]))  # NavFn keeps the running minimum in an int
            for r in ring:
                if pot[stc + r] < bp:
                    bp, best = float(int(pot[stc + r])), stc + r
            stc, dx, dy = best, 0.0, 0.0
            if pot[stc] >= POT_HIGH:
                return None
            continue
        g0, g1, g2, g3 = (_gradient(pot, nx, c) for c in (stc, stc + 1, stc + nx, stc + nx + 1))
        x1 = (1.0 - dx) * g0[0] + dx * g1[0]
        x2 = (1.0 - dx) * g2[0] + dx * g3[0]
        x = (1.0 - dy) * x1 + dy * x2
        y1 = (1.0 - dx) * g0[1] + dx * g1[1]
        y2 = (1.0 - dx) * g2[1] + dx * g3[1]
        y = (1.0 - dy) * y1 + dy * y2
        if x == 0.0 and y == 0.0:
            return None
        ss = 0.5 / math.sqrt(x * x + y * y)
        dx += x * ss
        dy += y * ss
        if dx > 1.0:
            stc += 1
            dx -= 1.0
        if dx < -1.0:
            stc -= 1
            dx += 1.0
        if dy > 1.0:
            stc += nx
            dy -= 1.0
        if dy < -1.0:
            stc -= nx
            dy += 1.0
    return None
