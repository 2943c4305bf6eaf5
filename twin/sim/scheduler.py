"""The rate scheduler: integer step counts, no accumulated floats.

A task at `rate_hz` fires for the i-th time at the first physics step whose time is at or after
`i / rate_hz` seconds, that is at step `ceil(i * 1e9 / (rate_hz * step_ns))`, computed in exact
integer arithmetic from the rate as a fraction. Over a run of duration T it fires
`floor(T * rate_hz) + 1` times, counting the firing at t = 0.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction

from twin.core.clock import NS_PER_S

__all__ = ["Scheduler", "Task"]

TaskFn = Callable[[int], None]


@dataclass(slots=True)
class Task:
    """A periodic callback `fn(t_ns)`; `priority` orders tasks that fall on the same step (low first)."""

    name: str
    fn: TaskFn
    priority: int
    num: int  # rate = num / den firings per second
    den: int
    step_ns: int
    count: int = 0
    due_k: int = field(default=0)
    origin_k: int = 0  # the step its grid starts from (a timer created while running: its creation)
    # The i-th firing is at step ceil(i * ns_den / num_step): both factors fixed, kept for the hot loop.
    ns_den: int = field(init=False, repr=False)
    num_step: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.ns_den = NS_PER_S * self.den
        self.num_step = self.num * self.step_ns

    def due_step(self, i: int) -> int:
        """Return the step index of the i-th firing."""
        return self.origin_k - (-i * self.ns_den // self.num_step)


class Scheduler:
    """Fires periodic tasks at their integer-step due times, in priority order within a step."""

    def __init__(self, step_ns: int) -> None:
        if step_ns <= 0:
            msg = f"step_ns must be positive, got {step_ns}"
            raise ValueError(msg)
        self.step_ns = step_ns
        self._heap: list[tuple[int, int, int, Task]] = []
        self._seq = 0
        self.tasks: list[Task] = []

    def add(
        self,
        name: str,
        rate_hz: float | Fraction,
        fn: TaskFn,
        *,
        priority: int = 50,
        start_k: int = 0,
        origin_k: int = 0,
    ) -> Task:
        """Add a task firing at `rate_hz` from step `start_k` on, on a grid that starts at step `origin_k`.

        A float rate is taken as the nearest fraction with a denominator up to 10^6; a `Fraction`
        (e.g. `Fraction(NS_PER_S, period_ns)`) exactly.

        Raises:
            ValueError: If the rate is not positive.
        """
        if not rate_hz > 0:
            msg = f"{name}: rate must be positive, got {rate_hz} Hz"
            raise ValueError(msg)
        frac = rate_hz if isinstance(rate_hz, Fraction) else Fraction(rate_hz).limit_denominator(1_000_000)
        task = Task(
            name=name,
            fn=fn,
            priority=priority,
            num=frac.numerator,
            den=frac.denominator,
            step_ns=self.step_ns,
            origin_k=origin_k,
        )
        first = 0
        while task.due_step(first) < start_k:
            first += 1
        task.count = first
        task.due_k = task.due_step(first)
        self.tasks.append(task)
        self._push(task)
        return task

    def once(self, name: str, fn: TaskFn, *, at_k: int = 0, priority: int = 50) -> Task:
        """Add a task that fires once, at step `at_k`."""
        task = Task(name=name, fn=fn, priority=priority, num=0, den=1, step_ns=self.step_ns, due_k=at_k)
        self.tasks.append(task)
        self._push(task)
        return task

    def _push(self, task: Task) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (task.due_k, task.priority, self._seq, task))

    def next_due(self) -> int:
        """Return the step index of the next firing (a very large number when there are no tasks)."""
        return self._heap[0][0] if self._heap else 1 << 62

    def fire_due(self, k: int) -> None:
        """Run every task due at step `k`, in priority order, and schedule their next firings."""
        # The hot loop of a run (hundreds of firings a simulated second): `due_step` and `_push`
        # inlined, with the same keys and sequence numbers.
        heap, pop, push = self._heap, heapq.heappop, heapq.heappush
        t_ns = k * self.step_ns
        while heap and heap[0][0] == k:
            task = pop(heap)[3]
            task.fn(t_ns)
            count = task.count = task.count + 1
            if task.num:
                due = task.due_k = task.origin_k - (-count * task.ns_den // task.num_step)
                seq = self._seq = self._seq + 1
                push(heap, (due, task.priority, seq, task))
