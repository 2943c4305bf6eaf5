"""`twin sweep`: a 6-run sweep on a 2-worker LocalCluster, its table checked against the bags; the same
sweep through `--scheduler` on a separately started Dask scheduler and two workers gives the same table."""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.integration.sweep_helpers import (
    GOAL_XY,
    dask_cli,
    env,
    free_port,
    read_table,
    stop,
    wait_for_port,
    write_inputs,
)
from twin.analysis import run_metrics
from twin.bag import read_messages

# Columns that describe the machine, not the run.
_MACHINE = ("wall_s", "bag_path")


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("sweep")
    sweep = write_inputs(folder)
    out = folder / "local"
    result = run_twin("sweep", str(sweep), "--workers", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "6 runs: 6 succeeded" in result.stdout
    return sweep, out


def _same_run(row: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in row.items() if k not in _MACHINE}


def test_the_table_has_one_row_per_run_with_its_inputs(local_sweep: tuple[Path, Path]) -> None:
    _, out = local_sweep
    rows = read_table(out)
    assert [r["run_id"] for r in rows] == [f"r{i:04d}" for i in range(6)]
    assert [r["seed"] for r in rows] == ["0", "1"] * 3
    assert [float(r["robot.initial_pose.y_m"]) for r in rows] == [0.0, 0.0, 0.1, 0.1, -0.1, -0.1]
    xs = [float(r["robot.initial_pose.x_m"]) for r in rows]
    assert all(-0.05 <= x <= 0.05 for x in xs) and len(set(xs)) == 6


def test_the_table_holds_what_the_bags_say(local_sweep: tuple[Path, Path]) -> None:
    _, out = local_sweep
    for row in read_table(out):
        bag = Path(row["bag_path"])
        assert bag == out.resolve() / "runs" / row["run_id"] / "bag"
        metrics = run_metrics(bag)
        assert row["outcome"] == "success" and metrics.outcome == "SUCCESS"
        assert int(row["goals_reached"]) == metrics.goals_succeeded == 1
        assert float(row["mission_time_s"]) == metrics.mission_duration_s
        assert float(row["path_length_m"]) == metrics.path_length_m
        assert int(row["contacts"]) == metrics.contacts == 0
        assert float(row["localization_error_p95_m"]) == metrics.localization_error_p95_m
        # The robot really went from its varied spawn pose to the goal: the bag's ground truth says so.
        poses = [m.msg.pose.pose.position for m in read_messages(bag, ["/ground_truth/odom"])]
        start, end = poses[0], poses[-1]
        assert math.isclose(start.x, float(row["robot.initial_pose.x_m"]), abs_tol=1e-6)
        assert math.isclose(start.y, float(row["robot.initial_pose.y_m"]), abs_tol=1e-6)
        # Nav2's goal checker: 0.25 m of the pose AMCL believes, which is within ~0.2 m of the truth
        assert math.hypot(end.x - GOAL_XY[0], end.y - GOAL_XY[1]) < 0.25 + 0.2
        straight = math.hypot(GOAL_XY[0] - start.x, GOAL_XY[1] - start.y)
        assert straight * 0.6 < float(row["path_length_m"]) < straight * 1.5


def test_the_summary_gives_the_rate_its_interval_and_the_plot(local_sweep: tuple[Path, Path]) -> None:
    _, out = local_sweep
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "Success rate: 6 of 6 (100.0 %, 95 % CI 61.0 to 100.0 %)" in summary
    assert "## Failures by reason" in summary
    assert (out / "mission_time.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import pyarrow.parquet as pq

    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["run_id"] for r in table] == [r["run_id"] for r in read_table(out)]


def test_running_the_sweep_again_skips_the_finished_runs(local_sweep: tuple[Path, Path]) -> None:
    sweep, out = local_sweep
    before = read_table(out)
    result = run_twin("sweep", str(sweep), "--workers", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "(6 finished before)" in result.stdout
    assert read_table(out) == before


@pytest.fixture
def dask_cluster() -> Iterator[str]:
    """A Dask scheduler and two single-threaded workers, as separate processes on 127.0.0.1."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes: list[subprocess.Popen[bytes]] = []
    try:
        processes.append(
            subprocess.Popen(
                [dask_cli(), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                env=env(),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        wait_for_port(port, timeout_s=60)
        for _ in range(2):
            processes.append(
                subprocess.Popen(
                    [dask_cli(), "worker", address, "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard"],
                    env=env(),
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        yield address
    finally:
        stop(processes[::-1])


def test_a_sweep_through_a_scheduler_gives_the_same_table_as_local(
    local_sweep: tuple[Path, Path], dask_cluster: str
) -> None:
    sweep, local = local_sweep
    out = local.parent / "cluster"
    result = run_twin("sweep", str(sweep), "--scheduler", dask_cluster, "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "6 runs: 6 succeeded" in result.stdout
    assert [_same_run(r) for r in read_table(out)] == [_same_run(r) for r in read_table(local)]
    assert all(Path(r["bag_path"]).parent.parent == out.resolve() / "runs" for r in read_table(out))


def test_sweep_help_names_files_that_exist() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "twin", "sweep", "--help"], env=env(), capture_output=True, text=True, check=True
    )
    assert "scenarios/sweeps/default_50_seeds.yaml" in result.stdout
    from tests.conftest import REPO

    assert (REPO / "scenarios/sweeps/default_50_seeds.yaml").is_file()
    assert (REPO / "scenarios/sweeps/robots.yaml").is_file()


def test_a_fleet_sweep_puts_each_robot_where_its_indexed_key_says(tmp_path: Path) -> None:
    """`robots[1].robot.initial_pose.x_m` moves robot2 only: its first ground-truth pose in each run's bag."""
    fleet = Path(__file__).resolve().parents[2] / "scenarios" / "house_two_waffles.yaml"
    sweep = tmp_path / "fleet.yaml"
    sweep.write_text(
        f"scenario: {fleet}\nvary:\n  max_duration_s: [1]\n  robots[1].robot.initial_pose.x_m: [1.4, 1.7]\n",
        encoding="utf-8",
    )
    result = run_twin("sweep", str(sweep), "--workers", "1", "--out", str(tmp_path / "out"))
    assert "2 runs" in result.stdout, result.stderr
    rows = read_table(tmp_path / "out")
    for row in rows:
        starts = {}
        for ns in ("robot1", "robot2"):
            first = next(iter(read_messages(row["bag_path"], [f"/{ns}/ground_truth/odom"])))
            starts[ns] = (first.msg.pose.pose.position.x, first.msg.pose.pose.position.y)
        assert starts["robot2"] == pytest.approx((float(row["robots[1].robot.initial_pose.x_m"]), -0.2), abs=1e-6)
        assert starts["robot1"] == pytest.approx((0.0, 0.0), abs=1e-6)
    assert sorted(float(r["robots[1].robot.initial_pose.x_m"]) for r in rows) == [1.4, 1.7]


@pytest.mark.parametrize(
    "mission",
    [
        "mission: {type: cmd_vel_script, segments: [{duration_s: 1.0, linear_mps: 0.1}]}\n",
        "mission: {type: none}\nmax_duration_s: 1\n",  # nothing to fail: the run goes its duration
    ],
)
def test_a_mission_that_is_not_a_tree_succeeds_when_it_completes(tmp_path: Path, mission: str) -> None:
    """A cmd_vel script has no SUCCESS: `twin simulate` says "mission complete", and the sweep counts a success."""
    (tmp_path / "base.yaml").write_text(
        f"name: script\ndrive: {{type: kinematic}}\n{mission}" + ("max_duration_s: 10\n" * ("none" not in mission)),
        encoding="utf-8",
    )
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text("scenario: base.yaml\nruns: 2\n", encoding="utf-8")
    result = run_twin("sweep", str(sweep), "--workers", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "2 runs: 2 succeeded" in result.stdout
    rows = read_table(tmp_path / "out")
    assert [(r["outcome"], r["reason"]) for r in rows] == [("success", "")] * 2
    summary = (tmp_path / "out" / "summary.md").read_text(encoding="utf-8")
    assert "**Success rate: 2 of 2" in summary
    assert "No successful run." not in summary
