"""`twin --help` starts at once: building the parser imports no heavy library (timings: bench_startup.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO, run_twin
from twin.cli import _COMMAND_MODULES

# Libraries whose import costs a tenth of a second or more; a command imports them when it runs.
HEAVY = (
    "numpy",
    "scipy",
    "filterpy",
    "trimesh",
    "fcl",
    "fmpy",
    "rosbags",
    "matplotlib",
    "control",
    "dask",
    "distributed",
    "pyarrow",
    "foxglove",
    "twin.sim",
    "twin.world",
    "twin.nav",
    "twin.robot",
    "twin.estimation",
    "twin.cosim",
    "twin.bt",
    "twin.mission",
)


def _imported_by(code: str) -> set[str]:
    probe = f"import sys\n{code}\nimport json\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return set(json.loads(out.stdout.splitlines()[-1]))


def _heavy(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if m.split(".")[0] in HEAVY or any(m.startswith(f"{h}.") for h in HEAVY))


def test_building_the_full_parser_imports_no_heavy_library() -> None:
    modules = _imported_by("from twin.cli import build_parser\nbuild_parser()")
    assert _heavy(modules) == []


@pytest.mark.parametrize("command", _COMMAND_MODULES)
def test_each_command_help_imports_no_heavy_library(command: str) -> None:
    code = f"from twin.cli import main\ntry:\n    main([{command!r}, '--help'])\nexcept SystemExit:\n    pass\n"
    assert _heavy(_imported_by(code)) == []


def test_a_named_command_loads_only_its_own_module() -> None:
    code = "from twin.cli import main\ntry:\n    main(['scenario', '--help'])\nexcept SystemExit:\n    pass\n"
    loaded = {m for m in _imported_by(code) if m.startswith("twin.cli.")}
    assert loaded == {"twin.cli.scenario"}


def test_top_level_help_still_lists_every_command() -> None:
    result = run_twin("--help")
    assert result.returncode == 0
    for command in _COMMAND_MODULES:
        assert command in result.stdout


def test_a_mistyped_command_is_named_with_the_valid_ones() -> None:
    result = run_twin("simulat")
    assert result.returncode == 2
    assert "invalid choice: 'simulat'" in result.stderr
    assert "simulate" in result.stderr


def test_fmu_profiles_spelled_in_the_cli_match_the_contract() -> None:
    from twin.cli.fmu import PROFILES
    from twin.cosim.contract import Profile

    assert tuple(p.value for p in Profile) == PROFILES


# What a default run does not use, so its first step must not wait for their import (each costs
# 0.02 s to 1 s): trimesh (the house is boxes), scipy.signal and scipy.stats (the IMU's drift is
# computed without them), the bag readers (a run only writes), urllib (URDF quoting), filterpy (the
# reference EKF), plots, Dask.
NOT_FOR_A_DEFAULT_RUN = (
    "trimesh",
    "scipy.signal",
    "scipy.stats",
    "rosbags.rosbag2",
    "twin.bag.reader",
    "urllib.request",
    "filterpy",
    "control",
    "matplotlib",
    "dask",
    "distributed",
)

_FIRST_STEP = """
from pathlib import Path
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation

class _First(Exception):
    pass

def _stop(sim_s, messages):
    raise _First

with Simulation(load_scenario({scenario}), bag_path=Path({bag!r}), duration_s=1.0) as sim:
    try:
        sim.run(progress=_stop)
    except _First:
        pass
"""


@pytest.mark.parametrize("scenario", ["default", "house_tour"])
def test_a_run_reaches_its_first_step_without_the_libraries_it_does_not_use(scenario: str, tmp_path: Path) -> None:
    path = (
        "default_scenario_path()"
        if scenario == "default"
        else f"Path({str(REPO / 'scenarios' / scenario)!r} + '.yaml')"
    )
    modules = _imported_by(_FIRST_STEP.format(scenario=path, bag=str(tmp_path / "bag")))
    assert "twin.sim.simulation" in modules
    assert sorted(m for m in modules if m in NOT_FOR_A_DEFAULT_RUN or m.split(".")[0] in NOT_FOR_A_DEFAULT_RUN) == []


@pytest.mark.parametrize(
    "mission",
    [
        "{type: cmd_vel_script, segments: [{duration_s: 1, linear_mps: 0.1}]}",
        "{type: waypoints, points: [[1.0, 0.0]]}",
        "{type: none}",
    ],
)
def test_a_mission_that_does_not_navigate_builds_and_imports_no_map_localization_or_nav2_stack(
    mission: str, tmp_path: Path
) -> None:
    scenario = tmp_path / "drive.yaml"
    scenario.write_text(f"name: drive\nmission: {mission}\n")
    code = _FIRST_STEP.format(scenario=f"Path({str(scenario)!r})", bag=str(tmp_path / "bag"))
    modules = _imported_by(code + "\nassert sim.navigation is None\n")
    assert "twin.sim.simulation" in modules
    unused = {"navigation", "amcl", "map_server", "costmap_2d", "planner", "controller", "bt_navigator", "params"}
    assert sorted(m for m in modules if m.startswith("twin.") and unused & set(m.split("."))) == []
