"""Generated Nav2 params files and maps: never an exit 70, a traceback, a run past 60 s or past 2 GB.

`scenario check` runs in-process on many generated cases (it reads the params file, the map and its
image as `simulate` does, and sizes every costmap, particle set and DWB sample grid against the
machine's memory before anything is allocated); a few cases that set a sizing or rate parameter to
a breaking value run whole (`twin simulate` for 2 s of sim time in a process limited to 2 GiB of
address space and 60 s). `benchmarks/fuzz_nav2_inputs.py`
runs more of both.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings

from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from tests.robustness.nav2_fuzz import cases, risky_cases, whole_run, write_case
from twin.cli import main

Case = tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=cases)
def test_scenario_check_on_generated_params_and_maps(case: Case, capsys: pytest.CaptureFixture[str]) -> None:
    folder = Path(tempfile.mkdtemp(prefix="twin-nav2-gen-"))
    try:
        code = main(["scenario", "check", str(write_case(case, folder))])
        err = capsys.readouterr().err
        assert code in (0, 2), err
        assert "Traceback" not in err and "internal error" not in err, err
        if code:
            assert_one_line_error(err)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@settings(max_examples=6, deadline=None, derandomize=True, database=None)
@given(case=risky_cases)
def test_whole_runs_on_generated_inputs_stay_within_2_gib_and_60_s(case: Case) -> None:
    folder = Path(tempfile.mkdtemp(prefix="twin-nav2-run-"))
    try:
        bag = folder / "bag"
        code, stderr, _ = whole_run(write_case(case, folder), bag)
        assert code >= 0, f"killed (signal {-code}) under 2 GiB / 60 s: {stderr[-2000:]}"
        assert code in (0, 1, 2), stderr
        assert "Traceback" not in stderr and "internal error" not in stderr, stderr
        if code == 2:
            assert_one_line_error(stderr)
            assert not bag.exists()
        else:
            assert_bag_reads_back(bag)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
