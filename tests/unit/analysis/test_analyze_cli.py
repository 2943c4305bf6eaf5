"""`twin analyze BAG`: exit 0 and a report whose numbers match the raw messages, on real and twin bags."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import shutil
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.bag.small_bags import edit_topics, small_bag
from twin.bag import Recorder, open_bag, read_messages


def _analyze(bag: Path, out: Path, *extra: str) -> dict:
    proc = run_twin("analyze", str(bag), "--out", str(out), "--json", *extra)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _odom_path_length(bag: Path, topic: str) -> float:
    xy = [(m.msg.pose.pose.position.x, m.msg.pose.pose.position.y) for m in read_messages(bag, [topic])]
    return sum(math.dist(a, b) for a, b in itertools.pairwise(xy))


def test_real_gazebo_bag_reports_its_path_and_health(gazebo_bag: Path, tmp_path: Path) -> None:
    report = _analyze(gazebo_bag, tmp_path / "r")
    assert report["metrics"]["path_length_m"] == pytest.approx(_odom_path_length(gazebo_bag, "/odom"), rel=1e-9)
    health = {h["topic"]: h for h in report["topic_health"]}
    assert health["/odom"]["count"] == 826
    assert health["/performance_metrics"]["decodable"] is False  # gazebo_msgs is in no type store
    # The record times are wall clock and the stamps sim time: the offset is the epoch, and says so.
    assert health["/odom"]["stamp_offset_mean_s"] > 1.7e9
    sections = {s["name"]: s for s in report["sections"]}
    assert sections["map"]["available"] and sections["velocity"]["available"]
    assert not sections["timeline"]["available"] and "/behavior_tree_log" in sections["timeline"]["needs"]
    assert not sections["localization"]["available"]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_twin_default_bag_in_both_storages(storage: str, twin_bag: Path, twin_bag_sqlite: Path, tmp_path: Path) -> None:
    bag = twin_bag if storage == "mcap" else twin_bag_sqlite
    report = _analyze(bag, tmp_path / "r")
    assert report["summary"]["storage"] == storage
    m = report["metrics"]
    assert m["path_length_m"] == pytest.approx(_odom_path_length(bag, "/ground_truth/odom"), rel=1e-9)
    assert m["goals_succeeded"] >= 1
    assert all(s["available"] for s in report["sections"])
    health = {h["topic"]: h for h in report["topic_health"]}
    assert health["/imu"]["rate_hz"] == pytest.approx(200.0, rel=1e-6)
    assert health["/imu"]["gaps_over_3_periods"] == 0
    assert health["/imu"]["non_monotonic_stamps"] == 0
    assert health["/scan"]["count"] == open_bag(bag).topic("/scan").message_count


def _fixture_bags() -> list[Path]:
    from tests.conftest import FIXTURES

    return sorted(p for p in (FIXTURES / "bags").iterdir() if (p / "metadata.yaml").exists())


@pytest.mark.parametrize("bag", _fixture_bags(), ids=lambda p: p.name)
def test_every_fixture_bag_analyzes(bag: Path, tmp_path: Path) -> None:
    report = _analyze(bag, tmp_path / "r")
    assert report["summary"]["messages"] == open_bag(bag).message_count
    assert any(s["available"] for s in report["sections"])


def test_jazzy_bag_metadata_version_9(tmp_path: Path) -> None:
    bag = tmp_path / "jazzy"
    proc = run_twin("simulate", "--duration", "5", "--distro", "jazzy", "--out", str(bag))
    assert proc.returncode == 0, proc.stderr
    report = _analyze(bag, tmp_path / "r")
    assert report["summary"]["metadata_version"] == 9
    assert report["metrics"]["path_length_m"] == pytest.approx(_odom_path_length(bag, "/ground_truth/odom"), rel=1e-9)


def test_report_files_are_self_contained(twin_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "r"
    report = _analyze(twin_bag, out)
    names = {p.name for p in out.iterdir()}
    assert {"report.md", "report.json", "report.html", "map.png", "velocity.png", "timeline.png"} <= names
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == sum(1 for s in report["sections"] if s["plot"])
    assert 'src="http' not in page and "<script" not in page
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (out / "report.md").read_text()
    assert "go_to_location1" in md and "| /imu |" in md


def test_terminal_summary_names_the_metrics(gazebo_bag: Path, tmp_path: Path) -> None:
    proc = run_twin("analyze", str(gazebo_bag), "--out", str(tmp_path / "r"))
    assert proc.returncode == 0, proc.stderr
    assert "path length" in proc.stdout and "report.html" in proc.stdout
    assert "needs /behavior_tree_log" in proc.stdout


def _copy_topics(src: Path, dst: Path, topics: list[str]) -> Path:
    info = open_bag(src)
    with Recorder(dst) as rec:
        handles = {t: rec.add_topic(t, info.topic(t).msgtype) for t in topics}
        for m in read_messages(src, topics, decode=False):
            rec.write(handles[m.topic], m.t_ns, m.msg)
    return dst


def test_bag_with_missing_topics_degrades_per_section(twin_bag: Path, tmp_path: Path) -> None:
    bag = _copy_topics(twin_bag, tmp_path / "odom_only", ["/odom", "/clock"])
    report = _analyze(bag, tmp_path / "r")
    sections = {s["name"]: s for s in report["sections"]}
    assert sections["map"]["available"]
    assert sections["velocity"]["available"]
    for name, needs in (("clearance", "/scan"), ("timeline", "/behavior_tree_log"), ("localization", "/ground_truth")):
        assert not sections[name]["available"]
        assert needs in sections[name]["needs"]
    m = report["metrics"]
    assert m["path_length_m"] == pytest.approx(_odom_path_length(bag, "/odom"), rel=1e-9)
    assert m["min_lidar_range_m"] is None and m["outcome"] == "unknown"


def test_bag_with_no_pose_at_all_still_reports(twin_bag: Path, tmp_path: Path) -> None:
    bag = _copy_topics(twin_bag, tmp_path / "imu_only", ["/imu"])
    report = _analyze(bag, tmp_path / "r")
    assert report["metrics"]["path_length_m"] is None
    assert {h["topic"] for h in report["topic_health"]} == {"/imu"}


def _one_line_error(proc: object, code: int = 5) -> str:
    assert proc.returncode == code, proc.stderr  # type: ignore[attr-defined]
    lines = proc.stderr.strip().splitlines()  # type: ignore[attr-defined]
    assert len(lines) == 1, proc.stderr  # type: ignore[attr-defined]
    assert "Traceback" not in proc.stderr  # type: ignore[attr-defined]
    return lines[0]


def test_truncated_bag_is_one_line_suggesting_recover(twin_bag: Path, tmp_path: Path) -> None:
    bag = tmp_path / "cut"
    shutil.copytree(twin_bag, bag)
    (storage_file,) = [p for p in bag.iterdir() if p.suffix in (".mcap", ".db3")]
    os.truncate(storage_file, storage_file.stat().st_size // 2)
    line = _one_line_error(run_twin("analyze", str(bag), "--out", str(tmp_path / "r")))
    assert "twin bag recover" in line


def test_a_damaged_sqlite3_file_is_one_line_naming_recover_which_keeps_what_still_reads(
    twin_bag_sqlite: Path, tmp_path: Path
) -> None:
    # A sqlite3 file cut short: SQLite calls it malformed. `twin bag recover` copies the rows that
    # still read (a quarter cut off keeps most), or says in one line that none does.
    bag = tmp_path / "cut"
    shutil.copytree(twin_bag_sqlite, bag)
    (storage_file,) = [p for p in bag.iterdir() if p.suffix == ".db3"]
    total = open_bag(bag).message_count
    os.truncate(storage_file, storage_file.stat().st_size * 3 // 4)
    line = _one_line_error(run_twin("analyze", str(bag), "--out", str(tmp_path / "r")))
    assert "malformed" in line and f"`twin bag recover {bag}` keeps the rows that still read" in line
    recovered = run_twin("bag", "recover", str(bag))
    assert recovered.returncode == 0, recovered.stderr
    assert 0 < open_bag(bag).message_count < total
    assert _analyze(bag, tmp_path / "r2")["metrics"]["duration_s"] > 0


def test_an_unsupported_serialization_format_is_one_line_without_a_recover_hint(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    edit_topics(bag, lambda t: dataclasses.replace(t, serialization_format="json"))
    line = _one_line_error(run_twin("analyze", str(bag), "--out", str(tmp_path / "r")))
    assert "not supported" in line and "recover" not in line


def test_a_folder_without_any_bag_file_is_one_line_without_a_recover_hint(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    line = _one_line_error(run_twin("analyze", str(tmp_path / "empty"), "--out", str(tmp_path / "r")))
    assert "not a bag folder" in line and "recover" not in line


def test_folder_without_metadata_is_one_line(twin_bag: Path, tmp_path: Path) -> None:
    bag = tmp_path / "nometa"
    shutil.copytree(twin_bag, bag)
    (bag / "metadata.yaml").unlink()
    line = _one_line_error(run_twin("analyze", str(bag)))
    assert "metadata.yaml" in line and "twin bag recover" in line
