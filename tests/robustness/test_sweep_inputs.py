"""Sweeps that fail early and say so.

Found by probing: a scenario whose node module sits beside it failed every run ("module not
found": the per-run scenario is written elsewhere) and the sweep exited 0; an unwritable `--out`
(a file, `/dev/null`, read-only storage) failed with exit 70 after every run had run; a
`--scheduler` that is not Dask gave exit 70 ("3.07 EiB") or waited for ever, and refused addresses
were followed by a 20 s hang and a traceback. Now: the scenario's folder stays on each run's module
path; a sweep whose runs did not complete exits 1 naming them; `--out` and `--scheduler` are
checked before any cluster or run starts (one line, exit 2).
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.integration.sweep_helpers import read_table, write_inputs
from tests.robustness.helpers import assert_one_line_error
from twin.cli import main

ONE_RUN = "scenario: base.yaml\ntimeout_s: 900\n"
_SWEEP = [sys.executable, "-m", "twin", "sweep"]


@pytest.mark.parametrize("where", ["file", "dev_null", "proc"])
def test_an_unwritable_out_is_refused_before_any_run(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sweep = write_inputs(tmp_path, ONE_RUN)
    out = {"file": tmp_path / "a_file", "dev_null": Path("/dev/null"), "proc": Path("/proc/twin-sweep-out")}[where]
    if where == "file":
        out.write_text("not a folder\n")
    code = main(["sweep", str(sweep), "--out", str(out), "--workers", "1"])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert_one_line_error(err, contains=f"--out {out}: ")
    assert not (tmp_path / "runs").exists()


@contextlib.contextmanager
def _server(greeting: bytes | None) -> Iterator[int]:
    """A TCP server on a free port that accepts connections and sends `greeting` (or nothing)."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    stop = threading.Event()
    held: list[socket.socket] = []

    def serve() -> None:
        listener.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            held.append(conn)
            if greeting is not None:
                conn.sendall(greeting)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield port
    finally:
        stop.set()
        thread.join(timeout=5)
        for conn in held:
            conn.close()
        listener.close()


@pytest.mark.parametrize(
    ("server", "address", "contains"),
    [
        ("silent", "tcp://127.0.0.1:{port}", "sent no Dask handshake"),
        ("silent", "127.0.0.1:{port}", "sent no Dask handshake"),
        ("banner", "tcp://127.0.0.1:{port}", "speaks another protocol"),
        (None, "foo", "no port"),
        (None, "http://127.0.0.1:8787", "http:// is not a Dask protocol"),
        (None, "", "empty"),
    ],
    ids=["web_server", "web_server_no_scheme", "ssh_banner", "no_port", "http", "empty"],
)
def test_a_scheduler_that_is_not_dask_is_one_line_and_no_hang(
    server: str | None, address: str, contains: str, tmp_path: Path
) -> None:
    sweep = write_inputs(tmp_path, ONE_RUN)
    greeting = {"silent": None, "banner": b"SSH-2.0-OpenSSH_9.6\r\n", None: None}[server]
    with _server(greeting) as port:
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        proc = subprocess.run(
            [*_SWEEP, str(sweep), "--scheduler", address.format(port=port), "--out", str(tmp_path / "out")],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,  # generous: only bounds a hang
            check=False,
        )
    assert proc.returncode == 2, proc.stderr
    assert_one_line_error(proc.stderr, contains=contains)
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr
    assert not (tmp_path / "out" / "runs").exists()


_QUIET_NODE = """
from twin.node import Node

class Quiet(Node):
    def __init__(self):
        super().__init__("quiet")
"""


def test_a_node_module_beside_the_scenario_works_in_a_sweep(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sweep = write_inputs(tmp_path, ONE_RUN)
    (tmp_path / "quiet_node.py").write_text(_QUIET_NODE)
    base = tmp_path / "base.yaml"
    base.write_text(base.read_text() + "nodes: [{plugin: quiet_node:Quiet}]\n")
    code = main(["sweep", str(sweep), "--out", str(tmp_path / "out"), "--workers", "1"])
    _, err = capsys.readouterr()
    assert code == 0, err
    (row,) = read_table(tmp_path / "out")
    assert row["outcome"] == "success", row["reason"]


def test_a_sweep_whose_runs_did_not_complete_exits_1_naming_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sweep = write_inputs(tmp_path, "scenario: base.yaml\nvary: {robot.model: [no_such_robot]}\ntimeout_s: 900\n")
    code = main(["sweep", str(sweep), "--out", str(tmp_path / "out"), "--workers", "1"])
    out, err = capsys.readouterr()
    assert code == 1, err
    assert "1 runs: 0 succeeded" in out
    line = assert_one_line_error(err, contains="1 of 1 runs did not complete (1 error); first, r0000: ")
    assert "no_such_robot" in line
    (row,) = read_table(tmp_path / "out")
    assert row["outcome"] == "error"


@pytest.mark.parametrize(
    ("body", "contains"),
    [
        ("runs: 1000000000", "runs: 1000000000 runs is more than a sweep makes (at most 100000)"),
        ("seeds: [-3]", "seeds: -3: must be a non-negative whole number"),
        ("timeout_s: 1e300", "timeout_s: 1e+300 s is out of range"),
        (
            "vary: {robot.initial_pose.x_m: [" + ", ".join(map(str, range(400))) + "],"
            " robot.initial_pose.y_m: [" + ", ".join(map(str, range(400))) + "]}",
            "vary: 160000 combinations x 1 seeds is more runs than a sweep makes",
        ),
    ],
    ids=["runs_1e9", "negative_seed", "timeout_1e300", "grid_160000"],
)
def test_sweep_numbers_are_bounded_before_any_cluster(
    body: str, contains: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sweep = write_inputs(tmp_path, f"scenario: base.yaml\n{body}\n")
    code = main(["sweep", str(sweep), "--out", str(tmp_path / "out"), "--workers", "1"])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert_one_line_error(err, contains=contains)


def test_a_refused_sweep_file_leaves_no_out_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sweep = write_inputs(tmp_path, ONE_RUN + "zip: true\nvary:\n  seed: [1, 2]\n  max_duration_s: [5]\n")
    out = tmp_path / "new" / "out"
    code = main(["sweep", str(sweep), "--out", str(out), "--workers", "1"])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert_one_line_error(err, contains="zip: true pairs the lists, but their lengths differ")
    assert not (tmp_path / "new").exists()
