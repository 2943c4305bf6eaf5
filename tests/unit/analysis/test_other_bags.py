"""`twin analyze` on bags that are not the twin's: header stamps, their own rates, n/a, a plot per standard type."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_twin
from tests.unit.analysis.test_analyze_cli import _analyze, _copy_topics
from twin.analysis import _cdr
from twin.bag import Recorder, open_bag, read_messages


def test_a_bag_with_only_imu_and_joint_states_gets_their_plots(gazebo_bag: Path, tmp_path: Path) -> None:
    bag = _copy_topics(gazebo_bag, tmp_path / "imu_joints", ["/imu", "/joint_states"])
    report = _analyze(bag, tmp_path / "r")
    plotted = {s["plot"] for s in report["sections"] if s["available"] and s["plot"]}
    assert {"imu_imu.png", "joints_joint_states.png"} <= plotted
    for png in plotted:
        assert (tmp_path / "r" / png).stat().st_size > 1000


def _neato_like(gazebo_bag: Path, bag: Path) -> tuple[np.ndarray, np.ndarray]:
    """/odom stamped at a steady 20 Hz but recorded in pairs 0.4 ms apart, as a real Neato's driver writes it."""
    store = _cdr.type_store()
    template = next(iter(read_messages(gazebo_bag, ["/odom"]))).msg
    time_t = store.types["builtin_interfaces/msg/Time"]
    n = 400
    stamps = 1_000_000_000 + np.arange(n, dtype=np.int64) * 50_000_000
    t = (stamps - stamps[0]) * 1e-9
    v = 0.2 + 0.1 * np.sin(0.8 * t)
    with Recorder(bag) as rec:
        h = rec.add_topic("/odom", "nav_msgs/msg/Odometry")
        for i in range(n):
            stamp = time_t(sec=int(stamps[i] // 1_000_000_000), nanosec=int(stamps[i] % 1_000_000_000))
            twist = dataclasses.replace(
                template.twist.twist, linear=dataclasses.replace(template.twist.twist.linear, x=float(v[i]))
            )
            msg = dataclasses.replace(
                template,
                header=dataclasses.replace(template.header, stamp=stamp),
                twist=dataclasses.replace(template.twist, twist=twist),
            )
            recorded = int(stamps[i - i % 2]) + (i % 2) * 400_000 + 30_000_000  # bunched pairs
            rec.write(h, recorded, bytes(store.serialize_cdr(msg, "nav_msgs/msg/Odometry")))
    return t, v


def test_jerk_comes_from_header_stamps_when_records_bunch_up(gazebo_bag: Path, tmp_path: Path) -> None:
    t, v = _neato_like(gazebo_bag, tmp_path / "neato")
    a = np.diff(v) / np.diff(t)
    j = np.diff(a) / np.diff(0.5 * (t[1:] + t[:-1]))
    by_hand = math.sqrt(float(np.mean(j * j)))
    report = _analyze(tmp_path / "neato", tmp_path / "r")
    jerk = report["metrics"]["rms_jerk_mps3"]
    assert by_hand / 2 <= jerk <= 2 * by_hand, (jerk, by_hand)


def test_another_robots_rates_are_not_judged_by_the_twins(gazebo_bag: Path, tmp_path: Path) -> None:
    _neato_like(gazebo_bag, tmp_path / "neato")  # /odom at 20 Hz: the twin publishes it at 30
    report = _analyze(tmp_path / "neato", tmp_path / "r")
    (odom,) = [h for h in report["topic_health"] if h["topic"] == "/odom"]
    assert odom["expected_rate_hz"] is None
    # judged against its own steady rate, read from its stamps: the bunched records look aperiodic
    assert odom["steady_rate_hz"] == pytest.approx(20.0)
    assert odom["gaps_over_3_periods"] == 0
    md = (tmp_path / "r" / "report.md").read_text()
    assert "expected 30" not in md and "20.0 (steady)" in md


def test_the_twins_own_bag_is_judged_by_its_nominal_rates(twin_bag: Path, tmp_path: Path) -> None:
    report = _analyze(twin_bag, tmp_path / "r")
    (odom,) = [h for h in report["topic_health"] if h["topic"] == "/odom"]
    assert odom["expected_rate_hz"] == 30.0
    assert odom["steady_rate_hz"] == pytest.approx(30.0, rel=0.02)  # 33 or 34 ms on the 1 ms step


def test_a_twin_bag_is_judged_by_the_rates_its_own_scenario_set(tmp_path: Path) -> None:
    # The lidar at 10 Hz (sensors.lidar.rate_hz): its /scan is expected at 10, not at the model's 5.
    scenario = tmp_path / "fast_lidar.yaml"
    scenario.write_text("name: fast_lidar\nsensors:\n  lidar: {rate_hz: 10.0}\n")
    proc = run_twin("simulate", str(scenario), "--duration", "4", "--out", str(tmp_path / "bag"))
    assert proc.returncode == 0, proc.stderr
    report = _analyze(tmp_path / "bag", tmp_path / "r")
    health = {h["topic"]: h for h in report["topic_health"]}
    assert health["/scan"]["expected_rate_hz"] == 10.0
    assert health["/scan"]["steady_rate_hz"] == pytest.approx(10.0, rel=0.02)
    assert (health["/imu"]["expected_rate_hz"], health["/odom"]["expected_rate_hz"]) == (200.0, 30.0)
    assert "expected 5" not in (tmp_path / "r" / "report.md").read_text()


def test_goals_are_na_without_a_tree(gazebo_bag: Path, tmp_path: Path) -> None:
    report = _analyze(gazebo_bag, tmp_path / "r")
    assert report["metrics"]["goals_succeeded"] is None and report["metrics"]["recoveries"] is None
    md = (tmp_path / "r" / "report.md").read_text()
    assert "| goals succeeded | n/a |" in md


def test_html_report_shows_names_as_they_are(gazebo_bag: Path, tmp_path: Path) -> None:
    _analyze(gazebo_bag, tmp_path / "r")
    page = (tmp_path / "r" / "report.html").read_text()
    assert "/ground_truth/odom" in page and "/behavior_tree_log" in page
    assert "ground truth" not in page and "behavior tree log" not in page
    assert open_bag(gazebo_bag).topic("/odom") is not None
