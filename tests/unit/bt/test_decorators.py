"""Decorators, including the timers that run on the simulation clock."""

from __future__ import annotations

from twin.bt import NodeStatus

from .helpers import v4

S, F, R, K = NodeStatus.SUCCESS, NodeStatus.FAILURE, NodeStatus.RUNNING, NodeStatus.SKIPPED


def test_inverter_swaps_results_and_passes_running(rig) -> None:
    r = rig(v4('<Inverter name="i"><Leaf name="A"/></Inverter>'), {"A": ["RUNNING", "SUCCESS", "FAILURE"]})
    assert [r.tick(), r.tick(), r.tick()] == [R, F, S]


def test_force_success_and_failure(rig) -> None:
    r = rig(
        v4(
            '<Sequence name="s"><ForceSuccess name="fs"><Leaf name="A"/></ForceSuccess><ForceFailure name="ff"><Leaf name="B"/></ForceFailure></Sequence>'
        ),
        {"A": ["FAILURE"], "B": ["SUCCESS"]},
    )
    assert r.tick() is F
    assert [c[0] for c in r.calls] == ["A", "B"]


def test_repeat_runs_the_child_the_given_number_of_times(rig) -> None:
    r = rig(v4('<Repeat name="r" num_cycles="3"><Leaf name="A"/></Repeat>'), {"A": ["SUCCESS"]})
    assert r.tick() is S
    assert len(r.calls) == 3


def test_repeat_stops_at_the_first_failure(rig) -> None:
    r = rig(v4('<Repeat name="r" num_cycles="5"><Leaf name="A"/></Repeat>'), {"A": ["SUCCESS", "FAILURE"]})
    assert r.tick() is F
    assert len(r.calls) == 2


def test_repeat_zero_cycles_succeeds_without_ticking(rig) -> None:
    r = rig(v4('<Repeat name="r" num_cycles="0"><Leaf name="A"/></Repeat>'), {"A": ["FAILURE"]})
    assert r.tick() is S
    assert r.calls == []


def test_retry_ticks_again_after_failures(rig) -> None:
    r = rig(
        v4('<RetryUntilSuccessful name="r" num_attempts="3"><Leaf name="A"/></RetryUntilSuccessful>'),
        {"A": ["FAILURE", "FAILURE", "SUCCESS"]},
    )
    assert r.tick() is S
    assert len(r.calls) == 3


def test_retry_gives_up_after_the_attempts(rig) -> None:
    r = rig(
        v4('<RetryUntilSuccessful name="r" num_attempts="2"><Leaf name="A"/></RetryUntilSuccessful>'),
        {"A": ["FAILURE"]},
    )
    assert r.tick() is F
    assert len(r.calls) == 2


def test_retry_returns_running_between_instant_attempts_when_ticked_exactly_once(rig) -> None:
    r = rig(
        v4('<RetryUntilSuccessful name="r" num_attempts="3"><Leaf name="A"/></RetryUntilSuccessful>'),
        {"A": ["FAILURE", "SUCCESS"]},
    )
    assert r.tick(exactly_once=True) is R
    assert r.tick(exactly_once=True) is S


def test_keep_running_until_failure(rig) -> None:
    r = rig(
        v4('<KeepRunningUntilFailure name="k"><Leaf name="A"/></KeepRunningUntilFailure>'),
        {"A": ["SUCCESS", "SUCCESS", "FAILURE"]},
    )
    assert [r.tick(), r.tick(), r.tick()] == [R, R, F]


def test_run_once_skips_afterwards_or_repeats_the_outcome(rig) -> None:
    r = rig(
        v4(
            '<Sequence name="s"><RunOnce name="o"><Leaf name="A"/></RunOnce><RunOnce name="p" then_skip="false"><Leaf name="B"/></RunOnce></Sequence>'
        ),
        {"A": ["SUCCESS"], "B": ["SUCCESS"]},
    )
    assert r.tick() is S
    assert r.tick() is S
    assert r.calls == []


def test_precondition_returns_else_without_ticking(rig) -> None:
    r = rig(v4('<Precondition name="p" if="1 == 2" else="SKIPPED"><Leaf name="A"/></Precondition>'), {"A": ["SUCCESS"]})
    assert r.tick() is K
    assert r.calls == []


def test_precondition_keeps_ticking_a_running_child_when_the_condition_turns_false(rig) -> None:
    xml = v4(
        '<Sequence name="s"><Script name="c" code="go := 1"/><Precondition name="p" if="go == 1"><Sequence name="inner"><Leaf name="A"/><Script name="stop" code="go := 0"/></Sequence></Precondition></Sequence>'
    )
    r = rig(xml, {"A": ["RUNNING", "SUCCESS"]})
    assert r.tick() is R
    assert r.tick() is S


def test_timeout_halts_a_child_still_running_when_its_time_is_up(rig) -> None:
    r = rig(v4('<Timeout name="t" msec="1000"><Leaf name="A"/></Timeout>'), {"A": ["RUNNING"]})
    assert r.tick() is R
    assert r.tick(advance_ms=999) is R
    assert r.tick(advance_ms=1) is F
    assert r.calls == [["A", "onHalted"]]


def test_timeout_does_not_fire_after_the_child_completed(rig) -> None:
    r = rig(v4('<Timeout name="t" msec="100"><Leaf name="A"/></Timeout>'), {"A": ["RUNNING", "SUCCESS", "RUNNING"]})
    r.tick()
    assert r.tick(advance_ms=50) is S
    assert r.tick(advance_ms=60) is R  # a new run: its timer starts now (t = 110 ms)
    assert r.tick(advance_ms=99) is R
    assert r.tick(advance_ms=1) is F


def test_delay_waits_on_the_simulation_clock_before_ticking_the_child(rig) -> None:
    r = rig(v4('<Delay name="d" delay_msec="500"><Leaf name="A"/></Delay>'), {"A": ["SUCCESS"]})
    assert r.tick() is R
    assert r.tick(advance_ms=499) is R
    assert r.calls == []
    assert r.tick(advance_ms=1) is S
    assert [c[0] for c in r.calls] == ["A"]


def test_sleep_is_running_until_its_simulated_time_passed(rig) -> None:
    r = rig(v4('<Sleep name="z" msec="200"/>'))
    assert r.tick() is R
    assert r.tick(advance_ms=100) is R
    assert r.tick(advance_ms=100) is S


def test_sleep_halted_does_not_complete_later(rig) -> None:
    r = rig(
        v4('<ReactiveSequence name="r"><Cond name="C"/><Sleep name="z" msec="100"/></ReactiveSequence>'),
        {"C": ["SUCCESS", "FAILURE", "SUCCESS"]},
    )
    r.tick()
    assert r.tick() is F
    assert r.tick(advance_ms=150) is R  # restarted, not finished by the old timer


def test_loop_pops_one_value_per_iteration(rig) -> None:
    xml = v4(
        '<Sequence name="s"><Script name="z" code="sum := 0.0"/><LoopDouble name="l" queue="0.5;1.5" value="{v}"><Script name="add" code="sum += v"/></LoopDouble></Sequence>'
    )
    r = rig(xml)
    statuses = [r.tick() for _ in range(3)]
    assert statuses == [R, R, S]
    assert r.tree.root_blackboard.get("sum") == 2.0
