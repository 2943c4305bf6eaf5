"""What each added robot costs: 1, 2, 4... robots in one world for N simulated seconds (`robots:`).

Prints JSON: for each fleet size, CPU seconds per robot-second (the run's process CPU time over
robots x simulated seconds), its ratio to one robot's (the architecture's target: within 1.2x),
the real-time factor, and the process's peak memory (each size in a fresh process, so memory per
added robot is the difference). Every robot runs the scenario's own mission and Nav2 stack under
its namespace; the bag is recorded, as a user's run records it. Speed is never asserted (this
machine is shared and noisy): compare the ratios within one run.

    python benchmarks/bench_fleet.py [--scenario scenarios/turtlebot3_world.yaml] [--robots 1 2 4 8] [--sim-s 60]
                                     [--alone]

With `--alone` each robot of each fleet also runs by itself (its spawn, its mission, the world to
itself), and a fleet's CPU is compared with the sum of its robots' alone (`cost_ratio_vs_alone`):
the cost of sharing the world (seeing and touching the others, the shared clock), apart from the
robots' missions costing differently.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.sim.scenario import InitialPose, RobotEntry, RobotSection, Scenario
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation

REPO = Path(__file__).resolve().parent.parent

# Free spawn poses (x, y, yaw), the scenario's own first: the TurtleBot3 world's west and east ends
# (then its south and north sides, for eight); in the house its middle and two of the thesis's locations.
SPAWNS = {
    "turtlebot3_world": [
        (-2.0, -0.5, 0.0),
        (2.0, 0.5, 3.1416),
        (-2.0, 0.5, 0.0),
        (2.0, -0.5, 3.1416),
        (-0.5, -1.8, 1.571),
        (0.5, 1.8, -1.571),
        (0.5, -1.8, 1.571),
        (-0.5, 1.8, -1.571),
    ],
    "house": [(0.0, 0.0, 0.0), (1.5, -0.2, 0.0), (4.0, 0.5, 1.571), (2.75, 2.5, -1.571)],
}


def _rotated(mission: Any, i: int, folder: Path) -> Any:
    """Robot `i`'s mission: the same tree, its location file's entries rotated by `i` (each robot its own way)."""
    if i == 0 or getattr(mission, "locations", None) is None:
        return mission
    keys = list(yaml.safe_load(mission.locations.read_text()).items())
    names = [k for k, _ in keys]
    values = [v for _, v in keys]
    values = values[i % len(values) :] + values[: i % len(values)]
    path = folder / f"robot{i + 1}_locations.yaml"
    path.write_text(yaml.safe_dump(dict(zip(names, values, strict=True))))
    return dataclasses.replace(mission, locations=path)


def fleet(scenario: Scenario, n: int, folder: Path) -> Scenario:
    """The scenario with `n` robots of its own sections at the world's spawn poses, each its own location order."""
    spawns = SPAWNS["turtlebot3_world" if "turtlebot3_world" in scenario.world.sdf.name else "house"]
    if n > len(spawns):
        msg = f"at most {len(spawns)} robots in this world (add spawn poses to SPAWNS)"
        raise SystemExit(msg)
    entries = []
    for i in range(n):
        x, y, yaw = spawns[i]
        robot = RobotSection(model=scenario.robot.model, initial_pose=InitialPose(x_m=x, y_m=y, yaw_rad=yaw))
        sections = {
            name: getattr(scenario, name)
            for name in ("mission", "sensors", "drive", "odometry", "estimation", "disturbances", "localization")
        }
        sections["mission"] = _rotated(scenario.mission, i, folder)
        entries.append(RobotEntry(name=f"robot{i + 1}", robot=robot, navigation=scenario.navigation, **sections))
    return dataclasses.replace(scenario, robots=tuple(entries))


def run_one(path: Path, n: int, sim_s: float, alone: int | None = None) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        scenario = fleet(load_scenario(path), n, Path(tmp))
        if alone is not None:  # robot `alone` of the fleet of `n`, by itself in the world
            scenario = dataclasses.replace(scenario, robots=(scenario.robots[alone],))
        cpu0, wall0 = time.process_time(), time.perf_counter()
        with Simulation(scenario, bag_path=Path(tmp) / "bag", duration_s=sim_s) as sim:
            setup_cpu = time.process_time() - cpu0
            run_cpu0 = time.process_time()
            summary = sim.run()
            run_cpu = time.process_time() - run_cpu0
        wall = time.perf_counter() - wall0
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {
        "robots": n,
        "sim_s": summary.sim_s,
        "run_cpu_s": round(run_cpu, 3),
        "setup_cpu_s": round(setup_cpu, 3),
        "cpu_ms_per_robot_s": round(1000.0 * run_cpu / (n * summary.sim_s), 3),
        "real_time_factor": round(summary.sim_s / summary.wall_s, 1),
        "wall_s": round(wall, 2),
        "peak_rss_mib": round(peak_mib, 1),
        "messages": summary.messages,
        "contacts": summary.contacts,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=REPO / "scenarios" / "turtlebot3_world.yaml")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--sim-s", type=float, default=60.0)
    parser.add_argument(
        "--alone",
        action="store_true",
        help="also run each robot of each fleet by itself (same spawn, same mission) and compare the fleet's "
        "CPU with the sum of theirs: what sharing the world costs, apart from which missions the robots have",
    )
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a child process: one fleet size
    parser.add_argument("--alone-index", type=int, help=argparse.SUPPRESS)  # ... or one robot of it alone
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(run_one(args.scenario, args.one, args.sim_s, args.alone_index)))
        return

    def child(n: int, alone: int | None = None) -> dict[str, Any]:
        cmd = [sys.executable, __file__, "--scenario", str(args.scenario), "--sim-s", str(args.sim_s), "--one", str(n)]
        if alone is not None:
            cmd += ["--alone-index", str(alone)]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        row: dict[str, Any] = json.loads(out.strip().splitlines()[-1])
        return row

    rows = [child(n) for n in args.robots]
    base = rows[0]
    alone_cpu: dict[int, float] = {}  # robot index -> its CPU by itself (the same in every fleet size)
    for row in rows:
        row["cost_ratio_vs_first"] = round(row["cpu_ms_per_robot_s"] / base["cpu_ms_per_robot_s"], 3)
        if args.alone and row["robots"] > 1:
            for i in range(row["robots"]):
                if i not in alone_cpu:
                    alone_cpu[i] = child(row["robots"], i)["run_cpu_s"]
            summed = sum(alone_cpu[i] for i in range(row["robots"]))
            row["alone_cpu_s"] = round(summed, 3)
            row["cost_ratio_vs_alone"] = round(row["run_cpu_s"] / summed, 3)
        added = row["robots"] - base["robots"]
        row["mib_per_added_robot"] = round((row["peak_rss_mib"] - base["peak_rss_mib"]) / added, 1) if added else 0.0
    print(json.dumps({"scenario": str(args.scenario), "sim_s": args.sim_s, "fleets": rows}, indent=2))


if __name__ == "__main__":
    main()
