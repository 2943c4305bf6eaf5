"""Nav2's control nodes, and Nav2's default navigate-to-pose tree with stand-in leaves."""

from __future__ import annotations

from pathlib import Path

from tests.unit.bt.helpers import v4
from twin.bt import BehaviorTreeFactory, ManualClock, NodeKind, NodeStatus
from twin.bt.conformance import LeafCallRecorder, ScriptedAction, ScriptedCondition, Step, scripted_node_class
from twin.bt.validate import validate_file
from twin.nav.bt_navigator.factory import nav2_factory
from twin.nav.bt_navigator.tree_nodes import NAV2_LEAVES

S, F, R = NodeStatus.SUCCESS, NodeStatus.FAILURE, NodeStatus.RUNNING
NAV2_TREE = Path(__file__).resolve().parents[4] / "trees" / "navigate_to_pose_w_replanning_and_recovery.xml"


def nav2_rig(rig, xml: str, scripts: dict[str, list[str]]):
    return rig(xml, scripts, factory=nav2_factory())


def test_pipeline_sequence_reticks_earlier_children_while_a_later_one_runs(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<PipelineSequence name="p"><Cond name="A"/><Leaf name="B"/></PipelineSequence>'),
        {"A": ["SUCCESS"], "B": ["RUNNING"]},
    )
    assert r.tick() is R
    assert r.tick() is R
    assert [c[:2] for c in r.calls] == [["A", "tick"], ["B", "onRunning"]]


def test_pipeline_sequence_fails_and_halts_everything_on_a_failure(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<PipelineSequence name="p"><Cond name="A"/><Leaf name="B"/></PipelineSequence>'),
        {"A": ["SUCCESS", "FAILURE"], "B": ["RUNNING"]},
    )
    r.tick()
    assert r.tick() is F
    assert ["B", "onHalted"] in r.calls


def test_recovery_node_runs_the_recovery_then_retries(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<RecoveryNode name="rn" number_of_retries="2"><Leaf name="Act"/><Leaf name="Fix"/></RecoveryNode>'),
        {"Act": ["FAILURE", "FAILURE", "SUCCESS"], "Fix": ["SUCCESS"]},
    )
    assert r.tick() is S
    assert [c[0] for c in r.calls] == ["Act", "Fix", "Act", "Fix", "Act"]


def test_recovery_node_gives_up_after_its_retries(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<RecoveryNode name="rn" number_of_retries="1"><Leaf name="Act"/><Leaf name="Fix"/></RecoveryNode>'),
        {"Act": ["FAILURE"], "Fix": ["SUCCESS"]},
    )
    assert r.tick() is F
    assert [c[0] for c in r.calls] == ["Act", "Fix", "Act"]


def test_round_robin_moves_to_the_next_child_on_each_activation(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<RoundRobin name="rr"><Leaf name="A"/><Leaf name="B"/><Leaf name="C"/></RoundRobin>'),
        {"A": ["SUCCESS"], "B": ["SUCCESS"], "C": ["SUCCESS"]},
    )
    firsts = []
    for _ in range(4):
        r.tick()
        firsts.append(r.calls[0][0])
    assert firsts == ["A", "B", "C", "A"]


def test_round_robin_fails_when_every_child_failed(rig) -> None:
    r = nav2_rig(
        rig,
        v4('<RoundRobin name="rr"><Leaf name="A"/><Leaf name="B"/></RoundRobin>'),
        {"A": ["FAILURE"], "B": ["FAILURE"]},
    )
    assert r.tick() is F


def test_rate_controller_ticks_its_child_at_the_rate_on_the_simulation_clock(rig) -> None:
    xml = v4(
        '<PipelineSequence name="p"><RateController name="rc" hz="2"><Leaf name="Plan"/></RateController><Leaf name="Follow"/></PipelineSequence>'
    )
    r = nav2_rig(rig, xml, {"Plan": ["SUCCESS"], "Follow": ["RUNNING"]})
    planned = []
    for _ in range(10):
        r.tick(advance_ms=100)
        planned.append(any(call[0] == "Plan" for call in r.calls))
    # the first tick, then once every 500 ms (5 ticks of 100 ms)
    assert planned == [True, False, False, False, False, True, False, False, False, False]


def _stand_in_factory(scripts: dict[str, tuple[Step, ...]]) -> tuple[BehaviorTreeFactory, LeafCallRecorder]:
    factory = nav2_factory()
    recorder = LeafCallRecorder()
    for node_id, (kind, ports) in NAV2_LEAVES.items():
        factory.unregister(node_id)
        base = ScriptedAction if kind is NodeKind.ACTION else ScriptedCondition
        factory.register_node_type(scripted_node_class(base, ports, node_id), node_id, scripts, recorder)
    return factory, recorder


def test_the_default_nav2_tree_validates_with_the_nav2_nodes_declared() -> None:
    report = validate_file(NAV2_TREE, nav2_factory())
    assert report.ok, report.problems
    assert "ComputePathToPose" in report.declared_only


def test_the_default_nav2_tree_recovers_from_a_failed_follow_path() -> None:
    def steps(*statuses: str) -> tuple[Step, ...]:
        return tuple(Step(status=NodeStatus[s], outputs={}) for s in statuses)

    scripts = {
        "ComputePathToPose::5": steps("SUCCESS"),
        "FollowPath::8": steps("RUNNING", "FAILURE", "RUNNING", "SUCCESS"),
        "ClearLocalCostmap-Context": steps("SUCCESS"),
    }
    factory, recorder = _stand_in_factory(scripts)
    clock = ManualClock()
    tree = factory.create_tree_from_file(NAV2_TREE, clock=clock)
    statuses = []
    for _ in range(6):
        statuses.append(tree.tick_once())
        clock.advance(100_000_000)
        if statuses[-1].is_completed:
            break
    assert statuses[-1] is S
    called = [call[:2] for call in recorder.calls]
    assert called == [
        ["ComputePathToPose::5", "onStart"],
        ["FollowPath::8", "onStart"],
        ["FollowPath::8", "onRunning"],  # fails
        ["ClearLocalCostmap-Context", "onStart"],
        ["FollowPath::8", "onStart"],
        ["FollowPath::8", "onRunning"],  # succeeds
    ]
