"""The thesis's mission end to end: the BT.CPP tree drives the robot through the house, recorded."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin

LOCATIONS = {
    "location1": (-1.0, -0.5, -2.25),
    "location2": (0.5, 4.0, 0.785),
    "location3": (4.0, 0.5, 1.571),
    "location4": (2.75, 2.5, -1.571),
}


def read(bag: Path, *topics: str) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {t: [] for t in topics}
    with AnyReader([bag]) as reader:
        cons = [c for c in reader.connections if c.topic in topics]
        for con, t_ns, raw in reader.messages(connections=cons):
            out[con.topic].append((t_ns, reader.deserialize(raw, con.msgtype)))
    return out


@pytest.fixture(scope="module")
def thesis_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("mission") / "thesis"
    result = run_twin("simulate", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert "mission complete" in result.stdout and "0 contacts" in result.stdout
    return bag


MISSION_LOG = "/mission/behavior_tree_log"  # the thesis's tree; /behavior_tree_log is bt_navigator's (Nav2)


def test_the_thesis_tree_visits_the_four_locations_in_order(thesis_bag: Path) -> None:
    msgs = read(thesis_bag, MISSION_LOG, "/ground_truth/odom", "/rosout")
    events = [(e.node_name, e.previous_status, e.current_status) for _, m in msgs[MISSION_LOG] for e in m.event_log]
    successes = [name for name, _, new in events if new == "SUCCESS"]
    assert successes == ["go_to_location1", "go_to_location2", "go_to_location3", "go_to_location4", "sequence"]
    assert events[0] == ("sequence", "IDLE", "RUNNING")
    # Each GoToPose succeeded with the robot at its location: Nav2's goal checker takes 0.25 m and
    # 0.25 rad of the pose AMCL believes, which Nav2's filter keeps within ~0.2 m and a few degrees of
    # the truth (docs/navigation.md).
    truth = msgs["/ground_truth/odom"]
    for t_ns, msg in msgs[MISSION_LOG]:
        for e in msg.event_log:
            if e.node_name.startswith("go_to_") and e.current_status == "SUCCESS":
                x, y, yaw = LOCATIONS[e.node_name.removeprefix("go_to_")]
                pose = min(truth, key=lambda m: abs(m[0] - t_ns))[1].pose.pose
                assert math.hypot(pose.position.x - x, pose.position.y - y) < 0.25 + 0.2
                heading = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
                assert abs((heading - yaw + math.pi) % (2 * math.pi) - math.pi) < 0.25 + 0.1
    logs = [m.msg for _, m in msgs["/rosout"]]
    assert any("Finished Navigation" in line for line in logs)
    assert sum("goal reached" in line for line in logs) == 4


def test_the_tree_is_ticked_every_500_ms_of_sim_time(thesis_bag: Path) -> None:
    stamps = [t for t, _ in read(thesis_bag, MISSION_LOG)[MISSION_LOG]]
    assert stamps and all(t % 500_000_000 == 0 for t in stamps)


def test_plans_are_recorded_and_stay_in_the_house(thesis_bag: Path) -> None:
    msgs = read(thesis_bag, "/plan", "/clock")
    plans = msgs["/plan"]
    duration_s = msgs["/clock"][-1][0] / 1e9
    assert 0.6 * duration_s < len(plans) <= duration_s + 8  # replanned at 1 Hz while navigating (Nav2's tree)
    for _, plan in plans:
        assert plan.header.frame_id == "map"
        for pose in plan.poses:
            assert -1.924 < pose.pose.position.x < 6.254 and -1.462 < pose.pose.position.y < 5.112


def test_the_queue_tree_shuffles_by_seed_and_ends_in_failure_by_design(tmp_path: Path) -> None:
    orders = []
    for seed in (1, 1, 2):
        scenario = tmp_path / "queue.yaml"
        # the subject is the tree's seeded shuffle: steer on /odom, not on AMCL's estimate
        scenario.write_text(
            f"name: queue\nseed: {seed}\nlocalization: {{type: none}}\n"
            f"mission: {{tree: {REPO / 'trees' / 'nav_tree_queue.xml'}}}\n"
        )
        bag = tmp_path / f"q{len(orders)}"
        result = run_twin("simulate", str(scenario), "--out", str(bag))
        assert result.returncode == 1, result.stderr  # a failed mission exits 1 (CI tells it from a good run)
        assert "(GetLocationFromQueue) returned FAILURE" in result.stderr  # the queue ran dry
        assert "mission failed (tree FAILURE)" in result.stdout  # ended, not "complete"
        logs = [m.msg for _, m in read(bag, "/rosout")["/rosout"]]
        assert any("Navigation Failed" in line for line in logs)  # the queue empties: FAILURE, as in the demos
        orders.append([line.split("sent goal ")[1].split(" ")[0] for line in logs if "sent goal" in line])
    assert sorted(orders[0]) == sorted(LOCATIONS)
    assert orders[0] == orders[1]
    assert orders[0] != orders[2]


def test_a_tree_file_error_is_one_line_with_its_location_and_exit_6(tmp_path: Path) -> None:
    tree = tmp_path / "bad.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence><GoToPos loc="x"/></Sequence></BehaviorTree></root>\n'
    )
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"name: bad\nmission: {{tree: {tree}}}\n")
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"))
    assert result.returncode == 6
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{tree}:1" in lines[0] and "GoToPos" in lines[0], result.stderr
