"""`twin simulate` builds its run without the cyclic collector and runs its loop with it on again."""

from __future__ import annotations

import gc
import subprocess
import sys

from tests.conftest import REPO
from twin.core import gcpolicy


def test_defer_then_resume_freezes_what_was_built_and_collects_again() -> None:
    assert gc.isenabled()
    gcpolicy.defer_collection()
    try:
        assert not gc.isenabled()
        built = [[i] for i in range(1000)]  # what a start-up makes and keeps
    finally:
        gcpolicy.resume_collection()
    try:
        assert gc.isenabled()
        assert gc.get_freeze_count() >= len(built)
        gcpolicy.resume_collection()  # a second resume changes nothing
        assert gc.isenabled()
    finally:
        gc.unfreeze()


def test_resume_without_defer_leaves_a_disabled_collector_alone() -> None:
    gc.disable()
    try:
        gcpolicy.resume_collection()
        assert not gc.isenabled()  # the user turned it off: twin does not turn it on
    finally:
        gc.enable()


def test_the_simulate_entry_point_runs_its_loop_with_the_collector_on() -> None:
    # The console entry (twin.cli.run) defers collection for simulate: the run is built with the collector off
    # and its loop starts with it on again.
    code = (
        "import gc, sys\n"
        "from twin.sim import simulation\n"
        "seen = []\n"
        "init = simulation.Simulation.__init__\n"
        "def building(self, *a, **k):\n"
        "    seen.append(gc.isenabled())\n"
        "    init(self, *a, **k)\n"
        "simulation.Simulation.__init__ = building\n"
        "spin = simulation.Executor.spin\n"
        "def watched(self, *a, **k):\n"
        "    seen.append(gc.isenabled())\n"
        "    return spin(self, *a, **k)\n"
        "simulation.Executor.spin = watched\n"
        "sys.argv = ['twin', 'simulate', '--duration', '0.2', '--out', sys.argv[1]]\n"
        "from twin.cli import run\n"
        "try:\n"
        "    run()\n"
        "except SystemExit as end:\n"
        "    assert end.code == 0, end.code\n"
        "print('seen', seen, gc.isenabled())\n"
    )
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run(
            [sys.executable, "-c", code, f"{tmp}/bag"], cwd=REPO, capture_output=True, text=True, check=False
        )
    assert out.returncode == 0, out.stderr
    seen = [line for line in out.stdout.splitlines() if line.startswith("seen ")]
    assert seen == ["seen [False, True] True"], out.stdout  # built without it, looped and ended with it
