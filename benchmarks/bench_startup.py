"""Start-up: `twin --help`, every `twin <command> --help`, and process start to the first simulated step.

    python benchmarks/bench_startup.py            # prints JSON
    python benchmarks/bench_startup.py --quick    # fewer repetitions
    python benchmarks/bench_startup.py --baseline REV [--pairs 15]   # first step, this tree vs REV

Every figure is the median wall time of fresh processes, measured in the same run as `python -c
pass` (the interpreter's own start-up), so a loaded machine shows in both; the first-step figures
also give the median CPU time (user + system) of those processes from start to exit (they exit at
the first step, closing the bag), which other processes on the machine disturb less. Targets
(issues 16 and 22): `--help` <= 0.3 s, first step of the default scenario <= 0.3 s, on a warm cache:
twin's bytecode compiled (as pip compiles an installed package; this environment may set
PYTHONDONTWRITEBYTECODE, which would make every process compile twin's modules again), then one
untimed run builds the native kernels and fills the OS file cache.

"First step" runs what `twin simulate` runs (load the scenario, build the Simulation, run) in a
fresh process and stamps the wall clock at the loop's first progress call (k = 0, the first events
fired); the parent stamps it just before starting the process. It is measured for the default
scenario (Nav2's stack) and for `scenarios/house_tour.yaml` (hand-made waypoints: no map, AMCL or
Nav2 stack is built). `simulate_whole_process_s` is `twin simulate --duration 0.001` from start to
exit (bag closed), an upper bound.

`--baseline REV` measures only the default scenario's first step, alternately in this tree and in
REV (checked out into a temporary git worktree; fresh processes, both on the same warm cache), and
prints each tree's median wall and CPU time and their ratio. Alternating cancels most of a shared
machine's drift.
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

from twin.cli import _COMMAND_MODULES  # noqa: E402

_FIRST_STEP = """
import sys, time
from twin.core.gcpolicy import defer_collection
defer_collection()  # as `twin simulate`'s entry point does (twin.cli.run); the loop turns collection back on
try:
    from twin.core import codecache
except ImportError:  # a baseline from before the code cache
    pass
else:
    codecache.enable("simulate")  # as the entry point does for `twin simulate`
from pathlib import Path
from twin.sim import default_scenario_path, load_scenario
from twin.sim.simulation import Simulation

class _First(Exception):
    pass

def _stamp(sim_s, messages):
    print(repr(time.time()), flush=True)
    raise _First

scenario = load_scenario(Path(sys.argv[2]) if len(sys.argv) > 2 else default_scenario_path())
with Simulation(scenario, bag_path=Path(sys.argv[1]), duration_s=1.0) as sim:
    try:
        sim.run(progress=_stamp)
    except _First:
        pass
"""


def _env(tree: Path = REPO) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(tree)}


def _wall(command: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _first_step_once(folder: Path, scenario: Path | None = None, tree: Path = REPO) -> tuple[float, float]:
    """Wall time to the first step, and CPU time of the whole process (it stops there and exits)."""
    command = [sys.executable, "-c", _FIRST_STEP, str(folder / f"bag{time.monotonic_ns()}")]
    if scenario is not None:
        command.append(str(scenario))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.time()
    out = subprocess.run(command, env=_env(tree), cwd=tree, capture_output=True, text=True, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return float(
        out.stdout.strip().splitlines()[-1]
    ) - start, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def _first_step(repeats: int, scenario: Path | None = None) -> tuple[float, float]:
    """Median wall time to the first step, and median CPU time of the whole process."""
    with tempfile.TemporaryDirectory() as tmp:
        runs = [_first_step_once(Path(tmp), scenario) for _ in range(repeats)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def compare_with(rev: str, pairs: int) -> dict[str, Any]:
    """The default scenario's first step, alternately in this tree and in `rev`, `pairs` times each."""
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "baseline"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(base), rev], check=True, capture_output=True
        )
        try:
            compileall.compile_dir(base / "twin", quiet=1)
            trees = {"current": REPO, "baseline": base}
            for tree in trees.values():  # warm: kernels built, files cached
                _first_step_once(Path(tmp), tree=tree)
            runs: dict[str, list[tuple[float, float]]] = {"current": [], "baseline": []}
            for _ in range(pairs):
                for name, tree in trees.items():
                    runs[name].append(_first_step_once(Path(tmp), tree=tree))
        finally:
            subprocess.run(
                ["git", "-C", str(REPO), "worktree", "remove", "--force", str(base)], check=False, capture_output=True
            )
    result: dict[str, Any] = {"benchmark": "startup_vs_baseline", "baseline_rev": rev, "pairs": pairs}
    for name, rs in runs.items():
        result[name] = {
            "first_step_s_median": round(statistics.median(r[0] for r in rs), 4),
            "first_step_s_best": round(min(r[0] for r in rs), 4),
            "first_step_cpu_s_median": round(statistics.median(r[1] for r in rs), 4),
        }
    cur, old = result["current"], result["baseline"]
    result["current_over_baseline_median"] = round(cur["first_step_s_median"] / old["first_step_s_median"], 3)
    result["current_within_target"] = cur["first_step_s_median"] <= 0.3
    result["load_average_1min"] = round(os.getloadavg()[0], 2)
    return result


def main() -> None:
    """Print the start-up figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--baseline", metavar="REV", help="first step of the default scenario: this tree vs REV")
    parser.add_argument("--pairs", type=int, default=15, help="alternating runs each with --baseline (default 15)")
    args = parser.parse_args()
    compileall.compile_dir(REPO / "twin", quiet=1)
    if args.baseline:
        print(json.dumps(compare_with(args.baseline, args.pairs), indent=2))
        return
    repeats = 3 if args.quick else 7
    py = sys.executable
    # Warm up: bytecode compiled (above), native kernels built, files cached.
    tour = REPO / "scenarios" / "house_tour.yaml"
    _first_step(1)
    _first_step(1, tour)
    _wall([py, "-m", "twin", "--help"], 1)
    baseline = _wall([py, "-c", "pass"], repeats)
    helps = {"twin --help": _wall([py, "-m", "twin", "--help"], repeats)}
    for command in _COMMAND_MODULES:
        helps[f"twin {command} --help"] = _wall([py, "-m", "twin", command, "--help"], repeats)
    first, first_cpu = _first_step(repeats)
    first_tour, first_tour_cpu = _first_step(repeats, tour)
    with tempfile.TemporaryDirectory() as tmp:
        whole = statistics.median(
            _wall([py, "-m", "twin", "simulate", "--duration", "0.001", "--out", str(Path(tmp) / f"b{i}")], 1)
            for i in range(max(1, repeats // 2))
        )
    result: dict[str, Any] = {
        "benchmark": "startup",
        "repeats": repeats,
        "python_pass_s": round(baseline, 4),
        "help_s": {k: round(v, 4) for k, v in helps.items()},
        "help_max_s": round(max(helps.values()), 4),
        "help_max_over_python_s": round(max(helps.values()) - baseline, 4),
        "first_step_s": round(first, 4),
        "first_step_cpu_s": round(first_cpu, 4),
        "first_step_over_python_s": round(first - baseline, 4),
        "first_step_house_tour_s": round(first_tour, 4),
        "first_step_house_tour_cpu_s": round(first_tour_cpu, 4),
        "simulate_whole_process_s": round(whole, 4),
        "targets_s": {"help": 0.3, "first_step": 0.3},
        "help_within_target": max(helps.values()) <= 0.3,
        "first_step_within_target": first <= 0.3,
        "first_step_house_tour_within_target": first_tour <= 0.3,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
