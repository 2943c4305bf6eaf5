"""Generated Nav2 params files and maps, more of them than CI runs; prints JSON.

The same generators as `tests/robustness/test_nav2_generated.py` (`tests/robustness/nav2_fuzz.py`):

* `check`: `twin scenario check` in-process on `--examples` generated cases (params file and map
  changed one to three ways): outcomes by exit code, how many printed a traceback or an internal
  error (must be 0), the slowest check.
* `runs`: `twin simulate --duration 2` on `--runs` cases that set a sizing or rate parameter to a
  breaking value, each in a process limited to 2 GiB of address space and 60 s: outcomes by exit
  code (a negative code is a signal: killed by the limit or the timeout; must not happen), the
  slowest run and the largest peak RSS.

Usage: python benchmarks/fuzz_nav2_inputs.py [--examples 600] [--runs 30] [--seed 0]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hypothesis import HealthCheck, given, seed, settings  # noqa: E402

from tests.robustness.nav2_fuzz import cases, describe, risky_cases, whole_run, write_case  # noqa: E402
from twin.cli import main  # noqa: E402


def _bad(stderr: str) -> bool:
    return "Traceback" in stderr or "internal error" in stderr


def run_checks(examples: int, rng_seed: int) -> dict[str, Any]:
    outcomes: Counter[int] = Counter()
    bad: list[str] = []
    slowest = 0.0

    @seed(rng_seed)
    @settings(max_examples=examples, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(case=cases)
    def one(case: Any) -> None:
        nonlocal slowest
        folder = Path(tempfile.mkdtemp(prefix="twin-nav2-fuzz-"))
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                t0 = time.perf_counter()
                code = main(["scenario", "check", str(write_case(case, folder))])
                slowest = max(slowest, time.perf_counter() - t0)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        outcomes[code] += 1
        if code == 70 or _bad(err.getvalue()):
            bad.append(f"{code}: {describe(case)}: {err.getvalue()[-300:]}")

    one()
    return {
        "examples": sum(outcomes.values()),
        "outcomes_by_exit_code": {str(k): v for k, v in sorted(outcomes.items())},
        "tracebacks_or_internal_errors": len(bad),
        "first_bad": bad[:5],
        "slowest_check_s": round(slowest, 3),
    }


def run_whole(runs: int, rng_seed: int) -> dict[str, Any]:
    outcomes: Counter[int] = Counter()
    bad: list[str] = []
    slowest = 0.0
    peak_mib = 0.0

    @seed(rng_seed)
    @settings(max_examples=runs, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(case=risky_cases)
    def one(case: Any) -> None:
        nonlocal slowest, peak_mib
        folder = Path(tempfile.mkdtemp(prefix="twin-nav2-run-"))
        try:
            t0 = time.perf_counter()
            code, stderr, peak = whole_run(write_case(case, folder), folder / "bag")
            slowest = max(slowest, time.perf_counter() - t0)
            peak_mib = max(peak_mib, peak if peak == peak else 0.0)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        outcomes[code] += 1
        if code < 0 or code == 70 or _bad(stderr):
            bad.append(f"{code}: {describe(case)}: {stderr[-300:]}")

    one()
    return {
        "runs": sum(outcomes.values()),
        "outcomes_by_exit_code": {str(k): v for k, v in sorted(outcomes.items())},
        "killed_tracebacks_or_internal_errors": len(bad),
        "first_bad": bad[:5],
        "slowest_run_s": round(slowest, 2),
        "largest_peak_rss_mib": round(peak_mib, 1),
    }


def main_cli() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=600, help="scenario check cases (default 600)")
    parser.add_argument("--runs", type=int, default=30, help="whole simulate runs (default 30)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    t0 = time.perf_counter()
    doc: dict[str, Any] = {"check": run_checks(args.examples, args.seed), "runs": run_whole(args.runs, args.seed)}
    doc["wall_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(doc, indent=2))
    failed = doc["check"]["tracebacks_or_internal_errors"] or doc["runs"]["killed_tracebacks_or_internal_errors"]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main_cli())
