"""`twin sweep SWEEP.yaml`: many runs of a scenario on Dask, one table and a success rate."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from twin.core.errors import ConfigError

_EPILOG = """\
examples:
  twin sweep scenarios/sweeps/default_50_seeds.yaml             the default mission over 50 seeds
  twin sweep scenarios/sweeps/robots.yaml --workers 2 --out /tmp/robots
  twin sweep my_sweep.yaml --scheduler tcp://10.0.0.5:8786      on a Dask cluster (shared --out!)
  twin sweep my_sweep.yaml --keep-bags failed                   keep only the bags of failed runs

A sweep file names a base scenario and what varies (docs/sweeps.md):
  scenario: ../default.yaml                # relative to the sweep file
  runs: 50                                 # seeds 0..49 (or seeds: [3, 7])
  vary: {robot.model: [turtlebot3_waffle, turtlebot3_burger]}   # a grid; zip: true pairs lists
  random: {robot.initial_pose.x_m: {uniform: [-0.2, 0.2]}}     # seeded draws per run
  timeout_s: 120                           # per run, wall clock

Each run is one `twin simulate` process in a Dask task: a crash or timeout fails that run only.
Running the same sweep again skips the runs that finished. Results: DIR/results.csv (and .parquet),
DIR/summary.md (success rate, 95 % Wilson interval, failures by reason), DIR/mission_time.png.
Exit codes: 0 every run completed (its mission succeeded or failed: both are results), 1 some runs
did not complete (error, crash, timeout, worker lost; the tables are written all the same), 2 a bad
sweep file, an --out that cannot be written, or a scheduler that is not a reachable Dask scheduler.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `sweep` command."""
    parser = subparsers.add_parser(
        "sweep",
        help="run a scenario many times (seeds, grids, random draws) on Dask; a results table",
        description=(
            "Run every combination of a sweep file's varied scenario keys and seeds, each as one isolated "
            "`twin simulate` process, on an embedded Dask LocalCluster (one single-threaded worker process "
            "per core) or on an existing Dask cluster by address; then write a results table and a summary."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("sweep", type=Path, metavar="SWEEP.yaml", help="sweep file")
    parser.add_argument("--workers", type=int, metavar="N", help="local cluster worker processes (default: cores)")
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="use the Dask scheduler at ADDRESS (tcp://HOST:8786) instead"
    )
    parser.add_argument("--out", type=Path, metavar="DIR", help="results folder (default: bags/<sweep name>_sweep)")
    parser.add_argument(
        "--keep-bags",
        choices=("all", "failed", "none"),
        default="all",
        help="which runs' bags to keep (default all)",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    parser.set_defaults(func=_sweep)


class _Bar:
    """`runs 12/50 [######------] failed 1  ETA 1m05s` on a terminal; nothing otherwise."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self.enabled = bool(getattr(stream, "isatty", lambda: False)())
        self._drawn = False
        self._last = 0.0

    def __call__(self, done: int, failed: int, total: int, eta_s: float | None) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if done < total and now - self._last < 0.2:
            return
        self._last = now
        filled = int(24 * done / total) if total else 24
        eta = "" if eta_s is None else f"  ETA {int(eta_s) // 60}m{int(eta_s) % 60:02d}s"
        self._stream.write(f"\rruns {done}/{total} [{'#' * filled}{'-' * (24 - filled)}] failed {failed}{eta}\x1b[K")
        self._stream.flush()
        self._drawn = True

    def close(self) -> None:
        if self._drawn:
            self._stream.write("\r\x1b[K")
            self._stream.flush()
            self._drawn = False


def _sweep(args: argparse.Namespace) -> int:
    from twin.core.config import load_yaml
    from twin.sweep import (
        Cluster,
        check_out_dir,
        check_scheduler,
        load_sweep,
        run_sweep,
        wilson_interval,
        write_reports,
    )

    if args.workers is not None and args.workers < 1:
        msg = f"--workers must be at least 1, got {args.workers}"
        raise ConfigError(msg)
    cores = os.cpu_count() or 1
    if args.workers is not None and args.workers > 4 * cores:  # each is a process running one run on one core
        msg = f"--workers {args.workers}: this machine has {cores} cores and a run uses one; give at most {4 * cores}"
        raise ConfigError(msg)
    if args.workers is not None and args.scheduler is not None:
        msg = "--workers sizes the local cluster; with --scheduler the cluster's own workers run the sweep"
        raise ConfigError(msg)
    load_yaml(args.sweep)  # a missing or malformed file is told at once, before any cluster starts
    if args.scheduler is not None:
        check_scheduler(args.scheduler)  # an address Dask would hang on, or crash on, is told at once
    if args.out is not None:
        check_out_dir(args.out, create=False)  # before any run: an unwritable --out would fail every run's results
    if not (args.verbose or args.debug):  # Dask's own shutdown notices are not the user's business
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
    bar = _Bar(sys.stderr)
    # SIGTERM stops the sweep as Ctrl-C does: the cluster shuts down, its runs are told to stop,
    # and the finished runs stay finished for the next start.
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        # The cluster comes up while the sweep file is read and checked.
        with Cluster(workers=args.workers, scheduler=args.scheduler) as cluster:
            spec = load_sweep(args.sweep)
            out = args.out if args.out is not None else Path("bags") / f"{spec.name}_sweep"
            check_out_dir(out, option="--out" if args.out is not None else "the default output folder")
            result = run_sweep(spec, out_dir=out, keep_bags=args.keep_bags, progress=bar, cluster=cluster)
    except KeyboardInterrupt as stop:
        bar.close()
        name = "SIGTERM" if isinstance(stop, _Terminated) else "SIGINT"
        print(
            f"twin: sweep stopped by {name}; the runs that finished are kept in their folders: "
            "the same command again runs the others and writes the results",
            file=sys.stderr,
        )
        return 128 + signal.SIGTERM if isinstance(stop, _Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        bar.close()
    files = write_reports(result)
    runs = len(result.rows)
    ok = sum(1 for r in result.rows if r.get("outcome") == "success")
    unfinished = [r for r in result.rows if r.get("outcome") not in ("success", "failure")]
    low, high = wilson_interval(ok, runs)
    if args.json:
        doc = {
            "sweep": str(args.sweep),
            "out": str(result.out_dir),
            "runs": runs,
            "succeeded": ok,
            "success_rate": ok / runs if runs else None,
            "wilson_95": [low, high],
            "resumed": result.resumed,
            "outcomes": {o: sum(1 for r in result.rows if r.get("outcome") == o) for o in _outcomes(result.rows)},
            "files": [str(f) for f in files],
        }
        print(json.dumps(doc, indent=2))
    else:
        resumed = f" ({result.resumed} finished before)" if result.resumed else ""
        print(
            f"{runs} runs{resumed}: {ok} succeeded ({100 * ok / runs:.1f} %, 95 % CI {100 * low:.1f} to "
            f"{100 * high:.1f} %), {runs - ok} did not; {result.out_dir / 'summary.md'}"
        )
    if unfinished:
        # The success rate leaves these runs out of what it measured: say so, and exit 1 for scripts and CI.
        kinds = ", ".join(f"{n} {o}" for o, n in _counts(unfinished).items())
        first = unfinished[0]
        print(
            f"twin: error: {len(unfinished)} of {runs} runs did not complete ({kinds}); first, "
            f"{first.get('run_id')}: {first.get('reason')}",
            file=sys.stderr,
        )
        return 1
    return 0


def _counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for row in rows:
        outcome = str(row.get("outcome"))
        counts[outcome] = counts.get(outcome, 0) + 1
    return counts


class _Terminated(KeyboardInterrupt):
    """SIGTERM, unwinding the sweep as Ctrl-C does (the cluster stops, its runs are told to stop)."""


def _interrupt(signum: int, frame: object) -> None:
    raise _Terminated


def _outcomes(rows: tuple[dict[str, Any], ...]) -> list[str]:
    seen: list[str] = []
    for row in rows:
        if row.get("outcome") not in seen:
            seen.append(str(row.get("outcome")))
    return seen
