"""Hold the twin's behaviours and their collision check to cases recorded from Nav2 Humble's (`twin nav conformance`).

Two kinds of case (`tests/unit/nav/behaviors/behavior_cases/README.md`):

- `behavior`: Spin, BackUp or DriveOnHeading with behavior_server's parameters, a local costmap and
  the robot's footprint, the action's request, the start (time and pose), then per cycle the time
  and the robot's pose. Nav2 gave whether `onRun` accepted the goal and, per cycle, the status
  (running, succeeded, time allowance exceeded, collision ahead) and the command. The twin's
  behaviour gets the same start and cycles; equal means the same acceptance, the same statuses
  and the same commands bit for bit.
- `behavior_collision`: poses on a costmap with obstacles: CostmapTopicCollisionChecker's
  `isCollisionFree` and its footprint score, and RPP's `inCollision` with and without unknown
  space tracked. Equal means the same answers and the same score.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav.behaviors.behavior_server import make_behavior
from twin.nav.behaviors.timed_behavior import BehaviorParams, BehaviorStatus, collision_free
from twin.nav.controller.regulated_pure_pursuit import in_collision
from twin.nav.costmap_2d.costmap_2d import CostGrid
from twin.nav.costmap_2d.footprint import footprint_cost

__all__ = ["check_behavior", "check_behavior_collision"]

Arrays = Mapping[str, NDArray[Any]]


def _costmap(meta: Mapping[str, Any], arrays: Arrays) -> CostGrid:
    origin = meta["origin"]
    return CostGrid(
        frame_id="odom",
        resolution_m=float(meta["resolution"]),
        origin_x_m=float(origin[0]),
        origin_y_m=float(origin[1]),
        cost=np.ascontiguousarray(arrays["cost"], dtype=np.uint8),
    )


def _footprint(arrays: Arrays) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in arrays["footprint"])


def _status(status: BehaviorStatus, reason: str) -> int:
    if status is BehaviorStatus.RUNNING:
        return 0
    if status is BehaviorStatus.SUCCEEDED:
        return 1
    return 2 if reason.startswith("Exceeded time allowance") else 3 if reason.startswith("Collision Ahead") else -1


def check_behavior(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's Spin / BackUp / DriveOnHeading differ from Nav2's on one case (empty: equal)."""
    del native
    p = meta["params"]
    params = BehaviorParams(
        cycle_frequency_hz=float(p["cycle_frequency"]),
        simulate_ahead_time_s=float(p["simulate_ahead_time"]),
        max_rotational_vel=float(p["max_rotational_vel"]),
        min_rotational_vel=float(p["min_rotational_vel"]),
        rotational_acc_lim=float(p["rotational_acc_lim"]),
        backup_limits=(float(p["acceleration_limit"]), float(p["deceleration_limit"]), float(p["minimum_speed"])),
        drive_on_heading_limits=(
            float(p["acceleration_limit"]),
            float(p["deceleration_limit"]),
            float(p["minimum_speed"]),
        ),
        footprint=_footprint(arrays),
    )
    behavior = make_behavior(str(meta["kind"]), params)
    start = meta["start"]
    refusal = behavior.start(meta["request"], (float(start[0]), float(start[1]), float(start[2])), meta["start_t_ns"])
    if bool(refusal) == bool(meta["run_ok"]):
        return [f"onRun: the twin {'refuses' if refusal else 'accepts'} the goal ({refusal}), Nav2 does not"]
    if refusal:
        return []
    costmap = _costmap(meta, arrays)
    codes = meta["status_codes"]
    want_status = arrays["out_status"].tolist()
    want_cmd = arrays["out_cmd"].tolist()
    for k, (t_ns, pose) in enumerate(zip(arrays["cycle_t_ns"].tolist(), arrays["cycle_pose"].tolist(), strict=True)):
        step = behavior.step(int(t_ns), (pose[0], pose[1], pose[2]), costmap)
        status = _status(step.status, step.reason)
        if status != want_status[k]:
            return [f"cycle {k}: {step.status.value} ({step.reason}), Nav2 {codes[str(want_status[k])]}"]
        got = step.cmd if status == 0 else (0.0, 0.0)
        if list(got) != want_cmd[k]:
            return [f"cycle {k}: command {got!r}, Nav2 {tuple(want_cmd[k])!r}"]
    return []


def check_behavior_collision(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's behaviour / RPP collision checks differ from Nav2's on one case (empty: equal)."""
    del native
    costmap = _costmap(meta, arrays)
    footprint = _footprint(arrays)
    out: list[str] = []
    rows = zip(
        arrays["poses"].tolist(),
        arrays["out_free"].tolist(),
        arrays["out_score"].tolist(),
        arrays["out_rpp_in_collision"].tolist(),
        strict=True,
    )
    for k, (pose, free, score, rpp) in enumerate(rows):
        xyz = (pose[0], pose[1], pose[2])
        got_free = collision_free(costmap, footprint, xyz)
        if got_free != bool(free):
            out.append(f"pose {k} {xyz}: collision free {got_free}, Nav2 {bool(free)}")
        if score >= 0.0 and (got := footprint_cost(costmap, footprint, xyz)) != score:
            out.append(f"pose {k} {xyz}: footprint cost {got}, Nav2 {score:g}")
        got_rpp = [int(in_collision(costmap, footprint, xyz, track_unknown=t)) for t in (False, True)]
        if got_rpp != rpp:
            out.append(f"pose {k} {xyz}: RPP inCollision (untracked, tracked unknown) {got_rpp}, Nav2 {rpp}")
        if len(out) >= 3:
            break
    return out
