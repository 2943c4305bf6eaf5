"""Speed of `twin world info` on a big world: N models of one box each (10,000 by default); prints JSON.

Times the three parts of the command in one process: loading the SDF (`load_world`), building the
collision scene (`build_scene`) and the summary (`summarize`, which builds the scene as the command
does, without building the collision objects), then the whole `twin world info` command in a fresh
process (`command_s`). The issue's budget is 3 s for the whole command on a 10,000-model world.

Usage: python benchmarks/bench_world_info.py [--models N]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from twin.cli.world import summarize  # noqa: E402
from twin.world import build_scene, load_world  # noqa: E402


def write_world(path: Path, models: int) -> None:
    parts = ["<sdf version='1.6'><world name='big'>"]
    for i in range(models):
        x, y = (i % 100) * 0.5, (i // 100) * 0.5
        box = "<geometry><box><size>0.2 0.2 0.5</size></box></geometry>"
        parts.append(
            f"<model name='box{i}'><static>true</static><pose>{x} {y} 0.25 0 0 0</pose><link name='l'>"
            f"<collision name='c'>{box}</collision><visual name='v'>{box}</visual></link></model>"
        )
    parts.append("</world></sdf>")
    path.write_text("".join(parts))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--models", type=int, default=10_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "big.world"
        write_world(path, args.models)
        t0 = time.perf_counter()
        world = load_world(path)
        t1 = time.perf_counter()
        scene = build_scene(world)
        t2 = time.perf_counter()
        summarize(world)
        t3 = time.perf_counter()
        # The whole command as a user runs it: interpreter start, imports, load, summary, output.
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        subprocess.run(
            [sys.executable, "-m", "twin", "world", "info", str(path)], check=True, env=env, stdout=subprocess.DEVNULL
        )
        t4 = time.perf_counter()
    print(
        json.dumps(
            {
                "models": args.models,
                "obstacles": len(scene.obstacles),
                "load_world_s": round(t1 - t0, 3),
                "build_scene_s": round(t2 - t1, 3),
                "summarize_s": round(t3 - t2, 3),
                "command_s": round(t4 - t3, 3),
                "command_budget_s": 3.0,
                "python": platform.python_version(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
