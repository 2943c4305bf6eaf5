"""`twin bag info` and `twin bag recover` as a user runs them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[3]
MixBagFactory = Callable[[str, str], Any]  # conftest.mix_bag


def twin(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "twin", *args],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_info_on_the_humble_fixture_bag(fixtures: Path) -> None:
    run = twin("bag", "info", str(fixtures / "bags" / "tb3_waffle_gazebo_humble"))
    assert run.returncode == 0, run.stderr
    out = run.stdout
    assert "Files:             rosbag_0.db3" in out
    assert "Storage id:        sqlite3" in out
    assert "Version:           5" in out
    assert "Duration:          29.842068479s" in out
    assert "Start:             Nov 29 2023 00:28:10.319080701 (1701217690.319080701)" in out
    assert "Messages:          9432" in out
    assert "Topic: /imu | Type: sensor_msgs/msg/Imu | Count: 5636 | Serialization Format: cdr" in out
    assert (
        "Topic: /tf_static | Type: tf2_msgs/msg/TFMessage | Count: 1 | Serialization Format: cdr | QoS: reliable, transient_local"
        in out
    )
    assert "No definition, cannot decode: /performance_metrics (gazebo_msgs/msg/PerformanceMetrics)" in out


def test_info_json_on_the_fixture(fixtures: Path) -> None:
    run = twin("bag", "info", str(fixtures / "bags" / "tb3_waffle_gazebo_humble"), "--json")
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout)
    assert info["version"] == 5 and info["storage"] == "sqlite3"
    assert info["duration_ns"] == 29842068479 and info["message_count"] == 9432
    topics = {t["name"]: t for t in info["topics"]}
    assert topics["/clock"]["qos"][0]["reliability"] == "best_effort"
    assert len(topics["/rosout"]["qos"]) == 3
    assert topics["/performance_metrics"]["decodable"] is False
    assert topics["/odom"]["definition"] == "type store"
    assert sum(t["message_count"] for t in info["topics"]) == 9432


@pytest.mark.parametrize(("storage", "distro"), [("mcap", "humble"), ("sqlite3", "jazzy")])
def test_info_on_twin_bags(mix_bag: MixBagFactory, storage: str, distro: str) -> None:
    bag = mix_bag(storage, distro)
    run = twin("bag", "info", str(bag.path), "--json")
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout)
    assert info["storage"] == storage and info["ros_distro"] == distro
    assert info["version"] == (8 if distro == "humble" else 9)
    assert {t["name"]: t["message_count"] for t in info["topics"]} == bag.counts
    assert all(t["definition"] == "embedded" for t in info["topics"])
    assert info["files"][0]["size_bytes"] > 0
    text = twin("bag", "info", str(bag.path))
    assert "Topic: /motor_state | Type: twin_msgs/msg/MotorState" in text.stdout


def test_bad_input_is_one_line_with_exit_code_5(tmp_path: Path) -> None:
    run = twin("bag", "info", str(tmp_path / "nope"))
    assert run.returncode == 5
    assert run.stderr.strip() == f"twin: error: {tmp_path / 'nope'}: no such bag folder or file"
    (tmp_path / "killed").mkdir()
    (tmp_path / "killed" / "killed_0.mcap").write_bytes(b"\x89MCAP0\r\n")
    run = twin("bag", "info", str(tmp_path / "killed"))
    assert run.returncode == 5 and "Traceback" not in run.stderr
    assert f"`twin bag recover {tmp_path / 'killed'}` rebuilds it" in run.stderr
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    run = twin("bag", "info", str(tmp_path / "bad"))
    assert run.returncode == 5 and run.stderr.count("\n") == 1
    assert "metadata.yaml:2: not valid YAML" in run.stderr


def test_recover_json(tmp_path: Path, mix_bag: MixBagFactory) -> None:
    import shutil

    bag = tmp_path / "copy"
    shutil.copytree(mix_bag("mcap", "humble").path, bag)
    (bag / "metadata.yaml").unlink()
    run = twin("bag", "recover", str(bag), "--json")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["storage"] == "mcap" and out["metadata_version"] == 8 and out["ros_distro"] == "humble"
    assert out["message_count"] == sum(mix_bag("mcap", "humble").counts.values())
    assert (bag / "metadata.yaml").exists()


def test_help_teaches_with_examples() -> None:
    run = twin("bag", "info", "--help")
    assert run.returncode == 0 and "examples:" in run.stdout and "--json" in run.stdout
    run = twin("bag", "recover", "--help")
    assert run.returncode == 0 and "killed" in run.stdout
