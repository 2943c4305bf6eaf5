"""run_metrics against values computed here from the raw, fully decoded messages."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from twin.analysis import run_metrics
from twin.bag import read_messages


def _poses(bag: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """(stamps ns, rows x, y, yaw) decoded by rosbags."""
    stamps, rows = [], []
    for m in read_messages(bag, [topic]):
        pose = m.msg.pose.pose if hasattr(m.msg.pose, "pose") else m.msg.pose
        q = pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        stamps.append(m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec)
        rows.append((pose.position.x, pose.position.y, yaw))
    return np.array(stamps), np.array(rows)


def _path_length(rows: np.ndarray) -> float:
    return sum(math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(rows))


def _min_scan_range(bag: Path) -> float:
    best = math.inf
    for m in read_messages(bag, ["/scan"]):
        for r in m.msg.ranges:
            if m.msg.range_min <= r <= m.msg.range_max:
                best = min(best, float(r))
    return best


def test_gazebo_bag_path_length_is_the_odometry_polyline(gazebo_bag: Path) -> None:
    m = run_metrics(gazebo_bag)
    _, rows = _poses(gazebo_bag, "/odom")
    assert m.pose_source == "/odom"
    assert m.path_length_m == pytest.approx(_path_length(rows), rel=1e-9)
    assert m.path_length_m > 4.0  # the robot drove across the TurtleBot3 world


def test_gazebo_bag_clearance_is_the_smallest_valid_beam(gazebo_bag: Path) -> None:
    m = run_metrics(gazebo_bag)
    assert m.min_lidar_range_m == pytest.approx(_min_scan_range(gazebo_bag), rel=1e-6)


def test_gazebo_bag_without_tree_log_or_truth_says_what_is_missing(gazebo_bag: Path) -> None:
    m = run_metrics(gazebo_bag)
    assert m.outcome == "unknown"
    assert m.contacts is None
    assert m.localization_error_median_m is None
    assert any("/behavior_tree_log" in n for n in m.notes)
    assert any("/ground_truth/odom" in n for n in m.notes)
    assert m.duration_s == pytest.approx(29.842068479)


def test_twin_bag_path_length_is_the_ground_truth_polyline(twin_bag: Path) -> None:
    m = run_metrics(twin_bag)
    _, rows = _poses(twin_bag, "/ground_truth/odom")
    assert m.pose_source == "/ground_truth/odom"
    assert m.path_length_m == pytest.approx(_path_length(rows), rel=1e-9)


def test_twin_bag_localization_error_matches_interpolated_truth(twin_bag: Path) -> None:
    m = run_metrics(twin_bag)
    t_ref, ref = _poses(twin_bag, "/ground_truth/odom")
    t_est, est = _poses(twin_bag, "/amcl_pose")  # AMCL's estimate, where the robot believes it is on the map
    errors = []
    for t, row in zip(t_est, est, strict=True):
        j = int(np.searchsorted(t_ref, t))
        if j == len(t_ref) or (t_ref[j] != t and j == 0):
            continue
        if t_ref[j] == t:
            rx, ry = ref[j, :2]
        else:
            f = (t - t_ref[j - 1]) / (t_ref[j] - t_ref[j - 1])
            rx, ry = ref[j - 1, :2] + f * (ref[j, :2] - ref[j - 1, :2])
        errors.append(math.hypot(row[0] - rx, row[1] - ry))
    assert m.localization_source == "/amcl_pose"
    assert m.localization_reference == "/ground_truth/odom"
    assert m.localization_error_median_m == pytest.approx(float(np.median(errors)), rel=1e-6, abs=1e-12)
    assert m.localization_error_p95_m == pytest.approx(float(np.percentile(errors, 95)), rel=1e-6, abs=1e-12)
    assert m.localization_error_max_m == pytest.approx(max(errors), rel=1e-6, abs=1e-12)


def test_twin_bag_goals_come_from_the_tree_log(twin_bag: Path) -> None:
    # the mission's tree (bt_navigator's is on /behavior_tree_log)
    m = run_metrics(twin_bag)
    changes = [
        (m_.t_ns, e.node_name, e.current_status)
        for m_ in read_messages(twin_bag, ["/mission/behavior_tree_log"])
        for e in m_.msg.event_log
    ]
    succeeded = [name for _, name, status in changes if name.startswith("go_to") and status == "SUCCESS"]
    started = [name for _, name, status in changes if name.startswith("go_to") and status == "RUNNING"]
    assert [g.name for g in m.goals] == started
    assert m.goals_succeeded == len(succeeded) >= 1
    assert m.outcome == "running"  # 20 s is shorter than the mission
    first = m.goals[0]
    end_ns = next(t for t, name, status in changes if name == first.name and status == "SUCCESS")
    assert first.duration_s == pytest.approx(end_ns * 1e-9 - first.start_s)


def test_twin_bag_counts_contacts_and_clearance(twin_bag: Path) -> None:
    m = run_metrics(twin_bag)
    begins = sum(1 for x in read_messages(twin_bag, ["/contacts"]) if x.msg.event == 1)
    assert m.contacts == begins
    assert m.min_lidar_range_m == pytest.approx(_min_scan_range(twin_bag), rel=1e-6)


def test_metrics_are_json_ready(twin_bag: Path) -> None:
    import json

    d = run_metrics(twin_bag).to_dict()
    assert json.loads(json.dumps(d))["path_length_m"] == d["path_length_m"]
    assert d["goals"][0]["duration_s"] is not None
