from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.bt import ManualClock, NodeStatus
from twin.bt.validate import validate_file
from twin.nav.actions import ActionState, ActionUpdate
from twin.nav.bt_navigator.factory import nav2_factory

TREES = Path("/work/shared/fixtures/nav2/nav2_humble/behavior_trees")
if not TREES.is_dir():
    TREES = Path(__file__).resolve().parents[5] / "shared" / "fixtures" / "nav2" / "nav2_humble" / "behavior_trees"
ALL_TREES = sorted(TREES.glob("*.xml"))
THROUGH_POSES = {"navigate_through_poses_w_replanning_and_recovery.xml"}


class FakeServices:
    """Servers that plan a straight line, drive the robot along it in `follow_polls` polls, and log every call."""

    def __init__(self, *, follow_fails: bool = False, follow_polls: int = 3) -> None:
        self.pose = (0.0, 0.0, 0.0)
        self.calls: list[str] = []
        self.follow_fails = follow_fails
        self.follow_polls = follow_polls
        self._goals: dict[int, dict[str, Any]] = {}
        self._next = 0

    def send_goal(self, server: str, request: Mapping[str, Any]) -> int:
        self._next += 1
        self._goals[self._next] = {"server": server, "request": dict(request), "polls": 0}
        self.calls.append(server)
        return self._next

    def update_goal(self, goal_id: int, request: Mapping[str, Any]) -> None:
        self._goals[goal_id]["request"] = dict(request)

    def poll(self, goal_id: int) -> ActionUpdate:
        goal = self._goals[goal_id]
        goal["polls"] += 1
        server, request = goal["server"], goal["request"]
        if server in ("compute_path_to_pose", "compute_path_through_poses"):
            end = request["goal"] if server == "compute_path_to_pose" else request["goals"][-1]
            path = np.array([[self.pose[0], self.pose[1], 0.0], [end[0], end[1], end[2]]])
            return ActionUpdate(state=ActionState.SUCCEEDED, result={"path": path})
        if server == "follow_path":
            if self.follow_fails:
                return ActionUpdate(state=ActionState.FAILED)
            if goal["polls"] < self.follow_polls:
                return ActionUpdate(state=ActionState.RUNNING)
            end = request["path"][-1]
            self.pose = (float(end[0]), float(end[1]), float(end[2]))
            return ActionUpdate(state=ActionState.SUCCEEDED)
        if server == "smooth_path":
            return ActionUpdate(state=ActionState.SUCCEEDED, result={"path": request["path"]})
        return ActionUpdate(state=ActionState.RUNNING if goal["polls"] < 2 else ActionState.SUCCEEDED)

    def cancel(self, goal_id: int) -> None:
        self.calls.append("cancel:" + self._goals[goal_id]["server"])

    def cancel_all(self, server: str) -> None:
        self.calls.append("cancel_all:" + server)

    def call_service(self, service: str, request: Mapping[str, Any]) -> bool:
        self.calls.append(service)
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


def _run(tree_file: Path, services: FakeServices, *, ticks: int = 3000) -> tuple[NodeStatus, int]:
    clock = ManualClock()
    factory = nav2_factory(services)
    tree = factory.create_tree_from_file(tree_file, clock=clock)
    bb = tree.root_blackboard
    goal = (3.0, 1.0, 0.5)
    bb.set("goal", goal)
    bb.set("goals", [(1.0, 0.0, 0.0), goal])
    bb.set("initial_pose_received", True)
    status = NodeStatus.RUNNING
    for k in range(ticks):
        status = tree.tick_once()
        if status is not NodeStatus.RUNNING:
            return status, k
        clock.advance(10_000_000)  # bt_loop_duration 10 ms
    return status, ticks


def test_the_fixture_holds_nav2_humbles_twelve_trees() -> None:
    assert len(ALL_TREES) == 12


@pytest.mark.parametrize("tree_file", ALL_TREES, ids=lambda p: p.stem)
def test_every_humble_tree_validates_with_the_nav2_nodes(tree_file: Path) -> None:
    report = validate_file(tree_file, nav2_factory())
    assert report.ok, report.problems
    implemented = nav2_factory(FakeServices())
    assert not validate_file(tree_file, implemented).declared_only  # every node the tree names is implemented


@pytest.mark.parametrize("tree_file", ALL_TREES, ids=lambda p: p.stem)
def test_every_humble_tree_runs_a_goal_with_fake_servers(tree_file: Path) -> None:
    services = FakeServices()
    status, _ = _run(tree_file, services, ticks=2000)
    if tree_file.stem == "follow_point":
        # follows a moving point until cancelled (KeepRunningUntilFailure): keeps running, path followed
        assert status is NodeStatus.RUNNING and "follow_path" in services.calls
        return
    assert status is NodeStatus.SUCCESS, services.calls[-10:]
    if tree_file.stem != "odometry_calibration":
        assert services.pose[:2] == pytest.approx((3.0, 1.0))


def test_default_tree_recovers_in_nav2s_order_and_fails_after_six_retries() -> None:
    services = FakeServices(follow_fails=True)
    status, _ = _run(TREES / "navigate_to_pose_w_replanning_and_recovery.xml", services)
    assert status is NodeStatus.FAILURE
    recoveries = [
        c
        for c in services.calls
        if c in ("spin", "wait", "backup")
        or c.endswith("clear_entirely_local_costmap")
        or c.endswith("clear_entirely_global_costmap")
    ]
    # the round robin: clear both costmaps, spin, wait, back up, then again from the start
    actions = [c for c in recoveries if c in ("spin", "wait", "backup")]
    assert actions == ["spin", "wait", "backup", "spin"]
    local, glob = "local_costmap/clear_entirely_local_costmap", "global_costmap/clear_entirely_global_costmap"
    follow_twice = ["compute_path_to_pose", "follow_path", local, "follow_path"]  # FollowPath's own context clear
    assert services.calls[:16] == [*follow_twice, local, glob, *follow_twice, "spin", *follow_twice, "wait"]
    rounds = services.calls.count("compute_path_to_pose")
    assert rounds == 7  # the first try and six retries


_RECOVERY_HELP = """<root BTCPP_format="4" main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>
  <ComputePathToPose goal="{goal}" path="{path}" error_code_id="{plan_code}"/>
  <Fallback>
    <FollowPath path="{path}" error_code_id="{follow_code}"/>
    <WouldAControllerRecoveryHelp error_code="{follow_code}"/>
  </Fallback>
</Sequence></BehaviorTree></root>"""


@pytest.mark.parametrize(("follow_fails", "follow_code"), [(False, 0), (True, 100)])
def test_the_leaves_write_iron_error_codes_that_would_a_recovery_help_reads(
    tmp_path: Path, follow_fails: bool, follow_code: int
) -> None:
    # Iron's and Jazzy's trees: a leaf's error_code_id (NONE on success, its action's code on failure)
    # read by WouldAControllerRecoveryHelp, which the twin did not run
    tree_file = tmp_path / "tree.xml"
    tree_file.write_text(_RECOVERY_HELP)
    tree = nav2_factory(FakeServices(follow_fails=follow_fails, follow_polls=1)).create_tree_from_file(
        tree_file, clock=ManualClock()
    )
    tree.root_blackboard.set("goal", (1.0, 0.0, 0.0))
    status = NodeStatus.RUNNING
    for _ in range(20):
        status = tree.tick_once()
        if status is not NodeStatus.RUNNING:
            break
    assert status is NodeStatus.SUCCESS  # followed, or failed with a code a recovery may mend (UNKNOWN)
    assert tree.root_blackboard.get("plan_code") == 0 and tree.root_blackboard.get("follow_code") == follow_code


@pytest.mark.parametrize(
    ("code", "planner", "controller"),
    [
        (200, True, False),
        (204, False, False),
        (208, True, False),
        (308, True, False),
        (105, False, True),
        (101, False, False),
    ],
)
def test_would_a_recovery_help_takes_irons_codes(tmp_path: Path, code: int, planner: bool, controller: bool) -> None:
    for node, helps in (("WouldAPlannerRecoveryHelp", planner), ("WouldAControllerRecoveryHelp", controller)):
        tree_file = tmp_path / f"{node}.xml"
        tree_file.write_text(
            f'<root BTCPP_format="4" main_tree_to_execute="M"><BehaviorTree ID="M"><{node} error_code="{{c}}"/>'
            "</BehaviorTree></root>"
        )
        tree = nav2_factory(FakeServices()).create_tree_from_file(tree_file, clock=ManualClock())
        tree.root_blackboard.set("c", code)
        assert (tree.tick_once() is NodeStatus.SUCCESS) == helps, (node, code)
