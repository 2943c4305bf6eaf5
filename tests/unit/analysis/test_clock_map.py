"""Record time to sim time through a bag's /clock, also outside the first and last /clock message."""

from __future__ import annotations

from array import array

import numpy as np

from twin.analysis.collect import BagData


def _bag_with_clock(record_ns: list[int], sim_ns: list[int]) -> BagData:
    data = BagData(info=None, start_ns=record_ns[0])  # type: ignore[arg-type]  # clock_at reads only the clock
    data.clock = (array("q", record_ns), array("q", sim_ns))
    return data


def test_sim_time_between_and_beyond_10_hz_clock_messages() -> None:
    # A Gazebo-like bag: wall-clock record times, sim time at 0.8x real time, /clock at 10 Hz from 0.1 s.
    record = [1_000_000_000 + round(k * 0.125e9) for k in range(1, 41)]
    sim = [round(k * 0.1e9) for k in range(1, 41)]
    data = _bag_with_clock(record, sim)
    at = np.array([record[0] - round(0.1e9), record[5] + round(0.0625e9), record[-1] + round(0.05e9)], dtype=np.int64)
    got = data.clock_at(at)
    assert got is not None
    # Before the first message and after the last, the clock goes on at its pace: it is not held (held, the
    # first would read 0.1 s and the last 4.0 s).
    assert list(got) == [round(0.02e9), round(0.65e9), round(4.04e9)]


def test_a_bag_with_fewer_than_two_clock_messages_has_no_map() -> None:
    data = _bag_with_clock([5], [5])
    assert data.clock_at(np.array([5], dtype=np.int64)) is None
