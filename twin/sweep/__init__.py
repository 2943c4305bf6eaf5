"""Layer 4: scenario sweeps on Dask. Expansion, per-run isolation, results tables; local and cluster.

A sweep file names a base scenario and what varies (lists as a grid or zipped, seeded random
draws, seeds); `run_sweep` runs each run as one `twin simulate` process in a Dask task, on an
embedded LocalCluster or on a cluster by address (a `Cluster` started first comes up while the
sweep file is read); `write_reports` writes results.csv/.parquet, summary.md and
mission_time.png. The only package that imports dask.
"""

from twin.sweep.engine import Cluster, SweepResult, run_sweep
from twin.sweep.preflight import check_out_dir, check_scheduler
from twin.sweep.report import wilson_interval, write_reports
from twin.sweep.spec import RunSpec, SweepSpec, expand_runs, load_sweep

__all__ = [
    "Cluster",
    "RunSpec",
    "SweepResult",
    "SweepSpec",
    "check_out_dir",
    "check_scheduler",
    "expand_runs",
    "load_sweep",
    "run_sweep",
    "wilson_interval",
    "write_reports",
]
