"""Sweep throughput: runs per minute on an embedded LocalCluster with 1 and with 2 workers.

    python benchmarks/bench_sweep.py                  # 8 runs per configuration, 2 pairs, prints JSON
    python benchmarks/bench_sweep.py --runs 4 --pairs 1

Each configuration runs the same sweep (the default scenario cut at 20 simulated seconds, seeds
0..N-1, bags removed) into a fresh folder, so nothing is resumed, in a fresh process, as `twin
sweep` does. The configurations alternate (1, 2, 1, 2, ...) so a change in the machine's load shows
in both; each pair gives a ratio, and the 1-minute load average is printed beside every measurement
(this machine is shared: other processes take cores too, and with a load of 2 on 2 cores no
configuration can scale).

`runs_per_minute` counts what `twin sweep` does between its imports and its reports: start the
cluster (in the background) while the sweep file is read and checked, run, stop the cluster;
`steady_runs_per_minute` counts from the first finished run to the last. Dask is imported before
the clock starts (a one-time cost of the client, the same for any cluster). As on an installed
package, twin's bytecode is compiled first, so runs do not compile it (this environment may set
PYTHONDONTWRITEBYTECODE). The issue asks for >= 1.8x with 2 workers on a 2-core machine.
"""

from __future__ import annotations

import argparse
import compileall
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)

from twin.sweep import Cluster, load_sweep, run_sweep  # noqa: E402

SWEEP = """scenario: {scenario}
runs: {runs}
vary:
  max_duration_s: [20]
timeout_s: 600
"""


def _measure(folder: Path, runs: int, workers: int) -> dict[str, Any]:
    sweep = folder / f"sweep_{workers}.yaml"
    sweep.write_text(SWEEP.format(scenario=REPO / "scenarios" / "default.yaml", runs=runs), encoding="utf-8")
    finished: list[float] = []

    def progress(done: int, failed: int, total: int, eta_s: float | None) -> None:
        if eta_s is not None:
            finished.append(time.perf_counter())

    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    # What `twin sweep` does: the cluster starts while the sweep file is read, runs, and stops.
    with Cluster(workers=workers) as cluster:
        spec = load_sweep(sweep)
        out = folder / f"out_{workers}"
        result = run_sweep(spec, out_dir=out, keep_bags="none", progress=progress, cluster=cluster)
        ran = time.perf_counter()
        # CPU seconds, which other processes on the machine disturb less than wall time: each
        # worker's own (its share of Dask, reading the metrics) and its runs' (reaped children).
        cpu = cluster.client().run(_cpu_s)
        stop = time.perf_counter()
    wall = (ran - start) + (time.perf_counter() - stop)  # the CPU query is not the sweep's
    client_cpu = resource.getrusage(resource.RUSAGE_SELF)
    steady = finished[-1] - finished[0] if len(finished) > 1 else float("nan")
    run_walls = [r["wall_s"] for r in result.rows if isinstance(r.get("wall_s"), float)]
    return {
        "workers": workers,
        "runs": runs,
        "wall_s": round(wall, 2),
        "first_result_s": round(finished[0] - start, 2) if finished else None,
        "runs_per_minute": round(60.0 * runs / wall, 2),
        "steady_runs_per_minute": round(60.0 * (len(finished) - 1) / steady, 2) if len(finished) > 1 else None,
        "mean_run_wall_s": round(sum(run_walls) / len(run_walls), 2) if run_walls else None,
        "outcomes": sorted({str(r["outcome"]) for r in result.rows}),
        "cpu_runs_s": round(sum(c[1] for c in cpu.values()), 2),
        "cpu_per_run_s": round(sum(c[1] for c in cpu.values()) / runs, 3),
        "cpu_workers_s": round(sum(c[0] for c in cpu.values()), 2),
        "cpu_client_s": round(client_cpu.ru_utime + client_cpu.ru_stime, 2),
        "load_average_1min_before": round(load_before, 2),
        "load_average_1min_after": round(os.getloadavg()[0], 2),
    }


def _cpu_s() -> tuple[float, float]:
    """In a worker: its own CPU seconds and those of the processes it started and reaped (its runs)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    runs = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, runs.ru_utime + runs.ru_stime


def _fresh(folder: Path, runs: int, workers: int) -> dict[str, Any]:
    """One measurement in a new process (its own Dask client and cluster, as `twin sweep` has)."""
    command = [sys.executable, __file__, "--one", str(workers), "--runs", str(runs), "--folder", str(folder)]
    out = subprocess.run(command, capture_output=True, text=True, check=True)
    measured: dict[str, Any] = json.loads(out.stdout)
    return measured


def main() -> None:
    """Print runs per minute with 1 and 2 workers, alternately, and their ratios, as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8, help="runs per configuration (default 8)")
    parser.add_argument("--pairs", type=int, default=2, help="1-worker/2-worker pairs, alternated (default 2)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a single measurement, in this process
    parser.add_argument("--folder", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        import distributed  # noqa: F401 - the client's one-time import, before the clock starts

        print(json.dumps(_measure(args.folder, args.runs, args.one)))
        return
    compileall.compile_dir(REPO / "twin", quiet=1)
    pairs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.pairs):
            folder = Path(tmp) / f"pair{i}"
            folder.mkdir()
            one = _fresh(folder, args.runs, 1)
            two = _fresh(folder, args.runs, 2)
            steady = (
                two["steady_runs_per_minute"] / one["steady_runs_per_minute"]
                if one["steady_runs_per_minute"] and two["steady_runs_per_minute"]
                else None
            )
            pairs.append(
                {
                    "one_worker": one,
                    "two_workers": two,
                    "speedup_2_over_1": round(two["runs_per_minute"] / one["runs_per_minute"], 3),
                    "steady_speedup_2_over_1": round(steady, 3) if steady is not None else None,
                }
            )
    result = {
        "benchmark": "sweep",
        "cpus": os.cpu_count(),
        "pairs": pairs,
        "speedup_2_over_1_median": round(statistics.median(p["speedup_2_over_1"] for p in pairs), 3),
        "speedup_2_over_1_best": max(p["speedup_2_over_1"] for p in pairs),
        "target_speedup": 1.8,
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
