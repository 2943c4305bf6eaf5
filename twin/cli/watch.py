"""The watchdog's actions for the commands that run a simulation (`simulate`, `graph`).

Two stages are watched. While the simulation is being built, only a user node's constructor can
hang it for good (a world may take as long as it takes to load): `build_watched` ends the build
when a constructor has not returned for the watchdog's time. While it runs, a step that does not
return ends the run (`Guard`). Either way the main thread is first asked to unwind; if it is inside
a C call and cannot, the guard closes the bag itself and ends the process.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

from twin.core.errors import Interrupted, SimulationError

if TYPE_CHECKING:
    from twin.sim.simulation import Simulation
    from twin.sim.watchdog import StuckReport

__all__ = ["Guard", "build_watched"]

T = TypeVar("T")

# After the watchdog asks a stuck main thread to unwind, how long it waits before it closes the bag
# itself and ends the process (the thread is then inside a C call, e.g. an FMU's doStep).
UNWIND_S = 2.0


class Guard:
    """What the watchdog does when a step (or a node's constructor) is stuck, or a signal is not seen.

    Args:
        sim: The simulation whose bag to close, or None while it is being built (nothing recorded yet).
        debug: Print the stuck thread's stack.
    """

    def __init__(self, sim: Simulation | None, *, debug: bool) -> None:
        self.sim = sim
        self.debug = debug
        self.main = threading.get_ident()
        self.done = threading.Event()  # set by the main thread once the bag is closed
        self.report: StuckReport | None = None
        self.signum: int | None = None
        self.constructing: str | None = None  # the user node class whose constructor was stuck

    def message(self) -> str:
        """One line: what was stuck, where, and what was kept."""
        report = self.report
        assert report is not None
        if self.sim is None:
            what = f"the constructor of node class {self.constructing or '?'}"
            kept = "nothing was recorded"
            if self.signum is None:
                return (
                    f"{what} has not returned for {report.stuck_s:.1f} s of wall time (watchdog): stuck in "
                    f"{report.where}; {kept}"
                )
            return f"stopped by {signal.Signals(self.signum).name} while {what} was stuck in {report.where}; {kept}"
        recorder = self.sim.recorder
        kept = f"the bag up to t={report.sim_t_s:.3f} s is in {recorder.path}" if recorder is not None else "no bag"
        if self.signum is None:
            return (
                f"the step at t={report.sim_t_s:.3f} s has not returned for {report.stuck_s:.1f} s of wall time "
                f"(watchdog): stuck in {report.where}; {kept}"
            )
        name = signal.Signals(self.signum).name
        return f"stopped by {name} while the step at t={report.sim_t_s:.3f} s was stuck in {report.where}; {kept}"

    def exit_code(self) -> int:
        """8 for a stuck step, 130 for SIGINT, 128 + N for another signal."""
        if self.signum is None:
            return SimulationError.exit_code
        return Interrupted.exit_code if self.signum == signal.SIGINT else 128 + self.signum

    def error(self) -> SimulationError | Interrupted:
        """The error the command raises once the main thread has unwound."""
        err: SimulationError | Interrupted = (
            SimulationError(self.message()) if self.signum is None else Interrupted(self.message())
        )
        if self.signum is not None and self.signum != signal.SIGINT:
            err.exit_code = 128 + self.signum  # type: ignore[misc]
        return err

    def on_stuck(self, report: StuckReport) -> None:
        """Watchdog callback: a step (or constructor) is stuck."""
        self._abort(report, None)

    def on_signal(self, signum: int, report: StuckReport) -> None:
        """Watchdog callback: a signal arrived while the main thread could not see it."""
        self._abort(report, signum)

    def _abort(self, report: StuckReport, signum: int | None) -> None:
        from twin.sim.launch import constructing_node
        from twin.sim.watchdog import interrupt_main_thread

        self.report, self.signum = report, signum
        if self.sim is None:
            self.constructing = constructing_node(self.main)
        interrupt_main_thread(self.main, signum)  # a Python loop unwinds: the main thread closes the bag
        if self.done.wait(UNWIND_S):
            return
        # The main thread is inside a C call and cannot unwind: save the bag from here and end the process.
        try:
            if self.sim is not None and self.sim.recorder is not None:
                self.sim.recorder.close()
        except BaseException as err:  # the process ends either way; say what happened
            print(f"twin: error: closing the bag failed: {err}", file=sys.stderr)
        if self.debug:
            print(f"twin: stuck main thread:\n{report.stack}", file=sys.stderr, end="")
        print(f"twin: error: {self.message()}", file=sys.stderr)
        sys.stderr.flush()
        sys.stdout.flush()
        os._exit(self.exit_code())


def build_watched(build: Callable[[], T], *, timeout_s: float, debug: bool) -> T:
    """Call `build()` (a Simulation's constructor) under a watchdog that ends a user node's stuck constructor.

    Time spent anywhere else in the build counts as progress: only a constructor that has not
    returned for `timeout_s` wall seconds is stuck.

    Raises:
        SimulationError: Naming the node class and where it was stuck (exit 8).
        Interrupted: If a signal arrived while it was stuck.
    """
    from twin.sim.launch import constructing_node
    from twin.sim.watchdog import Watchdog, WatchdogAbort

    guard = Guard(None, debug=debug)
    ticks = [0.0]

    def progress() -> float:
        if constructing_node(guard.main) is None:
            ticks[0] += 1.0
        return ticks[0]

    watchdog = Watchdog(progress, timeout_s=timeout_s, on_stuck=guard.on_stuck, on_signal=guard.on_signal)
    try:
        with watchdog:
            return build()
    except WatchdogAbort:
        if guard.report is None:  # not ours: never hide an exception
            raise
        if debug:
            print(f"twin: stuck main thread:\n{guard.report.stack}", file=sys.stderr, end="")
        raise guard.error() from None
    finally:
        guard.done.set()
