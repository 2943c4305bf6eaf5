"""Provenance and reproduction: the bag says which scenario, version, seed and FMU binaries made it
(`twin bag info` shows it), and `twin simulate --from-bag` re-runs it to the same messages."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader

from tests.conftest import REPO, run_twin
from twin.bag import read_provenance
from twin.cosim.build import resolve_fmu


def _messages(bag: Path) -> list[tuple[str, int, bytes]]:
    with Reader(bag) as reader:
        return [(con.topic, t, bytes(raw)) for con, t, raw in reader.messages()]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_from_bag_reproduces_the_default_run_byte_for_byte(storage: str, tmp_path: Path) -> None:
    first, again = tmp_path / "first", tmp_path / "again"
    result = run_twin(
        "simulate", str(REPO / "scenarios" / "default.yaml"), "--duration", "8", "--storage", storage, "--seed", "7",
        "--out", str(first),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    provenance = read_provenance(first)
    assert provenance is not None
    assert provenance["seed"] == "7" and provenance["duration_s"] == "8.0"
    assert "name: house_waffle" in provenance["scenario_yaml"]
    assert f"storage: {storage}" in provenance["scenario_yaml"]
    (fmu,) = json.loads(provenance["fmus"])
    built = resolve_fmu("builtin:xm430_w210_servo")
    assert fmu["file"] == built.name and fmu["model_name"] == "DcMotorWheel"
    assert len(fmu["sha256"]) == 64 and fmu["guid"].startswith("{")

    result = run_twin("simulate", "--from-bag", str(first), "--out", str(again))
    assert result.returncode == 0, result.stderr
    assert "differ" not in result.stderr
    a, b = _messages(first), _messages(again)
    assert len(a) > 3000
    assert a == b


def test_bag_info_shows_the_provenance(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    assert run_twin("simulate", "--duration", "1", "--out", str(bag)).returncode == 0
    result = run_twin("bag", "info", str(bag))
    assert result.returncode == 0, result.stderr
    assert "Twin provenance:   twin " in result.stdout and "seed 0, duration 1.0 s" in result.stdout
    assert "scenario house_waffle" in result.stdout
    assert "model DcMotorWheel | GUID {" in result.stdout and "SHA-256 " in result.stdout
    as_json = json.loads(run_twin("bag", "info", str(bag), "--json").stdout)
    assert as_json["provenance"]["seed"] == "0"


def test_from_bag_of_a_bag_without_provenance_is_one_clear_error(tmp_path: Path) -> None:
    result = run_twin("simulate", "--from-bag", "/work/shared/fixtures/bags/tb3_waffle_gazebo_humble")
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "has no twin provenance" in result.stderr
