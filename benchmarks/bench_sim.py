"""Whole-run speed: the default scenario for N simulated seconds, with a per-subsystem breakdown.

Prints JSON: real-time factor, CPU ms per simulated second, and each subsystem's share of the loop,
for two configurations of the same scenario:
  foundation  kinematic drive, lidar at 5 Hz, recording; ground-truth /odom, no IMU, the hand-made
              house tour instead of the tree and planner (issue 2's scope)
  full        the default scenario as shipped: IMU at 200 Hz, encoders, EKF /odom, ground truth
Speed is compared as ratios within one run (this machine is shared and noisy), never asserted.

    python benchmarks/bench_sim.py [--sim-s 60] [--scenario FILE] [--drive scenario|kinematic|fmu] [--repeat 3]

`--drive scenario` (the default) keeps the scenario's drive: the FMU drive of the robot's own motors in
velocity mode for the default scenario. `kinematic` swaps in ideal wheels, `fmu` the default FMU drive.

    python benchmarks/bench_sim.py --baseline REV [--pairs 5]

`--baseline REV` compares this tree with an earlier commit in the same run: it checks REV out into
a temporary git worktree and runs the whole default mission alternately in both trees (fresh
processes, same scenario file and seed), then prints each tree's best and median real-time factor
and their ratio. Alternating cancels most of a shared machine's drift.

    python benchmarks/bench_sim.py --versus scenarios/house_obstacles.yaml [--pairs 5]

`--versus FILE` runs the default mission and FILE alternately in this tree (whole runs, fresh
processes) and prints the same figures and their ratio: e.g. what the obstacles of
house_obstacles.yaml (three blocks, a walker, a box for 60 s) cost the mission.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.robot.fmu_drive import FmuDrive
from twin.sim.scenario import KinematicDrive, default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation


def foundation(scenario):  # type: ignore[no-untyped-def]
    """The scenario without IMU, EKF, tree and planner: Gazebo-like /odom, the house tour's waypoints."""
    sensors = dataclasses.replace(scenario.sensors, imu=dataclasses.replace(scenario.sensors.imu, enabled=False))
    tour = load_scenario(Path(__file__).resolve().parent.parent / "scenarios" / "house_tour.yaml").mission
    no_blocks = dataclasses.replace(scenario.blocks, count=0)  # blocks stand at a tree mission's locations
    return dataclasses.replace(scenario, sensors=sensors, odometry="ground_truth", mission=tour, blocks=no_blocks)


def run_once(scenario, sim_s: float, *, profile: bool) -> dict[str, object]:  # type: ignore[no-untyped-def]
    with (
        tempfile.TemporaryDirectory() as tmp,
        Simulation(scenario, bag_path=Path(tmp) / "bag", duration_s=sim_s, profile=profile) as sim,
    ):
        cpu0 = time.process_time()
        summary = sim.run()
        cpu_s = time.process_time() - cpu0
    return {"summary": summary, "cpu_s": cpu_s}


def measure(scenario, sim_s: float, repeat: int) -> dict[str, object]:  # type: ignore[no-untyped-def]
    # Unprofiled runs give the real-time factor; one profiled run gives the breakdown.
    runs = [run_once(scenario, sim_s, profile=False) for _ in range(repeat)]
    best = min(runs, key=lambda r: r["summary"].wall_s)  # type: ignore[union-attr]
    profiled = run_once(scenario, sim_s, profile=True)["summary"]
    loop_s = profiled.wall_s  # type: ignore[union-attr]
    parts = {k: v for k, v in profiled.breakdown_s.items() if k != "setup"}  # type: ignore[union-attr]
    parts["scheduler_and_rest"] = max(0.0, loop_s - sum(parts.values()))
    summary = best["summary"]
    ordered = sorted(parts.items(), key=lambda kv: -kv[1])
    return {
        "sim_s": summary.sim_s,  # type: ignore[union-attr]
        "wall_s_best_of": repeat,
        "wall_s": round(summary.wall_s, 4),  # type: ignore[union-attr]
        "real_time_factor": round(summary.real_time_factor, 1),  # type: ignore[union-attr]
        "cpu_ms_per_sim_s": round(1000 * best["cpu_s"] / summary.sim_s, 3),  # type: ignore[operator,union-attr]
        "messages": summary.messages,  # type: ignore[union-attr]
        "setup_s": round(profiled.breakdown_s.get("setup", 0.0), 3),  # type: ignore[union-attr]
        "share": {k: round(v / loop_s, 3) for k, v in ordered},
        "ms_per_sim_s": {k: round(1000 * v / profiled.sim_s, 3) for k, v in ordered},  # type: ignore[union-attr]
    }


_ONE_RUN = """
import json, sys, tempfile, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from twin.sim import load_scenario  # the package, whose exports a baseline commit has too
from twin.sim.simulation import Simulation
scenario = load_scenario(Path(sys.argv[2]))
with tempfile.TemporaryDirectory() as tmp, Simulation(scenario, bag_path=Path(tmp) / "bag") as sim:
    cpu0 = time.process_time()
    s = sim.run()
    cpu = time.process_time() - cpu0
print(json.dumps({"sim_s": s.sim_s, "wall_s": s.wall_s, "cpu_s": cpu, "messages": s.messages}))
"""


def _summarise(runs: dict[str, list[dict[str, float]]], result: dict[str, object], new: str, old: str) -> None:
    import statistics

    for name, rs in runs.items():
        rtf = [r["sim_s"] / r["wall_s"] for r in rs]
        cpu = [1000 * r["cpu_s"] / r["sim_s"] for r in rs]
        result[name] = {
            "sim_s": rs[0]["sim_s"],
            "messages": rs[0]["messages"],
            "real_time_factor_best": round(max(rtf), 1),
            "real_time_factor_median": round(statistics.median(rtf), 1),
            "cpu_ms_per_sim_s_best": round(min(cpu), 3),
        }
    a, b = result[new], result[old]
    for stat in ("best", "median"):
        key = f"real_time_factor_{stat}"
        result[f"{new}_over_{old}_rtf_{stat}"] = round(a[key] / b[key], 3)  # type: ignore[index]


def compare_scenarios(other: Path, pairs: int) -> dict[str, object]:
    """Run the default mission and `other` alternately in this tree, `pairs` times each."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    runs: dict[str, list[dict[str, float]]] = {"other": [], "default": []}
    for _ in range(pairs):
        for name, scenario in (("other", other), ("default", default_scenario_path())):
            out = subprocess.run(
                [sys.executable, "-c", _ONE_RUN, str(root), str(scenario)], check=True, capture_output=True, text=True
            )
            runs[name].append(json.loads(out.stdout.strip().splitlines()[-1]))
    result: dict[str, object] = {"benchmark": "scenario_vs_default", "other": str(other), "pairs": pairs}
    _summarise(runs, result, "other", "default")
    return result


def compare_with(rev: str, scenario: Path, pairs: int) -> dict[str, object]:
    """Run the default mission alternately in this tree and in `rev`, `pairs` times each."""
    import statistics
    import subprocess

    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "baseline"
        subprocess.run(
            ["git", "-C", str(root), "worktree", "add", "--detach", str(base), rev], check=True, capture_output=True
        )
        try:
            runs: dict[str, list[dict[str, float]]] = {"current": [], "baseline": []}
            for _ in range(pairs):
                for name, tree in (("current", root), ("baseline", base)):
                    out = subprocess.run(
                        [sys.executable, "-c", _ONE_RUN, str(tree), str(scenario)],
                        check=True,
                        capture_output=True,
                        text=True,
                    )
                    runs[name].append(json.loads(out.stdout.strip().splitlines()[-1]))
        finally:
            subprocess.run(
                ["git", "-C", str(root), "worktree", "remove", "--force", str(base)], check=False, capture_output=True
            )
    result: dict[str, object] = {"benchmark": "node_graph_vs_baseline", "baseline_rev": rev, "pairs": pairs}
    for name, rs in runs.items():
        rtf = [r["sim_s"] / r["wall_s"] for r in rs]
        cpu = [1000 * r["cpu_s"] / r["sim_s"] for r in rs]
        result[name] = {
            "sim_s": rs[0]["sim_s"],
            "messages": rs[0]["messages"],
            "real_time_factor_best": round(max(rtf), 1),
            "real_time_factor_median": round(statistics.median(rtf), 1),
            "cpu_ms_per_sim_s_best": round(min(cpu), 3),
        }
    cur, old = result["current"], result["baseline"]
    result["current_over_baseline_rtf_best"] = round(cur["real_time_factor_best"] / old["real_time_factor_best"], 3)  # type: ignore[index]
    result["current_over_baseline_rtf_median"] = round(  # type: ignore[index]
        cur["real_time_factor_median"] / old["real_time_factor_median"],
        3,  # type: ignore[index]
    )
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", metavar="REV", help="compare the default mission with this git revision")
    parser.add_argument("--versus", type=Path, metavar="FILE", help="compare the default mission with this scenario")
    parser.add_argument("--pairs", type=int, default=5, help="alternating runs each with --baseline or --versus")
    parser.add_argument("--sim-s", type=float, default=60.0)
    parser.add_argument("--scenario", type=Path, default=default_scenario_path())
    parser.add_argument("--drive", choices=("scenario", "kinematic", "fmu"), default="scenario")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    if args.baseline:
        print(json.dumps(compare_with(args.baseline, args.scenario, args.pairs), indent=2))
        return 0
    if args.versus:
        print(json.dumps(compare_scenarios(args.versus, args.pairs), indent=2))
        return 0
    scenario = load_scenario(args.scenario)
    if args.drive == "fmu":
        scenario = dataclasses.replace(scenario, drive=FmuDrive(fmu="auto", profile="velocity-servo"))
    elif args.drive == "kinematic":
        scenario = dataclasses.replace(scenario, drive=KinematicDrive())
    configs = {"foundation": foundation(scenario), "full": scenario}
    drive = scenario.drive.type if args.drive == "scenario" else args.drive
    out: dict[str, object] = {"benchmark": "default_scenario", "scenario": str(args.scenario), "drive": drive}
    for name, config in configs.items():
        out[name] = measure(config, args.sim_s, args.repeat)
    full, base = out["full"], out["foundation"]
    out["full_over_foundation_cpu"] = round(full["cpu_ms_per_sim_s"] / base["cpu_ms_per_sim_s"], 2)  # type: ignore[index]
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
