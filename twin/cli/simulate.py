"""`twin simulate [SCENARIO]`: run a scenario headless and record a ROS 2 bag."""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.cli.play import live_banner, speed_arg
from twin.cli.progress import Progress
from twin.cli.watch import Guard, build_watched
from twin.core.errors import BagFolderTaken, ConfigError, Interrupted, TwinError, WorldError
from twin.core.numbers import number_problem

if TYPE_CHECKING:
    from twin.sim.executor import Sink
    from twin.sim.scenario import Scenario
    from twin.sim.simulation import RunSummary

_EPILOG = """\
examples:
  twin simulate                                   the default scenario (house, Waffle), bag in bags/
  twin simulate scenarios/default.yaml --duration 60 --out /tmp/run1
  twin simulate my.yaml --seed 7 --storage sqlite3 --distro jazzy
  twin simulate --json | jq .bag_path             a machine-readable summary on stdout
  twin simulate --live                            watch it in Foxglove (ws://127.0.0.1:8765), in real time
  twin simulate --live --speed 5 --port 9000      five times faster, on another port
  twin simulate scenarios/house_two_waffles.yaml --live --namespace robot2   one robot of a fleet, as one robot's
  twin simulate --from-bag bags/run1 --out /tmp/rerun   re-run the scenario, seed and duration a bag recorded
  twin simulate --ros2 --ros2-role simulator      Gazebo's part on ROS 2 domain 0 (loopback), for your Nav2

The run ends when the mission ends, at --duration (or the scenario's max_duration_s), on
Ctrl-C / SIGTERM, or when the watchdog finds a step that has not returned for --watchdog-s wall
seconds (a hung FMU, a tree that never returns); in every case the bag is closed and readable.
The scenario is checked first (as `twin scenario check` does): a refused run creates no bag folder.

exit codes:
  0    the run ended: mission SUCCESS, --duration reached, or a mission with no result
  1    the mission ended in FAILURE (the summary names the goal and why; the bag is complete)
  2    scenario or option error (a value that cannot be honoured, a missing or broken file)
  3    world error (SDF world or robot model)
  4    FMU error
  5    bag error (cannot write the bag folder, disk full)
  6    behaviour-tree error (the tree file, or a node failing while it ticks)
  7    estimation error
  8    the simulation cannot continue, e.g. the watchdog found a stuck step (what, and where)
  70   internal error (a bug in twin: please report it with the --debug output)
  130  interrupted by Ctrl-C (SIGINT); the bag is complete
  143  stopped by SIGTERM; the bag is complete
"""


_WATCHDOG_S = 10.0
# A robot model the loader could not find, named by its scenario key (a fleet's names its entry).
_ROBOT_MODEL_KEY = re.compile(r"(robots\[\d+\]\.)?robot\.model: ")


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `simulate` command."""
    parser = subparsers.add_parser(
        "simulate",
        help="run a scenario and record a ROS 2 bag",
        description=(
            "Run a scenario with no ROS, no Gazebo and no display, faster than real time, and record "
            "everything as a ROS 2 bag (MCAP by default) that ros2 bag, Foxglove, PlotJuggler, rosbags "
            "and mcap read. Without SCENARIO, runs the shipped default scenario."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("scenario", nargs="?", type=Path, metavar="SCENARIO", help="scenario YAML file")
    parser.add_argument(
        "--duration", type=float, metavar="S", help="simulated seconds to run (overrides the mission end)"
    )
    parser.add_argument("--out", type=Path, metavar="DIR", help="bag folder to create (default: a new folder in bags/)")
    parser.add_argument("--seed", type=int, metavar="N", help="seed for every noise stream (overrides the scenario)")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), help="bag storage (overrides the scenario)")
    parser.add_argument(
        "--distro", choices=("humble", "iron", "jazzy", "kilted", "rolling"), help="ROS 2 distro the bag targets"
    )
    parser.add_argument(
        "--from-bag",
        type=Path,
        metavar="BAG",
        help="re-run exactly the scenario a twin bag recorded (its seed and duration too; same messages)",
    )
    parser.add_argument(
        "--watchdog-s",
        type=float,
        default=_WATCHDOG_S,
        metavar="S",
        help=f"end the run (exit 8) when a step has not returned for S wall seconds (default {_WATCHDOG_S:g})",
    )
    parser.add_argument("--json", action="store_true", help="print the run summary as JSON on stdout")
    live = parser.add_argument_group("live view (docs/live.md)")
    live.add_argument(
        "--live", action="store_true", help="serve the run to Foxglove over WebSocket while it runs (paced, --speed 1)"
    )
    live.add_argument("--host", default=None, metavar="ADDR", help="address to serve on (default 127.0.0.1)")
    live.add_argument("--port", type=int, default=None, metavar="N", help="port to serve on (default 8765)")
    live.add_argument(
        "--namespace",
        default=None,
        metavar="NS",
        help="a fleet (robots:): serve the robot under /NS/ alone, its topics as one robot's (/NS/scan as /scan), "
        "with /clock, /rosout and the shared /tf (default: every robot's topics as they are)",
    )
    live.add_argument(
        "--speed",
        type=speed_arg,
        metavar="X",
        help="sim seconds per wall second: 1 real time, 5 five times faster, max as fast as possible "
        "(default: max, or 1 with --live or --ros2)",
    )
    ros2 = parser.add_argument_group("ROS 2 (docs/ros2.md)")
    ros2.add_argument(
        "--ros2",
        action="store_true",
        help="join a ROS 2 domain over DDS: topics out as rt/<topic>, /cmd_vel and /initialpose in (real time)",
    )
    ros2.add_argument("--domain-id", type=int, default=None, metavar="N", help="ROS_DOMAIN_ID, 0 to 232 (default 0)")
    ros2.add_argument(
        "--ros2-role",
        choices=("full", "simulator"),
        default=None,
        help="full: the twin's own stack runs too; simulator: Gazebo's part alone, for an external Nav2",
    )
    ros2.add_argument(
        "--ros2-interface",
        default=None,
        metavar="NAME",
        help="network interface DDS uses (default lo: loopback only; any other reaches the network)",
    )
    parser.set_defaults(func=_simulate)


@contextmanager
def _crash_note(scenario: Scenario, bag_path: Path) -> Iterator[None]:
    """While a user's FMU runs in this process, a fatal signal writes one line naming it before the process dies.

    A segfault or abort inside an FMU (drive.isolation: none) ended the run with no word at all, the
    bag unclosed. The line names the FMU, `drive.isolation: process` (which ends such a run with one
    error line and a closed bag) and `twin bag recover` for the bag left open.
    """
    from twin.robot.fmu_drive import FmuDrive

    fmus = sorted(
        {
            Path(sc.drive.fmu_file).name
            for _, sc in scenario.robot_scenarios()
            if isinstance(sc.drive, FmuDrive) and sc.drive.fmu_file is not None and sc.drive.isolation == "none"
        }
    )
    if not fmus:
        yield
        return
    from twin.cosim.build import crash_note

    crash_note(
        f"twin: error: the process died while the drive's FMU {', '.join(fmus)} ran in it (drive.isolation: "
        "none); with drive.isolation: process a crash inside the FMU ends the run in one line and closes the "
        f"bag; this bag reads after `twin bag recover {bag_path}`"
    )
    try:
        yield
    finally:
        crash_note("")


def _bag_path(scenario: Scenario, out: Path | None) -> Path:
    if out is not None:
        return out
    stamp = datetime.datetime.now().strftime("%Y_%m_%d-%H_%M_%S")
    out_dir = Path(scenario.recording.out_dir)
    above = next((p for p in (out_dir, *out_dir.parents) if p.exists()), None)
    if above is not None and not above.is_dir():  # a file, a device (/dev/null): no folder can go there
        where = f"{scenario.source_path}: " if scenario.source_path is not None else ""
        msg = f"{where}recording.out_dir: {out_dir}: {above} is not a folder; give a folder for the bags (or --out)"
        raise ConfigError(msg)
    base = out_dir / f"{scenario.name}_{stamp}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}_{n}")
    return path


class _StopFlag:
    """Set by SIGINT/SIGTERM; a second Ctrl-C stops at once."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self) -> bool:
        return self.signum is not None

    def handle(self, signum: int, frame: object) -> None:
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signum = signum


class _Terminated(BaseException):
    """SIGTERM during start-up (a BaseException, as KeyboardInterrupt is: no `except Exception` keeps it)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise _Terminated


@contextmanager
def _terminated_raises() -> Iterator[None]:
    """While start-up runs, SIGTERM unwinds it (the bag folder, if made, is removed) instead of killing the process."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def _graceful_signals(flag: _StopFlag) -> Iterator[None]:
    previous = {sig: signal.signal(sig, flag.handle) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _duration(seconds: float, digits: int) -> str:
    """A duration with the digits it has: `28.0 s`, `0.140 s`, `1.6 ms`, never `0.00 s` beside a speed-up."""
    if seconds >= 10.0 ** (1 - digits):
        return f"{seconds:.{digits}f} s"
    if seconds >= 0.01:
        return f"{seconds:.3f} s"
    return f"{seconds * 1e3:.2g} ms"


def _summary_line(summary: RunSummary) -> str:
    return (
        f"simulated {_duration(summary.sim_s, 1)} in {_duration(summary.wall_s, 2)} "
        f"({summary.real_time_factor:.0f}x real time), "
        f"{summary.messages} messages, {summary.contacts} contacts, "
        f"{f'{summary.drive} drive, ' if summary.drive else ''}"
        f"{f'{summary.drive_notes}, ' if summary.drive_notes else ''}{_refused(summary)}{summary.ended_by}"
        f"{_result(summary)}: {summary.bag_path}"
    )


def _refused(summary: RunSummary) -> str:
    refused = summary.refused_messages
    if not refused:
        return ""
    topics = ", ".join(f"{n} on {t}" for t, n in refused.items())
    return f"{sum(refused.values())} non-finite messages refused ({topics}), "


def _result(summary: RunSummary) -> str:
    if summary.robots:  # a fleet: each robot's
        return " (" + ", ".join(f"{ns} {result}" for ns, result in summary.robots.items()) + ")"
    return f" (tree {summary.mission_result})" if summary.mission_result in ("SUCCESS", "FAILURE") else ""


def _from_bag(bag: Path) -> tuple[Scenario, float | None, Mapping[str, str]]:
    """The scenario, duration limit and provenance a twin bag recorded."""
    from twin.bag import read_provenance
    from twin.sim.scenario_file import load_scenario, without_retired_keys

    provenance = read_provenance(bag)
    if provenance is None or "scenario_yaml" not in provenance:
        msg = f"{bag}: --from-bag: the bag has no twin provenance (an older twin's bag, or another tool's)"
        raise ConfigError(msg)
    with tempfile.TemporaryDirectory(prefix="twin-from-bag-") as tmp:
        recorded = Path(tmp) / "scenario.yaml"
        recorded.write_text(without_retired_keys(provenance["scenario_yaml"]), encoding="utf-8")
        scenario = load_scenario(recorded)
    duration = provenance.get("duration_s", "")
    return scenario, (float(duration) if duration else None), provenance


def _check_fmus(recorded: Mapping[str, str], bag: Path) -> None:
    """Warn when a re-run's FMU binaries differ from the recorded ones (e.g. built by another compiler)."""
    from twin.bag import read_provenance

    now = read_provenance(bag) or {}
    before = {f["file"]: f["sha256"] for f in json.loads(recorded.get("fmus", "[]"))}
    after = {f["file"]: f["sha256"] for f in json.loads(now.get("fmus", "[]"))}
    if before != after:
        print(
            f"twin: warning: the FMUs differ from the recorded run's ({sorted(before)} -> {sorted(after)}); "
            "the messages may differ too",
            file=sys.stderr,
        )


def _check_options(args: argparse.Namespace) -> None:
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        msg = f"--duration must be a positive, finite number of seconds, got {args.duration}"
        raise ConfigError(msg)
    problem = None if args.duration is None else number_problem(args.duration, "--duration", unit="s")
    if problem is not None:
        msg = f"--duration {problem}"
        raise ConfigError(msg)
    if not args.watchdog_s > 0:  # NaN too; inf turns the stuck-step check off
        msg = f"--watchdog-s must be a positive number of seconds (inf: no watchdog), got {args.watchdog_s}"
        raise ConfigError(msg)
    if args.seed is not None and args.seed < 0:
        msg = f"--seed must be a non-negative whole number, got {args.seed}"
        raise ConfigError(msg)


def _simulate(args: argparse.Namespace) -> int:
    # SIGTERM during start-up (reading, checking, building: seconds for a large world) stops it at
    # once, as Ctrl-C does, and leaves no half-made bag; during the run it ends the run cleanly.
    with _terminated_raises():
        try:
            return _simulate_checked(args)
        except _Terminated:
            err = Interrupted("stopped by SIGTERM before the run started; nothing was recorded")
            err.exit_code = 128 + signal.SIGTERM  # type: ignore[misc]
            raise err from None


def _simulate_checked(args: argparse.Namespace) -> int:
    from twin.sim.check import check_scenario
    from twin.sim.scenario import default_scenario_path, for_ros2_role
    from twin.sim.scenario_file import load_scenario

    _check_options(args)
    provenance: Mapping[str, str] | None = None
    if args.from_bag is not None:
        if args.scenario is not None:
            msg = f"give a SCENARIO or --from-bag {args.from_bag}, not both"
            raise ConfigError(msg)
        path = args.from_bag
        scenario, recorded_duration, provenance = _from_bag(args.from_bag)
        if args.duration is None:
            args.duration = recorded_duration
    else:
        path = args.scenario if args.scenario is not None else default_scenario_path()
        scenario = load_scenario(path)
    changes: dict[str, Any] = {}
    if args.seed is not None:
        changes["seed"] = args.seed
    recording: dict[str, Any] = {}
    if args.storage is not None:
        recording["storage"] = args.storage
    if args.distro is not None:
        recording["distro"] = args.distro
    if recording:
        changes["recording"] = dataclasses.replace(scenario.recording, **recording)
    ros2 = _ros2_section(args, scenario)
    if ros2 is not None:
        changes["ros2"] = ros2
    scenario = dataclasses.replace(scenario, **changes)
    check_scenario(scenario, path)
    scenario = for_ros2_role(scenario)
    bag_path = _bag_path(scenario, args.out)

    flag = _StopFlag()
    live = _live_view(
        args,
        flag,
        ros2=scenario.ros2.enabled,
        namespaces=[e.ns for e in scenario.robots],
        frame_prefix=scenario.tf.mode == "frame_prefix",
    )
    # (the crash note from the user FMU's first instance on)
    with live as sinks, _ros2_bridge(scenario) as bridge, _crash_note(scenario, bag_path):
        return _run(args, path, scenario, bag_path, flag=flag, sinks=sinks + bridge, provenance=provenance)


_ROS2_FLAGS = {
    "domain_id": ("--domain-id", "domain_id"),
    "role": ("--ros2-role", "ros2_role"),
    "interface": ("--ros2-interface", "ros2_interface"),
}  # section key: (flag, argparse dest)


def _ros2_section(args: argparse.Namespace, scenario: Scenario) -> Any:
    """The scenario's `ros2:` section with `--ros2`, `--domain-id`, `--ros2-role`, `--ros2-interface` over it."""
    given = {key: getattr(args, dest) for key, (_, dest) in _ROS2_FLAGS.items() if getattr(args, dest) is not None}
    if given and not (args.ros2 or scenario.ros2.enabled):
        verb = "configures" if len(given) == 1 else "configure"
        msg = f"{', '.join(_ROS2_FLAGS[k][0] for k in given)}: {verb} the ROS 2 bridge; add --ros2"
        raise ConfigError(msg)
    if not (args.ros2 or given):
        return None
    try:
        return dataclasses.replace(scenario.ros2, enabled=True, **given)
    except ValueError as err:
        key = next((k for k in given if str(err).startswith(k)), "domain_id")
        msg = f"{_ROS2_FLAGS[key][0]}: {err}"
        raise ConfigError(msg) from None


@contextmanager
def _ros2_bridge(scenario: Scenario) -> Iterator[list[Sink]]:
    """The ROS 2 participant `--ros2` (or `ros2.enabled`) asks for, as a sink after the others."""
    if not scenario.ros2.enabled:
        yield []
        return
    from twin.ros2 import Ros2Bridge

    section = scenario.ros2
    with Ros2Bridge(section) as bridge:
        where = "loopback only" if section.interface == "lo" else f"interface {section.interface}"
        print(
            f"twin: ROS 2 domain {section.domain_id} ({where}), role {section.role}: topics as rt/<topic>; "
            f"taking {', '.join(section.subscribe) or 'nothing'}",
            file=sys.stderr,
        )
        yield [bridge]


@contextmanager
def _live_view(
    args: argparse.Namespace,
    flag: _StopFlag,
    *,
    ros2: bool = False,
    namespaces: Sequence[str] = (),
    frame_prefix: bool = False,
) -> Iterator[list[Sink]]:
    """The live server and pacer `--live`, `--speed` (and `--ros2`: real time) ask for, as sinks after the recorder."""
    if not args.live and (args.host is not None or args.port is not None or args.namespace is not None):
        given = [f for f, v in (("--host", args.host), ("--port", args.port), ("--namespace", args.namespace)) if v]
        msg = f"{' and '.join(given)}: {'configures' if len(given) == 1 else 'configure'} the live view; add --live"
        raise ConfigError(msg)
    namespace = _live_namespace(args.namespace, namespaces)
    speed = args.speed if args.speed is not None else (1.0 if args.live or ros2 else math.inf)
    if not args.live and speed == math.inf:
        yield []
        return
    from twin.live import DEFAULT_HOST, DEFAULT_PORT, LiveServer, LiveSink, Pacer

    pacer = Pacer(speed, should_stop=flag) if speed != math.inf else None
    if not args.live:
        yield [LiveSink(None, pacer=pacer)]
        return
    port = DEFAULT_PORT if args.port is None else args.port
    with LiveServer(host=args.host or DEFAULT_HOST, port=port, hold_clients=True) as server:
        print(live_banner(server.url, speed), file=sys.stderr)
        if namespace is not None:
            alone = f"twin: serving /{namespace}/ alone, as one robot's topics (/{namespace}/scan as /scan)"
            print(alone, file=sys.stderr)
        yield [LiveSink(server, pacer=pacer, namespace=namespace, frame_prefix=frame_prefix, robots=namespaces)]


def _live_namespace(given: str | None, namespaces: Sequence[str]) -> str | None:
    """The robot `--namespace` picks for the live view, checked against the scenario's robots.

    Raises:
        ConfigError: If the scenario has no such robot (naming its robots, with a "did you mean"), or no fleet.
    """
    if given is None:
        return None
    from twin.core.config import suggest

    ns = given.strip("/")
    if not namespaces:
        msg = f"--namespace {given!r}: the scenario has one robot (no robots:); leave --namespace out"
        raise ConfigError(msg)
    if ns not in namespaces:
        msg = f"--namespace {given!r} is not a robot of the scenario{suggest(ns, namespaces)}"
        raise ConfigError(msg)
    return ns


def _run(
    args: argparse.Namespace,
    path: Path,
    scenario: Scenario,
    bag_path: Path,
    *,
    flag: _StopFlag,
    sinks: list[Sink],
    provenance: Mapping[str, str] | None,
) -> int:
    from twin.core.config import key_location
    from twin.sim.check import in_scenario
    from twin.sim.simulation import Simulation
    from twin.sim.watchdog import Watchdog, WatchdogAbort

    existed = bag_path.exists()
    progress = Progress(args.duration or scenario.max_duration_s)
    # Crash tests set TWIN_BAG_WRITE_LOG to learn what the recorder was handed, and when.
    write_log = os.environ.get("TWIN_BAG_WRITE_LOG")
    debug = bool(getattr(args, "debug", False))
    try:
        simulation = build_watched(
            lambda: Simulation(
                scenario,
                bag_path=bag_path,
                duration_s=args.duration,
                write_log=Path(write_log) if write_log else None,
                sinks=sinks,
            ),
            timeout_s=args.watchdog_s,
            debug=debug,
        )
    except BaseException as err:
        # Refused after the bag folder was made: leave nothing behind; but never a folder another run
        # took between this run's look and its own (two runs on one --out: the other's bag stays)
        if not existed and bag_path.is_dir() and not isinstance(err, BagFolderTaken):
            shutil.rmtree(bag_path, ignore_errors=True)
        if isinstance(err, WorldError) and _ROBOT_MODEL_KEY.match(str(err)):  # the robot the scenario names
            raise err.with_context(before=f"{key_location(path, str(err).split(': ', 1)[0])}: ") from err
        if not isinstance(err, ConfigError) and not (isinstance(err, TwinError) and str(err).startswith("robots[")):
            raise
        # A scenario value the loaded world or robot refuses: name the scenario file too.
        named = in_scenario(err, path)
        if named is err:
            raise
        raise named from err
    guard = Guard(simulation, debug=debug)
    try:
        with _graceful_signals(flag), simulation as sim:
            watchdog = Watchdog(
                lambda: sim.t_s, timeout_s=args.watchdog_s, on_stuck=guard.on_stuck, on_signal=guard.on_signal
            )
            try:
                with watchdog:
                    summary = sim.run(should_stop=flag, progress=progress.update)
            except TwinError as err:
                progress.close()
                t_s = sim.t_s
                raise err.with_context(after=f" (the bag up to t={t_s:.3f} s is in {bag_path})") from err
            finally:
                progress.close()
    except WatchdogAbort:
        guard.done.set()
        if guard.report is None:  # not ours: cannot happen, but never hide an exception
            raise
        if guard.debug:
            print(f"twin: stuck main thread:\n{guard.report.stack}", file=sys.stderr, end="")
        print(f"twin: error: {guard.message()}", file=sys.stderr)
        return guard.exit_code()
    finally:
        guard.done.set()
    if provenance is not None and summary.bag_path is not None:
        _check_fmus(provenance, summary.bag_path)
    failure = simulation.failure if summary.mission_result == "FAILURE" else ""
    if args.json:
        doc = {**dataclasses.asdict(summary), "bag_path": str(summary.bag_path), "mission_failure": failure}
        print(json.dumps(doc, indent=2))
    else:
        print(_summary_line(summary))
    if flag.signum is not None:
        print(f"twin: stopped by {signal.Signals(flag.signum).name}; the bag is complete", file=sys.stderr)
        return Interrupted.exit_code if flag.signum == signal.SIGINT else 128 + flag.signum
    if failure:
        print(f"twin: mission FAILURE: {failure}; the bag is complete: {summary.bag_path}", file=sys.stderr)
        return 1
    return 0
