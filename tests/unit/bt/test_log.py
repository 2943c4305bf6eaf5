"""The status log: timeline, JSON-lines round trip, and the per-tick buffer for bag recording."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.bt import NodeStatus
from twin.bt.log import StatusChangeBuffer, StatusLog, read_jsonl, render_timeline
from twin.core.errors import TreeError

from .helpers import v4


def logged_run(rig) -> StatusLog:
    r = rig(v4('<Sequence name="seq"><Leaf name="go"/></Sequence>'), {"go": ["RUNNING", "SUCCESS"]})
    log = StatusLog()
    r.tree.add_listener(log)
    for advance in (0, 500):
        status = r.tick(advance_ms=advance)
        log.mark_tick(r.tree.now_ns, status)
    return log


def test_the_log_keeps_every_change_with_its_tick(rig) -> None:
    log = logged_run(rig)
    assert [(c.path, c.new.name) for c in log.changes[:2]] == [("seq", "RUNNING"), ("go", "RUNNING")]
    assert [(m.tick, m.status) for m in log.ticks] == [(1, NodeStatus.RUNNING), (2, NodeStatus.SUCCESS)]
    assert log.ticks[1].first_change == 2
    assert all(c.t_ns == 500_000_000 for c in log.changes[2:])


def test_the_timeline_shows_times_nodes_and_tick_results(rig) -> None:
    text = render_timeline(logged_run(rig))
    lines = text.splitlines()
    assert lines[1].split() == ["0.000", "seq", "IDLE", "->", "RUNNING"]
    assert "-- tick 1: root RUNNING" in lines[3]
    assert lines[-1].endswith("-- tick 2: root SUCCESS")


def test_jsonl_round_trip(rig, tmp_path: Path) -> None:
    log = logged_run(rig)
    path = tmp_path / "run.jsonl"
    log.write_jsonl(path)
    again = read_jsonl(path)
    assert again.changes == log.changes
    assert again.ticks == log.ticks


def test_a_bad_jsonl_line_is_reported_with_its_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text('{"t_ns": 0, "path": "a", "uid": 1, "prev": "IDLE", "new": "RUNNING"}\n{"t_ns": 1}\n')
    with pytest.raises(TreeError, match=r"bad.jsonl:2:"):
        read_jsonl(path)


def test_the_buffer_hands_over_one_batch_per_tick(rig) -> None:
    r = rig(v4('<Sequence name="seq"><Leaf name="go"/></Sequence>'), {"go": ["RUNNING", "RUNNING", "SUCCESS"]})
    buffer = StatusChangeBuffer()
    r.tree.add_listener(buffer)
    r.tick()
    assert [c.path for c in buffer.flush()] == ["seq", "go"]
    r.tick()
    assert buffer.flush() == []  # nothing changed: Nav2 publishes no message
    r.tick()
    assert [c.new.name for c in buffer.flush()][-1] == "IDLE"


def test_the_status_buffer_keeps_the_last_changes_of_a_tick_that_never_ends() -> None:
    from twin.bt.log import StatusChangeBuffer
    from twin.bt.status import NodeStatus

    buffer = StatusChangeBuffer(max_pending=3)
    for i in range(5):
        buffer(i, f"node{i}", i, NodeStatus.IDLE, NodeStatus.SUCCESS)
    changes = buffer.flush()
    assert [c.t_ns for c in changes] == [2, 3, 4]
    assert buffer.dropped == 2
    assert buffer.flush() == []
