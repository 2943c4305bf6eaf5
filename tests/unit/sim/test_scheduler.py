from __future__ import annotations

import pytest

from twin.core.clock import NS_PER_S
from twin.sim.scheduler import Scheduler


def run(scheduler: Scheduler, end_k: int) -> None:
    k = 0
    while True:
        k = scheduler.next_due()
        if k > end_k:
            break
        scheduler.fire_due(k)


@pytest.mark.parametrize(
    ("rate_hz", "step_ns"), [(30.0, 1_000_000), (200.0, 1_000_000), (5.0, 2_000_000), (7.3, 1_000_000)]
)
def test_count_over_a_run_is_rate_times_duration_plus_one(rate_hz: float, step_ns: int) -> None:
    sched = Scheduler(step_ns)
    stamps: list[int] = []
    sched.add("t", rate_hz, stamps.append)
    duration_s = 10
    run(sched, duration_s * NS_PER_S // step_ns)
    assert len(stamps) == int(rate_hz * duration_s) + 1
    assert stamps[0] == 0
    # The i-th firing is the first step at or after i / rate: never early, never a whole step late.
    for i, t_ns in enumerate(stamps):
        ideal = i * NS_PER_S / rate_hz
        assert ideal <= t_ns < ideal + step_ns


def test_tasks_on_the_same_step_fire_in_priority_order() -> None:
    sched = Scheduler(1_000_000)
    order: list[str] = []
    sched.add("late", 10.0, lambda t: order.append("late"), priority=90)
    sched.add("early", 10.0, lambda t: order.append("early"), priority=10)
    sched.fire_due(0)
    assert order == ["early", "late"]


def test_start_step_skips_earlier_firings() -> None:
    sched = Scheduler(1_000_000)
    stamps: list[int] = []
    sched.add("t", 100.0, stamps.append, start_k=25)
    run(sched, 60)
    assert stamps == [30_000_000, 40_000_000, 50_000_000, 60_000_000]


def test_once_fires_a_single_time_at_its_step() -> None:
    sched = Scheduler(1_000_000)
    stamps: list[int] = []
    sched.once("static", stamps.append, at_k=3)
    sched.add("t", 100.0, lambda t: None)
    run(sched, 100)
    assert stamps == [3_000_000]
