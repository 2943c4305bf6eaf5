"""Pacer: message times held to an absolute wall-clock schedule at any speed."""

from __future__ import annotations

import pytest

from twin.core.errors import ConfigError
from twin.live import Pacer


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 100.0
        self.slept: list[float] = []

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, seconds: float) -> None:
        self.slept.append(seconds)
        self.now_s += seconds


def test_each_message_waits_until_its_sim_time_divided_by_speed_has_passed_since_the_first() -> None:
    clock = FakeClock()
    pacer = Pacer(2.0, clock=clock, sleep=clock.sleep)
    pacer.wait(1_000_000_000)  # the first message starts the schedule
    pacer.wait(2_000_000_000)  # 1 sim second later = 0.5 s wall at speed 2
    pacer.wait(3_000_000_000)
    assert clock.slept == pytest.approx([0.5, 0.5])
    assert clock.now_s == pytest.approx(101.0)


def test_a_late_message_is_not_slept_for_and_the_schedule_catches_up() -> None:
    clock = FakeClock()
    pacer = Pacer(1.0, clock=clock, sleep=clock.sleep)
    pacer.wait(0)
    clock.now_s += 0.25  # a slow step: 0.25 s of wall time went by
    pacer.wait(100_000_000)  # due at 0.1 s: late, no sleep
    pacer.wait(400_000_000)  # due at 0.4 s: sleeps only what is left
    assert clock.slept == pytest.approx([0.15])
    assert pacer.lag_s(400_000_000) == pytest.approx(0.0)


def test_messages_at_the_same_time_wait_once() -> None:
    clock = FakeClock()
    pacer = Pacer(1.0, clock=clock, sleep=clock.sleep)
    pacer.wait(0)
    for _ in range(5):
        pacer.wait(10_000_000)
    assert clock.slept == pytest.approx([0.01])


def test_once_stop_is_asked_for_it_no_longer_sleeps() -> None:
    clock = FakeClock()
    stop = [False]
    pacer = Pacer(1.0, clock=clock, sleep=clock.sleep, should_stop=lambda: stop[0])
    pacer.wait(0)
    pacer.wait(1_000_000_000)
    stop[0] = True
    pacer.wait(60_000_000_000)
    assert clock.slept == pytest.approx([1.0])


def test_restart_begins_a_new_schedule_for_a_replayed_stream() -> None:
    clock = FakeClock()
    pacer = Pacer(1.0, clock=clock, sleep=clock.sleep)
    pacer.wait(5_000_000_000)
    pacer.wait(6_000_000_000)
    pacer.restart()
    pacer.wait(5_000_000_000)  # back to the start: due now, not in the past
    pacer.wait(5_500_000_000)
    assert clock.slept == pytest.approx([1.0, 0.5])


@pytest.mark.parametrize("speed", [0.0, -1.0, float("inf"), float("nan")])
def test_a_speed_that_is_not_a_positive_number_is_refused(speed: float) -> None:
    with pytest.raises(ConfigError, match="--speed"):
        Pacer(speed)
