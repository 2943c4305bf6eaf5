"""Pre-conditions (_skipIf, _successIf, _failureIf, _while) and post-conditions (_on*, _post)."""

from __future__ import annotations

from twin.bt import NodeStatus

from .helpers import v4


def test_skip_if_neither_ticks_nor_logs_the_node(rig) -> None:
    r = rig(
        v4('<Sequence name="s"><Leaf name="A" _skipIf="true"/><Leaf name="B"/></Sequence>'),
        {"A": ["SUCCESS"], "B": ["SUCCESS"]},
    )
    assert r.tick() is NodeStatus.SUCCESS
    assert r.changes_of("A") == []
    assert [c[0] for c in r.calls] == ["B"]


def test_success_if_and_failure_if_set_the_status_without_a_tick(rig) -> None:
    r = rig(
        v4('<Fallback name="f"><Leaf name="A" _failureIf="true"/><Leaf name="B" _successIf="true"/></Fallback>'),
        {"A": ["SUCCESS"], "B": ["FAILURE"]},
    )
    assert r.tick() is NodeStatus.SUCCESS
    assert r.calls == []
    assert r.changes_of("A")[0] == ("IDLE", "FAILURE")


def test_failure_if_is_checked_before_success_if(rig) -> None:
    r = rig(v4('<Leaf name="A" _successIf="true" _failureIf="true"/>'), {"A": ["SUCCESS"]})
    assert r.tick() is NodeStatus.FAILURE


def test_preconditions_are_not_checked_while_the_node_runs_except_while(rig) -> None:
    xml = v4(
        '<Sequence name="s"><Script name="c" code="n := 0" _skipIf="n == 1"/><Leaf name="A" _failureIf="n == 1"/><Script name="i" code="n := 1"/></Sequence>'
    )
    r = rig(xml.replace('<Script name="i" code="n := 1"/>', ""), {"A": ["RUNNING", "SUCCESS"]})
    r.tree.root_blackboard.set("n", 0)
    assert r.tick() is NodeStatus.RUNNING
    r.tree.root_blackboard.set("n", 1)
    assert r.tick() is NodeStatus.SUCCESS  # _failureIf ignored while A was RUNNING


def test_while_false_halts_a_running_node_and_skips_it(rig) -> None:
    r = rig(
        v4('<Sequence name="s"><Leaf name="A" _while="go == 1" _onHalted="halted := 1"/></Sequence>'),
        {"A": ["RUNNING"]},
    )
    r.tree.root_blackboard.set("go", 1)
    assert r.tick() is NodeStatus.RUNNING
    r.tree.root_blackboard.set("go", 0)
    assert r.tick() is NodeStatus.SKIPPED
    assert r.calls == [["A", "onHalted"]]
    assert r.tree.root_blackboard.get("halted") == 1


def test_post_conditions_run_by_outcome(rig) -> None:
    xml = v4(
        '<Sequence name="s"><RunOnce name="once"><Script name="z" code="ok := 0; ko := 0; n := 0"/></RunOnce>'
        '<ForceSuccess name="f"><Leaf name="A" _onSuccess="ok += 1" _onFailure="ko += 1" _post="n += 1"/></ForceSuccess>'
        "</Sequence>"
    )
    r = rig(xml, {"A": ["FAILURE", "SUCCESS"]})
    r.tick()
    r.tick()
    board = r.tree.root_blackboard
    assert (board.get("ok"), board.get("ko"), board.get("n")) == (1, 1, 2)


def test_post_conditions_do_not_run_for_running_or_skipped(rig) -> None:
    r = rig(
        v4(
            '<Sequence name="s"><Leaf name="A" _post="p := 1"/><Leaf name="B" _skipIf="true" _post="q := 1"/></Sequence>'
        ),
        {"A": ["RUNNING"]},
    )
    r.tick()
    assert "p" not in r.tree.root_blackboard
    assert "q" not in r.tree.root_blackboard


def test_a_failing_precondition_script_names_the_node(rig) -> None:
    import pytest

    from twin.bt import TickError

    r = rig(v4('<Sequence name="s"><Leaf name="A" _skipIf="missing == 1"/></Sequence>'), {"A": ["SUCCESS"]})
    with pytest.raises(TickError, match="node 'A'.*Variable not found: missing"):
        r.tick()
