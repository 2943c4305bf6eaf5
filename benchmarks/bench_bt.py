"""Speed of the behaviour-tree engine (twin.bt); prints JSON.

* `nav2_default_tree`: Nav2's default navigate-to-pose tree (18 nodes; trees/navigate_to_pose_...)
  with Python stand-in leaves, in steady state: the path is replanned at 1 Hz of simulated time
  and FollowPath is RUNNING, ticked at Nav2's bt_loop_duration (10 ms).
* `nav2_recovery_cycle`: the same tree while FollowPath keeps failing, so every tick walks the
  recovery branch (clear costmaps, spin, wait, back up in turn).
* `tree_200`: a 201-node tree whose every node is ticked and reset on each tick (a ReactiveSequence
  of 40 sequences of 4 conditions, then a RUNNING action): a worst case for per-node cost.
* `thesis_mission`: the thesis's tree.xml at 2 Hz (its autonomy node's 500 ms timer) while a goal is
  being navigated, with a status buffer attached as the bag recorder will attach one. Its cost
  per simulated second is compared with the whole-run budget of 10 ms of CPU per simulated second.

Usage: python benchmarks/bench_bt.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import platform
import random
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from twin.bt import (  # noqa: E402
    BehaviorTreeFactory,
    ConditionNode,
    ManualClock,
    NodeKind,
    NodeStatus,
    StatefulActionNode,
    SyncActionNode,
    Tree,
)
from twin.bt.log import StatusChangeBuffer  # noqa: E402
from twin.mission.bt_nodes import NavigationStatus, Pose2D, register_mission_nodes  # noqa: E402
from twin.nav.bt_navigator.factory import nav2_factory  # noqa: E402
from twin.nav.bt_navigator.tree_nodes import NAV2_LEAVES  # noqa: E402

TREES = REPO / "trees"
BUDGET_MS_PER_SIM_S = 10.0


class Instant(SyncActionNode):
    """A stand-in action that succeeds at once (clearing a costmap, planning a path)."""

    def tick(self) -> NodeStatus:
        return NodeStatus.SUCCESS


class Busy(StatefulActionNode):
    """A stand-in action that keeps running (following a path)."""

    def on_start(self) -> NodeStatus:
        return NodeStatus.RUNNING

    def on_running(self) -> NodeStatus:
        return NodeStatus.RUNNING


class Failing(StatefulActionNode):
    """A stand-in action that runs one tick, then fails."""

    def on_start(self) -> NodeStatus:
        return NodeStatus.RUNNING

    def on_running(self) -> NodeStatus:
        return NodeStatus.FAILURE


class No(ConditionNode):
    """A condition that is false (the goal was not updated)."""

    def tick(self) -> NodeStatus:
        return NodeStatus.FAILURE


class Yes(ConditionNode):
    """A condition that holds."""

    def tick(self) -> NodeStatus:
        return NodeStatus.SUCCESS


def with_ports(cls: type, node_id: str) -> type:
    ports = NAV2_LEAVES[node_id][1]
    return type(node_id, (cls,), {"provided_ports": classmethod(lambda c: ports)})


def nav2_tree(follow: type) -> tuple[Tree, ManualClock]:
    factory = nav2_factory()
    roles = {"ComputePathToPose": Instant, "FollowPath": follow, "GoalUpdated": No}
    for node_id, (kind, _) in NAV2_LEAVES.items():
        factory.unregister(node_id)
        cls = roles.get(node_id, No if kind is NodeKind.CONDITION else Instant)
        factory.register_node_type(with_ports(cls, node_id), node_id)
    clock = ManualClock()
    tree = factory.create_tree_from_file(TREES / "navigate_to_pose_w_replanning_and_recovery.xml", clock=clock)
    return tree, clock


def tree_200() -> tuple[Tree, ManualClock]:
    factory = BehaviorTreeFactory()
    factory.register_node_type(Yes, "Yes")
    factory.register_node_type(Busy, "Busy")
    groups = "".join(f'<Sequence name="g{i}">' + "<Yes/>" * 4 + "</Sequence>" for i in range(40))
    body = f'<ReactiveSequence name="root">{groups}<Busy/></ReactiveSequence>'
    xml = f'<root BTCPP_format="4"><BehaviorTree ID="M">{body}</BehaviorTree></root>'
    clock = ManualClock()
    return factory.create_tree_from_text(xml, clock=clock), clock


class EndlessNavigator:
    """A navigator whose goals never finish (the robot is on its way)."""

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        return 0

    def goal_status(self, goal_id: int) -> NavigationStatus:
        return NavigationStatus.RUNNING


def thesis_tree() -> tuple[Tree, ManualClock]:
    factory = BehaviorTreeFactory()
    register_mission_nodes(factory, navigator=EndlessNavigator(), rng=random.Random(0))
    clock = ManualClock()
    tree = factory.create_tree_from_file(TREES / "tree.xml", clock=clock)
    tree.root_blackboard.set("location_file", str(TREES / "sim_house_locations.yaml"))
    buffer = StatusChangeBuffer()
    tree.add_listener(buffer)
    return tree, clock


def measure(make: Callable[[], tuple[Tree, ManualClock]], period_ns: int, ticks: int, repeats: int) -> dict[str, float]:
    """Tick a fresh tree `ticks` times, `repeats` times; the best run gives the cost."""
    runs = []
    for _ in range(repeats):
        tree, clock = make()
        tree.tick_once()  # first tick: start-up, not steady state
        start = time.perf_counter()
        for _ in range(ticks):
            clock.advance(period_ns)
            tree.tick_once()
        runs.append((time.perf_counter() - start) / ticks)
    best = min(runs)
    return {
        "nodes": len(make()[0].nodes),
        "tick_period_ms": period_ns / 1e6,
        "us_per_tick": round(best * 1e6, 2),
        "us_per_tick_median": round(statistics.median(runs) * 1e6, 2),
        "ticks_per_s": round(1.0 / best),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer ticks (a smoke run)")
    args = parser.parse_args()
    ticks, repeats = (500, 2) if args.quick else (5000, 5)

    results: dict[str, object] = {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "nav2_default_tree": measure(lambda: nav2_tree(Busy), 10_000_000, ticks, repeats),
        "nav2_recovery_cycle": measure(lambda: nav2_tree(Failing), 10_000_000, ticks, repeats),
        "tree_200": measure(tree_200, 10_000_000, ticks, repeats),
    }
    mission = measure(thesis_tree, 500_000_000, ticks, repeats)
    mission_ms_per_sim_s = mission["us_per_tick"] * 2 / 1000.0
    mission.update(
        tick_rate_hz=2.0,
        cpu_ms_per_sim_s=round(mission_ms_per_sim_s, 4),
        share_of_10ms_budget=round(mission_ms_per_sim_s / BUDGET_MS_PER_SIM_S, 5),
    )
    results["thesis_mission"] = mission
    nav2 = results["nav2_default_tree"]
    assert isinstance(nav2, dict)
    nav2_ms_per_sim_s = nav2["us_per_tick"] * 100 / 1000.0
    results["nav2_default_tree_at_100hz"] = {
        "cpu_ms_per_sim_s": round(nav2_ms_per_sim_s, 3),
        "share_of_10ms_budget": round(nav2_ms_per_sim_s / BUDGET_MS_PER_SIM_S, 4),
    }
    tree200 = results["tree_200"]
    assert isinstance(tree200, dict)
    results["ratios"] = {
        "tree_200_vs_nav2_us_per_tick": round(tree200["us_per_tick"] / nav2["us_per_tick"], 2),
        "us_per_node_tree_200": round(tree200["us_per_tick"] / tree200["nodes"], 3),
    }
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
