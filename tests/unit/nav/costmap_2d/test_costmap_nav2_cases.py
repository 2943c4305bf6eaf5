"""The costmap against Nav2 Humble's own nav2_costmap_2d: every case in `costmap_*_cases/` (see their README).

Static layer (`costmap_static`), published values (`costmap_publish`), footprint cost
(`costmap_footprint`) and the obstacle and voxel layers' cells after update cycles (`costmap_layer`):
every cell and value equal to Nav2's, through the C kernels and through the Python paths.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.nav.conformance import check_case

HERE = Path(__file__).parent
PARTS = ("costmap_static", "costmap_publish", "costmap_footprint", "costmap_layer")
FILES = sorted(f for part in PARTS for f in (HERE / f"{part}_cases").glob("*.npz"))
NATIVE = [pytest.param(True, id="native"), pytest.param(False, id="python")]


def _meta(path: Path) -> dict[str, Any]:
    with np.load(path, allow_pickle=False) as data:
        return dict(json.loads(str(data["meta"])))


def test_the_recorded_sets_cover_the_issue() -> None:
    metas = [_meta(f) for f in FILES]
    assert len(metas) >= 150
    by_part = {part: [m for m in metas if m["component"] == part] for part in PARTS}
    assert all(by_part.values())
    assert len({m["nav2_commit"] for m in metas}) == 1  # one pinned Nav2 commit
    assert {m["oracle"] for m in by_part["costmap_footprint"]} == {"compiled"}
    layers = by_part["costmap_layer"]
    assert {m["kind"] for m in layers} == {"obstacle", "voxel"}
    assert {m["group"] for m in layers} == {"mission", "synthetic"}
    assert any(m["rolling_window"] for m in layers) and not all(m["rolling_window"] for m in layers)
    assert {m["default_value"] for m in layers} == {0, 255}  # track_unknown_space false and true
    statics = by_part["costmap_static"]
    assert {(m["track_unknown_space"], m["trinary_costmap"]) for m in statics} == {
        (False, False), (False, True), (True, False), (True, True)
    }  # fmt: skip


@pytest.mark.parametrize("native", NATIVE)
@pytest.mark.parametrize("case", FILES, ids=[f"{f.parent.name[:-6]}/{f.stem}" for f in FILES])
def test_the_costmap_equals_nav2(case: Path, native: bool) -> None:
    result = check_case(case, native=native)
    assert result.component == case.parent.name.removesuffix("_cases")
    assert result.equal, "; ".join(result.differences)
