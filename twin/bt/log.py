"""The status log: every status change of a tree with its simulation time, and its text timeline.

Attach a `StatusLog` to a tree as a listener; it keeps every change and, when told about ticks
(`mark_tick`), which tick caused it. `render_timeline()` prints it; `write_jsonl()`/`read_jsonl()`
save and load it.

For a bag recorder writing `/behavior_tree_log` (nav2_msgs/BehaviorTreeLog), `StatusChangeBuffer`
does what Nav2's `RosTopicLogger` does: collect the changes of one tick, and hand them over in one
batch (`flush()`) after `tick_once()` returns. Status names are the Nav2 strings IDLE, RUNNING,
SUCCESS and FAILURE (SKIPPED is never logged: a skipped node keeps IDLE).
"""

from __future__ import annotations

import collections
import dataclasses
import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import NamedTuple

from twin.bt.status import NodeStatus
from twin.core.config import read_text_file
from twin.core.errors import TreeError

__all__ = ["StatusChange", "StatusChangeBuffer", "StatusLog", "TickMark", "read_jsonl", "render_timeline"]


class StatusChange(NamedTuple):
    """One stored status change of one node."""

    t_ns: int
    path: str
    uid: int
    prev: NodeStatus
    new: NodeStatus


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class TickMark:
    """A completed root tick: its number, time and result, and the slice of the log it caused."""

    tick: int
    t_ns: int
    status: NodeStatus
    first_change: int
    end_change: int


class StatusLog:
    """A listener that keeps every status change; call `mark_tick` after each tick to number them."""

    def __init__(self) -> None:
        self.changes: list[StatusChange] = []
        self.ticks: list[TickMark] = []

    def __call__(self, t_ns: int, path: str, uid: int, prev: NodeStatus, new: NodeStatus) -> None:
        """Record one change (the `Tree.add_listener` signature)."""
        self.changes.append(StatusChange(t_ns, path, uid, prev, new))

    def mark_tick(self, t_ns: int, status: NodeStatus) -> None:
        """Close the current tick: the changes since the previous mark belong to it."""
        first = self.ticks[-1].end_change if self.ticks else 0
        end = len(self.changes)
        self.ticks.append(
            TickMark(tick=len(self.ticks) + 1, t_ns=t_ns, status=status, first_change=first, end_change=end)
        )

    def write_jsonl(self, path: Path) -> None:
        """Save as JSON lines: each change (`t_ns, path, uid, prev, new`), each tick mark after its changes."""
        with Path(path).open("w", encoding="utf-8") as out:
            for item in _items(self):
                if isinstance(item, TickMark):
                    out.write(json.dumps({"tick": item.tick, "t_ns": item.t_ns, "status": item.status.name}) + "\n")
                else:
                    record = {"t_ns": item.t_ns, "path": item.path, "uid": item.uid, "prev": item.prev.name}
                    out.write(json.dumps({**record, "new": item.new.name}) + "\n")


def _items(log: StatusLog) -> Iterable[StatusChange | TickMark]:
    """Changes and tick marks in order (a mark after the changes of its tick)."""
    done = 0
    for mark in log.ticks:
        yield from log.changes[done : mark.end_change]
        done = mark.end_change
        yield mark
    yield from log.changes[done:]


def read_jsonl(path: Path) -> StatusLog:
    """Load a log saved with `StatusLog.write_jsonl`.

    Raises:
        TreeError: `file:line: ...` if a line is not a change or a tick mark.
    """
    log = StatusLog()
    lines = read_text_file(Path(path), TreeError, what="a tree status log").splitlines()
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
            if "tick" in item:
                log.mark_tick(int(item["t_ns"]), NodeStatus[item["status"]])
            else:
                prev, new = NodeStatus[item["prev"]], NodeStatus[item["new"]]
                log(int(item["t_ns"]), str(item["path"]), int(item["uid"]), prev, new)
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
            msg = f"{path}:{number}: not a status-log line ({type(err).__name__}: {err})"
            raise TreeError(msg) from None
    return log


def render_timeline(log: StatusLog, *, width: int = 36) -> str:
    """The log as a text timeline: one line per change, and a line per tick with the root's result."""
    lines = [f"{'t [s]':>10}  {'node':<{width}}  transition"]
    for item in _items(log):
        if isinstance(item, TickMark):
            lines.append(f"{item.t_ns / 1e9:>10.3f}  {'':<{width}}  -- tick {item.tick}: root {item.status.name}")
        else:
            lines.append(f"{item.t_ns / 1e9:>10.3f}  {item.path:<{width}}  {item.prev.name} -> {item.new.name}")
    return "\n".join(lines)


class StatusChangeBuffer:
    """Collects status changes until `flush()` (Nav2's RosTopicLogger: one message per tick).

    It keeps the last `max_pending` changes: a tick that never returns (a `Repeat` of -1 cycles
    over a node that always succeeds) changes statuses without end, and must not fill the memory
    while the watchdog waits to stop it. `dropped` counts what was let go.
    """

    def __init__(self, max_pending: int = 10_000) -> None:
        self._pending: collections.deque[StatusChange] = collections.deque(maxlen=max_pending)
        self.dropped = 0

    def __call__(self, t_ns: int, path: str, uid: int, prev: NodeStatus, new: NodeStatus) -> None:
        """Record one change (the `Tree.add_listener` signature)."""
        pending = self._pending
        if len(pending) == pending.maxlen:
            self.dropped += 1
        pending.append(StatusChange(t_ns, path, uid, prev, new))

    def flush(self) -> Sequence[StatusChange]:
        """The changes since the last flush (empty when nothing changed: Nav2 then publishes nothing)."""
        pending = list(self._pending)
        self._pending.clear()
        return pending
