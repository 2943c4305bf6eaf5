"""Control nodes: order of ticks, halts and status changes as BT.CPP 4.x."""

from __future__ import annotations

from twin.bt import NodeStatus

from .helpers import v4

S, F, R = NodeStatus.SUCCESS, NodeStatus.FAILURE, NodeStatus.RUNNING


def test_sequence_stops_at_a_running_child_and_resumes_there(rig) -> None:
    r = rig(
        v4('<Sequence name="s"><Leaf name="A"/><Leaf name="B"/></Sequence>'),
        {"A": ["SUCCESS"], "B": ["RUNNING", "SUCCESS"]},
    )
    assert r.tick() is R
    assert r.tick() is S
    assert [c[:2] for c in r.calls] == [["B", "onRunning"]]


def test_sequence_failure_restarts_from_the_first_child(rig) -> None:
    r = rig(
        v4('<Sequence name="s"><Leaf name="A"/><Leaf name="B"/></Sequence>'),
        {"A": ["SUCCESS"], "B": ["FAILURE", "SUCCESS"]},
    )
    assert r.tick() is F
    assert r.tick() is S
    assert [c[0] for c in r.calls] == ["A", "B"]


def test_sequence_resets_children_before_its_own_status(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A"/></Sequence>'), {"A": ["SUCCESS"]})
    r.tick()
    assert r.transitions[-4:] == [
        ("A", "IDLE", "SUCCESS"),
        ("A", "SUCCESS", "IDLE"),
        ("s", "RUNNING", "SUCCESS"),
        ("s", "SUCCESS", "IDLE"),
    ]


def test_sequence_with_memory_skips_children_that_succeeded_before_a_failure(rig) -> None:
    r = rig(
        v4('<SequenceWithMemory name="m"><Leaf name="A"/><Leaf name="B"/></SequenceWithMemory>'),
        {"A": ["SUCCESS"], "B": ["FAILURE", "SUCCESS"]},
    )
    assert r.tick() is F
    assert r.tick() is S
    assert [c[0] for c in r.calls] == ["B"]


def test_sequence_with_memory_needs_one_exactly_once_tick_per_instant_child(rig) -> None:
    r = rig(
        v4('<SequenceWithMemory name="m"><Leaf name="A"/><Leaf name="B"/><Leaf name="C"/></SequenceWithMemory>'),
        {"A": ["SUCCESS"], "B": ["SUCCESS"], "C": ["SUCCESS"]},
    )
    assert [r.tick(exactly_once=True) for _ in range(3)] == [R, R, S]


def test_tick_once_hides_the_wake_ups_of_instant_children(rig) -> None:
    r = rig(
        v4('<SequenceWithMemory name="m"><Leaf name="A"/><Leaf name="B"/><Leaf name="C"/></SequenceWithMemory>'),
        {"A": ["SUCCESS"], "B": ["SUCCESS"], "C": ["SUCCESS"]},
    )
    assert r.tick() is S


def test_plain_sequence_runs_instant_children_in_one_pass_without_wake_ups(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A"/><Leaf name="B"/></Sequence>'), {"A": ["SUCCESS"], "B": ["SUCCESS"]})
    assert r.tick(exactly_once=True) is S


def test_fallback_returns_the_first_success(rig) -> None:
    r = rig(
        v4('<Fallback name="f"><Cond name="C"/><Leaf name="A"/><Leaf name="B"/></Fallback>'),
        {"C": ["FAILURE"], "A": ["SUCCESS"]},
    )
    assert r.tick() is S
    assert [c[0] for c in r.calls] == ["C", "A"]


def test_reactive_sequence_rechecks_conditions_and_halts_the_action(rig) -> None:
    r = rig(
        v4('<ReactiveSequence name="r"><Cond name="C"/><Leaf name="A"/></ReactiveSequence>'),
        {"C": ["SUCCESS", "FAILURE"], "A": ["RUNNING"]},
    )
    assert r.tick() is R
    assert r.tick() is F
    assert r.calls == [["C", "tick", "FAILURE"], ["A", "onHalted"]]


def test_reactive_sequence_resets_a_succeeded_condition_when_a_child_runs(rig) -> None:
    r = rig(
        v4('<ReactiveSequence name="r"><Cond name="C"/><Leaf name="A"/></ReactiveSequence>'),
        {"C": ["SUCCESS"], "A": ["RUNNING"]},
    )
    r.tick()
    assert r.changes_of("C") == [("IDLE", "SUCCESS"), ("SUCCESS", "IDLE")]


def test_reactive_fallback_halts_the_action_when_the_condition_succeeds(rig) -> None:
    r = rig(
        v4('<ReactiveFallback name="r"><Cond name="C"/><Leaf name="A"/></ReactiveFallback>'),
        {"C": ["FAILURE", "SUCCESS"], "A": ["RUNNING"]},
    )
    assert r.tick() is R
    assert r.tick() is S
    assert ["A", "onHalted"] in r.calls


def test_parallel_succeeds_at_the_success_count_and_halts_the_others(rig) -> None:
    r = rig(
        v4('<Parallel name="p" success_count="1"><Leaf name="A"/><Leaf name="B"/></Parallel>'),
        {"A": ["RUNNING", "SUCCESS"], "B": ["RUNNING"]},
    )
    assert r.tick() is R
    assert r.tick() is S
    assert r.calls == [["A", "onRunning", "SUCCESS"], ["B", "onHalted"]]


def test_parallel_does_not_tick_a_completed_child_again(rig) -> None:
    r = rig(
        v4('<Parallel name="p"><Leaf name="A"/><Leaf name="B"/></Parallel>'),
        {"A": ["SUCCESS"], "B": ["RUNNING", "RUNNING", "SUCCESS"]},
    )
    for _ in range(3):
        r.tick()
    assert [c[0] for c in r.calls] == ["B"]


def test_parallel_fails_when_success_becomes_impossible(rig) -> None:
    r = rig(
        v4(
            '<Parallel name="p" success_count="2" failure_count="2"><Leaf name="A"/><Leaf name="B"/><Leaf name="C"/></Parallel>'
        ),
        {"A": ["FAILURE"], "B": ["FAILURE"], "C": ["RUNNING"]},
    )
    assert r.tick() is F


def test_parallel_all_waits_for_every_child(rig) -> None:
    r = rig(
        v4('<ParallelAll name="p" max_failures="1"><Leaf name="A"/><Leaf name="B"/></ParallelAll>'),
        {"A": ["FAILURE"], "B": ["RUNNING", "SUCCESS"]},
    )
    assert r.tick() is R
    assert r.tick() is F


def test_if_then_else_keeps_the_running_branch_without_rechecking(rig) -> None:
    r = rig(
        v4('<IfThenElse name="i"><Cond name="C"/><Leaf name="A"/><Leaf name="B"/></IfThenElse>'),
        {"C": ["SUCCESS", "FAILURE"], "A": ["RUNNING", "SUCCESS"]},
    )
    assert r.tick() is R
    assert r.tick() is S
    assert [c[0] for c in r.calls] == ["A"]


def test_while_do_else_switches_branch_when_the_condition_flips(rig) -> None:
    r = rig(
        v4('<WhileDoElse name="w"><Cond name="C"/><Leaf name="D"/><Leaf name="E"/></WhileDoElse>'),
        {"C": ["SUCCESS", "FAILURE"], "D": ["RUNNING"], "E": ["RUNNING"]},
    )
    r.tick()
    assert r.tick() is R
    assert r.calls == [["C", "tick", "FAILURE"], ["D", "onHalted"], ["E", "onStart", "RUNNING"]]


def test_switch_selects_by_string_then_number_and_falls_back_to_default(rig) -> None:
    xml = v4(
        '<Sequence name="s"><Script name="v" code="x := 2"/>'
        '<Switch3 name="sw" variable="{x}" case_1="one" case_2="2.0" case_3="3"><Leaf name="A"/><Leaf name="B"/><Leaf name="C"/><Leaf name="D"/></Switch3>'
        "</Sequence>"
    )
    r = rig(xml, {"A": ["SUCCESS"], "B": ["SUCCESS"], "C": ["SUCCESS"], "D": ["SUCCESS"]})
    r.tick()
    assert [c[0] for c in r.calls] == ["B"]


def test_switch_logs_its_running_status_after_the_child(rig) -> None:
    r = rig(
        v4(
            '<Switch2 name="sw" variable="a" case_1="a" case_2="b"><Leaf name="A"/><Leaf name="B"/><Leaf name="D"/></Switch2>'
        ),
        {"A": ["RUNNING"]},
    )
    r.tick()
    assert r.transitions == [("A", "IDLE", "RUNNING"), ("sw", "IDLE", "RUNNING")]


def test_a_sequence_of_skipped_children_is_skipped(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A" _skipIf="true"/></Sequence>'), {"A": ["SUCCESS"]})
    assert r.tick() is NodeStatus.SKIPPED
    assert r.calls == []


def test_async_sequence_wakes_up_between_instant_children(rig) -> None:
    r = rig(
        v4('<AsyncSequence name="a"><Leaf name="A"/><Leaf name="B"/></AsyncSequence>'),
        {"A": ["SUCCESS"], "B": ["SUCCESS"]},
    )
    assert r.tick(exactly_once=True) is R
    assert r.tick(exactly_once=True) is S
