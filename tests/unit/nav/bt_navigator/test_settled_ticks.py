"""bt_navigator skips the ticks that would repeat themselves: the same statuses, calls and outcome."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.unit.nav.bt_navigator.test_leaves import ALL_TREES, TREES
from twin.bt import ManualClock, NodeStatus
from twin.nav.actions import ActionState, ActionUpdate
from twin.nav.bt_navigator.factory import nav2_factory

LOOP_NS = 10_000_000  # bt_loop_duration


class TimedServices:
    """Servers whose goals end at set simulated times, as the node graph's servers do between ticks.

    Planning answers at once; FollowPath runs `follow_s` (or fails after it, `follow_fails`);
    behaviours run 1.5 s. `step(now)` ends the goals that are due, as the servers' timers do, and
    every change a poll could see moves `generation`.
    """

    def __init__(self, clock: ManualClock, *, follow_s: float = 2.35, follow_fails: bool = False) -> None:
        self.clock = clock
        self.follow_ns = round(follow_s * 1e9)
        self.follow_fails = follow_fails
        self.pose = (0.0, 0.0, 0.0)
        self.calls: list[tuple[int, str]] = []
        self.generation = 0
        self._goals: dict[int, dict[str, Any]] = {}
        self._next = 0

    def _log(self, what: str) -> None:
        self.calls.append((self.clock(), what))

    def send_goal(self, server: str, request: Mapping[str, Any]) -> int:
        self._next += 1
        self.generation += 1
        state, result, due = ActionState.RUNNING, {}, self.clock() + 1_500_000_000
        if server in ("compute_path_to_pose", "compute_path_through_poses"):
            end = request["goal"] if server == "compute_path_to_pose" else request["goals"][-1]
            state = ActionState.SUCCEEDED
            result = {"path": np.array([[self.pose[0], self.pose[1], 0.0], [end[0], end[1], end[2]]])}
        elif server == "smooth_path":
            state, result = ActionState.SUCCEEDED, {"path": request["path"]}
        elif server == "follow_path":
            due = self.clock() + self.follow_ns
        self._goals[self._next] = {"server": server, "request": dict(request), "state": state, "result": result}
        self._goals[self._next]["due"] = due
        self._log(server)
        return self._next

    def update_goal(self, goal_id: int, request: Mapping[str, Any]) -> None:
        self.generation += 1
        self._goals[goal_id]["request"] = dict(request)
        self._log("update:" + self._goals[goal_id]["server"])

    def step(self, now_ns: int) -> None:
        for goal in self._goals.values():
            if goal["state"] is ActionState.RUNNING and now_ns >= goal["due"]:
                self.generation += 1
                if goal["server"] == "follow_path":
                    if self.follow_fails:
                        goal["state"] = ActionState.FAILED
                        continue
                    end = goal["request"]["path"][-1]
                    self.pose = (float(end[0]), float(end[1]), float(end[2]))
                goal["state"] = ActionState.SUCCEEDED

    def poll(self, goal_id: int) -> ActionUpdate:
        goal = self._goals[goal_id]
        return ActionUpdate(state=goal["state"], result=goal["result"])

    def cancel(self, goal_id: int) -> None:
        goal = self._goals[goal_id]
        if goal["state"] is ActionState.RUNNING:
            self.generation += 1
            goal["state"] = ActionState.FAILED
        self._log("cancel:" + goal["server"])

    def cancel_all(self, server: str) -> None:
        self._log("cancel_all:" + server)

    def call_service(self, service: str, request: Mapping[str, Any]) -> bool:
        self._log(service)
        return True

    def robot_pose(self) -> tuple[float, float, float]:
        return self.pose

    def robot_speed(self) -> float:
        return 0.2

    def is_path_valid(self, path: np.ndarray) -> bool:
        return True

    def selection(self, topic: str) -> str | None:
        return None

    def updated_goal(self) -> tuple[float, float, float] | None:
        return None

    def is_stuck(self) -> bool:
        return False


def _navigate(tree_file: Path, *, settle: bool, follow_fails: bool = False, seconds: float = 60.0) -> dict[str, Any]:
    clock = ManualClock()
    services = TimedServices(clock, follow_fails=follow_fails)
    tree = nav2_factory(services).create_tree_from_file(tree_file, clock=clock)
    changes: list[tuple[int, str, str, str]] = []
    tree.add_listener(lambda t, path, uid, prev, new: changes.append((t, path, prev.name, new.name)))
    bb = tree.root_blackboard
    goal = (3.0, 1.0, 0.5)
    bb.set("goal", goal)
    bb.set("goals", [(1.0, 0.0, 0.0), goal])
    bb.set("initial_pose_received", True)
    status: NodeStatus | None = NodeStatus.RUNNING
    ticked = 0
    for _ in range(round(seconds * 1e9 / LOOP_NS)):
        services.step(clock())
        status = tree.tick_unless_settled(lambda: services.generation) if settle else tree.tick_once()
        ticked += status is not None
        if status is not None and status is not NodeStatus.RUNNING:
            break
        clock.advance(LOOP_NS)
    return {"status": status, "end_ns": clock(), "calls": services.calls, "changes": changes, "ticks": ticked}


@pytest.mark.parametrize("tree_file", ALL_TREES, ids=lambda p: p.stem)
def test_skipping_settled_ticks_changes_nothing_in_nav2s_trees(tree_file: Path) -> None:
    every = _navigate(tree_file, settle=False, seconds=20.0)
    settled = _navigate(tree_file, settle=True, seconds=20.0)
    assert settled["calls"] == every["calls"]
    assert settled["changes"] == every["changes"]
    assert (settled["status"] or NodeStatus.RUNNING) is every["status"]
    assert settled["end_ns"] == every["end_ns"]


def test_the_default_tree_settles_between_replans_and_recovers_the_same() -> None:
    default = TREES / "navigate_to_pose_w_replanning_and_recovery.xml"
    every = _navigate(default, settle=False)
    settled = _navigate(default, settle=True)
    assert every["status"] is NodeStatus.SUCCESS and settled["status"] is NodeStatus.SUCCESS
    assert settled["calls"] == every["calls"] and settled["changes"] == every["changes"]
    # following for 2.35 s with replanning at 1 Hz: a handful of ticks instead of 236
    assert every["ticks"] == 236 and settled["ticks"] < 20
    failing = _navigate(default, settle=True, follow_fails=True)
    reference = _navigate(default, settle=False, follow_fails=True)
    assert failing["status"] is NodeStatus.FAILURE
    assert failing["calls"] == reference["calls"] and failing["changes"] == reference["changes"]
    calls = [c for _, c in failing["calls"]]
    assert calls.count("follow_path") == 14  # seven rounds (the first and six retries), each following twice
    assert [c for c in calls if c in ("spin", "wait", "backup")] == ["spin", "wait", "backup", "spin"]
    assert failing["ticks"] < reference["ticks"] / 2
