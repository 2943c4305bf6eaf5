"""`twin scenario check FILE`: load a scenario and report what it would run, or the first problem."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

_CHECK_EPILOG = """\
examples:
  twin scenario check scenarios/house_burger.yaml          valid: prints what it would run, exit 0
  twin scenario check my.yaml --json                       the resolved scenario, for a script
  twin scenario check bad.yaml                             a problem: one line, e.g.
    twin: error: bad.yaml:2: drive.type: unknown type 'kinematc'; did you mean 'kinematic'?
  for f in scenarios/*.yaml; do twin scenario check "$f" >/dev/null || exit 1; done   in CI
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `scenario` command group."""
    parser = subparsers.add_parser(
        "scenario",
        help="check scenario files",
        description="Scenario files: one YAML file per run, laid over the packaged defaults.",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="scenario_command", metavar="SUBCOMMAND", required=True)
    check = sub.add_parser(
        "check",
        help="load a scenario and print it resolved, or name the first problem (file:line: key: fix)",
        description=(
            "Load FILE over the packaged defaults, check every value as `twin simulate` would (NaN, "
            "infinite, negative or out-of-range numbers, rates above the physics rate), load every file it "
            "names (world, robot, tree, locations, FMU mapping) and print the resolved scenario. Exit 0 when "
            "it is valid; else one line naming file, key and fix, exit 2 (3 world, 4 FMU, 6 tree)."
        ),
        epilog=_CHECK_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    check.add_argument("file", type=Path, metavar="FILE", help="scenario YAML file")
    check.add_argument("--json", action="store_true", help="print the resolved scenario as JSON")
    check.set_defaults(func=_check)


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if hasattr(value, "items"):
        return {str(k): _plain(v) for k, v in value.items()}
    return value


def _drive_text(scenario: Any, model_name: str) -> str:
    """The drive as the run resolves it: `fmu: auto` names the motor FMU of the robot (its model's name)."""
    from twin.robot.fmu_drive import builtin_motor

    drive = scenario.drive
    if drive.type != "fmu":
        return str(drive.type)
    fmu = drive.fmu_file or drive.fmu
    if fmu == "auto":
        fmu = f"{builtin_motor(model_name, drive.profile)} (auto)"
    return f"fmu {fmu}, {drive.profile}"


def _mission_text(scenario: Any) -> str:
    """The mission with the files it reads."""
    mission = scenario.mission
    files = [getattr(mission, key, None) for key in ("tree", "locations", "bag")]
    named = ", ".join(str(f) for f in files if f is not None)
    return f"{mission.type} {named}" if named else str(mission.type)


def _navigation_text(scenario: Any, model_name: str) -> str | None:
    """The Nav2 params file and navigator tree a run reads (None: the run uses no Nav2)."""
    from twin.nav.params import default_params_path
    from twin.sim.navigation import DEFAULT_BT_XML
    from twin.sim.scenario import runs_amcl, runs_nav2

    if not (runs_nav2(scenario) or runs_amcl(scenario)):
        return None
    nav = scenario.navigation
    params = nav.params if nav.params is not None else default_params_path(model_name)
    tree = f", tree {nav.bt_xml or DEFAULT_BT_XML}" if runs_nav2(scenario) else ""
    localizer = "AMCL" if runs_amcl(scenario) else "none (map = odom)"
    return f"params {params}{tree}, map {scenario.map}, localization {localizer}"


def _check(args: argparse.Namespace) -> int:
    from twin.sim.check import check_inputs, check_scenario
    from twin.sim.scenario_file import load_scenario

    scenario = load_scenario(args.file)
    check_scenario(scenario, args.file)
    names = check_inputs(scenario, args.file)
    if args.json:
        print(json.dumps(_plain(scenario), indent=2))
        return 0
    print(f"{args.file}: ok")
    print(f"  name      {scenario.name}")
    print(f"  world     {scenario.world.sdf}")
    if scenario.robots:  # a fleet: each robot under its namespace, with its own sections
        print(f"  robots    {len(scenario.robots)}, frames {scenario.tf.mode}")
        for ns, robot in scenario.robot_scenarios():
            print(
                f"    /{ns:<12} {robot.robot.model} at {dataclasses.astuple(robot.robot.initial_pose)}, "
                f"drive {robot.drive.type}, mission {robot.mission.type}"
            )
    else:
        print(f"  robot     {scenario.robot.model} at {dataclasses.astuple(scenario.robot.initial_pose)}")
        print(f"  drive     {_drive_text(scenario, names[0])}")
        print(f"  mission   {_mission_text(scenario)}")
        navigation = _navigation_text(scenario, names[0])
        if navigation:
            print(f"  nav2      {navigation}")
    print(f"  recording {scenario.recording.storage} ({scenario.recording.distro}) in {scenario.recording.out_dir}")
    print(f"  seed      {scenario.seed}, at most {scenario.max_duration_s:g} s")
    return 0
