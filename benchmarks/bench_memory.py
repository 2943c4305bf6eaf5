"""Memory: the bag streams to disk, so a long run's peak resident memory matches a short run's.

Runs `twin simulate` (default scenario) for 1 and 30 simulated minutes under `/usr/bin/time -v` and
prints JSON with each run's peak resident set size and bag size, and their ratio.

    python benchmarks/bench_memory.py [--short-s 60] [--long-s 1800] [--storage mcap|sqlite3]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def peak_rss_kib(duration_s: float, storage: str, out: Path) -> tuple[int, int]:
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "twin", "simulate", "--duration", str(duration_s)]
    cmd += ["--storage", storage, "--out", str(out)]
    run = subprocess.run(
        cmd, capture_output=True, text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, check=True
    )
    match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr)
    assert match, run.stderr
    size = sum(f.stat().st_size for f in out.iterdir())
    return int(match.group(1)), size


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--short-s", type=float, default=60.0)
    parser.add_argument("--long-s", type=float, default=1800.0)
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        short = peak_rss_kib(args.short_s, args.storage, Path(tmp) / "short")
        long = peak_rss_kib(args.long_s, args.storage, Path(tmp) / "long")
    print(
        json.dumps(
            {
                "benchmark": "memory",
                "storage": args.storage,
                "short": {
                    "sim_s": args.short_s,
                    "peak_rss_mib": round(short[0] / 1024, 1),
                    "bag_mib": round(short[1] / 2**20, 1),
                },
                "long": {
                    "sim_s": args.long_s,
                    "peak_rss_mib": round(long[0] / 1024, 1),
                    "bag_mib": round(long[1] / 2**20, 1),
                },
                "peak_rss_ratio_long_over_short": round(long[0] / short[0], 3),
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
