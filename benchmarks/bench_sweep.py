"""Sweep throughput: runs per minute on an embedded LocalCluster with 1 and with 2 workers.

    python benchmarks/bench_sweep.py              # 8 runs per configuration, prints JSON
    python benchmarks/bench_sweep.py --runs 4     # quicker

Each configuration runs the same sweep (the default scenario cut at 20 simulated seconds, seeds
0..N-1, bags removed) into a fresh folder, so nothing is resumed. `runs_per_minute` counts from the
call to the last result, cluster start included; `steady_runs_per_minute` from the first finished
run to the last. The issue asks for >= 1.8x with 2 workers on a 2-core machine; other processes on
the machine take cores too, so the 1-minute load average is printed beside the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)

from twin.sweep import load_sweep, run_sweep  # noqa: E402

SWEEP = """scenario: {scenario}
runs: {runs}
vary:
  max_duration_s: [20]
timeout_s: 600
"""


def _measure(folder: Path, runs: int, workers: int) -> dict[str, Any]:
    sweep = folder / f"sweep_{workers}.yaml"
    sweep.write_text(SWEEP.format(scenario=REPO / "scenarios" / "default.yaml", runs=runs), encoding="utf-8")
    spec = load_sweep(sweep)
    finished: list[float] = []

    def progress(done: int, failed: int, total: int, eta_s: float | None) -> None:
        if eta_s is not None:
            finished.append(time.perf_counter())

    start = time.perf_counter()
    result = run_sweep(spec, out_dir=folder / f"out_{workers}", workers=workers, keep_bags="none", progress=progress)
    wall = time.perf_counter() - start
    steady = finished[-1] - finished[0] if len(finished) > 1 else float("nan")
    run_walls = [r["wall_s"] for r in result.rows if isinstance(r.get("wall_s"), float)]
    return {
        "workers": workers,
        "runs": runs,
        "wall_s": round(wall, 2),
        "runs_per_minute": round(60.0 * runs / wall, 2),
        "steady_runs_per_minute": round(60.0 * (len(finished) - 1) / steady, 2) if len(finished) > 1 else None,
        "mean_run_wall_s": round(sum(run_walls) / len(run_walls), 2) if run_walls else None,
        "outcomes": sorted({str(r["outcome"]) for r in result.rows}),
        "load_average_1min_after": round(os.getloadavg()[0], 2),
    }


def main() -> None:
    """Print runs per minute with 1 and 2 workers, and their ratio, as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8, help="runs per configuration (default 8)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        load_before = round(os.getloadavg()[0], 2)
        one = _measure(folder, args.runs, 1)
        two = _measure(folder, args.runs, 2)
    ratio = two["runs_per_minute"] / one["runs_per_minute"]
    steady = (
        two["steady_runs_per_minute"] / one["steady_runs_per_minute"]
        if one["steady_runs_per_minute"] and two["steady_runs_per_minute"]
        else None
    )
    result = {
        "benchmark": "sweep",
        "cpus": os.cpu_count(),
        "load_average_1min_before": load_before,
        "one_worker": one,
        "two_workers": two,
        "speedup_2_over_1": round(ratio, 3),
        "steady_speedup_2_over_1": round(steady, 3) if steady is not None else None,
        "target_speedup": 1.8,
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
