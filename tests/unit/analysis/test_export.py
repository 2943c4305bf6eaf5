"""`twin bag export`: one table per topic, ROS field paths as columns, values as decoded."""

from __future__ import annotations

import csv
import dataclasses
import json
import sqlite3
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.conftest import run_twin
from tests.unit.bag.small_bags import (
    COUNT,
    LEGACY_TYPE,
    edit_metadata,
    edit_topics,
    legacy_type_bag,
    message_compressed_bag,
    small_bag,
    storage_file,
)
from twin.analysis.export import export_topics
from twin.bag import OdometryEncoder, Recorder, open_bag, read_messages
from twin.core.errors import BagError


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


def test_parquet_takes_a_sequence_of_messages_empty_in_some_rows_as_json_text(gazebo_bag: Path, tmp_path: Path) -> None:
    # The real Humble bag's /parameter_events: new_parameters is [] in one event and a list in another
    # (it was an ArrowTypeError, exit 70: a list column, then text).
    proc = run_twin(
        "bag", "export", str(gazebo_bag), "--topics", "/parameter_events", "--format", "parquet", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stderr
    table = pq.read_table(tmp_path / "parameter_events.parquet").to_pydict()
    events = [m.msg for m in read_messages(gazebo_bag, ["/parameter_events"])]
    exported = [json.loads(v) for v in table["new_parameters"]]
    assert [[p["name"] for p in row] for row in exported] == [[p.name for p in e.new_parameters] for e in events]
    assert [[p["value"]["type"] for p in row] for row in exported] == [
        [p.value.type for p in e.new_parameters] for e in events
    ]
    assert any(e.new_parameters for e in events) and any(not e.new_parameters for e in events)


def test_unknown_topic_is_one_line_exit_5(twin_bag: Path, tmp_path: Path) -> None:
    proc = run_twin("bag", "export", str(twin_bag), "--topics", "/nope", "--out", str(tmp_path))
    assert proc.returncode == 5
    assert len(proc.stderr.strip().splitlines()) == 1 and "/nope" in proc.stderr


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_failed_export_leaves_no_file_behind(tmp_path: Path, fmt: str) -> None:
    bag = message_compressed_bag(tmp_path / "bag")  # then described as uncompressed: nothing decodes
    edit_metadata(bag, lambda meta: dataclasses.replace(meta, compression_format="", compression_mode=""))
    out = tmp_path / "tables"
    with pytest.raises(BagError, match="does not parse"):
        export_topics(bag, ["/chatter", "/odom"], out, fmt=fmt)
    assert list(out.iterdir()) == []


def test_an_empty_topic_gets_a_csv_with_its_header_row(tmp_path: Path) -> None:
    with Recorder(tmp_path / "bag") as rec:
        rec.add_topic("/odom", OdometryEncoder.msgtype)  # offered, never published
    full = small_bag(tmp_path / "full")
    written = export_topics(tmp_path / "bag", ["/odom"], tmp_path / "empty")
    export_topics(full, ["/odom"], tmp_path / "full_tables")
    assert written == {"/odom": (tmp_path / "empty" / "odom.csv", 0)}
    lines = (tmp_path / "empty" / "odom.csv").read_text().splitlines()
    assert lines == (tmp_path / "full_tables" / "odom.csv").read_text().splitlines()[:1]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_legacy_type_name_exports_as_info_says_it_decodes(tmp_path: Path, storage: str) -> None:
    bag = legacy_type_bag(tmp_path / "bag", storage=storage)
    (topic,) = open_bag(bag).topics
    assert (topic.msgtype, topic.decodable) == (LEGACY_TYPE, True)
    written = export_topics(bag, ["/reading"], tmp_path / "tables")
    assert written["/reading"][1] == COUNT
    with (tmp_path / "tables" / "reading.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(float(r["value"]), r["label"]) for r in rows] == [(1.5 * k, f"r{k}") for k in range(COUNT)]


def test_exporting_an_undecodable_topic_says_what_the_user_can_do(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag", storage="sqlite3")
    with sqlite3.connect(storage_file(bag)) as db:  # a type whose definition is nowhere
        db.execute("UPDATE topics SET type = 'mystery_msgs/msg/Thing' WHERE name = '/chatter'")
    edit_topics(bag, lambda t: dataclasses.replace(t, msgtype="mystery_msgs/msg/Thing") if t.name == "/chatter" else t)
    proc = run_twin("bag", "export", str(bag), "--topics", "/chatter", "/odom", "--out", str(tmp_path / "t"))
    assert proc.returncode == 5 and proc.stderr.count("\n") == 1, proc.stderr
    assert "/chatter (mystery_msgs/msg/Thing)" in proc.stderr and "export the other topics" in proc.stderr
    assert "decode=False" not in proc.stderr


def test_ekf_replay_takes_wheel_geometry_from_the_bags_urdf_and_says_so(gazebo_bag: Path, tmp_path: Path) -> None:
    import json

    proc = run_twin("ekf", "replay", str(gazebo_bag), "--out", str(tmp_path / "e"), "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    # turtlebot3_waffle_pi.urdf: wheel joints at y = +-0.144 m, tyre cylinders of radius 0.033 m.
    assert s["wheel_radius_m"] == pytest.approx(0.033)
    assert s["wheel_separation_m"] == pytest.approx(0.288)
    assert (s["left_joint"], s["right_joint"]) == ("wheel_left_joint", "wheel_right_joint")
    assert all("/robot_description" in v and "turtlebot3_waffle_pi" in v for v in s["geometry_sources"].values())


def test_ekf_replay_without_urdf_names_the_default_it_used(twin_bag: Path, tmp_path: Path) -> None:
    import json

    from tests.unit.analysis.test_analyze_cli import _copy_topics

    bag = _copy_topics(twin_bag, tmp_path / "no_urdf", ["/imu", "/joint_states", "/odom"])
    proc = run_twin("ekf", "replay", str(bag), "--out", str(tmp_path / "e"), "--wheel-separation", "0.287", "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["geometry_sources"]["wheel_separation"] == "--wheel-separation"
    assert s["geometry_sources"]["wheel_radius"] == "TurtleBot3 Waffle default (no /robot_description)"
    assert s["wheel_radius_m"] == 0.033


def test_a_message_types_constants_are_not_columns(twin_bag: Path, tmp_path: Path) -> None:
    # rcl_interfaces/Log declares DEBUG...FATAL: they were five columns of the same value in every row
    proc = run_twin("bag", "export", str(twin_bag), "--topics", "/rosout", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / "rosout.csv").open() as f:
        header = next(csv.reader(f))
    assert header[1:] == ["stamp.sec", "stamp.nanosec", "level", "name", "msg", "file", "function", "line"]
