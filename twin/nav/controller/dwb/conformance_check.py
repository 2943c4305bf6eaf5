"""Hold the twin's DWB to a case recorded from Nav2 Humble's own (`twin nav conformance`).

A case (`tests/unit/nav/controller/dwb_cases/README.md`) is one controller cycle's inputs — the local
costmap, the global plan (already in the costmap's frame), the robot's pose and odometry velocity, the
critics' state (RotateToGoal's latches, Oscillation's flags, trends and the pose of the last flip) and
the FollowPath parameters — and what
Nav2's code made of them: where transformGlobalPlan cut the plan, the goal, each critic's scale, every
velocity sample in the iterator's order with its trajectory's pose count and end pose (all poses in a
few cases), each critic's raw score until the first that rejects it, which one that was, the total,
the sample Nav2 chose (or none legal), and Oscillation's flags after the cycle's debrief.

The twin's numpy cycle (`DwbController.evaluate`) is compared sample by sample, bit for bit; the
cycle that runs in missions (the C kernel with `native`, else numpy) must choose the same command with
the same total.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav.controller.dwb.critics import CommandTrend
from twin.nav.controller.dwb.dwb_params import DwbParams, NoValidTrajectory
from twin.nav.controller.dwb.local_planner import DwbController, Evaluation
from twin.nav.costmap_2d.costmap_2d import CostGrid

__all__ = ["check_dwb", "controller_for_case"]

_STATUS = {"Received plan with zero length": "empty_plan", "Resulting plan has 0 poses in it.": "empty_transformed"}


def _bits(a: NDArray[Any]) -> NDArray[np.uint64]:
    return np.ascontiguousarray(a, dtype="<f8").view("<u8")


def _first(got: NDArray[Any], want: NDArray[Any], what: str) -> str:
    """'' when bit-equal (NaN equal to NaN), else where they first differ."""
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    if got.shape != want.shape:
        return f"{what}: shape {got.shape}, Nav2 {want.shape}"
    same = (_bits(got) == _bits(want)) | (np.isnan(got) & np.isnan(want))
    if same.all():
        return ""
    index = np.unravel_index(int(np.flatnonzero(~same.ravel())[0]), want.shape)
    where = ", ".join(str(int(i)) for i in index)
    return f"{what}: {int((~same).sum())} values differ, first at ({where}): twin {got[index]!r}, Nav2 {want[index]!r}"


def controller_for_case(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> DwbController:
    """A DWB controller with the case's parameters, plan and critic state (before its cycle)."""
    section = dict(meta["params"])
    frequency = float(section.pop("controller_frequency", 10.0))  # controller_server's (TB3: 10 Hz)
    params = DwbParams.from_nav2(section, controller_frequency_hz=frequency, where="case params")
    dwb = DwbController(params, native=native)
    dwb.set_plan(arrays["plan"])
    in_window, rotating, x_pos, x_neg, th_pos, th_neg = (bool(v) for v in arrays["state"][:6])
    x_sign, th_sign = (int(v) for v in arrays["state"][6:8])
    cr = dwb._critics
    cr.in_window, cr.rotating = in_window, rotating
    cr.x = CommandTrend(sign=x_sign, positive_only=x_pos, negative_only=x_neg)
    cr.theta = CommandTrend(sign=th_sign, positive_only=th_pos, negative_only=th_neg)
    cr.stationary = _pose(arrays["stationary"])
    return dwb


def _oscillation_after(dwb: DwbController, arrays: Mapping[str, NDArray[Any]], path: str) -> list[str]:
    """Oscillation's flags after the cycle's debrief against Nav2's (x +only, x -only, theta +only, -only)."""
    if "oscillation_after" not in arrays:
        return []
    cr = dwb._critics
    got = [cr.x.positive_only, cr.x.negative_only, cr.theta.positive_only, cr.theta.negative_only]
    want = [bool(v) for v in arrays["oscillation_after"]]
    if got != want:
        return [f"Oscillation's flags after the debrief ({path}): twin {got}, Nav2 {want}"]
    return []


def _costmap(arrays: Mapping[str, NDArray[Any]]) -> CostGrid:
    ox, oy, res = (float(v) for v in arrays["grid"])
    return CostGrid(frame_id="odom", resolution_m=res, origin_x_m=ox, origin_y_m=oy, cost=arrays["cost"])


def _pose(a: NDArray[Any]) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))


def _check_evaluation(ev: Evaluation, meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]]) -> list[str]:
    out: list[str] = []
    if (ev.begin, ev.end) != (meta["begin"], meta["end"]):
        out.append(f"transformGlobalPlan: poses [{ev.begin}, {ev.end}), Nav2 [{meta['begin']}, {meta['end']})")
    if d := _first(np.array(ev.goal), np.array(meta["goal"]), "goal"):
        out.append(d)
    if d := _first(ev.scales, arrays["scales"], "critic scales"):
        out.append(d)
    traj = ev.trajectories
    if d := _first(traj.velocity, arrays["samples"], "velocity samples"):
        return [*out, d]
    n = len(traj.velocity)
    include_last = 1 if DwbParams.from_nav2(dict(meta["params"])).include_last_point else 0
    n_poses = traj.steps + 1 + include_last
    if not np.array_equal(n_poses, arrays["n_poses"]):
        s = int(np.flatnonzero(n_poses != arrays["n_poses"])[0])
        out.append(f"trajectory poses: sample {s} has {n_poses[s]}, Nav2 {arrays['n_poses'][s]}")
        return out
    ends = traj.poses[np.arange(n), traj.steps]
    if d := _first(ends, arrays["end_poses"], "trajectory end poses"):
        out.append(d)
    if "poses" in arrays:
        full = np.full(arrays["poses"].shape, np.nan)
        for s in range(n):
            k = int(traj.steps[s]) + 1
            full[s, :k] = traj.poses[s, :k]
            if include_last:
                full[s, k] = traj.poses[s, k - 1]
        if d := _first(full, arrays["poses"], "trajectory poses"):
            out.append(d)
    thrower = ev.thrower
    if not np.array_equal(thrower, arrays["thrower"]):
        s = int(np.flatnonzero(thrower != arrays["thrower"])[0])
        names = ev.critics

        def name(k: int) -> str:
            return "legal" if k < 0 else f"rejected by {names[k]}"

        out.append(
            f"sample {s} {tuple(arrays['samples'][s])}: twin {name(int(thrower[s]))}, "
            f"Nav2 {name(int(arrays['thrower'][s]))} ({int((thrower != arrays['thrower']).sum())} samples differ)"
        )
    # raw scores as Nav2 reports them: up to (not including) the critic that rejected the sample
    raw = ev.raw.copy()
    column = np.arange(raw.shape[1])[None, :]
    cut = np.where(thrower < 0, raw.shape[1], thrower)[:, None]
    raw[column >= cut] = np.nan
    if d := _first(raw, arrays["raw"], "raw critic scores (sample, critic)"):
        out.append(d)
    legal = arrays["thrower"] < 0
    if d := _first(np.where(legal, ev.total, 0.0), np.where(legal, arrays["total"], 0.0), "totals"):
        out.append(d)
    return out


def check_dwb(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """The ways the twin's DWB differs from Nav2's on one case (empty: equal)."""
    out: list[str] = []
    costmap = _costmap(arrays)
    pose, velocity = _pose(arrays["pose"]), (float(arrays["velocity"][0]), float(arrays["velocity"][1]))
    status = meta["status"]
    # the numpy cycle, every sample
    try:
        ev = controller_for_case(meta, arrays, native=False).evaluate(pose, velocity, costmap)
    except NoValidTrajectory as err:
        got = _STATUS.get(str(err), str(err))
        if got != status:
            out.append(f"Nav2: {status}; the twin's numpy cycle: {err}")
    else:
        if status in _STATUS.values():
            out.append(f"Nav2: {status}; the twin's numpy cycle went on to score {len(ev.raw)} samples")
        else:
            out += _check_evaluation(ev, meta, arrays)
    # the cycle missions run: its choice
    dwb = controller_for_case(meta, arrays, native=native)
    if dwb.native is not native:
        return [*out, "the C kernel is not available (no C compiler?): only the Python path can be checked"]
    path = "C kernel" if native else "numpy cycle"
    try:
        cmd = dwb.compute_velocity(pose, velocity, costmap)
    except NoValidTrajectory as err:
        got = _STATUS.get(str(err), "no_legal" if str(err).startswith("No valid trajectories") else str(err))
        if got != status:
            out.append(f"Nav2: {status}; the twin's {path}: {err}")
        return out + _oscillation_after(dwb, arrays, path)
    if status != "ok":
        return [*out, f"Nav2: {status}; the twin's {path} chose {cmd}"]
    want = arrays["samples"][meta["best"]]
    if d := _first(np.array(cmd), want, f"the chosen command ({path})"):
        out.append(d)
    if native and (d := _first(np.array([dwb._out[3]]), np.array([meta["best_total"]]), "the chosen total (C kernel)")):
        out.append(d)
    # the chosen trajectory (`/local_plan`): every pose where the case has them, else its length and end
    best, local = int(meta["best"]), dwb.local_plan
    if "poses" in arrays:
        want = arrays["poses"][best, : int(arrays["n_poses"][best])]
        if d := _first(local, want, f"the chosen trajectory ({path})"):
            out.append(d)
    elif len(local) != int(arrays["n_poses"][best]):
        out.append(f"the chosen trajectory ({path}): {len(local)} poses, Nav2 {int(arrays['n_poses'][best])}")
    elif d := _first(local[-1], arrays["end_poses"][best], f"the chosen trajectory's end ({path})"):
        out.append(d)
    return out + _oscillation_after(dwb, arrays, path)
