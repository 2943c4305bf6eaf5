"""A metadata.yaml naming the wrong type for a topic: the storage's own type wins, with one warning.

The MCAP schema or the sqlite3 topics table says what the messages were written as; metadata.yaml
is a copy that can go wrong (edited by hand, written by another tool). Trusting it read such a topic
as no message at all: `bag export` wrote 0 rows and exited 0, `play` dropped the topics without
naming them, `ekf replay` found no IMU and no joint states.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import shutil
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.bag.small_bags import edit_topics
from twin.bag import open_bag

#: Each topic's wrong type in metadata.yaml (the storage keeps the right one).
WRONG = {
    "/odom": "geometry_msgs/msg/Twist",
    "/imu": "sensor_msgs/msg/JointState",
    "/joint_states": "sensor_msgs/msg/Imu",
}


@pytest.fixture(scope="module", params=["mcap", "sqlite3"])
def retyped(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    """A 5 s run whose metadata.yaml names wrong types for /odom, /imu and /joint_states; and its true counts."""
    root = tmp_path_factory.mktemp(f"retyped_{request.param}")
    bag = root / "run"
    proc = run_twin("simulate", "--duration", "5", "--storage", request.param, "--out", str(bag), "-q")
    assert proc.returncode == 0, proc.stderr
    counts = {t.name: t.message_count for t in open_bag(bag).topics}
    edit_topics(bag, lambda t: dataclasses.replace(t, msgtype=WRONG.get(t.name, t.msgtype)))
    return bag, counts


def _one_warning_per_topic(stderr: str, topics: list[str]) -> None:
    for topic in topics:
        lines = [line for line in stderr.splitlines() if "WARNING" in line and f" {topic}'s type " in line]
        assert len(lines) == 1, stderr
        assert WRONG[topic] in lines[0] and "the storage's" in lines[0], lines[0]
    assert "Traceback" not in stderr


def test_bag_export_reads_the_storage_type(retyped: tuple[Path, dict[str, int]], tmp_path: Path) -> None:
    bag, counts = retyped
    proc = run_twin("bag", "export", str(bag), "--topics", "/odom", "--out", str(tmp_path / "csv"))
    assert proc.returncode == 0, proc.stderr
    assert f"/odom: {counts['/odom']} rows" in proc.stdout
    with (tmp_path / "csv" / "odom.csv").open() as f:
        header = next(csv.reader(f))
    assert "pose.pose.position.x" in header  # Odometry's columns, not Twist's
    _one_warning_per_topic(proc.stderr, ["/odom"])


def test_play_serves_the_retyped_topics(retyped: tuple[Path, dict[str, int]]) -> None:
    bag, counts = retyped
    proc = run_twin("play", str(bag), "--speed", "max", "--port", "0")
    assert proc.returncode == 0, proc.stderr
    played = re.search(r"played (\d+) messages on (\d+) topics", proc.stdout)
    assert played is not None, proc.stdout
    assert int(played.group(1)) == sum(counts.values())
    assert "not served" not in proc.stdout + proc.stderr
    _one_warning_per_topic(proc.stderr, list(WRONG))


def test_ekf_replay_fuses_the_retyped_imu_and_joint_states(
    retyped: tuple[Path, dict[str, int]], tmp_path: Path
) -> None:
    bag, counts = retyped
    proc = run_twin("ekf", "replay", str(bag), "--out", str(tmp_path / "ekf"), "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["joint_states"] == counts["/joint_states"]
    assert out["imu_samples"] == counts["/imu"] and out["gyro_fused"]
    _one_warning_per_topic(proc.stderr, ["/imu", "/joint_states"])


def test_bag_info_shows_the_storage_type(retyped: tuple[Path, dict[str, int]]) -> None:
    bag, _ = retyped
    info = {t.name: t for t in open_bag(bag).topics}
    assert info["/odom"].msgtype == "nav_msgs/msg/Odometry" and info["/odom"].decodable
    assert info["/imu"].msgtype == "sensor_msgs/msg/Imu"


def test_recover_rewrites_the_wrong_type_from_the_storage(retyped: tuple[Path, dict[str, int]], tmp_path: Path) -> None:
    """`recover` does not call such a bag complete: it writes the storage's types, the original kept beside."""
    bag, _ = retyped
    copy = tmp_path / "copy"
    shutil.copytree(bag, copy)
    proc = run_twin("bag", "recover", str(copy))
    assert proc.returncode == 0, proc.stderr
    assert "type: nav_msgs/msg/Odometry" in (copy / "metadata.yaml").read_text()
    assert "type: geometry_msgs/msg/Twist" in (copy / "metadata.yaml.orig").read_text()
