"""Run a sweep's runs as Dask tasks: on an embedded LocalCluster, or on a cluster by its address.

Both modes share one code path: a `distributed.Client` gets one `execute_run` task per run that
has not finished yet, and the rows come back as the tasks complete. The embedded cluster has one
single-threaded worker process per core (a run is one process on one core), forked from a
forkserver that imported Dask once, and does not retry a run whose worker died; a cluster of your
own retries it as its `distributed.scheduler.allowed-failures` says, then the run is marked
`worker lost`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.core.closing import Closing
from twin.core.errors import ConfigError
from twin.sweep.runner import KeepBags, RunTask, execute_run, read_result
from twin.sweep.spec import RunSpec, SweepSpec, expand_runs

__all__ = ["Cluster", "ProgressFn", "SweepResult", "run_sweep"]

_log = logging.getLogger(__name__)

ProgressFn = Callable[[int, int, int, float | None], None]
"""Called as runs finish with (runs done, runs failed, runs in the sweep, ETA in s or None)."""

_CONNECT_TIMEOUT_S = 10.0
_WORKERS_TIMEOUT_S = 60.0


@dataclass(frozen=True, kw_only=True, slots=True)
class SweepResult:
    """What a sweep produced: one row per run in run order, and how many were finished before."""

    spec: SweepSpec
    out_dir: Path
    rows: tuple[dict[str, Any], ...]
    resumed: int


class Cluster(Closing):
    """A Dask client started in the background: an embedded LocalCluster, or a scheduler by address.

    Starting a cluster takes a second or more (worker processes, Dask's imports); started when the
    command starts, it comes up while the sweep file is read and checked. `client()` waits for it.
    Closing stops the embedded cluster (or disconnects from the scheduler). A failure to start (an
    unreachable scheduler) is raised by `client()`, so a sweep whose runs are all finished never
    needs the cluster and never fails for it.

    Args:
        workers: Worker processes of the embedded cluster (default: one per core).
        scheduler: Address of an existing Dask scheduler (`tcp://HOST:8786`) instead.
    """

    def __init__(self, *, workers: int | None = None, scheduler: str | None = None) -> None:
        self._workers = workers
        self._scheduler = scheduler
        self._stack = ExitStack()
        self._client: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._start, name="twin-sweep-cluster", daemon=True)
        self._thread.start()

    def _start(self) -> None:
        try:
            self._client = self._stack.enter_context(_client(self._scheduler, self._workers))
        except BaseException as err:  # handed to the caller by client()
            self._error = err

    def client(self) -> Any:
        """Return the `distributed.Client` once the cluster is up.

        Raises:
            ConfigError: If the scheduler cannot be reached or has no workers.
        """
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._client

    def close(self) -> None:
        """Stop the embedded cluster (after it finished starting), or disconnect from the scheduler."""
        self._thread.join()
        self._stack.close()


def run_sweep(
    spec: SweepSpec,
    *,
    out_dir: Path,
    workers: int | None = None,
    scheduler: str | None = None,
    keep_bags: KeepBags = "all",
    progress: ProgressFn | None = None,
    cluster: Cluster | None = None,
) -> SweepResult:
    """Run every unfinished run of `spec`, each as one `twin simulate` process in a Dask task.

    Args:
        spec: The loaded sweep file.
        out_dir: Results folder; each run gets `runs/<run id>/` (scenario, bag, stderr, result.json).
            With `scheduler`, it must be on storage every worker shares.
        workers: Worker processes of the embedded cluster (default: one per core).
        scheduler: Address of an existing Dask scheduler (`tcp://HOST:8786`) instead.
        keep_bags: Which bags to keep: `all`, `failed` (runs that did not succeed) or `none`.
        progress: Told about each finished run.
        cluster: A cluster already being started (`workers` and `scheduler` are then its own); the
            caller closes it. Without one, a cluster is started for the runs and stopped after them.

    Raises:
        ConfigError: If the scheduler cannot be reached or has no workers.
    """
    out_dir = out_dir.resolve()
    runs = expand_runs(spec)
    rows: dict[int, dict[str, Any]] = {}
    todo: list[tuple[RunSpec, RunTask]] = []
    for run in runs:
        run_dir = out_dir / "runs" / run.run_id
        done = read_result(run_dir, run.key)
        if done is not None:
            rows[run.index] = done
            continue
        task = RunTask(
            run_id=run.run_id,
            key=run.key,
            seed=run.seed,
            scenario_yaml=run.scenario_yaml,
            run_dir=str(run_dir),
            timeout_s=spec.timeout_s,
            keep_bags=keep_bags,
        )
        todo.append((run, task))
    resumed = len(rows)
    failed = sum(1 for r in rows.values() if r.get("outcome") != "success")
    if progress is not None:
        progress(len(rows), failed, len(runs), None)
    if todo:
        from distributed import as_completed

        with ExitStack() as stack:
            if cluster is None:
                cluster = stack.enter_context(Cluster(workers=workers, scheduler=scheduler))
            client = cluster.client()
            tag = uuid.uuid4().hex[:8]
            futures = {
                client.submit(execute_run, task, key=f"twin-run-{run.run_id}-{tag}", pure=False): run
                for run, task in todo
            }
            start = time.monotonic()
            for finished, future in enumerate(as_completed(futures, loop=client.loop), start=1):  # type: ignore[no-untyped-call]
                run = futures[future]
                row = future.result() if future.status == "finished" else _lost(run, future.exception())
                rows[run.index] = row
                failed += row.get("outcome") != "success"
                if progress is not None:
                    left = len(runs) - len(rows)
                    eta = (time.monotonic() - start) / finished * left
                    progress(len(rows), failed, len(runs), eta)
    ordered = tuple(_with_inputs(rows[run.index], run) for run in runs)
    return SweepResult(spec=spec, out_dir=out_dir, rows=ordered, resumed=resumed)


def _with_inputs(row: dict[str, Any], run: RunSpec) -> dict[str, Any]:
    """The row led by what the run was given: its id, seed and varied values."""
    out: dict[str, Any] = {"run_id": run.run_id, "seed": _seed_of(run)}
    out.update(dict(run.values))
    out.update({k: v for k, v in row.items() if k not in out and k != "key"})
    return out


def _seed_of(run: RunSpec) -> int | None:
    """The seed the run ran with: the sweep's (`runs:`/`seeds:`), a varied `seed`, else its scenario's own."""
    if run.seed is not None:
        return run.seed
    varied = dict(run.values).get("seed")
    if varied is not None:
        return int(varied)
    import yaml

    scenario = yaml.safe_load(run.scenario_yaml)
    seed = scenario.get("seed", _DEFAULT_SEED) if isinstance(scenario, dict) else _DEFAULT_SEED
    return seed if isinstance(seed, int) else None


_DEFAULT_SEED = 0  # the packaged defaults' (twin/data/scenario_defaults.yaml)


def _lost(run: RunSpec, err: BaseException | None) -> dict[str, Any]:
    """The row of a run whose task did not return (its worker died, or the task itself failed)."""
    name = type(err).__name__ if err is not None else "unknown"
    if name == "KilledWorker":
        reason = "the Dask worker running it died"
        outcome = "worker lost"
    else:
        reason = f"the task failed: {name}: {err}".splitlines()[0]
        outcome = "crash"
    return {"run_id": run.run_id, "outcome": outcome, "reason": reason, "wall_s": None, "bag_path": ""}


@contextmanager
def _client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A Dask client on `scheduler`, or on an embedded LocalCluster of `workers` processes."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=_CONNECT_TIMEOUT_S, set_as_default=False)  # type: ignore[no-untyped-call]
        except (OSError, TimeoutError, ValueError) as err:
            why = str(err).splitlines()[0] if str(err) else type(err).__name__
            msg = (
                f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({why}); start one with "
                f"`dask scheduler` and workers with `dask worker {scheduler}` (twin installed, --out on storage "
                "they share), or leave out --scheduler to run on this machine"
            )
            raise ConfigError(msg) from None
        with client:
            try:
                client.wait_for_workers(1, timeout=_WORKERS_TIMEOUT_S)
            except TimeoutError:
                msg = (
                    f"--scheduler {scheduler}: the scheduler has no workers after {_WORKERS_TIMEOUT_S:g} s; "
                    f"start some with `dask worker {scheduler}`"
                )
                raise ConfigError(msg) from None
            yield client
        return
    n = workers if workers is not None else os.cpu_count() or 1
    # A run is one process on one core; a worker that dies takes its run with it (marked, not retried).
    # Workers fork from a server process that imported Dask once, instead of each starting a new
    # interpreter that imports it (about 0.7 s of CPU per worker, paid while the runs wait), and a
    # forked worker exits without tearing an interpreter down (0.2-1 s at shutdown with `spawn`).
    # A worker is given its next run only when it is free (saturation 1: Dask's default 1.1 queues
    # a second run on each one-thread worker, which can leave the last run waiting behind a busy
    # worker while another is idle). A worker only waits for its run's process, so it is not
    # profiled (a stack sample every 10 ms) and checks its memory once a second, not ten times:
    # 4.2 -> 2 % of a core per worker while a run goes on, CPU the runs beside it do not lose.
    with (
        dask.config.set(
            {
                "distributed.scheduler.allowed-failures": 0,
                "distributed.scheduler.worker-saturation": 1.0,
                "distributed.worker.multiprocessing-method": "forkserver",
                "distributed.worker.profile.enabled": False,
                "distributed.worker.memory.monitor-interval": "1s",
            }
        ),
        LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.CRITICAL,  # a worker's connection notices at shutdown are not the user's
        ) as cluster,
        Client(cluster, set_as_default=False) as client,  # type: ignore[no-untyped-call]
    ):
        yield client
