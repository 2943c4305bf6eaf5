"""NavFn against Nav2 Humble's own: every case in `navfn_cases/` (recorded from Nav2's navfn.cpp, see its README).

Equal means bitwise: the float32 potential (whole, or its SHA-256 and samples on the larger maps), the
cost array NavFn plans on, found or failed (and why), and every path point. The twin does the same
float32 and double operations in the same order as Nav2's build, so no tolerance is needed; both the
C kernel and the Python fallback are held to it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from twin.nav.conformance import check_case, load_case

CASES = Path(__file__).with_name("navfn_cases")
FILES = sorted(CASES.glob("*.npz"))


def test_the_recorded_set_covers_the_issue() -> None:
    metas = [load_case(f)[0] for f in FILES]
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
    result = check_case(case, native=native)
    assert result.component == "navfn" and result.native is native
    assert result.equal, "; ".join(result.differences)


def test_a_difference_is_named_with_its_first_cell(tmp_path: Path) -> None:
    """The checker is not blind: a case whose recorded potential or path is moved is reported, naming where."""
    source = next(f for f in FILES if "potential" in load_case(f)[1] and load_case(f)[0]["status"] == "ok")
    meta, arrays = load_case(source)
    arrays["potential"] = arrays["potential"].copy()
    reached = np.flatnonzero(arrays["potential"].ravel() < 1e10)
    arrays["potential"].ravel()[reached[len(reached) // 2]] += 1.0
    arrays["path"] = arrays["path"] + np.array([0.0, 1e-9])
    changed = tmp_path / source.name
    np.savez(changed, meta=json.dumps(meta), **arrays)
    result = check_case(changed, native=False)
    assert not result.equal
    assert result.differences[0].startswith("potential: 1 cells differ, first at (")
    assert any(d.startswith("path: ") for d in result.differences)
