"""The `twin` command: the only place that parses argv, configures logging and prints.

Each command group lives in its own module here with a `register(subparsers, common)` function
that adds its parser(s) and sets `func(args) -> int`. `main(argv)` returns the exit code: 0 on
success, the `exit_code` of a `TwinError`, 130 on Ctrl-C, 70 on an internal error. A traceback is
printed only with `--debug`.

Start-up is part of the interface (`twin --help` within 0.3 s): a command module imports only the
standard library and light twin modules at its top, and the libraries its command needs (numpy,
scipy, trimesh, fmpy, rosbags, matplotlib, dask, twin.sim, ...) inside the functions that run it.
When argv names a command whose module has that name, only that module is imported.
tests/unit/cli/test_startup.py holds every module to this.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import NoReturn

from twin import __version__
from twin.core.errors import Interrupted, TwinError

__all__ = ["main", "run"]

_log = logging.getLogger("twin")

# Command-group modules under twin.cli, in the order `twin --help` lists them.
_COMMAND_MODULES: tuple[str, ...] = (
    "simulate",
    "scenario",
    "graph",
    "world",
    "map",
    "fmu",
    "tree",
    "nav",
    "bag",
    "ekf",
    "analyze",
    "replay",
    "sweep",
    "play",
)

_EPILOG = """\
examples:
  twin simulate                         the thesis's mission in the house; a bag in bags/
  twin simulate scenarios/house_fmu.yaml --duration 60 --out /tmp/run1
  twin scenario check scenarios/house_burger.yaml
  twin graph                            the default scenario's nodes and topics
  twin bag info bags/<run>              what a bag holds
  twin simulate --live                  watch the run in Foxglove (ws://127.0.0.1:8765), in real time
  twin play bags/<run> --speed 2        serve a bag to Foxglove
  twin tree validate trees/tree.xml
  twin world info ../shared/fixtures/gazebo_classic/worlds/turtlebot3_house.world \\
      --model-path ../shared/fixtures/gazebo_classic/models
  twin <command> --help                 more on one command
"""


class _Formatter(argparse.RawDescriptionHelpFormatter):
    pass


class _Parser(argparse.ArgumentParser):
    """A usage error is one line (argparse printed the whole usage block before it), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _common_parser(*, top: bool) -> argparse.ArgumentParser:
    """The global options; a subcommand's copy leaves unset options alone, so they work on either side."""
    common = _Parser(add_help=False)
    group = common.add_argument_group("output")
    default: object = False if top else argparse.SUPPRESS
    group.add_argument("--debug", action="store_true", default=default, help="show tracebacks and debug logs")
    group.add_argument("-v", "--verbose", action="store_true", default=default, help="show info logs")
    group.add_argument("-q", "--quiet", action="store_true", default=default, help="show only errors")
    return common


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Return the argument parser: all commands, or only `command` (one of `_COMMAND_MODULES`).

    `main` and the docs use the full parser; `main` builds only the command argv names.
    """
    common = _common_parser(top=False)
    parser = _Parser(
        prog="twin",
        description=(
            "A headless digital twin of a TurtleBot3: SDF worlds, FMU drivetrains, an EKF, "
            "BehaviorTree.CPP missions, ROS 2 bags. No ROS, no Gazebo, no display."
        ),
        epilog=_EPILOG,
        formatter_class=_Formatter,
        parents=[_common_parser(top=True)],
    )
    parser.add_argument("--version", action="version", version=f"twin {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _COMMAND_MODULES if command is None else (command,):
        module = importlib.import_module(f"twin.cli.{name}")
        module.register(subparsers, common)
    return parser


def _named_command(argv: Sequence[str]) -> str | None:
    """Return the command argv names when it is one module's own name (the rest need not load)."""
    for token in argv:
        if token == "--":
            return None
        if not token.startswith("-"):
            return token if token in _COMMAND_MODULES else None
    return None


_NODE_LOGGER = "twin.node."
# Loggers under twin.node. that are modules, not nodes; FMU instances name themselves in their lines.
_NOT_NODES = ("twin.node.node", "twin.node.readers", "twin.node.fmu")


class _ConsoleFormatter(logging.Formatter):
    """`twin: LEVEL: message`; a node's lines (its `get_logger()`) carry its name, as ROS 2 prints them."""

    def format(self, record: logging.LogRecord) -> str:
        name = record.name
        if name.startswith(_NODE_LOGGER) and not any(name == m or name.startswith(m + ".") for m in _NOT_NODES):
            node = name.removeprefix(_NODE_LOGGER)
            fields = {**record.__dict__, "msg": f"[{node}] %s", "args": (record.getMessage(),)}
            record = logging.makeLogRecord(fields)
        return super().format(record)


class _ConsoleHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """The console's log lines, each on a line of its own when a progress line is drawn."""

    def emit(self, record: logging.LogRecord) -> None:
        from twin.cli.progress import clear_progress_line

        clear_progress_line()
        super().emit(record)


def _configure_logging(args: argparse.Namespace) -> None:
    level = logging.WARNING
    if getattr(args, "verbose", False):
        level = logging.INFO
    if getattr(args, "debug", False):
        level = logging.DEBUG
    if getattr(args, "quiet", False):
        level = logging.ERROR
    handler = _ConsoleHandler(sys.stderr)
    handler.setFormatter(_ConsoleFormatter("twin: %(levelname)s: %(message)s"))
    handler.setLevel(level)
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)
    # twin's own INFO lines are made even when the console shows less: a simulation copies them
    # into the bag's /rosout, as a ROS 2 system records its nodes' logs.
    logging.getLogger("twin").setLevel(min(level, logging.INFO))
    logging.captureWarnings(True)


def _interrupted_at_start(signum: int, frame: object) -> None:
    # Start-up (imports, parsing) holds nothing to save: one line and exit at once.
    os.write(2, b"twin: interrupted\n")
    os._exit(Interrupted.exit_code)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line and return its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    in_main_thread = threading.current_thread() is threading.main_thread()
    if in_main_thread:
        previous = signal.signal(signal.SIGINT, _interrupted_at_start)
    try:
        parser = build_parser(_named_command(argv))
        args = parser.parse_args(argv)
        _configure_logging(args)
    finally:
        if in_main_thread:
            restore = previous if previous is not _interrupted_at_start else signal.default_int_handler
            signal.signal(signal.SIGINT, restore)
    debug = bool(getattr(args, "debug", False))
    try:
        code: int = args.func(args)
    except TwinError as err:
        if debug:
            _log.exception("%s", err)
        else:
            print(f"twin: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print("twin: interrupted", file=sys.stderr)
        return Interrupted.exit_code
    except BrokenPipeError:
        return 0
    except Exception as err:
        if debug:
            _log.exception("internal error")
        else:
            print(
                f"twin: internal error: {type(err).__name__}: {err} (run again with --debug for the traceback)",
                file=sys.stderr,
            )
        return 70
    return code


def run() -> None:
    """Console-script entry point."""
    from twin.core import codecache

    argv = sys.argv[1:]
    codecache.enable(_named_command(argv) or "twin")  # dataclasses' methods compiled once (twin.core.codecache)
    if _named_command(argv) == "simulate":  # start-up without the cyclic collector (see twin.core.gcpolicy)
        from twin.core.gcpolicy import defer_collection, resume_collection

        defer_collection()
        try:
            code = main(argv)
        finally:
            resume_collection()  # the loop resumed it already; an early exit or error path, here
        sys.exit(code)
    sys.exit(main())
