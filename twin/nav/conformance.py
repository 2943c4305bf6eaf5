"""Replay cases recorded from Nav2 Humble's own code through the twin's navigation parts, and compare.

A case is one `.npz` file: `meta`, a JSON string with the inputs, Nav2's answer and the Nav2 commit
it came from, and the arrays of both (a costmap, a potential, a path...). Each component the twin
holds to Nav2's code has a checker that runs the twin's part on the case's inputs and lists every
way its answer differs (empty: equal). `twin nav conformance` runs them over case files and folders;
the test suite runs them over the recorded sets (`tests/unit/nav/*/..._cases/`, each with a README
saying how Nav2's answers were recorded).

Components:
- `navfn`: the NavFn planner (`twin.nav.planner.navfn`): found or failed and why, NavFn's cost
  array, its float32 potential and every path point, bit for bit.
- `inflation`: the inflation layer (`twin.nav.costmap_2d`): one `updateCosts` over a window of a
  master grid, every cell equal.
- `velocity_smoother` (`twin.nav.velocity_smoother`): on which timer ticks it publishes, and what, bit for bit.
- `amcl_motion_model`: AMCL's differential motion model (`twin.nav.amcl.filter.odometry_update`)
  given the normal draws Nav2 consumed: every particle pose, bit for bit (the numpy path within
  1e-12; `twin.nav.amcl.conformance_check`).
- `amcl_likelihood_field`: AMCL's likelihood-field distances and each particle's weight before
  normalisation, bit for bit.
- `amcl_resample`: AMCL's KLD resampling given Nav2's uniform draws: how many samples, and each one.
- `amcl_estimate`: the pose AMCL publishes (the heaviest cluster's mean) and the covariance it carries.
- `rpp`: Regulated Pure Pursuit (`twin.nav.controller.regulated_pure_pursuit`) over a sequence of
  cycles: statuses, the plan's pruning, the branch, lookahead, carrot, curvature and command within
  1e-9 (`twin.nav.controller.rpp_conformance_check`).
- `behavior`: Spin, BackUp, DriveOnHeading (`twin.nav.behaviors`): acceptance, each cycle's status
  and command, bit for bit; `behavior_collision`: the behaviours' and RPP's footprint collision checks
  (`twin.nav.behaviors.conformance_check`).
- `dwb`: one DWB controller cycle (`twin.nav.controller.dwb`): the plan's cut, the velocity samples,
  each trajectory's poses, each critic's raw score and which critic rejects a sample, the totals,
  bit for bit, and the command chosen (`twin.nav.controller.dwb.conformance_check`).
- `costmap_static`, `costmap_publish`, `costmap_footprint`, `costmap_layer` (`twin.nav.costmap_2d`): the
  static layer's costs from an OccupancyGrid, the published 0..100 values, the footprint's cost at poses
  (FootprintCollisionChecker), and an obstacle or voxel layer's cells (and voxel columns) after update
  cycles of clearing, marking, footprint clearing and rolling; every cell and value equal.
- `amcl_run`: AMCL over a recorded run (the twin's default mission's scans and odometry, Nav2's draws):
  at every filter update the particle set after the laser model and after resampling, and the published
  pose and covariance, bit for bit (the numpy path within 1e-9).
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.core.errors import ConfigError
from twin.nav.amcl.conformance_check import (
    check_amcl_estimate,
    check_amcl_likelihood_field,
    check_amcl_motion_model,
    check_amcl_resample,
    check_amcl_run,
)
from twin.nav.behaviors.conformance_check import check_behavior, check_behavior_collision
from twin.nav.controller.dwb.conformance_check import check_dwb
from twin.nav.controller.rpp_conformance_check import check_rpp
from twin.nav.costmap_2d.conformance_check import (
    check_footprint,
    check_inflation,
    check_layer,
    check_publish,
    check_static,
)
from twin.nav.velocity_smoother.conformance_check import check_velocity_smoother

__all__ = ["COMPONENTS", "WITH_C_KERNEL", "CaseResult", "case_files", "check_case", "component_of", "load_case"]

Arrays = Mapping[str, NDArray[Any]]
Checker = Callable[[Mapping[str, Any], Arrays, bool], list[str]]


@dataclass(frozen=True, kw_only=True, slots=True)
class CaseResult:
    """One case replayed: which component, through which path (C kernel or Python), and what differed."""

    path: Path
    name: str
    component: str
    native: bool
    differences: tuple[str, ...]

    @property
    def equal(self) -> bool:
        """True when the twin's answer equals Nav2's in everything the case records."""
        return not self.differences


def load_case(path: Path) -> tuple[dict[str, Any], dict[str, NDArray[Any]]]:
    """A case's meta (parsed) and arrays.

    Raises:
        ConfigError: If the file is not a case (not an .npz, no `meta`, or `meta` not JSON); one line.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        msg = f"{path}: no such case file"
        raise ConfigError(msg) from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        # (numpy takes a file that is no .npz for a pickle and offers to unpickle it: never)
        why = "it is not an .npz archive" if "pickle" in str(err) else str(err)
        msg = f"{path}: not a recorded Nav2 case (an .npz with a `meta` entry): {why}"
        raise ConfigError(msg) from None
    if "meta" not in arrays:
        msg = f"{path}: no `meta` entry; a recorded Nav2 case holds its inputs and Nav2's answer there"
        raise ConfigError(msg)
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except json.JSONDecodeError as err:
        msg = f"{path}: its `meta` is not JSON ({err.msg} at character {err.pos})"
        raise ConfigError(msg) from None
    if not isinstance(meta, dict):
        msg = f"{path}: its `meta` must be a JSON object"
        raise ConfigError(msg)
    return meta, arrays


def component_of(meta: Mapping[str, Any]) -> str | None:
    """The component a case is for: its `component` field, or the set's for the first two recorded sets (no field)."""
    named = meta.get("component")
    if isinstance(named, str):
        return named
    if "cell_inflation_radius" in meta and "window" in meta:
        return "inflation"  # the inflation set names no component either
    return "navfn" if "use_astar" in meta and "status" in meta else None


def _sha256(a: NDArray[Any]) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def _first_cell(got: NDArray[Any], want: NDArray[Any]) -> str:
    """How two arrays of one shape differ: how many cells, and the first (row, column) with both values."""
    differ = np.flatnonzero(got.ravel() != want.ravel())
    if differ.size == 0:
        return ""
    index = np.unravel_index(int(differ[0]), want.shape)
    where = ", ".join(str(int(i)) for i in index)
    return f"{differ.size} cells differ, first at ({where}): twin {got[index]!r}, Nav2 {want[index]!r}"


_NAVFN_REASONS = {
    "fail lethal_start": "START_IN_LETHAL",
    "fail start_off_map": "START_OUTSIDE_MAP",
    "fail goal_off_map": "GOAL_OUTSIDE_MAP",
    "fail no_potential_within_tolerance": "NO_VALID_PATH",
    "fail trace": "NO_VALID_PATH",
}


def check_navfn(meta: Mapping[str, Any], arrays: Arrays, native: bool) -> list[str]:
    """The ways the twin's NavFn differs from Nav2's on one case (`tests/unit/nav/planner/navfn_cases/README.md`)."""
    from twin.nav.costmap_2d.costmap_2d import CostGrid
    from twin.nav.planner.navfn import NavfnParams, NavfnPlanner, Plan, navfn_costs

    params = NavfnParams(
        tolerance_m=meta["tolerance"], use_astar=meta["use_astar"], allow_unknown=meta["allow_unknown"]
    )
    planner = NavfnPlanner(params, native=native)
    if planner.native is not native:
        return ["the C kernel is not available (no C compiler?): only the Python path can be checked"]
    cost = arrays["cost"]
    origin = meta["origin"]
    costmap = CostGrid(
        frame_id="map", resolution_m=meta["resolution"], origin_x_m=origin[0], origin_y_m=origin[1], cost=cost
    )
    result = planner.make_plan(costmap, tuple(meta["start"]), tuple(meta["goal"]))
    out: list[str] = []
    if meta["navfn_ran"]:
        pot = planner.potential
        if pot.dtype != np.float32 or pot.shape != cost.shape:
            out.append(f"potential: {pot.dtype} {pot.shape}, Nav2 float32 {cost.shape}")
        elif "potential" in arrays:
            if differ := _first_cell(pot, arrays["potential"]):
                out.append(f"potential: {differ}")
        else:
            sample = pot.ravel()[arrays["potential_index"]]
            if not np.array_equal(sample, arrays["potential_sample"]) or _sha256(pot.astype("<f4")) != meta.get(
                "potential_sha256"
            ):
                out.append("potential: differs from Nav2's (its sample or its SHA-256)")
        node = planner.world_to_node(costmap, meta["start"][0], meta["start"][1])
        if node is None:
            out.append("the start is off the map for the twin, not for Nav2")
        else:
            cleared = cost.copy()
            cleared[node[1], node[0]] = 0  # Nav2's clearRobotCell
            mapped = navfn_costs(cleared, allow_unknown=meta["allow_unknown"])
            if "navfn_cost" in arrays:
                if differ := _first_cell(mapped, arrays["navfn_cost"]):
                    out.append(f"NavFn's cost array: {differ}")
            elif _sha256(mapped) != meta.get("navfn_cost_sha256"):
                out.append("NavFn's cost array: differs from Nav2's (its SHA-256)")
    if meta["status"] == "ok":
        if not isinstance(result, Plan):
            out.append(f"Nav2 planned a path of {len(arrays['path'])} points; the twin failed ({result.reason.name})")
            return out
        path, want = result.poses[:, :2], arrays["path"]
        if path.shape != want.shape:
            out.append(f"path: {len(path)} points, Nav2 {len(want)}")
        elif differ := _first_cell(path, want):
            out.append(f"path: {differ}")
        if result.poses[-1, 2] != meta["goal"][2]:
            out.append(f"path: the last pose's yaw {result.poses[-1, 2]!r}, Nav2 the goal's {meta['goal'][2]!r}")
    elif isinstance(result, Plan):
        out.append(f"Nav2: {meta['status']}; the twin planned {len(result.poses)} poses")
    elif result.reason.name != _NAVFN_REASONS.get(meta["status"]):
        out.append(f"Nav2: {meta['status']}; the twin failed with {result.reason.name}")
    return out


COMPONENTS: dict[str, Checker] = {
    "navfn": check_navfn,
    "inflation": check_inflation,
    "velocity_smoother": check_velocity_smoother,
    "amcl_motion_model": check_amcl_motion_model,
    "amcl_likelihood_field": check_amcl_likelihood_field,
    "amcl_resample": check_amcl_resample,
    "amcl_estimate": check_amcl_estimate,
    "rpp": check_rpp,
    "behavior": check_behavior,
    "behavior_collision": check_behavior_collision,
    "dwb": check_dwb,
    "costmap_static": check_static,
    "costmap_publish": check_publish,
    "costmap_footprint": check_footprint,
    "costmap_layer": check_layer,
    "amcl_run": check_amcl_run,
}
"""Each component's checker: (meta, arrays, native) -> differences."""

WITH_C_KERNEL = frozenset(
    {"navfn", "inflation", "amcl_motion_model", "amcl_likelihood_field", "amcl_resample", "amcl_estimate"}
    | {"amcl_run", "dwb", "costmap_footprint", "costmap_layer"}
)
"""The components whose twin part has a C kernel beside its Python path (the others are Python only)."""


def check_case(path: Path, *, native: bool = True) -> CaseResult:
    """Replay one case file through its component (the C kernel, or the Python path with `native=False`).

    Raises:
        ConfigError: If the file is not a case, or is for a component the twin does not check.
    """
    meta, arrays = load_case(path)
    component = component_of(meta)
    checker = COMPONENTS.get(component or "")
    if checker is None:
        msg = (
            f"{path}: a case for {component or 'an unnamed component'}; "
            f"the twin checks {', '.join(sorted(COMPONENTS))} (its meta's `component`)"
        )
        raise ConfigError(msg)
    try:
        differences = checker(meta, arrays, native)
    except (KeyError, IndexError, TypeError, ValueError) as err:
        msg = f"{path}: a {component} case without what its checker needs ({type(err).__name__}: {err})"
        raise ConfigError(msg) from None
    name = str(meta.get("name", path.stem))
    return CaseResult(path=path, name=name, component=str(component), native=native, differences=tuple(differences))


def case_files(paths: Iterable[Path]) -> list[Path]:
    """The case files named: files as given, folders by their `*.npz` (sorted).

    Raises:
        ConfigError: If a path does not exist, or a folder holds no case.
    """
    out: list[Path] = []
    for path in paths:
        if path.is_dir():
            found = sorted(path.glob("*.npz"))
            if not found:
                msg = f"{path}: no case files (*.npz) in this folder"
                raise ConfigError(msg)
            out += found
        elif path.exists():
            out.append(path)
        else:
            msg = f"{path}: no such case file or folder"
            raise ConfigError(msg)
    return out
