"""Poses wherever a bag carries them: `analyze` on a real robot's topic names (`/odometry/filtered`), and
`analyze compare` on one clock (two topics of one bag, or two recordings of one run, matched on their
stamps as they are, so a topic that starts late or with an old latched message is not shifted)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.analysis.test_analyze_cli import _analyze, _odom_path_length
from twin.analysis.compare import compare_bags
from twin.bag import Recorder, open_bag, read_messages

TRUTH = "/ground_truth/odom"
LATE = "/late/odom"
SKIP_NS = 5_000_000_000  # the late topic's first message comes 5 s after the truth's


def _with_late_topic(src: Path, dst: Path, *, keep_truth: bool = True) -> Path:
    """A bag holding the truth (unless not `keep_truth`) and, as LATE, the same messages from SKIP_NS on."""
    msgtype = open_bag(src).topic(TRUTH).msgtype
    with Recorder(dst) as rec:
        truth = rec.add_topic(TRUTH, msgtype) if keep_truth else None
        late = rec.add_topic(LATE, msgtype)
        for m in read_messages(src, [TRUTH], decode=False):
            if truth is not None:
                rec.write(truth, m.t_ns, m.msg)
            if m.t_ns >= SKIP_NS:
                rec.write(late, m.t_ns, m.msg)
    return dst


def test_two_topics_of_one_bag_are_matched_on_their_stamps(twin_bag: Path, tmp_path: Path) -> None:
    bag = _with_late_topic(twin_bag, tmp_path / "late")
    result = compare_bags(bag, bag, topics=(TRUTH, LATE))
    assert len(result.t_s) > 100
    assert result.t_s[0] == pytest.approx(SKIP_NS * 1e-9, abs=0.05)  # only where both topics have poses
    assert result.max_position_error_m == 0.0  # the same poses at the same stamps
    # ... and the same twists: they were timed from each topic's own first stamp (an RMS of 0.06 m/s)
    twist = {f["field"]: f for f in result.to_dict()["field_differences"] if f["topic"] == f"{TRUTH} | {LATE}"}
    assert twist and all(f["max_abs_diff"] == 0.0 for f in twist.values()), twist
    doc = result.to_dict()  # the span and the 1 s series are the matched ones, from 5 s on
    assert doc["matched_span_s"] == pytest.approx(float(result.t_s[-1] - result.t_s[0]))
    assert doc["position_error_each_s"][0]["t_s"] == pytest.approx(float(result.t_s[0]))
    # matched from each topic's first pose instead, the late one is shifted by 5 s of driving
    shifted = compare_bags(bag, bag, topics=(TRUTH, LATE), same_clock=False)
    assert shifted.max_position_error_m > 0.05


def test_same_clock_matches_two_recordings_of_one_run(twin_bag: Path, tmp_path: Path) -> None:
    late = _with_late_topic(twin_bag, tmp_path / "late_only", keep_truth=False)
    proc = run_twin(
        "analyze", "compare", str(twin_bag), str(late), "--topic", TRUTH, LATE, "--same-clock", "--json"
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["ate_m"] == 0.0
    # without --same-clock two bags are matched from each first pose (a twin run against a real one)
    assert compare_bags(twin_bag, late, topics=(TRUTH, LATE)).max_position_error_m > 0.05


def test_a_bag_with_poses_under_other_names_is_analysed(twin_bag: Path, tmp_path: Path) -> None:
    # a real robot's names: robot_localization's output and a wheel odometry, no /odom or ground truth
    info = open_bag(twin_bag)
    names = {"/odom": "/odometry/filtered", "/amcl_pose": "/pose"}
    bag = tmp_path / "renamed"
    with Recorder(bag) as rec:
        handles = {src: rec.add_topic(dst, info.topic(src).msgtype) for src, dst in names.items()}
        for m in read_messages(twin_bag, list(names), decode=False):
            rec.write(handles[m.topic], m.t_ns, m.msg)
    report = _analyze(bag, tmp_path / "r")
    sections = {s["name"]: s for s in report["sections"]}
    assert sections["map"]["available"] and sections["velocity"]["available"]
    # the path is the Odometry topic's polyline (Odometry before other pose types)
    assert report["metrics"]["path_length_m"] == pytest.approx(_odom_path_length(bag, "/odometry/filtered"), rel=1e-9)
    # and compare takes such a topic by name
    result = compare_bags(twin_bag, bag, topics=("/odom", "/odometry/filtered"))
    assert result.max_position_error_m == 0.0


def test_a_bag_whose_lidar_is_not_on_scan_gets_its_clearance_from_its_one_laserscan(
    twin_bag: Path, tmp_path: Path
) -> None:
    # A Jackal's /front/scan: the clearance was "needs /scan"; with two LaserScan topics none is guessed.
    info = open_bag(twin_bag)
    expected = _analyze(twin_bag, tmp_path / "r0")["metrics"]["min_lidar_range_m"]
    assert expected is not None

    def renamed(folder: Path, names: dict[str, str]) -> Path:
        with Recorder(folder) as rec:
            handles = {src: rec.add_topic(dst, info.topic(src).msgtype) for src, dst in names.items()}
            for m in read_messages(twin_bag, list(names), decode=False):
                rec.write(handles[m.topic], m.t_ns, m.msg)
        return folder

    front = renamed(tmp_path / "front", {"/odom": "/odom", "/scan": "/front/scan"})
    report = _analyze(front, tmp_path / "r1")
    assert report["metrics"]["min_lidar_range_m"] == expected
    assert "clearance from /front/scan (the bag has no /scan)" in report["metrics"]["notes"]
    with Recorder(tmp_path / "two") as rec:  # the same scans on two topics: which is the lidar is not guessed
        front_h = rec.add_topic("/front/scan", info.topic("/scan").msgtype)
        rear_h = rec.add_topic("/rear/scan", info.topic("/scan").msgtype)
        for m in read_messages(twin_bag, ["/scan"], decode=False):
            rec.write(front_h, m.t_ns, m.msg)
            rec.write(rear_h, m.t_ns, m.msg)
    two = _analyze(tmp_path / "two", tmp_path / "r2")["metrics"]
    assert two["min_lidar_range_m"] is None
    assert "the bag has several LaserScan topics (/front/scan, /rear/scan)" in " ".join(two["notes"])
    # ... and the user names it
    chosen = _analyze(tmp_path / "two", tmp_path / "r3", "--scan-topic", "/rear/scan")["metrics"]
    assert chosen["min_lidar_range_m"] == expected
    assert "clearance from /rear/scan (the bag has no /scan)" in chosen["notes"]
    wrong = run_twin("analyze", str(tmp_path / "two"), "--out", str(tmp_path / "r4"), "--scan-topic", "/odom")
    assert wrong.returncode == 2
    assert wrong.stderr.strip().endswith("has no LaserScan topic of that name (it has: /front/scan, /rear/scan)")
