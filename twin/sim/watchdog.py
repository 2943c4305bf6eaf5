"""The watchdog: a thread that notices a simulation step that does not return, and signals that must not wait.

A run's main thread can get stuck in two ways: in a Python loop (a behaviour tree whose `Repeat
num_cycles="-1"` over `AlwaysSuccess` never returns RUNNING, a user node that never returns) or in
a C call (a vendor FMU's `fmi2DoStep` called through ctypes, which releases the GIL). In both, the
simulation time stops advancing, and SIGINT/SIGTERM are not acted on: Python runs signal handlers
only in the main thread between bytecodes, and the run loop polls its stop flag only between steps.

The watchdog watches the public sim time (`progress()`, e.g. `lambda: sim.t_s`) from its own thread:

- If it has not advanced for `timeout_s` of wall time, the watchdog describes what the main thread
  is doing (its innermost frames, from `sys._current_frames()`; a tree node or FMU call by name) and
  calls `on_stuck(report)`.
- Signals reach it through `signal.set_wakeup_fd` (written by the C-level handler even while the main
  thread is inside a C call). If the sim time then stops advancing for `signal_grace_s`, the main
  loop will not see the signal in time, and the watchdog calls `on_signal(signum, report)`.

What the callbacks do is the caller's choice (`twin simulate` first asks the main thread to unwind
with `interrupt_main_thread`, then, if it is in C, closes the bag and ends the process). The watchdog
itself never prints and never exits.
"""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from types import FrameType

__all__ = ["StuckReport", "Watchdog", "WatchdogAbort", "describe_thread", "interrupt_main_thread"]

_POLL_S = 0.05
_TWIN_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class WatchdogAbort(BaseException):
    """Raised asynchronously in the main thread to unwind a stuck step.

    A BaseException, so that no `except Exception` in a node or FMU wrapper swallows it.

    Attributes:
        signum: The signal that asked for the stop, or None when the step timed out.
    """

    signum: int | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class StuckReport:
    """What the main thread was doing when the watchdog looked.

    Attributes:
        sim_t_s: The sim time the run was stuck at, s.
        stuck_s: Wall seconds since the sim time last advanced.
        where: One line: the innermost function (file:line), and the tree node or FMU call if known.
        stack: The main thread's full stack, formatted (for `--debug`).
    """

    sim_t_s: float
    stuck_s: float
    where: str
    stack: str


def _tree_node(node: object) -> str:
    """Name a behaviour-tree node ("tree node 'path' (type)"), or "" for anything else."""
    full_path = getattr(node, "full_path", None)
    if not isinstance(full_path, str):
        return ""
    registration = getattr(node, "registration_name", None)
    kind = f" ({registration})" if isinstance(registration, str) else ""
    return f"tree node '{full_path}'{kind}"


def _node_of(frame: FrameType) -> str:
    """Name a behaviour-tree node or FMU call that a frame belongs to, if it does."""
    owner = frame.f_locals.get("self")
    node = _tree_node(owner)
    if node:
        return node
    root = _tree_node(getattr(owner, "root", None))  # the tree itself, between ticks of its root (a wake-up loop)
    if root:
        return f"{root} ticked again and again by its tree"
    name = frame.f_code.co_name
    label = getattr(getattr(owner, "_file", None), "label", None)  # an FMU drive (its compiled loop's closure too)
    if isinstance(label, str):
        return (
            f"the drive's FMU {label} (a step of it that does not return; drive.isolation: process with "
            "drive.step_timeout_s ends such a run in one line)"
        )
    if name.lower().endswith(("dostep", "do_step")) or "fmi" in frame.f_code.co_filename.lower():
        return f"FMU call {name}"
    return ""


def describe_thread(ident: int) -> tuple[str, str]:
    """Return (one-line location, full formatted stack) of thread `ident`'s current frame."""
    frame = sys._current_frames().get(ident)
    if frame is None:
        return ("the thread has ended", "")
    stack = "".join(traceback.format_stack(frame))
    innermost = frame
    where = f"{innermost.f_code.co_name} ({innermost.f_code.co_filename}:{innermost.f_lineno})"
    # The innermost named node or FMU call (the step's owner), searching outwards.
    node = ""
    f: FrameType | None = frame
    while f is not None and not node:
        node = _node_of(f)
        f = f.f_back
    if not node:  # else the innermost frame of twin's own code, which names the subsystem
        f = frame
        while f is not None and not f.f_code.co_filename.startswith(_TWIN_DIR):
            f = f.f_back
        if f is not None and f is not frame:
            node = f"called from {f.f_code.co_name} ({os.path.relpath(f.f_code.co_filename, _TWIN_DIR)}:{f.f_lineno})"
    return (f"{where}{', ' + node if node else ''}", stack)


def interrupt_main_thread(ident: int, signum: int | None = None) -> None:
    """Raise `WatchdogAbort` in thread `ident` at its next bytecode (does nothing while it is in a C call)."""
    exc = type("WatchdogAbort", (WatchdogAbort,), {"signum": signum})
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident), ctypes.py_object(exc))


class Watchdog:
    """Watch a run's sim time from a thread; use as a context manager around `Simulation.run`.

    Args:
        progress: Returns the sim time reached, s (read from the watchdog thread).
        timeout_s: Wall seconds without progress that make a step stuck (`inf`: only watch signals).
        on_stuck: Called once, from the watchdog thread, when a step is stuck.
        on_signal: Called once, from the watchdog thread, when SIGINT/SIGTERM arrived and the sim time
            then did not advance for `signal_grace_s` (the run loop cannot see the signal).
        signal_grace_s: See `on_signal`.
        signals: The signals to watch; the caller installs their Python handlers as usual.

    Construct and enter it in the main thread (it installs `signal.set_wakeup_fd`).
    """

    def __init__(
        self,
        progress: Callable[[], float],
        *,
        timeout_s: float,
        on_stuck: Callable[[StuckReport], None],
        on_signal: Callable[[int, StuckReport], None],
        signal_grace_s: float = 1.0,
        signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM),
    ) -> None:
        if not timeout_s > 0:
            msg = f"timeout_s must be positive, got {timeout_s}"
            raise ValueError(msg)
        self._progress = progress
        self._timeout_s = timeout_s
        self._on_stuck = on_stuck
        self._on_signal = on_signal
        self._grace_s = signal_grace_s
        self._signals = frozenset(signals)
        self._main = threading.main_thread().ident or threading.get_ident()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._rsock: socket.socket | None = None
        self._wsock: socket.socket | None = None
        self._old_fd = -1
        self.fired = False

    def __enter__(self) -> Watchdog:
        self._rsock, self._wsock = socket.socketpair()
        self._rsock.setblocking(False)
        self._wsock.setblocking(False)
        self._old_fd = signal.set_wakeup_fd(self._wsock.fileno(), warn_on_full_buffer=False)
        self._thread = threading.Thread(target=self._watch, name="twin-watchdog", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        """End the watch (from the main thread) and restore the previous wakeup fd."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        if self._wsock is not None:
            signal.set_wakeup_fd(self._old_fd)
            self._wsock.close()
            self._wsock = None
        if self._rsock is not None:
            self._rsock.close()
            self._rsock = None

    def _report(self, sim_t_s: float, since: float) -> StuckReport:
        where, stack = describe_thread(self._main)
        return StuckReport(sim_t_s=sim_t_s, stuck_s=time.monotonic() - since, where=where, stack=stack)

    def _signals_arrived(self) -> list[int]:
        assert self._rsock is not None
        try:
            data = self._rsock.recv(64)
        except (BlockingIOError, InterruptedError, OSError):
            return []
        return [b for b in data if b in self._signals]

    def _watch(self) -> None:
        last_t = self._progress()
        last_change = time.monotonic()
        pending_signal: int | None = None
        signal_since = 0.0
        while not self._stop.wait(_POLL_S):
            now = time.monotonic()
            t = self._progress()
            if t != last_t:
                last_t, last_change = t, now
                if pending_signal is not None:
                    signal_since = now  # the loop moves: it will see the stop flag itself
            arrived = self._signals_arrived()
            if arrived and pending_signal is None:
                pending_signal, signal_since = arrived[-1], now
            if self._stop.is_set():
                return
            if (
                pending_signal is not None
                and now - signal_since >= self._grace_s
                and now - last_change >= self._grace_s
            ):
                self.fired = True
                self._on_signal(pending_signal, self._report(t, last_change))
                return
            if now - last_change >= self._timeout_s:
                self.fired = True
                self._on_stuck(self._report(t, last_change))
                return
