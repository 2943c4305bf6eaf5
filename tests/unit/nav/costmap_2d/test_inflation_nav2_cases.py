"""The inflation layer against Nav2 Humble's own: every case in `inflation_cases/` (see its README).

Each case is one `InflationLayer::updateCosts` call recorded from Nav2's inflation_layer.cpp: the master
grid before it, the layer's parameters and the update window, and the master grid after it. Equal means
every cell equal; both the C kernel and the Python fallback are held to it, and so is the costmap's own
update (static layer in, inflated master out) where the case inflates the whole grid.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.nav.conformance import check_case
from twin.nav.costmap_2d.costmap_2d import LETHAL_OBSTACLE, NO_INFORMATION
from twin.nav.costmap_2d.layered_costmap import Costmap, inflate, inflation_cost_table
from twin.nav.map_server.map_io import OccupancyMap
from twin.nav.params import CostmapParams, InflationParams, StaticLayerParams

CASES = Path(__file__).with_name("inflation_cases")
FILES = sorted(CASES.glob("*.npz"))
NATIVE = [pytest.param(True, id="native"), pytest.param(False, id="python")]


def _load(path: Path) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return json.loads(str(data["meta"])), data["master"], data["expected"]


def _radius_cells(meta: dict[str, Any]) -> int:
    return int(meta["cell_inflation_radius"])


def _is_whole(meta: dict[str, Any], shape: tuple[int, ...]) -> bool:
    rows, cols = shape
    return bool(meta["window"] == {"min_i": 0, "min_j": 0, "max_i": cols, "max_j": rows})


def test_the_recorded_set_covers_the_issue() -> None:
    loaded = [_load(f) for f in FILES]
    metas = [meta for meta, _, _ in loaded]
    assert len(metas) >= 150
    assert {m["group"] for m in metas} == {"synthetic", "house", "tb3_map", "random"}
    assert len({m["nav2_commit"] for m in metas}) == 1  # one pinned Nav2 commit
    assert {m["oracle"] for m in metas} == {"compiled"}
    flags = {(m["inflate_unknown"], m["inflate_around_unknown"]) for m in metas}
    assert flags == {(False, False), (False, True), (True, False), (True, True)}
    assert sum(not _is_whole(meta, master.shape) for meta, master, _ in loaded) >= 40  # partial update windows
    assert sum(m["changed_cells"] > 0 for m in metas) >= 140
    assert {m["inflation_radius"] for m in metas} >= {0.55, 1.0}
    assert {m["cost_scaling_factor"] for m in metas} >= {1.0, 3.0, 10.0}
    assert any(m["cell_inflation_radius"] == 0 for m in metas)


def test_the_cell_radius_is_nav2s() -> None:
    for path in FILES:
        meta = _load(path)[0]
        assert _radius_cells(meta) == max(0, int(np.ceil(meta["inflation_radius"] / meta["resolution"])))


@pytest.mark.parametrize("native", NATIVE)
@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_inflation_equals_nav2(case: Path, native: bool) -> None:
    result = check_case(case, native=native)
    assert result.component == "inflation"
    assert result.equal, "; ".join(result.differences)


def _full_window_static_cases() -> list[Path]:
    """Cases over the whole grid whose master a static layer can give (free, lethal, unknown only)."""
    chosen = []
    for path in FILES:
        meta, master, _ = _load(path)
        whole = _is_whole(meta, master.shape)
        trinary = set(np.unique(master).tolist()) <= {0, LETHAL_OBSTACLE, NO_INFORMATION}
        if whole and trinary and meta["group"] in {"house", "tb3_map", "synthetic"}:
            chosen.append(path)
    return chosen


STATIC = _full_window_static_cases()


@pytest.mark.parametrize("native", NATIVE)
@pytest.mark.parametrize("case", STATIC, ids=[f.stem for f in STATIC])
def test_a_static_costmap_inflates_as_nav2(case: Path, native: bool) -> None:
    """The costmap's own first update (static layer, then inflation over the whole map) gives Nav2's grid."""
    meta, master, expected = _load(case)
    data = np.where(master == LETHAL_OBSTACLE, 100, np.where(master == NO_INFORMATION, -1, 0)).astype(np.int8)
    occupancy = OccupancyMap(resolution_m=meta["resolution"], origin_x_m=0.0, origin_y_m=0.0, data=data)
    params = CostmapParams(
        name="global_costmap",
        resolution_m=meta["resolution"],
        track_unknown_space=True,
        plugins=("static_layer", "inflation_layer"),
        static_layer=StaticLayerParams(name="static_layer"),
        obstacle_layers=(),
        inflation=InflationParams(
            name="inflation_layer",
            inflation_radius_m=meta["inflation_radius"],
            cost_scaling_factor=meta["cost_scaling_factor"],
            inflate_unknown=meta["inflate_unknown"],
            inflate_around_unknown=meta["inflate_around_unknown"],
        ),
    )
    costmap = Costmap(params, static_map=occupancy, native=native)
    costmap.inscribed_radius_m = meta["inscribed_radius"]  # the case's footprint, not the params' default one
    costmap.update(0.0, 0.0, 0.0)
    differing = int((costmap.grid.cost != expected).sum())
    assert differing == 0


def test_inflate_refuses_a_grid_it_cannot_write_in_place() -> None:
    table = inflation_cost_table(resolution_m=0.05, inscribed_radius_m=0.1, cost_scaling_factor=3.0, radius_cells=2)
    grid = np.zeros((6, 8), dtype=np.uint8)
    with pytest.raises(ValueError, match="C-contiguous"):
        inflate(grid.T, window=(0, 8, 0, 6), radius_cells=2, table=table)
