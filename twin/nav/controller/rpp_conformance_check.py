"""Hold the twin's Regulated Pure Pursuit to cases recorded from Nav2 Humble's (`twin nav conformance`).

A case (`tests/unit/nav/controller/rpp_cases/README.md`) is RPP's parameters, a local costmap with
the robot's footprint and radii, the goal checker's tolerance, a global plan (in the costmap's frame)
and a sequence of controller cycles, each the robot's pose and odometry speed. Per cycle Nav2 gave a
status (a command, or which exception), how many plan poses it erased and kept, which branch chose
the command, the lookahead, the carrot, the curvature, the command and how many projected poses the
collision check looked at. The twin's `RppController` gets the same plan once and the same cycles in
order; equal means the same statuses, counts and branches, and every number within 1e-9 (absolute,
or relative above 1): the re-typed oracle rotates the plan into the robot's frame in 2D where Nav2
goes through tf2's quaternions, so bit-equality is not the claim.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav.controller.regulated_pure_pursuit import (
    MSG_COLLISION,
    MSG_COSTMAP_SMALL,
    MSG_ZERO_LENGTH,
    MSG_ZERO_POSES,
    NoValidCommand,
    RppController,
    RppParams,
)
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["TOLERANCE", "check_rpp"]

TOLERANCE = 1e-9
"""Absolute below 1, relative above."""

_STATUS = {MSG_ZERO_LENGTH: 1, MSG_ZERO_POSES: 2, MSG_COLLISION: 3, MSG_COSTMAP_SMALL: 4}
_FLOATS = ("lookahead", "carrot x", "carrot y", "curvature", "vx", "wz")


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= TOLERANCE * max(1.0, abs(b))


def check_rpp(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """The ways the twin's RPP differs from Nav2's on one case (empty: equal).

    `native` is accepted for the registry's signature (the footprint cost runs in C when built).
    """
    del native
    section = {k: v for k, v in meta["params"].items() if v is not None}
    params = RppParams.from_nav2(section, controller_frequency_hz=float(meta["controller_frequency"]), where="case")
    controller = RppController(params)
    footprint = tuple((float(x), float(y)) for x, y in arrays["footprint"])
    controller.use_costmap(
        footprint, float(meta["inscribed_radius"]), float(meta["circumscribed_radius"]), bool(meta["track_unknown"])
    )
    controller.goal_dist_tol_m = float(meta["goal_dist_tol"])
    origin = meta["origin"]
    costmap = CostGrid(
        frame_id="odom",
        resolution_m=float(meta["resolution"]),
        origin_x_m=float(origin[0]),
        origin_y_m=float(origin[1]),
        cost=np.ascontiguousarray(arrays["cost"], dtype=np.uint8),
    )
    controller.set_plan(arrays["plan"])
    out: list[str] = []
    cycles = arrays["cycles_in"].tolist()
    want_status = arrays["out_status"].tolist()
    want_erased, want_kept = arrays["out_erased"].tolist(), arrays["out_transformed"].tolist()
    want_branch, want_arc = arrays["out_branch"].tolist(), arrays["out_arc_n"].tolist()
    want_floats = arrays["out_float"].tolist()
    for k, (x, y, yaw, vx, wz) in enumerate(cycles):
        status, cmd = 0, (0.0, 0.0)
        try:
            cmd = controller.compute_velocity((x, y, yaw), (vx, wz), costmap)
        except NoValidCommand as err:
            status = _STATUS.get(str(err), -1)
        c = controller.last_cycle
        if status != want_status[k]:
            named = meta["status_codes"][str(want_status[k])]
            out.append(f"cycle {k}: status {status}, Nav2 {want_status[k]} ({named})")
            break
        compared = 1 if status in (1, 2) else 3  # failing in the plan's cut, only the erasure is known
        got_ints = (c.erased, c.transformed, c.branch)[:compared]
        want_ints = (want_erased[k], want_kept[k], want_branch[k])[:compared]
        if got_ints != want_ints:
            out.append(f"cycle {k}: erased, kept, branch {got_ints}, Nav2 {want_ints}")
            break
        if status in (1, 2, 4):
            continue
        compared = 4 if status == 3 else 6  # a collision: no command
        got = (c.lookahead_m, c.carrot[0], c.carrot[1], c.curvature, cmd[0], cmd[1])[:compared]
        want = tuple(want_floats[k])[:compared]
        bad = [f"{n} {g!r}, Nav2 {w!r}" for n, g, w in zip(_FLOATS, got, want, strict=False) if not _close(g, w)]
        if bad:
            out.append(f"cycle {k}: " + "; ".join(bad))
            break
        if c.arc_poses != want_arc[k]:
            out.append(f"cycle {k}: collision check over {c.arc_poses} projected poses, Nav2 {want_arc[k]}")
            break
    return out
