"""play_bag and pacing without a server: what `twin play` and `twin simulate --speed X` rest on."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from tests.foxglove_client import watch
from twin.bag import ClockEncoder, Recorder, StringEncoder
from twin.core.errors import BagError
from twin.live import LiveServer, LiveSink, Pacer, play_bag


def small_bag(path: Path, *, clock_msgs: int = 20) -> Path:
    with Recorder(path) as rec:
        description = rec.add_topic("/robot_description", StringEncoder.msgtype)
        clock = rec.add_topic("/clock", ClockEncoder.msgtype)
        rec.write(description, 0, StringEncoder().encode("<robot name='x'/>"))
        encoder = ClockEncoder()
        for k in range(clock_msgs):
            rec.write(clock, k * 10_000_000, encoder.encode(k * 10_000_000))
    return path


def test_play_publishes_every_message_once_and_reports_what_it_served(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    with LiveServer(port=0) as server:
        report = play_bag(bag, server, speed=None)
    assert report.topics == ("/clock", "/robot_description")
    assert report.messages == 21 and report.passes == 1 and not report.stopped
    assert report.bag_s == pytest.approx(0.19)


def test_play_loops_until_asked_to_stop(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    passes: list[int] = []
    with LiveServer(port=0) as server:
        report = play_bag(
            bag, server, speed=None, loop=True, should_stop=lambda: len(passes) >= 3, on_pass=passes.append
        )
    assert passes == [1, 2, 3]
    assert report.passes == 3 and report.stopped
    assert report.messages == 2 * 21  # two whole passes, the third stopped before its first message
    assert report.reached_s == 0.0  # of that last pass


def test_play_stopped_partway_reports_how_far_into_the_bag_it_got(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")  # /clock at 0, 10, ..., 190 ms
    served: list[int] = []
    with LiveServer(port=0) as server:
        original = server.publish

        def counting(*args: Any) -> None:
            served.append(1)
            original(*args)

        server.publish = counting  # type: ignore[method-assign]
        report = play_bag(bag, server, speed=None, should_stop=lambda: len(served) >= 6)
    assert report.stopped and report.messages == 6  # the description and /clock up to 40 ms
    assert report.reached_s == pytest.approx(0.04) and report.bag_s == pytest.approx(0.19)


def test_play_paces_to_the_bags_timing_times_the_speed(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag", clock_msgs=11)  # 0.1 s of bag
    slept: list[float] = []
    original = Pacer.__init__

    def recording_pacer(self: Pacer, speed: float, **kwargs: Any) -> None:
        original(self, speed, sleep=slept.append, clock=lambda: 0.0, **kwargs)

    with pytest.MonkeyPatch.context() as mp, LiveServer(port=0) as server:
        mp.setattr(Pacer, "__init__", recording_pacer)
        play_bag(bag, server, speed=2.0)
    # A frozen clock: each message's delay is its bag time since the first, halved.
    assert slept == pytest.approx([k * 0.005 for k in range(1, 11)])


def test_a_late_client_of_a_played_bag_gets_the_latched_robot_description(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    with LiveServer(port=0) as server:
        play_bag(bag, server, speed=None)  # all played before anyone connects
        seen = asyncio.run(
            watch(
                server.url,
                ["/robot_description", "/clock"],
                stop=lambda w: bool(w.messages["/robot_description"]),
                timeout_s=10,
            )
        )
    assert [seen.decode("/robot_description", p).data for _, p in seen.messages["/robot_description"]] == [
        "<robot name='x'/>"
    ]
    assert seen.messages["/clock"] == []


def test_a_missing_bag_is_a_bag_error(tmp_path: Path) -> None:
    with LiveServer(port=0) as server, pytest.raises(BagError, match="no such bag folder"):
        play_bag(tmp_path / "missing", server)


def test_without_a_server_the_sink_only_paces() -> None:
    slept: list[float] = []
    now = [0.0]

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    sink = LiveSink(None, pacer=Pacer(4.0, clock=lambda: now[0], sleep=sleep))
    handle = sink.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    for k in range(5):
        sink.write(handle, k * 100_000_000, b"c")
    assert slept == pytest.approx([0.025] * 4)
