"""`twin bag export`: one table per topic, ROS field paths as columns, values as decoded."""

from __future__ import annotations

import csv
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.conftest import run_twin
from twin.bag import read_messages


def test_csv_has_a_row_per_message_with_field_path_columns(gazebo_bag: Path, tmp_path: Path) -> None:
    proc = run_twin("bag", "export", str(gazebo_bag), "--topics", "/odom", "/scan", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / "odom.csv").open() as f:
        rows = list(csv.DictReader(f))
    msgs = list(read_messages(gazebo_bag, ["/odom"]))
    assert len(rows) == len(msgs) == 826
    for row, m in zip(rows, msgs, strict=True):
        assert int(row["t_ns"]) == m.t_ns
        assert float(row["pose.pose.position.x"]) == m.msg.pose.pose.position.x
        assert row["child_frame_id"] == m.msg.child_frame_id
        assert [float(v) for v in row["pose.covariance"].split()] == list(m.msg.pose.covariance)
    with (tmp_path / "scan.csv").open() as f:
        first = next(csv.DictReader(f))
    scan = next(iter(read_messages(gazebo_bag, ["/scan"]))).msg
    assert len(first["ranges"].split()) == len(scan.ranges) == 360


def test_parquet_keeps_arrays_as_lists(twin_bag: Path, tmp_path: Path) -> None:
    proc = run_twin(
        "bag", "export", str(twin_bag), "--topics", "/ground_truth/odom", "--format", "parquet", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stderr
    table = pq.read_table(tmp_path / "ground_truth_odom.parquet").to_pydict()
    msgs = list(read_messages(twin_bag, ["/ground_truth/odom"]))
    assert table["pose.pose.position.y"] == [m.msg.pose.pose.position.y for m in msgs]
    assert table["twist.covariance"][0] == pytest.approx(list(msgs[0].msg.twist.covariance))


def test_unknown_topic_is_one_line_exit_5(twin_bag: Path, tmp_path: Path) -> None:
    proc = run_twin("bag", "export", str(twin_bag), "--topics", "/nope", "--out", str(tmp_path))
    assert proc.returncode == 5
    assert len(proc.stderr.strip().splitlines()) == 1 and "/nope" in proc.stderr
