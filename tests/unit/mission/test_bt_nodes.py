"""The thesis's mission nodes and trees, driven by a scripted navigator."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest

from twin.bt import BehaviorTreeFactory, ManualClock, NodeStatus, TickError
from twin.core.errors import ConfigError
from twin.mission.bt_nodes import (
    NavigationStatus,
    Pose2D,
    ScriptedNavigator,
    load_locations,
    register_mission_nodes,
)

TREES = Path(__file__).resolve().parents[3] / "trees"
LOCATIONS = TREES / "sim_house_locations.yaml"
TICK_NS = 500_000_000


def mission(tree_file: str, *, seed: int = 0, polls: int = 2, failing=(), location_file: Path | None = LOCATIONS):
    factory = BehaviorTreeFactory()
    navigator = ScriptedNavigator(polls_to_arrive=polls, failing_goals=failing)
    register_mission_nodes(factory, navigator=navigator, rng=random.Random(seed))
    clock = ManualClock()
    tree = factory.create_tree_from_file(TREES / tree_file, clock=clock)
    if location_file is not None:
        tree.root_blackboard.set("location_file", str(location_file))
    return tree, navigator, clock


def run(tree, clock, max_ticks: int = 100) -> list[NodeStatus]:
    statuses = []
    for _ in range(max_ticks):
        status = tree.tick_once()
        statuses.append(status)
        if status.is_completed:
            break
        clock.advance(TICK_NS)
    return statuses


def test_the_location_file_holds_the_four_house_locations() -> None:
    locations = load_locations(LOCATIONS)
    assert list(locations) == ["location1", "location2", "location3", "location4"]
    assert locations["location2"] == Pose2D(0.5, 4.0, 0.785)


def test_a_malformed_location_file_names_file_and_key(tmp_path: Path) -> None:
    bad = tmp_path / "locations.yaml"
    bad.write_text("kitchen: [1.0, 2.0]\n")
    with pytest.raises(ConfigError, match="locations.yaml:1"):
        load_locations(bad)


def test_the_thesis_tree_visits_the_four_locations_in_order_in_the_map_frame() -> None:
    tree, navigator, clock = mission("tree.xml")
    statuses = run(tree, clock)
    assert statuses[-1] is NodeStatus.SUCCESS
    assert [pose for pose, _ in navigator.goals] == list(load_locations(LOCATIONS).values())
    assert {frame for _, frame in navigator.goals} == {"map"}


def test_the_thesis_tree_fails_when_a_goal_fails() -> None:
    tree, navigator, clock = mission("tree.xml", failing=[1])
    assert run(tree, clock)[-1] is NodeStatus.FAILURE
    assert len(navigator.goals) == 2


def test_the_queue_tree_visits_every_location_in_a_seeded_order_then_fails_by_design() -> None:
    orders = []
    for seed in (1, 1, 2):
        tree, navigator, clock = mission("nav_tree_queue.xml", seed=seed)
        assert run(tree, clock)[-1] is NodeStatus.FAILURE
        orders.append([pose for pose, _ in navigator.goals])
    assert orders[0] == orders[1]
    assert sorted(orders[0]) == sorted(load_locations(LOCATIONS).values())
    assert orders[0] != orders[2]


def test_the_retry_tree_stops_at_the_first_reachable_location() -> None:
    tree, navigator, clock = mission("queue_first_reachable.xml", failing=[0])
    assert run(tree, clock)[-1] is NodeStatus.SUCCESS
    assert len(navigator.goals) == 2


def test_set_locations_fails_without_a_location_file() -> None:
    tree, navigator, _ = mission("nav_tree_queue.xml", location_file=None)
    assert tree.tick_once() is NodeStatus.FAILURE
    assert navigator.goals == []


def test_go_to_pose_reports_an_unknown_location(tmp_path: Path) -> None:
    other = tmp_path / "other.yaml"
    other.write_text("dock: [0.0, 0.0, 0.0]\n")
    tree, _, _ = mission("tree.xml", location_file=other)
    with pytest.raises(TickError, match=r"unknown location 'location1' \(the locations are dock"):
        tree.tick_once()


def test_a_halted_go_to_pose_does_not_cancel_its_goal() -> None:
    class Recording(ScriptedNavigator):
        cancelled = False

        def cancel(self) -> None:  # a navigator may offer it; GoToPose must not call it
            self.cancelled = True

    factory = BehaviorTreeFactory()
    navigator = Recording(polls_to_arrive=10)
    register_mission_nodes(factory, navigator=navigator, rng=random.Random(0))
    xml = (
        '<root BTCPP_format="4"><BehaviorTree ID="M"><ReactiveSequence>'
        '<ScriptCondition code="go == 1"/><GoToPose name="g" loc="location1"/>'
        "</ReactiveSequence></BehaviorTree></root>"
    )
    tree = factory.create_tree_from_text(xml)
    tree.root_blackboard.set("location_file", str(LOCATIONS))
    tree.root_blackboard.set("go", 1)
    assert tree.tick_once() is NodeStatus.RUNNING
    tree.root_blackboard.set("go", 0)
    assert tree.tick_once() is NodeStatus.FAILURE
    assert not navigator.cancelled
    assert navigator.goal_status(0) is NavigationStatus.RUNNING


def test_scripted_navigator_counts_polls() -> None:
    navigator = ScriptedNavigator(polls_to_arrive=2, failing_goals=[1])
    first = navigator.send_goal(Pose2D(0.0, 0.0, math.pi), "map")
    assert [navigator.goal_status(first) for _ in range(2)] == [NavigationStatus.RUNNING, NavigationStatus.SUCCEEDED]
    second = navigator.send_goal(Pose2D(1.0, 0.0, 0.0), "map")
    navigator.goal_status(second)
    assert navigator.goal_status(second) is NavigationStatus.FAILED
