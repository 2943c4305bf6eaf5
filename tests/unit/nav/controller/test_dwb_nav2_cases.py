"""DWB against Nav2 Humble's own: every case in `dwb_cases/` (see its README).

Equal means bitwise: each velocity sample, each trajectory's poses, each critic's raw score and which
critic rejects a sample, the totals, and the command the cycle chooses, on the C kernel and the numpy
cycle. The tests below the replay pin the two behaviours the cases changed, on recorded inputs.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.nav.conformance import check_case, load_case
from twin.nav.controller.dwb.conformance_check import _costmap, controller_for_case
from twin.nav.controller.dwb.critics import shortest_angle

CASES = Path(__file__).with_name("dwb_cases")
FILES = sorted(CASES.glob("*.npz"))


def test_the_recorded_set_covers_the_issue() -> None:
    metas = [load_case(f)[0] for f in FILES]
    assert len(metas) >= 200
    assert {m["component"] for m in metas} == {"dwb"}
    assert len({m["nav2_commit"] for m in metas}) == 1
    groups = {m["group"] for m in metas}
    assert {"mission", "mission_state", "rotate_to_goal", "goal_close", "obstacles", "corridor", "velocity"} <= groups
    assert {"oscillation", "plan", "params", "limited_accel"} <= groups
    assert sum(m["group"].startswith("mission") for m in metas) >= 100
    assert {m["status"] for m in metas} == {"ok", "no_legal", "empty_plan", "empty_transformed"}
    assert sum("poses" in load_case(f)[1] for f in FILES) >= 3
    # the critics' state is exercised: RotateToGoal's latches and each of Oscillation's flags and signs
    states = np.array([load_case(f)[1]["state"] for f in FILES])
    assert states[:, :6].any(axis=0).all()
    assert {-1, 1} <= set(states[:, 6:].ravel().tolist())
    # Oscillation's debrief both sets flags and clears them (the robot moved or turned since the flip)
    cases = (load_case(f)[1] for f in FILES)
    after = [(a["state"][2:6], a["oscillation_after"]) for a in cases if "oscillation_after" in a]
    assert any(not s.any() and o.any() for s, o in after)
    assert any(s.any() and not o.any() for s, o in after)


@pytest.mark.parametrize("native", [True, False], ids=["c", "numpy"])
@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_dwb_equals_nav2(case: Path, native: bool) -> None:
    result = check_case(case, native=native)
    assert result.component == "dwb"
    assert result.equal, "; ".join(result.differences)


def test_rotate_to_goal_uses_humbles_angle_normalisation() -> None:
    """angles 1.15: fmod(a + pi, 2 pi) -/+ pi; the double-fmod form differs in the last bits."""
    a = np.array([0.3, -2.9, 3.1, 1.0])
    b = 0.1
    got = shortest_angle(a, b)
    for x, g in zip(a.tolist(), got.tolist(), strict=True):
        r = math.fmod((b - x) + math.pi, 2.0 * math.pi)
        assert g == (r + math.pi if r <= 0.0 else r - math.pi)
    meta, arrays = load_case(CASES / "rotate_window_v0.2_0.1.npz")
    j = meta["params"]["critics"].index("RotateToGoal")
    assert np.isfinite(arrays["raw"][:, j]).any()


@pytest.mark.parametrize("native", [True, False], ids=["c", "numpy"])
def test_local_plan_is_nav2s_trajectory_bit_for_bit(native: bool) -> None:
    """`/local_plan` integrates `x + (v * cos(th)) * dt` step by step, as StandardTrajectoryGenerator."""
    meta, arrays = load_case(CASES / "velocity_0.0_1.0.npz")
    dwb = controller_for_case(meta, arrays, native=native)
    pose = tuple(float(v) for v in arrays["pose"])
    cmd = dwb.compute_velocity(pose, tuple(float(v) for v in arrays["velocity"]), _costmap(arrays))  # type: ignore[arg-type]
    best = meta["best"]
    assert cmd == tuple(arrays["samples"][best])
    want = arrays["poses"][best, : arrays["n_poses"][best]]
    assert dwb.local_plan.shape == want.shape
    assert np.array_equal(dwb.local_plan.view(np.uint64), want.view(np.uint64))


def test_the_kernels_fast_table_never_changes_an_answer() -> None:
    """The C kernel places samples with rotated headings and closed-form sums, and recomputes Nav2's exact
    doubles only for points near a cell edge: on poses on cell edges (straight along them, and not) and
    random ones, it chooses what the exact numpy cycle (held to Nav2 above) chooses, with its total."""
    rng = np.random.default_rng(7)
    for name in ("mission_s1_0240", "corridor_20cm", "obstacle_lethal_35cm", "plan_uturn_v0.1"):
        meta, arrays = load_case(CASES / f"{name}.npz")
        costmap = _costmap(arrays)
        x0, y0, yaw0 = (float(v) for v in arrays["pose"])
        res = costmap.resolution_m
        edge_x = costmap.origin_x_m + round((x0 - costmap.origin_x_m) / res) * res
        edge_y = costmap.origin_y_m + round((y0 - costmap.origin_y_m) / res) * res
        poses = [(edge_x, edge_y, yaw) for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2, yaw0)]
        poses += [
            (x0 + rng.uniform(-0.1, 0.1), y0 + rng.uniform(-0.1, 0.1), yaw0 + rng.uniform(-1, 1)) for _ in range(12)
        ]
        for pose in poses:
            velocity = (float(rng.uniform(0.0, 0.22)), float(rng.uniform(-1.0, 1.0)))
            exact = controller_for_case(meta, arrays, native=False)
            ev = exact.evaluate(pose, velocity, costmap)
            legal = ev.legal
            kernel = controller_for_case(meta, arrays, native=True)
            if not legal.any():
                with pytest.raises(RuntimeError):
                    kernel.compute_velocity(pose, velocity, costmap)
                continue
            best = int(np.argmin(np.where(legal, ev.total, np.inf)))
            assert kernel.compute_velocity(pose, velocity, costmap) == tuple(ev.trajectories.velocity[best])
            assert kernel._out[3] == ev.total[best]
            steps = int(ev.trajectories.steps[best])
            assert np.array_equal(kernel.local_plan[: steps + 1], ev.trajectories.poses[best, : steps + 1])
