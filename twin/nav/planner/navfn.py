"""NavFn as Nav2 Humble's planner_server runs it (`nav2_navfn_planner/NavfnPlanner`).

What carries over from Nav2 (and is held to it by recorded cases of Nav2's own code,
tests/unit/nav/planner/navfn_cases):

- Costs: a costmap cost c < 253 becomes 50 + 0.8 c (COST_NEUTRAL, COST_FACTOR; truncated to an
  integer as NavFn stores it); 253 (inscribed) and 254 (lethal) are forbidden; 255 (unknown) costs
  253 when `allow_unknown`, else is forbidden. The outermost ring of cells is forbidden too.
- Potential: float32, as NavFn's. From the robot's cell outward in batches: each batch's cells are
  updated from their two lowest neighbours by NavFn's quadratic interpolation of the Eikonal update;
  an improved cell re-queues a neighbour only when that neighbour's potential lies past its own by
  0.707 x the neighbour's cost, into the next batch while under a cost threshold (254 at first,
  raised by 100 each time the batch under it runs dry), else into the overflow block. A cell can be
  updated again later (there is no settled set). Propagation stops after the batch in which the
  goal's cell first gets a value (`use_astar`: keys and the first threshold carry 50 per cell of
  distance to the goal). The robot's own cell is cleared first (Nav2's `clearRobotCell`).
- Tolerance: when the goal cell has no potential, Nav2's square scan: from (goal - tolerance) in
  steps of one resolution (accumulated, so the last row or column may fall short), row by row, the
  first point of least squared distance whose cell has a potential becomes the path's end.
- Path: NavFn's calcPath in float32: gradient descent on the potential from the end back to the
  robot in half-cell steps (a lowest-neighbour step where the potential is not defined around the
  point or the path oscillates), done when the nearest node has a potential below 50 (the robot's
  node is then the last point), at most 4 x the costmap's larger side steps; reversed; the end
  replaces the last point if it is closer to the one before, else is appended. Middle poses carry
  identity orientation (yaw 0), the last pose the goal's yaw.
- Start == goal (the same x and y): no NavFn; a one-pose path at the start with the goal's yaw,
  refused when the start's cell is lethal (254).
- Grid nodes: world -> node by rounding (x - origin) / resolution half away from zero (`std::round`)
  and node -> world as origin + node * resolution (a node sits on a cell's corner, not its centre).

The two loops (potential, trace) run in C (`_native`, `navfn_kernels.c`); `_potential_py` and `_trace_py` are
the same algorithm in Python (a fallback used only without a C compiler, and the tests' reference) with
every float32 operation rounded as C rounds it.
"""

from __future__ import annotations

import ctypes
import enum
import math
from array import array
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
BLOCK_CAP = 10000  # NavFn's PRIORITYBUFSIZE
HALF_DIAGONAL = 0.707106781  # NavFn's INVSQRT2


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
    START_IN_LETHAL = "start on a lethal cell (start == goal)"
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
        #: The float32 potential of the last NavFn run (rows x cols, POT_HIGH where unreached), for inspection.
        self.potential: NDArray[np.float32] = np.zeros((0, 0), dtype=np.float32)

    @property
    def native(self) -> bool:
        """True when plans are computed by the C kernel."""
        return self._kernel is not None

    def make_plan(
        self, costmap: CostGrid, start: tuple[float, float, float], goal: tuple[float, float, float]
    ) -> Plan | PlanFailure:
        """Plan from `start` to `goal` ((x_m, y_m, yaw_rad) in the costmap's frame).

        Returns:
            The plan, or a `PlanFailure` (start or goal outside the costmap, a lethal start equal to the
            goal, or no path within tolerance).
        """
        self.potential = np.zeros((0, 0), dtype=np.float32)
        if start[0] == goal[0] and start[1] == goal[1]:
            return self._unique_pose(costmap, start, goal)
        ny, nx = costmap.cost.shape
        s_node = self.world_to_node(costmap, start[0], start[1])
        if s_node is None:
            return PlanFailure(
                reason=PlanFailureReason.START_OUTSIDE_MAP,
                message=f"start ({start[0]:.2f}, {start[1]:.2f}) is outside the costmap",
            )
        g_node = self.world_to_node(costmap, goal[0], goal[1])
        if g_node is None:
            return PlanFailure(
                reason=PlanFailureReason.GOAL_OUTSIDE_MAP,
                message=f"goal ({goal[0]:.2f}, {goal[1]:.2f}) is outside the costmap",
            )
        grid = costmap.cost.copy()
        grid[s_node[1], s_node[0]] = 0  # Nav2's clearRobotCell
        cost = np.ascontiguousarray(navfn_costs(grid, allow_unknown=self.params.allow_unknown).ravel())
        source = s_node[1] * nx + s_node[0]
        pot = self._potential(cost, nx, ny, source, g_node[1] * nx + g_node[0])
        self.potential = pot.reshape(ny, nx)
        end = self._best_end(costmap, pot, goal)
        if end is None:
            return PlanFailure(
                reason=PlanFailureReason.NO_VALID_PATH,
                message=f"no path to ({goal[0]:.2f}, {goal[1]:.2f}) within {self.params.tolerance_m} m",
            )
        e_node = self.world_to_node(costmap, end[0], end[1])
        assert e_node is not None  # the scan only keeps points whose node has a potential
        end_cell = e_node[1] * nx + e_node[0]
        trace = self._trace(pot, nx=nx, ny=ny, start=end_cell, goal=source, max_cycles=4 * max(nx, ny))
        if trace is None:
            return PlanFailure(
                reason=PlanFailureReason.NO_VALID_PATH,
                message=f"the path to ({goal[0]:.2f}, {goal[1]:.2f}) could not be traced on the potential",
            )
        cells = trace[::-1].astype(np.float64)  # from the robot's node to the plan's end
        res = costmap.resolution_m
        xy = np.column_stack([costmap.origin_x_m + cells[:, 0] * res, costmap.origin_y_m + cells[:, 1] * res])
        xy = _approach(xy, end)
        poses = np.zeros((len(xy), 3))
        poses[:, :2] = xy
        poses[-1, 2] = goal[2]
        return Plan(frame_id=costmap.frame_id, poses=poses)

    # -- internals -------------------------------------------------------------------------

    @staticmethod
    def _unique_pose(
        costmap: CostGrid, start: tuple[float, float, float], goal: tuple[float, float, float]
    ) -> Plan | PlanFailure:
        """Nav2's createPlan for start == goal: the start with the goal's yaw, unless its cell is lethal."""
        col = math.floor((start[0] - costmap.origin_x_m) / costmap.resolution_m)
        row = math.floor((start[1] - costmap.origin_y_m) / costmap.resolution_m)
        if not (0 <= col < costmap.cols and 0 <= row < costmap.rows):
            return PlanFailure(
                reason=PlanFailureReason.START_OUTSIDE_MAP,
                message=f"start ({start[0]:.2f}, {start[1]:.2f}) is outside the costmap",
            )
        if int(costmap.cost[row, col]) == COST_OBS:
            return PlanFailure(
                reason=PlanFailureReason.START_IN_LETHAL,
                message=f"start ({start[0]:.2f}, {start[1]:.2f}) equals the goal and lies on a lethal cell",
            )
        return Plan(frame_id=costmap.frame_id, poses=np.array([[start[0], start[1], goal[2]]]))

    @staticmethod
    def world_to_node(costmap: CostGrid, x_m: float, y_m: float) -> tuple[int, int] | None:
        """NavfnPlanner::worldToMap: the nearest node, halves rounded away from zero; None off the map."""
        if x_m < costmap.origin_x_m or y_m < costmap.origin_y_m:
            return None
        mx = _round_half_away((x_m - costmap.origin_x_m) / costmap.resolution_m)
        my = _round_half_away((y_m - costmap.origin_y_m) / costmap.resolution_m)
        return (mx, my) if mx < costmap.cols and my < costmap.rows else None

    def _best_end(
        self, costmap: CostGrid, pot: NDArray[np.float32], goal: tuple[float, float, float]
    ) -> tuple[float, float] | None:
        """The goal if its node has a potential, else Nav2's scan of the tolerance square (see the module)."""
        nx = costmap.cols

        def potential_at(x_m: float, y_m: float) -> float:
            node = self.world_to_node(costmap, x_m, y_m)
            return POT_HIGH if node is None else float(pot[node[1] * nx + node[0]])

        if potential_at(goal[0], goal[1]) < POT_HIGH:
            return goal[0], goal[1]
        tol, res = self.params.tolerance_m, costmap.resolution_m
        best: tuple[float, float] | None = None
        best_d2 = math.inf
        y = goal[1] - tol
        while y <= goal[1] + tol:
            x = goal[0] - tol
            while x <= goal[0] + tol:
                dx, dy = x - goal[0], y - goal[1]
                d2 = dx * dx + dy * dy
                if d2 < best_d2 and potential_at(x, y) < POT_HIGH:
                    best, best_d2 = (x, y), d2
                x += res
            y += res
        return best

    def _potential(self, cost: NDArray[np.uint8], nx: int, ny: int, source: int, target: int) -> NDArray[np.float32]:
        pot = np.empty(nx * ny, dtype=np.float32)
        astar = int(self.params.use_astar)
        if self._kernel is None:
            pot[:] = _potential_py(cost, nx=nx, ny=ny, source=source, target=target, astar=astar)
            return pot
        self._kernel.twin_navfn_potential(
            cost.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
            nx,
            ny,
            source,
            target,
            astar,
            pot.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
            np.empty(3 * BLOCK_CAP, dtype=np.int32).ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
            np.zeros(nx * ny, dtype=np.uint8).ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte)),
        )
        return pot

    def _trace(
        self, pot: NDArray[np.float32], *, nx: int, ny: int, start: int, goal: int, max_cycles: int
    ) -> NDArray[np.float32] | None:
        if self._kernel is None:
            return _trace_py(pot, nx=nx, ny=ny, start=start, goal=goal, max_cycles=max_cycles)
        out = np.empty((max_cycles, 2), dtype=np.float32)
        n = self._kernel.twin_navfn_trace(
            pot.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
            nx,
            ny,
            start,
            goal,
            max_cycles,
            out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)),
        )
        return None if n < 0 else out[:n]


def _round_half_away(v: float) -> int:
    """C's round(): the nearest integer, halves away from zero."""
    t = math.trunc(v)
    if abs(v - t) >= 0.5:
        t += 1 if v > 0 else -1
    return t


def _approach(xy: NDArray[np.float64], end: tuple[float, float]) -> NDArray[np.float64]:
    """Nav2's smoothApproachToGoal: the end replaces the last point if nearer the one before, else is appended."""
    if len(xy) >= 2:
        bx, by = float(xy[-2, 0]), float(xy[-2, 1])
        lx, ly = float(xy[-1, 0]) - bx, float(xy[-1, 1]) - by
        ex, ey = end[0] - bx, end[1] - by
        if lx * lx + ly * ly > ex * ex + ey * ey:
            out = xy.copy()
            out[-1] = end
            return out
    return np.vstack([xy, np.array([end])])


# -- the Python reference of the C kernel: the same operations, each float32 result rounded as C rounds it --

_F32 = array("f", [0.0])


def _f32(v: float) -> float:
    """`v` rounded to float32 (a double result of float32 operands rounds to the float32 result exactly)."""
    _F32[0] = v
    return _F32[0]


def _potential_py(cost: NDArray[np.uint8], *, nx: int, ny: int, source: int, target: int, astar: int) -> array[float]:
    """NavFn's batched propagation (see `twin_navfn_potential` in `_native`); the float32 potential."""
    ns = nx * ny
    c = cost.tolist()
    pot = array("f", [POT_HIGH]) * ns
    queued = bytearray(ns)
    blocks: list[list[int]] = [[], [], []]
    tx, ty = target % nx, target // nx

    def enqueue(which: int, n: int) -> None:
        if 0 <= n < ns and not queued[n] and c[n] < COST_OBS and len(blocks[which]) < BLOCK_CAP:
            blocks[which].append(n)
            queued[n] = 1

    threshold = float(COST_OBS)
    pot[source] = 0.0
    for n in (source + 1, source - 1, source - nx, source + nx):
        enqueue(0, n)
    if astar:
        threshold = _f32(_f32(math.sqrt((source % nx - tx) ** 2 + (source // nx - ty) ** 2) * COST_NEUTRAL) + threshold)
    cycles = max(ns // 20, nx + ny)
    for _ in range(cycles):
        if not blocks[0] and not blocks[1]:
            break
        batch = blocks[0]
        for n in batch:
            queued[n] = 0
        for n in batch:
            left, right, below, above = pot[n - 1], pot[n + 1], pot[n - nx], pot[n + nx]
            horizontal = left if left < right else right
            vertical = below if below < above else above
            hf = float(c[n])
            low, gap = vertical, _f32(horizontal - vertical)
            if gap < 0:
                gap, low = -gap, horizontal
            if gap >= hf:
                p = _f32(low + hf)
            else:
                q = _f32(gap / hf)
                weight = _f32(-0.2301 * q * q + 0.5307 * q + 0.7040)
                p = _f32(low + _f32(hf * weight))
            if not p < pot[n]:
                continue
            pot[n] = p
            if astar:
                p = _f32(p + _f32(math.sqrt((n % nx - tx) ** 2 + (n // nx - ty) ** 2) * COST_NEUTRAL))
            which = 1 if p < threshold else 2
            if left > _f32(p + _f32(HALF_DIAGONAL * c[n - 1])):
                enqueue(which, n - 1)
            if right > _f32(p + _f32(HALF_DIAGONAL * c[n + 1])):
                enqueue(which, n + 1)
            if below > _f32(p + _f32(HALF_DIAGONAL * c[n - nx])):
                enqueue(which, n - nx)
            if above > _f32(p + _f32(HALF_DIAGONAL * c[n + nx])):
                enqueue(which, n + nx)
        blocks[0], blocks[1] = blocks[1], []
        if not blocks[0]:
            threshold = _f32(threshold + 2 * COST_NEUTRAL)
            blocks[0], blocks[2] = blocks[2], []
        if pot[target] < POT_HIGH:
            break
    return pot


def _gradient(pot: array[float], nx: int, n: int) -> tuple[float, float]:
    """NavFn's gradCell: the normalised descent direction at a cell (0 outside rows 1 .. ny-2), float32."""
    if n < nx or n > len(pot) - nx:
        return 0.0, 0.0
    cv = pot[n]
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
            dx = _f32(dx + _f32(pot[n - 1] - cv))
        if pot[n + 1] < POT_HIGH:
            dx = _f32(dx + _f32(cv - pot[n + 1]))
        if pot[n - nx] < POT_HIGH:
            dy = _f32(dy + _f32(pot[n - nx] - cv))
        if pot[n + nx] < POT_HIGH:
            dy = _f32(dy + _f32(cv - pot[n + nx]))
    norm = _f32(math.sqrt(dx * dx + dy * dy))
    if norm > 0.0:
        norm = _f32(1.0 / norm)
        return _f32(norm * dx), _f32(norm * dy)
    return 0.0, 0.0


def _as_int(p: float) -> int:
    """A float32 truncated to int as x86-64 does it (INT_MIN when out of range), NavFn's `int minp = potarr[...]`."""
    return -(2**31) if not -(2.0**31) <= p < 2.0**31 else int(p)


def _trace_py(
    pot_np: NDArray[np.float32], *, nx: int, ny: int, start: int, goal: int, max_cycles: int
) -> NDArray[np.float32] | None:
    """NavFn's calcPath (see `twin_navfn_trace` in `_native`); (x, y) in cells, or None."""
    pot = array("f", pot_np.tobytes())
    ns = nx * ny
    ring = (-nx - 1, -nx, -nx + 1, -1, 1, nx - 1, nx, nx + 1)
    stc, dx, dy = start, 0.0, 0.0
    xs: list[float] = []
    ys: list[float] = []
    for _ in range(max_cycles):
        near = min(max(stc + _round_half_away(dx) + nx * _round_half_away(dy), 0), ns - 1)
        if pot[near] < COST_NEUTRAL:
            xs.append(float(goal % nx))
            ys.append(float(goal // nx))
            return np.array([xs, ys], dtype=np.float32).T.copy()
        if stc < nx or stc > ns - nx:
            return None
        xs.append(_f32(stc % nx + dx))
        ys.append(_f32(stc // nx + dy))
        oscillating = len(xs) > 2 and xs[-1] == xs[-3] and ys[-1] == ys[-3]
        if oscillating or pot[stc] >= POT_HIGH or any(pot[stc + r] >= POT_HIGH for r in ring):
            best, best_p = stc, _as_int(pot[stc])
            for r in ring:
                if pot[stc + r] < _f32(float(best_p)):
                    best, best_p = stc + r, _as_int(pot[stc + r])
            stc, dx, dy = best, 0.0, 0.0
            if pot[stc] >= POT_HIGH:
                return None
            continue
        g0, g1, g2, g3 = (_gradient(pot, nx, c) for c in (stc, stc + 1, stc + nx, stc + nx + 1))
        x1 = _f32((1.0 - dx) * g0[0] + _f32(dx * g1[0]))
        x2 = _f32((1.0 - dx) * g2[0] + _f32(dx * g3[0]))
        x = _f32((1.0 - dy) * x1 + _f32(dy * x2))
        y1 = _f32((1.0 - dx) * g0[1] + _f32(dx * g1[1]))
        y2 = _f32((1.0 - dx) * g2[1] + _f32(dx * g3[1]))
        y = _f32((1.0 - dy) * y1 + _f32(dy * y2))
        if x == 0.0 and y == 0.0:
            return None
        ss = _f32(0.5 / _f32(math.sqrt(x * x + y * y)))
        dx = _f32(dx + _f32(x * ss))
        dy = _f32(dy + _f32(y * ss))
        if dx > 1.0:
            stc, dx = stc + 1, _f32(dx - 1.0)
        if dx < -1.0:
            stc, dx = stc - 1, _f32(dx + 1.0)
        if dy > 1.0:
            stc, dy = stc + nx, _f32(dy - 1.0)
        if dy < -1.0:
            stc, dy = stc - nx, _f32(dy + 1.0)
    return None
