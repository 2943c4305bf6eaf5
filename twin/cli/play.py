"""`twin play BAG`: serve a recorded bag to Foxglove over WebSocket, at the bag's pace or any speed."""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path
from typing import Any

_EPILOG = """\
examples:
  twin play bags/<run>                                       the twin's own bag, in real time
  twin play ../shared/fixtures/bags/tb3_waffle_gazebo_humble --speed 2 --loop
  twin play bags/<run> --port 9000 --host 0.0.0.0            serve other machines too
  twin play bags/<fleet run> --namespace robot2              one robot of a fleet, as one robot's bag

Then in Foxglove (app or browser): Open connection > Foxglove WebSocket > ws://127.0.0.1:8765, and
import docs/foxglove_layout.json for the 3D view, speed plots and the behaviour-tree log. Topics are
sent as foxglove_bridge sends them (CDR with ros2msg schemas); latched topics (/tf_static,
/robot_description, /map) reach a client that connects late. Any rosbag2 the twin reads plays:
MCAP or sqlite3, metadata versions 4 to 9; a topic whose type is defined nowhere is left out.
A fleet's bag serves every robot's topics as they are (/robot1/scan, /robot1/tf...); --namespace NS
serves one robot alone under a single robot's names (/NS/scan as /scan, /NS/tf as /tf), with the
topics under no namespace (/clock, /rosout), so the shipped layout shows it (docs/fleet.md). In a
bag whose robots share one /tf with prefixed frames (NS/odom, Gazebo's frame_prefix), NS/ is taken
off the robot's frames and only its own and the world's transforms of the shared /tf are served.
Ctrl-C stops. Exit codes: 0 done, 2 bad option or port in use, 5 bag error, 130 interrupted.
"""


def speed_arg(text: str) -> float:
    """Parse `--speed`: a positive real-time factor, or `max` (as fast as possible, math.inf)."""
    if text.strip().lower() == "max":
        return math.inf
    try:
        speed = float(text)
    except ValueError:
        speed = math.nan
    if not (math.isfinite(speed) and speed > 0):
        msg = f"--speed must be a positive number (1 = real time, 5 = five times faster) or max, got {text!r}"
        raise argparse.ArgumentTypeError(msg)
    from twin.live.pacing import MIN_SPEED

    if speed < MIN_SPEED:  # (a second of messages would be due centuries on: past what a clock can wait for)
        msg = f"--speed must be at least {MIN_SPEED:g} (a million times slower than real time), got {text!r}"
        raise argparse.ArgumentTypeError(msg)
    return speed


def live_banner(url: str, speed: float) -> str:
    """The line that tells where the live view is served."""
    pace = "as fast as possible" if speed == math.inf else f"{speed:g}x real time"
    return f"twin: live on {url} ({pace}); in Foxglove: Open connection > Foxglove WebSocket > {url}"


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `play` command."""
    parser = subparsers.add_parser(
        "play",
        help="serve a bag to Foxglove over WebSocket, in real time or at any speed",
        description=(
            "Publish a ROS 2 bag's messages on a Foxglove WebSocket server, paced to the bag's own "
            "timing times --speed, for viewing real or simulated runs without ROS."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag folder, or a single .mcap or .db3 file")
    parser.add_argument(
        "--speed",
        type=speed_arg,
        default=1.0,
        metavar="X",
        help="bag seconds per wall second: 1 real time (default), 5 five times faster, max as fast as possible",
    )
    parser.add_argument("--loop", action="store_true", help="play again from the start at the end, until Ctrl-C")
    parser.add_argument("--host", default="127.0.0.1", metavar="ADDR", help="address to serve on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8765, metavar="N", help="port to serve on (default 8765)")
    parser.add_argument(
        "--namespace",
        metavar="NS",
        help="a fleet's bag: serve the robot under /NS/ alone, its topics as one robot's (/NS/scan as /scan), "
        "with the topics under no namespace (default: every topic as it is)",
    )
    parser.set_defaults(func=_play)


def _play(args: argparse.Namespace) -> int:
    from twin.bag import open_bag, require_readable
    from twin.live import LiveServer, play_bag

    require_readable(args.bag)  # a truncated file: one error line, before the port is taken
    info = open_bag(args.bag)  # a bad bag (or namespace) is reported before the port is taken
    namespace = None
    robots: list[str] = []
    if args.namespace is not None:
        from twin.analysis.fleet import check_namespace
        from twin.bag import robot_namespaces

        namespace = check_namespace(info, args.namespace)
        robots = robot_namespaces(info)
    stop: list[int] = []

    def handle(signum: int, frame: object) -> None:
        if stop and signum == signal.SIGINT:
            raise KeyboardInterrupt
        stop.append(signum)

    previous = {sig: signal.signal(sig, handle) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with LiveServer(host=args.host, port=args.port, hold_clients=True) as server:
            print(live_banner(server.url, args.speed), file=sys.stderr)
            report = play_bag(
                args.bag,
                server,
                speed=None if args.speed == math.inf else args.speed,
                loop=args.loop,
                should_stop=lambda: bool(stop),
                namespace=namespace,
                robots=robots,
            )
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
    skipped = f"; not served (no definition): {', '.join(report.skipped)}" if report.skipped else ""
    if namespace is not None:
        skipped += f"; /{namespace}/ alone, as one robot's topics"
    if args.loop and not report.messages and not report.stopped:
        skipped += "; nothing to loop over"
    passes = f" in {report.passes} passes" if report.passes > 1 else ""
    span = f"{report.bag_s:.1f} s of bag each"
    if report.stopped:  # stopped partway: how far into the bag (its last pass) it got
        span = f"stopped at {report.reached_s:.1f} s of the bag's {report.bag_s:.1f} s"
    print(
        f"played {report.messages} messages on {len(report.topics)} topics{passes} ({span}): {report.bag_path}{skipped}"
    )
    if stop:
        return 130 if stop[0] == signal.SIGINT else 128 + stop[0]
    return 0
