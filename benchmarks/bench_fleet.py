"""What each added robot costs: 1, 2, 4... robots in one world for N simulated seconds (`robots:`).

Prints JSON: for each fleet size, CPU seconds per robot-second (the run's process CPU time over
robots x simulated seconds), its ratio to one robot's (the architecture's target: within 1.2x),
the real-time factor, and the process's peak memory (each size in a fresh process, so memory per
added robot is the difference). Every robot runs the scenario's own mission and Nav2 stack under
its namespace; the bag is recorded, as a user's run records it. Speed is never asserted (this
machine is shared and noisy): compare the ratios within one run.

With `--camera` every robot is a Waffle with its camera on (640x480 RGB + depth at 10 Hz, noise from
the SDF), recorded as the shipped camera scenarios record it (the JPEG image and camera_info; not
the raw image, depth and points, 0.9, 1.2 and 9.8 MB a frame). Each fleet size then runs twice in
fresh processes, without and with the cameras, and the JSON adds the frames each robot's camera
drew, the CPU the renderer's calls took per frame, and the run's CPU over the same run without
cameras per frame (drawing, the JPEG and the bag together): the missions compute the same either way
(each camera has its own random stream), so the difference is what the cameras cost. (The one-off
import of scipy.special that the first noisy frame of a process needs is made before the run and
quoted on its own.)

    python benchmarks/bench_fleet.py [--scenario scenarios/turtlebot3_world.yaml] [--robots 1 2 4 8] [--sim-s 60]
                                     [--alone]
    python benchmarks/bench_fleet.py --camera [--robots 1 2 4] [--scenario scenarios/default.yaml] [--repeat 3]
    python benchmarks/bench_fleet.py --instructions [--robots 1 4] [--alone] [--sim-s 60]

`--repeat N` runs each size N times, the sizes alternated round after round, and keeps each size's
run of least CPU (the others' figures are listed), as a shared machine's load only ever adds.

`--instructions` counts instead of timing: each run goes under valgrind's cachegrind (no cache
simulation), once for `--sim-s` and once for a moment (`_SETUP_SIM_S`), and the difference is the
run's own instructions, with setup and start-up taken out. The count hardly depends on the
machine's load (the same run counts the same to about 1 %: the recorder flushes and the watchdog
wakes by wall time, which valgrind stretches), where CPU times here vary by 20 %, so ratios of a
few percent are read from one pass; it does not see memory stalls, which a CPU time does. Each size
and each robot alone then runs once (`--repeat` is ignored), about 50 times slower than natively:
a 4-robot minute takes about three minutes; the two runs of each go in parallel on two cores.

With `--alone` each robot of each fleet also runs by itself (its spawn, its mission, the world to
itself), and a fleet's CPU is compared with the sum of its robots' alone (`cost_ratio_vs_alone`):
the cost of sharing the world (seeing and touching the others, the shared clock), apart from the
robots' missions costing differently.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.bag import open_bag
from twin.sim.scenario import (
    CameraSection,
    InitialPose,
    RecordingSection,
    RobotEntry,
    RobotSection,
    Scenario,
    SensorsSection,
)
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation
from twin.world.render import Renderer

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


# The shipped camera scenarios' camera (house_search_*.yaml), with the depth image the architecture's
# 5 ms frame budget counts; the raw images are not recorded, as those scenarios leave them out.
CAMERA = CameraSection(enabled=True, width=640, height=480, rate_hz=10.0, depth=True, compressed=True)
NOT_RECORDED = r"/.*/camera/(image_raw|depth/image_raw|points)"


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


def with_cameras(scenario: Scenario) -> Scenario:
    """The scenario with every robot a Waffle whose camera is on and recorded (before `fleet`, which copies both)."""
    robot = dataclasses.replace(scenario.robot, model="turtlebot3_waffle")
    sensors: SensorsSection = dataclasses.replace(scenario.sensors, camera=CAMERA)
    topics = dataclasses.replace(scenario.recording.topics, exclude_regex=NOT_RECORDED)
    recording: RecordingSection = dataclasses.replace(scenario.recording, topics=topics)
    return dataclasses.replace(scenario, robot=robot, sensors=sensors, recording=recording)


class RenderClock:
    """Counts and times `Renderer.render` calls, per renderer (each robot's camera has its own)."""

    def __init__(self) -> None:
        self.frames: dict[int, int] = {}
        self.cpu_s = 0.0
        self.extra_triangles = 0
        self.native = True
        self._render = Renderer.render

    def __enter__(self) -> RenderClock:
        draw = self._render

        def timed(renderer: Renderer, *args: Any, **kwargs: Any) -> Any:
            t0 = time.process_time()
            frame = draw(renderer, *args, **kwargs)
            self.cpu_s += time.process_time() - t0
            self.frames[id(renderer)] = self.frames.get(id(renderer), 0) + 1
            self.native = self.native and renderer.native
            extra = args[1] if len(args) > 1 else kwargs.get("extra")
            self.extra_triangles += 0 if extra is None else len(extra.faces)
            return frame

        Renderer.render = timed  # type: ignore[method-assign,assignment]
        return self

    def __exit__(self, *exc: object) -> None:
        Renderer.render = self._render  # type: ignore[method-assign]


def run_one(path: Path, n: int, sim_s: float, *, camera: bool = False, alone: int | None = None) -> dict[str, Any]:
    """One run of `n` robots (or, with `alone`, robot `alone` of those `n` by itself)."""
    scenario = load_scenario(path)
    import_cpu = 0.0
    if camera:
        scenario = with_cameras(scenario)
        # The renderer's noise table imports scipy.special at the first noisy frame: once per
        # process, whatever the fleet's size. Imported here, it stays out of the per-robot-second figures.
        t0 = time.process_time()
        import scipy.special  # noqa: F401

        import_cpu = time.process_time() - t0
    with tempfile.TemporaryDirectory() as tmp, RenderClock() as clock:
        scenario = fleet(scenario, n, Path(tmp))
        if alone is not None:
            scenario = dataclasses.replace(scenario, robots=(scenario.robots[alone],))
        cpu0, wall0 = time.process_time(), time.perf_counter()
        with Simulation(scenario, bag_path=Path(tmp) / "bag", duration_s=sim_s) as sim:
            setup_cpu = time.process_time() - cpu0
            run_cpu0 = time.process_time()
            summary = sim.run()
            run_cpu = time.process_time() - run_cpu0
        wall = time.perf_counter() - wall0
        in_bag = {t.name: t.message_count for t in open_bag(Path(tmp) / "bag").topics}
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    row: dict[str, Any] = {
        "robots": n,
        "sim_s": summary.sim_s,
        "run_cpu_s": round(run_cpu, 3),
        "setup_cpu_s": round(setup_cpu, 3),
        "cpu_ms_per_robot_s": round(1000.0 * run_cpu / (len(scenario.robots or (0,)) * summary.sim_s), 3),
        "real_time_factor": round(summary.sim_s / summary.wall_s, 1),
        "wall_s": round(wall, 2),
        "peak_rss_mib": round(peak_mib, 1),
        "messages": summary.messages,
        "contacts": summary.contacts,
    }
    if camera:
        frames = sorted(clock.frames.values())
        recorded = [in_bag.get(f"/robot{i + 1}/camera/image_raw/compressed", 0) for i in range(n)]
        row |= {
            "cameras": len(frames),
            "frames_per_robot": frames,  # each camera's drawn frames, fewest first
            "frames_recorded_per_robot": recorded,  # /robotN/camera/image_raw/compressed in the bag
            "render_cpu_s": round(clock.cpu_s, 3),
            "render_ms_per_frame": round(1000.0 * clock.cpu_s / max(sum(frames), 1), 3),
            "robot_triangles_per_frame": round(clock.extra_triangles / max(sum(frames), 1)),
            "native_renderer": clock.native,
            "noise_import_cpu_s": round(import_cpu, 3),  # scipy.special, before the run (see above)
        }
    return row


# `--instructions`: the short run whose count is taken from the whole run's (setup, start-up, a moment).
_SETUP_SIM_S = 0.05
_I_REFS = re.compile(r"I\s+refs:\s+([\d,]+)")


def _child(args: argparse.Namespace, n: int, *, camera: bool, alone: int | None = None) -> dict[str, Any]:
    if args.instructions:
        return _counted_child(args, n, camera=camera, alone=alone)
    return _run_child(args, n, args.sim_s, camera=camera, alone=alone)[0]


def _run_child(
    args: argparse.Namespace, n: int, sim_s: float, *, camera: bool, alone: int | None, counted: bool = False
) -> tuple[dict[str, Any], int]:
    """One run in a fresh process (under cachegrind when `counted`): its row, and its instructions (0: not counted)."""
    cmd = [sys.executable, __file__, "--scenario", str(args.scenario), "--sim-s", str(sim_s), "--one", str(n)]
    cmd += ["--camera"] if camera else []
    cmd += [] if alone is None else ["--alone-index", str(alone)]
    env = None
    if counted:
        cmd = ["valgrind", "--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null", *cmd]
        # Python's own allocator confuses valgrind; a fixed hash seed keeps set and dict orders the same.
        env = {**os.environ, "PYTHONMALLOC": "malloc", "PYTHONHASHSEED": "0"}
    done = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    row: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    found = _I_REFS.findall(done.stderr) if counted else []
    if counted and not found:
        raise SystemExit(f"valgrind printed no instruction count: {done.stderr.strip()[-300:]}")
    return row, int(found[-1].replace(",", "")) if found else 0


def _counted_child(args: argparse.Namespace, n: int, *, camera: bool, alone: int | None) -> dict[str, Any]:
    """A run's row with its own instructions: counted for `--sim-s` and for a moment, the two in parallel."""
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        whole, setup = (
            pool.submit(_run_child, args, n, s, camera=camera, alone=alone, counted=True)
            for s in (args.sim_s, _SETUP_SIM_S)
        )
        row, total = whole.result()
        _, before = setup.result()
    robots = 1 if alone is not None else n
    row["run_instructions"] = total - before
    # (the run's own simulated time: a mission that ends before --sim-s ends the run there)
    row["instructions_per_robot_s"] = round((total - before) / (robots * (row["sim_s"] - _SETUP_SIM_S)))
    return row


def _rows(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Each size's runs (without, then with cameras), round after round; per size its run of least CPU.

    With `--camera` the row is the camera run's, the best run without cameras beside it.
    """
    kinds = (False, True) if args.camera else (False,)
    runs: dict[tuple[int, bool], list[dict[str, Any]]] = {(n, k): [] for n in args.robots for k in kinds}
    for _ in range(args.repeat):
        for n in args.robots:
            for camera in kinds:
                runs[n, camera].append(_child(args, n, camera=camera))
    rows = []
    for n in args.robots:
        bare = min(runs[n, False], key=lambda r: r["run_cpu_s"])
        row = min(runs[n, args.camera], key=lambda r: r["run_cpu_s"])
        if args.repeat > 1:
            row["cpu_ms_per_robot_s_runs"] = [r["cpu_ms_per_robot_s"] for r in runs[n, args.camera]]
        if args.camera:
            frames = sum(row["frames_per_robot"])
            keys = ("run_cpu_s", "cpu_ms_per_robot_s", "real_time_factor", "peak_rss_mib", "messages", "contacts")
            row["without_cameras"] = {k: bare[k] for k in keys}
            row["camera_ms_per_frame"] = round(1000.0 * (row["run_cpu_s"] - bare["run_cpu_s"]) / max(frames, 1), 3)
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=REPO / "scenarios" / "turtlebot3_world.yaml")
    parser.add_argument("--robots", type=int, nargs="+", help="fleet sizes (default: 1 2 4 8; with --camera 1 2 4)")
    parser.add_argument("--sim-s", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=1, help="runs of each size, alternated; the least CPU is kept")
    parser.add_argument("--camera", action="store_true", help="every robot a Waffle with its camera on and recorded")
    parser.add_argument(
        "--alone",
        action="store_true",
        help="also run each robot of each fleet by itself (same spawn, same mission) and compare the fleet's "
        "CPU with the sum of theirs: what sharing the world costs, apart from which missions the robots have",
    )
    parser.add_argument(
        "--instructions",
        action="store_true",
        help="count each run's instructions under valgrind instead of timing it (load-independent; slow)",
    )
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a child process: one fleet size
    parser.add_argument("--alone-index", type=int, help=argparse.SUPPRESS)  # ... or one robot of it alone
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error(f"--repeat must be 1 or more, got {args.repeat}")
    if args.one is not None:
        print(json.dumps(run_one(args.scenario, args.one, args.sim_s, camera=args.camera, alone=args.alone_index)))
        return
    if args.instructions:
        if shutil.which("valgrind") is None:
            parser.error("--instructions runs each child under valgrind, which is not installed (apt install valgrind)")
        if args.sim_s <= _SETUP_SIM_S:
            parser.error(f"--instructions needs --sim-s above {_SETUP_SIM_S} (the moment taken out), got {args.sim_s}")
        args.repeat = 1  # a count is the same every time
    if args.robots is None:
        args.robots = [1, 2, 4] if args.camera else [1, 2, 4, 8]
    rows = _rows(args)
    base = rows[0]
    for row in rows:
        row["cost_ratio_vs_first"] = round(row["cpu_ms_per_robot_s"] / base["cpu_ms_per_robot_s"], 3)
        if args.instructions:
            row["instruction_ratio_vs_first"] = round(
                row["instructions_per_robot_s"] / base["instructions_per_robot_s"], 3
            )
        added = row["robots"] - base["robots"]
        row["mib_per_added_robot"] = round((row["peak_rss_mib"] - base["peak_rss_mib"]) / added, 1) if added else 0.0
    if args.alone:
        alone_cpu: dict[int, float] = {}  # robot index -> its least CPU by itself (the same in every fleet size)
        alone_instructions: dict[int, int] = {}  # ... and its instructions (`--instructions`)
        for row in rows:
            if row["robots"] < 2:
                continue
            for i in range(row["robots"]):
                if i not in alone_cpu:
                    runs = [_child(args, row["robots"], camera=args.camera, alone=i) for _ in range(args.repeat)]
                    alone_cpu[i] = min(r["run_cpu_s"] for r in runs)
                    alone_instructions[i] = runs[0].get("run_instructions", 0)
            summed = sum(alone_cpu[i] for i in range(row["robots"]))
            row["alone_cpu_s"] = round(summed, 3)
            row["cost_ratio_vs_alone"] = round(row["run_cpu_s"] / summed, 3)
            if args.instructions:
                counted = sum(alone_instructions[i] for i in range(row["robots"]))
                row["alone_instructions"] = counted
                row["instruction_ratio_vs_alone"] = round(row["run_instructions"] / counted, 3)
    out: dict[str, Any] = {"scenario": str(args.scenario), "sim_s": args.sim_s, "repeat": args.repeat}
    if args.instructions:
        out["instructions"] = {
            "tool": "valgrind --tool=cachegrind --cache-sim=no",
            "setup_sim_s": _SETUP_SIM_S,
            "times": "valgrind's (about 50x slower): read the instruction fields",
        }
    if args.camera:
        out["camera"] = {
            **{k: getattr(CAMERA, k) for k in ("width", "height", "rate_hz", "depth", "compressed", "noise")},
            "not_recorded": NOT_RECORDED,
        }
    out["fleets"] = rows
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
