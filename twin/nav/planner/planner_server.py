"""nav2_planner's planner_server: NavFn on the global costmap (map frame), and its node publishing `/plan`.

`PlannerServer.compute_path` answers ComputePathToPose and ComputePathThroughPoses within the
simulated instant it is asked (a path through several poses is the pieces joined, each planned from
the previous pose); `is_path_valid` is the server's IsPathValid service. `PlannerServerNode`
publishes each computed path on `/plan` (nav_msgs/Path, map).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from twin.bag import PathEncoder
from twin.nav.costmap_2d.layered_costmap import Costmap
from twin.nav.frames import Frames
from twin.nav.planner.navfn import NavfnParams, NavfnPlanner, PlanFailure, PlanFailureReason
from twin.node import Encoded, Node, node_logger

__all__ = ["PlannerServer", "PlannerServerNode"]


F64 = NDArray[np.float64]


class PlannerServer:
    """planner_server with its one NavFn planner (`GridBased`).

    Args:
        params: NavFn's parameters.
        frames: The shared transforms (the robot's map pose is a path's default start).
        global_costmap: The costmap the planner plans on (map frame).
        native: Use NavFn's C kernel when it is available.
    """

    def __init__(self, params: NavfnParams, frames: Frames, global_costmap: Costmap, *, native: bool = True) -> None:
        self._log = node_logger("planner_server")  # its node's lines: `[robot1.planner_server]` in a fleet
        self.frames = frames
        self.global_costmap = global_costmap
        self.planner = NavfnPlanner(params, native=native)
        #: Called with (t_ns, path) for every computed path (the node publishes `/plan`).
        self.on_plan: Callable[[int, F64], None] | None = None
        #: Why the last `compute_path` found no path (None: it found one, or had no goal poses).
        self.last_failure: PlanFailureReason | None = None

    def compute_path(self, targets: Sequence[Any], start: Any, t_ns: int) -> F64 | str:
        """Plan from `start` (None: the robot's map pose) through `targets`; the path, or why there is none."""
        self.last_failure = None
        if not targets:
            return "no goal poses to plan through"
        here = self.frames.map_pose() if start is None else tuple(float(v) for v in start)
        pieces: list[F64] = []
        grid = self.global_costmap.grid
        for target in targets:
            end = (float(target[0]), float(target[1]), float(target[2]))
            result = self.planner.make_plan(grid, here, end)  # type: ignore[arg-type]
            if isinstance(result, PlanFailure):
                self._log.warning("GridBased: failed to create plan: %s", result.message)
                self.last_failure = result.reason
                return f"planner: {result.message}"
            pieces.append(result.poses if not pieces else result.poses[1:])
            here = end
        path = np.concatenate(pieces) if len(pieces) > 1 else pieces[0]
        if self.on_plan is not None:
            self.on_plan(t_ns, path)
        return path

    def is_path_valid(self, path: np.ndarray) -> bool:
        """planner_server's is_path_valid: no lethal or inscribed cell under the path (Humble)."""
        grid = self.global_costmap.grid
        p = np.asarray(path, dtype=np.float64).reshape(-1, 3)
        col = np.floor((p[:, 0] - grid.origin_x_m) / grid.resolution_m).astype(np.int64)
        row = np.floor((p[:, 1] - grid.origin_y_m) / grid.resolution_m).astype(np.int64)
        rows, cols = grid.cost.shape
        inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        cost = grid.cost[row[inside], col[inside]]
        return not bool(((cost == 253) | (cost == 254)).any())


class _Servers(Protocol):
    @property
    def planner_server(self) -> PlannerServer: ...


class PlannerServerNode(Node):
    """planner_server: publishes `/plan` for each path it computes."""

    def __init__(self, servers: _Servers) -> None:
        super().__init__("planner_server")
        pub = self.create_publisher(PathEncoder.msgtype, "plan", 10)
        encode = PathEncoder("map").encode

        def on_plan(t_ns: int, path: F64) -> None:
            pub.publish(Encoded((encode, (t_ns, path), path)))

        servers.planner_server.on_plan = on_plan
