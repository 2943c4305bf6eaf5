"""`twin analyze BAG` and `twin analyze compare A B`: reports on bags, and two bags of one run compared."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


class _Fraction:
    """`reading BAG  42%` on stderr, only when stderr is a terminal; cleared on exit."""

    def __init__(self, label: str, *, enabled: bool) -> None:
        self._label = label
        self._on = enabled and sys.stderr.isatty()
        self._drawn = False

    def update(self, fraction: float) -> None:
        if self._on:
            sys.stderr.write(f"\r{self._label} {100 * min(max(fraction, 0.0), 1.0):3.0f}%\x1b[K")
            sys.stderr.flush()
            self._drawn = True

    def __enter__(self) -> _Fraction:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._drawn:
            sys.stderr.write("\r\x1b[K")
            sys.stderr.flush()


_EPILOG = """\
examples:
  twin analyze ../shared/fixtures/bags/tb3_waffle_gazebo_humble
  twin analyze bags/run1 --out /tmp/run1_report         report.md, report.html, report.json, PNGs
  twin analyze bags/run1 --json | jq .metrics.path_length_m
  twin analyze bags/fleet                  a fleet's bag: one section per robot, distance between them
  twin analyze bags/fleet --namespace robot2                     one robot of a fleet's bag
  twin analyze ../shared/fixtures/bags/tb3_waffle_gazebo_humble \\
      --world ../shared/fixtures/gazebo_classic/worlds/turtlebot3_world.world \\
      --model-path ../shared/fixtures/gazebo_classic/models     the world's walls on the map
  twin analyze compare bags/twin_run ../shared/fixtures/bags/tb3_waffle_gazebo_humble --max-position-error 0.05

Reads any rosbag2 bag (MCAP or sqlite3, metadata 4 to 9, any distro) in one streaming pass. A
section whose topics the bag lacks says what it needs; the rest still runs. The report (default
folder: bags/<BAG name>_report) holds report.md, report.json, report.html (self-contained,
plots inline) and the PNG plots. A fleet's bag (robots found by namespace: /<ns>/odom or
/<ns>/ground_truth/odom with the robot's other topics) gets one section per robot, each read from
its own topics, and the smallest distance between robots over time (from ground truth, else AMCL
in the map frame). Exit codes: 0 done, 2 a --namespace the bag has no robot under, 5 unreadable
bag (a truncated one: run `twin bag recover`).
"""

_COMPARE_EPILOG = """\
examples:
  twin analyze compare bags/replay ../shared/fixtures/bags/tb3_waffle_gazebo_humble
  twin analyze compare bags/fmu_run bags/kinematic_run --topic /ground_truth/odom --align
  twin analyze compare A B --max-position-error 0.05 && echo "within 5 cm"
  twin analyze compare bags/fleet bags/fleet --namespace robot1 robot2     two robots of one fleet's bag

Poses of the chosen topic in each bag (default: /ground_truth/odom, else /odom, the first both
have; or --topic for both, --topic A_TOPIC B_TOPIC for each) are matched in time from each bag's
first pose (sim time from the header stamps; two topics of one bag, or --same-clock, on the stamps
as they are), then compared: position and yaw error over time, ATE
(RMS position error, optionally after a Umeyama rigid alignment with --align) and RPE over 1 s.
A fleet's bag (robots under namespaces: /robot1/odom...) needs --namespace NS: that robot's
topics are read as a one-robot bag's (--topic with or without the namespace). Exit codes: 0 done
(and within --max-position-error), 1 over the threshold, 2 a fleet's bag without --namespace (or
one it lacks), 5 unreadable bags or no common pose topic.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `analyze` command (and its `compare` form)."""
    parser = subparsers.add_parser(
        "analyze",
        help="report on a bag: metrics, mission timeline, topic health, plots (or compare two bags)",
        description=(
            "Analyse a ROS 2 bag: mission outcome and goals, path, speed, contacts, localization error, "
            "clearance, topic health, and plots; `twin analyze compare A B` compares two bags of one run."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
        usage=(
            "twin analyze [-h] [--debug] [-v] [-q] [--out DIR] [--json] [options] BAG\n"
            "       twin analyze compare [-h] [--namespace NS [NS]] [compare options] A B"
        ),
    )
    parser.add_argument("bag", metavar="BAG", help="bag folder or .mcap/.db3 file to analyse (or `compare`)")
    parser.add_argument("rest", nargs="*", metavar="B", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, metavar="DIR", help="report folder (default: bags/<BAG name>_report)")
    parser.add_argument("--json", action="store_true", help="print the report (or comparison) as JSON on stdout")
    parser.add_argument("--world", type=Path, metavar="SDF", help="draw this world's walls on the map")
    parser.add_argument(
        "--model-path", type=Path, action="append", default=[], metavar="DIR", help="where model:// URIs resolve"
    )
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots (faster)")
    parser.add_argument(
        "--namespace",
        nargs="+",
        metavar="NS",
        help="a fleet's bag: only the robot under /NS/ (compare: in each fleet bag, or one NS per bag)",
    )
    parser.add_argument(
        "--scan-topic",
        metavar="TOPIC",
        help="the LaserScan topic clearance comes from (default: /scan, else the bag's only LaserScan topic)",
    )
    cmp = parser.add_argument_group("compare A B")
    cmp.add_argument("--topic", nargs="+", metavar="TOPIC", help="pose topic in both bags (or one per bag)")
    cmp.add_argument("--align", action="store_true", help="Umeyama-align B's trajectory to A's before the ATE")
    cmp.add_argument(
        "--same-clock",
        action="store_true",
        help="match the poses on their stamps as they are (two recordings of one run), not from each first pose",
    )
    cmp.add_argument(
        "--max-position-error", type=float, metavar="M", help="exit 1 when the final or max position error exceeds M"
    )
    parser.set_defaults(func=_analyze)


def _writing(out: Path, write: Any) -> Any:
    """Run `write()`, turning a folder that cannot be written into one error line."""
    from twin.core.errors import BagError

    try:
        return write()
    except OSError as err:
        msg = f"{out}: cannot write the report ({err.strerror or err}); choose another --out"
        raise BagError(msg) from None


def _walls(args: argparse.Namespace) -> Any:
    if args.world is None:
        return None
    from twin.analysis.report import world_walls
    from twin.cli.world import model_path_folders

    return world_walls(args.world, model_path_folders(args.model_path))


def _analyze(args: argparse.Namespace) -> int:
    if args.bag == "compare":
        return _compare(args)
    if args.rest:
        print(
            f"twin: error: analyze takes one BAG, got {1 + len(args.rest)}; use `twin analyze compare A B`",
            file=sys.stderr,
        )
        return 2
    from twin.analysis.fleet import bag_robots, check_namespace
    from twin.analysis.report import analyze, summary_lines, write_report
    from twin.core.errors import ConfigError

    bag = Path(args.bag)
    if args.namespace is not None and len(args.namespace) > 1:
        msg = f"--namespace takes one robot for analyze, got {len(args.namespace)}; analyze one at a time"
        raise ConfigError(msg)
    info, namespaces = bag_robots(bag)
    namespace = None if args.namespace is None else check_namespace(info, args.namespace[0])
    walls = _walls(args)
    out = args.out if args.out is not None else Path("bags") / f"{bag.resolve().name}_report"
    if namespaces and namespace is None:
        if args.scan_topic is not None:
            msg = f"--scan-topic is one robot's: {bag} holds {len(namespaces)} robots; add --namespace NS"
            raise ConfigError(msg)
        return _analyze_fleet(args, bag, walls, out)
    with _Fraction(f"reading {bag}", enabled=not args.quiet) as bar:
        report = analyze(
            bag,
            walls=walls,
            world_name=args.world.name if args.world else "",
            plots_enabled=not args.no_plots,
            progress=bar.update,
            namespace=namespace,
            scan_topic=args.scan_topic,
        )
    files = _writing(out, lambda: write_report(report, out))
    if args.json:
        print(json.dumps({**report.to_dict(), "files": [str(f) for f in files]}, indent=2))
    else:
        print("\n".join(summary_lines(report)))
        print(f"report: {out / 'report.html'} (and report.md, report.json, {len(report.pngs)} plots)")
    return 0


def _analyze_fleet(args: argparse.Namespace, bag: Path, walls: Any, out: Path) -> int:
    """A fleet's bag: one section per robot and the distance between them."""
    from twin.analysis.fleet import analyze_fleet, fleet_summary_lines, write_fleet_report

    with _Fraction(f"reading {bag}", enabled=not args.quiet) as bar:
        report = analyze_fleet(
            bag,
            walls=walls,
            world_name=args.world.name if args.world else "",
            plots_enabled=not args.no_plots,
            progress=bar.update,
        )
    files = _writing(out, lambda: write_fleet_report(report, out))
    if args.json:
        print(json.dumps({**report.to_dict(), "files": [str(f) for f in files]}, indent=2))
    else:
        print("\n".join(fleet_summary_lines(report)))
        n = sum(1 for f in files if f.suffix == ".png")
        print(f"report: {out / 'report.html'} (and report.md, report.json, {n} plots)")
    return 0


def _compare_namespaces(a: Path, b: Path, given: list[str] | None) -> tuple[str | None, str | None]:
    """The robot to compare in each bag: --namespace's in a fleet's bag, none in a one-robot bag.

    One NS applies to each fleet bag; two apply to A and B in turn. A bag of several robots without
    one is refused, naming its robots: comparing whichever robot came first would be a silent guess.
    A bag of one robot under a namespace compares that robot.
    """
    from twin.analysis.fleet import bag_robots, check_namespace
    from twin.core.errors import ConfigError

    if given is not None and len(given) > 2:
        msg = f"--namespace takes one robot (each fleet bag) or two (A's, B's), got {len(given)}"
        raise ConfigError(msg)
    out: list[str | None] = []
    fleets = 0
    for k, bag in enumerate((a, b)):
        info, robots = bag_robots(bag)
        fleets += bool(robots)
        ns = None if given is None else given[k] if len(given) == 2 else given[0]
        if len(robots) > 1 and ns is None:
            msg = f"{bag} holds {len(robots)} robots ({', '.join(robots)}): choose one with --namespace NS"
            raise ConfigError(msg)
        if len(robots) == 1 and ns is None:
            ns = robots[0]  # its only robot
        if ns is not None and (robots or (given is not None and len(given) == 2)):
            out.append(check_namespace(info, ns))
        else:
            out.append(None)
    if given is not None and not fleets:
        msg = f"--namespace {' '.join(given)}: neither {a} nor {b} holds namespaced robots; leave it out"
        raise ConfigError(msg)
    return out[0], out[1]


def check_threshold(value: float | None, flag: str = "--max-position-error") -> None:
    """Refuse a position-error threshold that is not a finite distance >= 0 (NaN turned the check off).

    Raises:
        ConfigError: Naming the flag and the value.
    """
    from twin.core.errors import ConfigError
    from twin.core.numbers import number_problem

    if value is None:
        return
    problem = number_problem(value, flag, unit="m")
    if problem is not None or value < 0.0:
        msg = f"{flag} must be a distance >= 0 m: {problem or f'got {value}'}"
        raise ConfigError(msg)


def _compare(args: argparse.Namespace) -> int:
    from twin.analysis.compare import compare_bags, write_comparison
    from twin.core.errors import ConfigError

    if len(args.rest) != 2:  # usage errors: exit 2, as argparse's
        msg = f"analyze compare needs two bags A B, got {len(args.rest)}: `twin analyze compare A B`"
        raise ConfigError(msg)
    a, b = (Path(p) for p in args.rest)
    topics = tuple(args.topic) if args.topic else None
    if topics is not None and len(topics) > 2:
        msg = f"--topic takes one topic (both bags) or two (A's, B's), got {len(topics)}"
        raise ConfigError(msg)
    check_threshold(args.max_position_error)
    namespaces = _compare_namespaces(a, b, args.namespace)
    result = compare_bags(
        a, b, topics=topics, align=args.align, same_clock=True if args.same_clock else None, namespaces=namespaces
    )
    out = args.out
    if out is not None:
        walls = _walls(args)
        _writing(out, lambda: write_comparison(result, out, walls=walls))
    d = result.to_dict()
    over = args.max_position_error is not None and result.max_position_error_m > args.max_position_error
    d["threshold_m"] = args.max_position_error
    d["within_threshold"] = None if args.max_position_error is None else not over
    if args.json:
        print(json.dumps(d, indent=2))
    else:
        print("\n".join(result.summary_lines()))
        if args.max_position_error is not None:
            verdict = "over" if over else "within"
            print(f"  max position error {result.max_position_error_m:.4f} m: {verdict} {args.max_position_error:g} m")
    return 1 if over else 0
