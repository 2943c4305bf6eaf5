"""NavFn against Nav2 Humble's own: every case in `navfn_cases/` (recorded from Nav2's navfn.cpp, see its README).

Equal means bitwise: the float32 potential (whole, or its SHA-256 and samples on the larger maps), the
cost array NavFn plans on, found or failed (and why), and every path point. The twin does the same
float32 and double operations in the same order as Nav2's build, so no tolerance is needed; both the
C kernel and the Python fallback are held to it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid
from twin.nav.planner.navfn import (
    NavfnParams,
    NavfnPlanner,
    Plan,
    PlanFailure,
    PlanFailureReason,
    navfn_costs,
)

CASES = Path(__file__).with_name("navfn_cases")
FILES = sorted(CASES.glob("*.npz"))

REASONS = {
    "fail lethal_start": PlanFailureReason.START_IN_LETHAL,
    "fail start_off_map": PlanFailureReason.START_OUTSIDE_MAP,
    "fail goal_off_map": PlanFailureReason.GOAL_OUTSIDE_MAP,
    "fail no_potential_within_tolerance": PlanFailureReason.NO_VALID_PATH,
    "fail trace": PlanFailureReason.NO_VALID_PATH,
}


def _load(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    return json.loads(str(arrays.pop("meta"))), arrays


def _sha(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def test_the_recorded_set_covers_the_issue() -> None:
    metas = [_load(f)[0] for f in FILES]
    groups = {m["group"] for m in metas}
    assert {"synthetic", "random", "house_mission", "house_pairs", "tb3_world_mission"} <= groups
    assert sum(m["group"].startswith("house") for m in metas) >= 200
    assert len(metas) >= 380
    assert len({m["nav2_commit"] for m in metas}) == 1  # one pinned Nav2 commit
    statuses = {m["status"] for m in metas}
    assert {
        "ok",
        "fail lethal_start",
        "fail no_potential_within_tolerance",
        "fail goal_off_map",
        "fail trace",
    } <= statuses
    assert any(m["use_astar"] for m in metas) and any(not m["allow_unknown"] for m in metas)


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_navfn_equals_nav2(case: Path, native: bool) -> None:
    meta, arrays = _load(case)
    planner = NavfnPlanner(
        NavfnParams(tolerance_m=meta["tolerance"], use_astar=meta["use_astar"], allow_unknown=meta["allow_unknown"]),
        native=native,
    )
    assert planner.native is native
    costmap = grid(arrays["cost"], resolution_m=meta["resolution"], origin_m=tuple(meta["origin"]))
    result = planner.make_plan(costmap, tuple(meta["start"]), tuple(meta["goal"]))

    if meta["navfn_ran"]:
        pot = planner.potential
        assert pot.dtype == np.float32 and pot.shape == arrays["cost"].shape
        if "potential" in arrays:
            differ = np.flatnonzero(pot.ravel() != arrays["potential"].ravel())
            assert differ.size == 0, f"{differ.size} potentials differ, first at cell {differ[:1]}"
        else:
            got = pot.ravel()[arrays["potential_index"]]
            np.testing.assert_array_equal(got, arrays["potential_sample"])
            assert _sha(pot.astype("<f4")) == meta["potential_sha256"]
        node = planner._node(costmap, meta["start"][0], meta["start"][1])
        assert node is not None
        cleared = arrays["cost"].copy()
        cleared[node[1], node[0]] = 0
        mapped = navfn_costs(cleared, allow_unknown=meta["allow_unknown"])
        if "navfn_cost" in arrays:
            np.testing.assert_array_equal(mapped, arrays["navfn_cost"])
        else:
            assert _sha(mapped) == meta["navfn_cost_sha256"]

    if meta["status"] == "ok":
        assert isinstance(result, Plan), result
        np.testing.assert_array_equal(result.poses[:, :2], arrays["path"])
        assert result.poses[-1, 2] == meta["goal"][2]
    else:
        assert isinstance(result, PlanFailure), f"Nav2: {meta['status']}, twin: a plan of {len(result.poses)} poses"
        assert result.reason is REASONS[meta["status"]]
