"""What a node reaches of the tree it belongs to while it ticks: time, timers and the wake-up signal.

`TickContext` is the part of a `Tree` (which extends it) that nodes use: the simulation time of the
current tick, the `TimerQueue` that `Delay`, `Timeout` and `Sleep` schedule on, the wake-up signal a
node emits to have the root ticked again at once, and the bookkeeping a tick uses to tell whether it
settled. Nodes hold a `TickContext`, so the node classes need nothing of the tree that holds them.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from typing import Final

__all__ = ["TickContext", "TimerHandle", "TimerQueue"]


class TimerHandle:
    """A pending timer; `cancel()` it before it fires to run its callback with `aborted=True`."""

    __slots__ = ("_callback", "_state", "due_ns")

    _PENDING: Final = 0
    _FIRED: Final = 1
    _CANCELLED: Final = 2

    def __init__(self, due_ns: int, callback: Callable[[bool], None]) -> None:
        self.due_ns = due_ns
        self._callback = callback
        self._state = TimerHandle._PENDING

    @property
    def pending(self) -> bool:
        """True until the timer fired or was cancelled."""
        return self._state == TimerHandle._PENDING

    def cancel(self) -> bool:
        """Cancel a pending timer: its callback runs now with `aborted=True`. False if too late."""
        if self._state != TimerHandle._PENDING:
            return False
        self._state = TimerHandle._CANCELLED
        self._callback(True)
        return True

    def _fire(self) -> None:
        if self._state == TimerHandle._PENDING:
            self._state = TimerHandle._FIRED
            self._callback(False)


class TimerQueue:
    """Timers on the simulation clock, fired in due order (then in the order they were added)."""

    __slots__ = ("_heap", "_seq")

    def __init__(self) -> None:
        self._heap: list[tuple[int, int, TimerHandle]] = []
        self._seq = 0

    def add(self, due_ns: int, callback: Callable[[bool], None]) -> TimerHandle:
        """Schedule `callback(aborted=False)` at `due_ns`."""
        handle = TimerHandle(due_ns, callback)
        self._seq += 1
        heapq.heappush(self._heap, (due_ns, self._seq, handle))
        return handle

    def fire_due(self, now_ns: int) -> int:
        """Fire every pending timer due at or before `now_ns`; return how many came due."""
        heap = self._heap
        count = 0
        while heap and heap[0][0] <= now_ns:
            _, _, handle = heapq.heappop(heap)
            handle._fire()
            count += 1
        return count

    def next_due_ns(self) -> int | None:
        """When the next pending timer is due, or None."""
        heap = self._heap
        while heap and not heap[0][2].pending:
            heapq.heappop(heap)
        return heap[0][0] if heap else None


class TickContext:
    """The time, timers and wake-up signal of a tree, as its nodes see them.

    Args:
        clock: simulation time in integer nanoseconds.
    """

    def __init__(self, clock: Callable[[], int]) -> None:
        self.clock = clock
        self.timers = TimerQueue()
        self.btcpp3 = False
        """Ticked as BT.CPP 3.8 ticks (a v3 file): no node asks for a wake-up, none re-ticks the tree."""
        self._wake_up = False
        self._now_ns = clock()
        # A tick settles only if no node changed its status and no node that does not settle ran.
        self._status_changes = 0
        self._unsettled = False

    @property
    def now_ns(self) -> int:
        """The simulation time of the current (or last) tick."""
        return self._now_ns

    def emit_wake_up_signal(self) -> None:
        """Ask `tick_once()` to tick the root again (BT.CPP `WakeUpSignal::emitSignal`)."""
        self._wake_up = True

    def _take_wake_up(self) -> bool:
        woken = self._wake_up
        self._wake_up = False
        return woken
