"""Speed and memory of `twin analyze` on a long default bag, against a short one (memory must stay flat).

Records the default scenario for 60 s and 30 minutes (or takes `--bag`), then runs
`twin analyze BAG --out DIR` under `/usr/bin/time -v` on each and prints JSON: wall time, peak
resident memory, messages, and the long/short ratios. Targets (issue 15): the 30-minute bag in
<= 15 s wall and <= 400 MiB peak RSS.

    python benchmarks/bench_analyze.py [--long-s 1800] [--short-s 60] [--storage mcap|sqlite3] [--bag BAG]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def simulate(duration_s: float, storage: str, out: Path) -> None:
    cmd = [sys.executable, "-m", "twin", "simulate", "--duration", str(duration_s), "--storage", storage]
    subprocess.run([*cmd, "--out", str(out), "-q"], cwd=REPO, env=ENV, check=True, capture_output=True)


def analyze(bag: Path, out: Path) -> dict[str, float]:
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "twin", "analyze", str(bag), "--out", str(out), "--json"]
    start = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=ENV, check=True)
    wall = time.perf_counter() - start
    match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr)
    assert match, run.stderr
    cpu = re.search(r"User time \(seconds\): ([\d.]+)", run.stderr)
    report = json.loads(run.stdout)
    return {
        "wall_s": round(wall, 2),
        "user_cpu_s": float(cpu.group(1)) if cpu else -1.0,
        "peak_rss_mib": round(int(match.group(1)) / 1024, 1),
        "messages": report["summary"]["messages"],
        "bag_duration_s": round(report["summary"]["duration_s"], 1),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--short-s", type=float, default=60.0)
    parser.add_argument("--long-s", type=float, default=1800.0)
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    parser.add_argument("--bag", type=Path, help="analyse this bag as the long one instead of recording it")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        simulate(args.short_s, args.storage, root / "short")
        long_bag = args.bag
        if long_bag is None:
            long_bag = root / "long"
            simulate(args.long_s, args.storage, long_bag)
        short = analyze(root / "short", root / "short_report")
        long = analyze(long_bag, root / "long_report")
    print(
        json.dumps(
            {
                "benchmark": "analyze",
                "storage": args.storage,
                "cpus": os.cpu_count(),
                "load_average_1min": round(os.getloadavg()[0], 2),
                "short": short,
                "long": long,
                "long_us_per_message": round(long["wall_s"] / long["messages"] * 1e6, 2),
                "peak_rss_ratio_long_over_short": round(long["peak_rss_mib"] / short["peak_rss_mib"], 3),
                "targets": {"long_wall_s": 15.0, "long_peak_rss_mib": 400.0},
                "within_targets": long["wall_s"] <= 15.0 and long["peak_rss_mib"] <= 400.0,
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
