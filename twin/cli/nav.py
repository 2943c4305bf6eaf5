"""`twin nav conformance`: replay cases recorded from Nav2 Humble's own code through the twin's Nav2 parts."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

_REPO = Path(__file__).resolve().parents[2]
_RECORDED = (
    _REPO / "tests" / "unit" / "nav" / "planner" / "navfn_cases",
    _REPO / "tests" / "unit" / "nav" / "costmap_2d" / "inflation_cases",
    _REPO / "tests" / "unit" / "nav" / "velocity_smoother" / "smoother_cases",
    _REPO / "tests" / "unit" / "nav" / "amcl" / "amcl_cases",
    _REPO / "tests" / "unit" / "nav" / "controller" / "rpp_cases",
    _REPO / "tests" / "unit" / "nav" / "behaviors" / "behavior_cases",
    _REPO / "tests" / "unit" / "nav" / "controller" / "dwb_cases",
    _REPO / "tests" / "unit" / "nav" / "costmap_2d" / "costmap_static_cases",
    _REPO / "tests" / "unit" / "nav" / "costmap_2d" / "costmap_publish_cases",
    _REPO / "tests" / "unit" / "nav" / "costmap_2d" / "costmap_footprint_cases",
    _REPO / "tests" / "unit" / "nav" / "costmap_2d" / "costmap_layer_cases",
    _REPO / "tests" / "unit" / "nav" / "amcl" / "amcl_run_cases",
)
"""The recorded sets a checkout holds, replayed when no CASE is named."""

_EPILOG = """\
examples:
  twin nav conformance                                       every recorded set in this checkout
  twin nav conformance tests/unit/nav/planner/navfn_cases    one folder of cases
  twin nav conformance tests/unit/nav/planner/navfn_cases/corridor.npz --python --json

Each case (.npz) holds the inputs, Nav2 Humble's answer and the Nav2 commit it came from (each
set's README says how it was recorded). A case passes when the twin's part gives the same answer
in everything the case records, bit for bit where Nav2 computes in float32 (NavFn: found or failed
and why, its cost array, its potential, every path point; inflation: every cell of the master grid
after one update; AMCL given Nav2's random draws: particles, weights, resampling, the published
pose; costmap: static layer, published values, footprint cost, obstacle/voxel layer cells; DWB:
every sample's trajectory and critic scores; RPP and the behaviours: each cycle's command).
Components: navfn, inflation, velocity_smoother, amcl_motion_model, amcl_likelihood_field,
amcl_resample, amcl_estimate, amcl_run, costmap_static, costmap_publish, costmap_footprint,
costmap_layer, dwb, rpp, behavior, behavior_collision.
Exit status: 0 every case equal, 1 a case differs (its first difference is printed), 2 a file is
not a case.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `nav` command group."""
    parser = subparsers.add_parser(
        "nav",
        help="check the twin's Nav2 parts against cases recorded from Nav2's own code",
        description="The twin's Nav2 parts held to Nav2 Humble's own code.",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="nav_command", metavar="SUBCOMMAND", required=True)
    conformance = sub.add_parser(
        "conformance",
        help="replay recorded Nav2 cases through the twin and compare (equal / differs per case)",
        description=(
            "Replay each recorded Nav2 case through the twin's part for its component and compare the "
            "answers; print a line per differing case and a count per component."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    conformance.add_argument(
        "cases",
        type=Path,
        nargs="*",
        metavar="CASE",
        help="case files (.npz) or folders of them (default: the recorded sets in this checkout)",
    )
    conformance.add_argument(
        "--python", action="store_true", help="run the Python path instead of the compiled kernels"
    )
    conformance.add_argument("--json", action="store_true", help="print every case's result as JSON on stdout")
    conformance.set_defaults(func=_conformance)


def _conformance(args: argparse.Namespace) -> int:
    from twin.core.errors import ConfigError
    from twin.nav.conformance import WITH_C_KERNEL, case_files, check_case

    if args.cases:
        paths = list(args.cases)
    else:
        paths = [p for p in _RECORDED if p.is_dir()]
        if not paths:
            msg = "no recorded cases in this installation (they live in the checkout's tests/); name CASE files"
            raise ConfigError(msg)
    native = not args.python
    results = [check_case(path, native=native) for path in case_files(paths)]
    counts: dict[str, list[int]] = {}
    for r in results:
        equal_total = counts.setdefault(r.component, [0, 0])
        equal_total[0] += r.equal
        equal_total[1] += 1
    if args.json:
        cases = [
            {"file": str(r.path), "name": r.name, "component": r.component, "equal": r.equal,
             "differences": list(r.differences)}
            for r in results
        ]  # fmt: skip
        summary = {c: {"equal": e, "cases": n} for c, (e, n) in counts.items()}
        print(json.dumps({"path": "python" if args.python else "compiled", "components": summary, "cases": cases}))
    else:
        for r in results:
            if not r.equal:
                print(f"DIFFERS {r.component} {r.name} ({r.path}): {r.differences[0]}")
        sys.stdout.flush()
        for component, (equal, total) in sorted(counts.items()):
            how = "compiled kernel" if native and component in WITH_C_KERNEL else "Python path"
            print(f"{component} ({how}): {equal} of {total} cases equal Nav2's answer", file=sys.stderr)
    return 0 if all(r.equal for r in results) else 1
