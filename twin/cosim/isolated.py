"""FMU instances stepped in a child process, so that a crash or a hang in vendor code ends the run cleanly.

`IsolatedGroup` starts one child process per FMU file; the child loads the FMU and creates the
instances (e.g. the left and right wheel). Inputs and outputs live in a shared memory map: the
parent writes the inputs into `Stepper.inputs`, `step_next` sends one byte through a pipe, the child
steps every instance and answers with one byte, and the parent reads `Stepper.outputs`. A child
that dies (a segfault, an abort) or does not answer within `timeout_s` (a hang) raises `FmuError`
naming the FMU, the sim time and what happened; the child is killed. An FMU that reports an error
status is reported as in-process (`twin.cosim.adapter`). The FMU's own log messages are sent to the
parent ahead of each reply and logged there (so they reach the console and `/rosout` as in-process).

The group has the interface of `twin.cosim.step_group.StepGroup` that the Python step loops use
(`step_next`, `raise_failure`, `index`, `compiled`, `shim`), so the drivetrain steps it unchanged.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import mmap
import os
import signal
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.core.errors import FmuError
from twin.cosim.fmu import FmuFile

if TYPE_CHECKING:
    import multiprocessing.connection

__all__ = ["IsolatedGroup", "IsolatedStepper"]

_log = logging.getLogger(__name__)

_STEP = b"s"
_OK = b"k"
_CLOSE = b"c"
_LOG = b"\x01"  # a log record of the FMU, forwarded before the reply: level, logger name, message
_D = ctypes.sizeof(ctypes.c_double)
_START_TIMEOUT_S = 120.0  # the child imports fmpy and twin.cosim, and loads the FMU


class IsolatedStepper:
    """One instance in the child: its input and output buffers are views of the shared map."""

    def __init__(
        self, name: str, inputs: ctypes.Array[ctypes.c_double], outputs: ctypes.Array[ctypes.c_double]
    ) -> None:
        """Wrap the buffers of the instance `name`."""
        self.name = name
        self.inputs = inputs
        self.outputs = outputs

    def step(self, t_s: float) -> None:
        """Refused: an isolated instance steps with its group, all instances in one round trip.

        Raises:
            RuntimeError: Always; call `IsolatedGroup.step` instead.
        """
        msg = f"isolated FMU instance {self.name!r} steps only with its group (IsolatedGroup.step)"
        raise RuntimeError(msg)

    def read_outputs(self) -> None:
        """The child writes the outputs into the shared map; nothing to do."""

    def close(self) -> None:
        """The group closes the child."""


def _signal_name(exitcode: int | None) -> str:
    if exitcode is None:
        return "did not answer"
    if exitcode < 0:
        try:
            return f"died with {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"died with signal {-exitcode}"
    return f"exited with status {exitcode}"


class IsolatedGroup:
    """The instances of one FMU file in a child process, stepped together one communication step at a time."""

    def __init__(
        self,
        path: Path,
        label: str,
        names: Sequence[str],
        *,
        step_s: float,
        inputs: Sequence[int],
        outputs: Sequence[int],
        start: Mapping[str, float],
        timeout_s: float,
        process_per_instance: bool = False,
        log_name: str = "fmu",
    ) -> None:
        """Start the child, load `path` there and create one instance per name.

        Args:
            path: The .fmu file.
            label: `model (file)`, for messages.
            names: Instance names (e.g. left, right).
            step_s: Communication step, s.
            inputs: Input value references, written from each stepper's `inputs`.
            outputs: Output value references, read into each stepper's `outputs`.
            start: Start values (FMU names and units).
            timeout_s: Longest wall time one step of all instances may take before the FMU counts as hung.
            process_per_instance: One child process per instance, for an FMU that may be instantiated
                only once per process (`canBeInstantiatedOnlyOncePerProcess`); the children step in parallel.
            log_name: Where the instances' log messages go (`twin.cosim.adapter.fmu_logger`).

        Raises:
            FmuError: If the child cannot start, or the FMU cannot be loaded or instantiated there.
        """
        self._label = label
        self._h = float(step_s)
        self._timeout_s = float(timeout_s)
        self._index = 0
        self._failure = ""
        n_in, n_out, n = max(1, len(inputs)), max(1, len(outputs)), len(names)
        size = _D * (1 + n * (n_in + n_out))
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else None
        with tempfile.NamedTemporaryFile(prefix="twin-fmu-", dir=folder, delete=False) as backing:
            backing.truncate(size)
            self._map_path = backing.name
        with open(self._map_path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), size)
        self._time = ctypes.c_double.from_buffer(self._map, 0)
        self.steppers: tuple[IsolatedStepper, ...] = tuple(
            IsolatedStepper(
                f"{label} instance {name!r}",
                (ctypes.c_double * n_in).from_buffer(self._map, _D * (1 + k * n_in)),
                (ctypes.c_double * n_out).from_buffer(self._map, _D * (1 + n * n_in + k * n_out)),
            )
            for k, name in enumerate(names)
        )
        import multiprocessing  # only for an isolated FMU (tens of ms to import)

        context = multiprocessing.get_context("spawn")
        # The instances each child owns, by their position in `names` (and in the shared map).
        slots = [[k] for k in range(n)] if process_per_instance else [list(range(n))]
        self._children: list[_Child] = []
        try:
            for owned in slots:
                conn, child_conn = context.Pipe()
                spec = {
                    "path": str(path),
                    "map_path": self._map_path,
                    "size": size,
                    "names": list(names),
                    "slots": owned,
                    "step_s": self._h,
                    "inputs": list(inputs),
                    "outputs": list(outputs),
                    "start": dict(start),
                    "log_name": log_name,
                    "fmu_log_level": logging.getLogger(f"twin.node.{log_name}").getEffectiveLevel(),
                }
                process = context.Process(target=_child_main, args=(spec, child_conn), daemon=True)
                child = _Child(process, conn, owned)
                self._children.append(child)
                process.start()
                child_conn.close()
            for child in self._children:
                if not child.conn.poll(_START_TIMEOUT_S):
                    self._fail_hard(child, "did not start", 0.0)
                reply = self._reply(child, 0.0, "starting", _START_TIMEOUT_S)
                if reply != _OK:
                    self.close()
                    raise FmuError(reply.decode("utf-8", "replace"))
        except BaseException:
            self.close()
            raise
        finally:
            Path(self._map_path).unlink(missing_ok=True)

    # --- the StepGroup interface ---

    compiled = False

    @property
    def size(self) -> int:
        """How many instances the group steps."""
        return len(self.steppers)

    @property
    def processes(self) -> int:
        """How many child processes step them (one, or one per instance)."""
        return len(self._children)

    @property
    def index(self) -> int:
        """Communication steps taken so far."""
        return self._index

    def shim(self) -> None:
        """No compiled loop steps an isolated group."""
        return

    def step_next(self) -> int:
        """Step every instance from `index * step_s`; -1, or the instance that reported an error.

        Raises:
            FmuError: If the child dies or does not answer within the timeout.
        """
        t_s = self._index * self._h
        self._time.value = t_s
        for child in self._children:
            try:
                child.conn.send_bytes(_STEP)
            except OSError:
                self._fail_hard(child, _signal_name(child.process.exitcode), t_s)
        failed = -1
        for child in self._children:  # every child answers before the next step, even after a failure
            if not child.conn.poll(self._timeout_s):
                self._fail_hard(child, f"did not finish a step within {self._timeout_s:g} s (hung)", t_s)
            reply = self._reply(child, t_s, "stepping", self._timeout_s)
            if reply != _OK and failed < 0:
                position, _, text = reply.partition(b"\0")
                self._failure = text.decode("utf-8", "replace")
                failed = child.slots[int(position)]
        if failed < 0:
            self._index += 1
        return failed

    def step(self) -> None:
        """Take one communication step.

        Raises:
            FmuError: If an instance fails or the child dies or hangs.
        """
        failed = self.step_next()
        if failed >= 0:
            self.raise_failure(failed)

    def raise_failure(self, failed: int) -> None:
        """Raise the FmuError the child reported for instance `failed`."""
        raise FmuError(self._failure or f"{self.steppers[failed].name} failed at t = {self._index * self._h:.6f} s")

    def _reply(self, child: _Child, t_s: float, doing: str, timeout_s: float) -> bytes:
        """Receive the child's reply, logging the FMU's log records it sends first."""
        reply = self._receive(child, t_s, doing)
        while reply[:1] == _LOG:
            level, name, text = reply[1:].decode("utf-8", "replace").split("\0", 2)
            logging.getLogger(name).log(int(level), "%s", text)
            if not child.conn.poll(timeout_s):
                self._fail_hard(child, f"did not finish a step within {timeout_s:g} s (hung)", t_s, doing)
            reply = self._receive(child, t_s, doing)
        return reply

    def _receive(self, child: _Child, t_s: float, doing: str) -> bytes:
        try:
            reply: bytes = child.conn.recv_bytes()
        except (EOFError, OSError):
            child.process.join(timeout=5.0)
            self._fail_hard(child, _signal_name(child.process.exitcode), t_s, doing)
        return reply

    def _fail_hard(self, child: _Child, what: str, t_s: float, doing: str = "stepping") -> None:
        where = "its own process"
        if len(self._children) > 1:  # one process per instance: say whose
            where = f"the process of instance {self.steppers[child.slots[0]].name.rsplit(' instance ', 1)[-1]}"
        self.close()
        msg = f"{self._label} in {where} {what} at t = {t_s:.6f} s while {doing}; the run stops here"
        raise FmuError(msg)

    def close(self) -> None:
        """Stop the children (politely, else by force) and release the map (idempotent)."""
        children, self._children = self._children, []
        for child in children:
            child.close()


class _Child:
    """One child process, the pipe to it and the instances it steps (positions in the group)."""

    def __init__(self, process: Any, conn: multiprocessing.connection.Connection, slots: list[int]) -> None:
        self.process = process
        self.conn = conn
        self.slots = slots

    def close(self) -> None:
        """Ask the child to stop, kill it if it does not, and close the pipe."""
        process = self.process
        if process.pid is not None and process.is_alive():
            with contextlib.suppress(OSError):
                self.conn.send_bytes(_CLOSE)
            process.join(timeout=2.0)
        if process.pid is not None and process.is_alive():
            process.kill()
            process.join(timeout=5.0)
        self.conn.close()


class _Forward(logging.Handler):
    """In the child: sends each FMU log record to the parent, ahead of the reply it belongs to."""

    def __init__(self, conn: multiprocessing.connection.Connection) -> None:
        super().__init__()
        self._conn = conn

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(OSError):  # the parent is gone: the step loop ends on its own
            self._conn.send_bytes(_LOG + f"{record.levelno}\0{record.name}\0{record.getMessage()}".encode())


def _child_main(spec: dict[str, Any], conn: multiprocessing.connection.Connection) -> None:
    """The child: load the FMU, answer each step request, exit on close or when the parent goes away."""
    # The parent handles Ctrl-C and SIGTERM (a process group's, as `timeout` or a shell's kill sends them)
    # and closes the child; the child taking SIGTERM itself read as the FMU dying.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    fmu_log = logging.getLogger(f"twin.node.{spec['log_name']}")
    fmu_log.setLevel(spec["fmu_log_level"])
    fmu_log.propagate = False
    fmu_log.addHandler(_Forward(conn))
    names, n, slots = spec["names"], len(spec["names"]), spec["slots"]
    n_in, n_out = max(1, len(spec["inputs"])), max(1, len(spec["outputs"]))
    with open(spec["map_path"], "r+b") as f:
        shared = mmap.mmap(f.fileno(), spec["size"])
    time_s = ctypes.c_double.from_buffer(shared, 0)
    ins = [(ctypes.c_double * n_in).from_buffer(shared, _D * (1 + k * n_in)) for k in slots]
    outs = [(ctypes.c_double * n_out).from_buffer(shared, _D * (1 + n * n_in + k * n_out)) for k in slots]
    try:
        fmu = FmuFile(Path(spec["path"]))
        steppers = [
            fmu.instantiate(
                names[k],
                step_s=spec["step_s"],
                inputs=spec["inputs"],
                outputs=spec["outputs"],
                start=spec["start"],
                log_name=spec["log_name"],
            )
            for k in slots
        ]
    except FmuError as err:
        conn.send_bytes(str(err).encode())
        return
    for stepper, out in zip(steppers, outs, strict=True):
        ctypes.memmove(out, stepper.outputs, _D * n_out)
    conn.send_bytes(_OK)
    size_in, size_out = _D * n_in, _D * n_out
    try:
        while True:
            try:
                request = conn.recv_bytes()
            except EOFError:
                break
            if request != _STEP:
                break
            t_s = time_s.value
            for k, stepper in enumerate(steppers):
                ctypes.memmove(stepper.inputs, ins[k], size_in)
                try:
                    stepper.step(t_s)
                except FmuError as err:
                    conn.send_bytes(f"{k}".encode() + b"\0" + str(err).encode())
                    break
                ctypes.memmove(outs[k], stepper.outputs, size_out)
            else:
                conn.send_bytes(_OK)
    finally:
        fmu.close()
