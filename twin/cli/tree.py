"""`twin tree ...`: validate, show and run BehaviorTree.CPP files, and run conformance cases."""

from __future__ import annotations

import argparse
import json
import logging
import random
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.core.errors import ConfigError, TreeError

if TYPE_CHECKING:
    from twin.bt.conformance import Step
    from twin.bt.factory import BehaviorTreeFactory
    from twin.bt.log import StatusLog
    from twin.bt.node import TreeNode
    from twin.bt.tree import Tree

_DEFAULT_LOCATIONS = Path(__file__).resolve().parents[2] / "trees" / "sim_house_locations.yaml"

_EPILOG = """\
examples:
  twin tree validate trees/tree.xml
  twin tree show trees/navigate_to_pose_w_replanning_and_recovery.xml
  twin tree log trees/tree.xml --period-ms 500 --polls-to-arrive 4
  twin tree log trees/nav_tree_queue.xml --seed 3 --save run.jsonl && twin tree log run.jsonl
  twin tree conformance ../shared/bt_conformance/cases/*.json
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `tree` command group."""
    parser = subparsers.add_parser(
        "tree",
        help="validate, show and run behaviour-tree files; run BT.CPP conformance cases",
        description=(
            "BehaviorTree.CPP XML files (v4, and v3 normalised on load), ticked on the simulation clock as "
            "BT.CPP 4.x ticks a v4 file and as BT.CPP 3.8 (Nav2 Humble's) ticks a v3 file. Node types: "
            "BT.CPP's built-ins, Nav2's control nodes, the mission nodes "
            "(SetLocations, GetLocationFromQueue, GoToPose) and plugins of the entry-point group twin.bt_nodes; "
            "Nav2's action and condition nodes are known for validation."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    sub = parser.add_subparsers(dest="tree_command", metavar="SUBCOMMAND", required=True)

    validate = sub.add_parser(
        "validate",
        help="check a tree file: node types, ports, scripts, SubTrees (one file:line per problem)",
        description=(
            "Check every tree of FILE: known node types, required ports given, port names valid, literals "
            "convertible, SubTree references resolving without recursion, scripts parsing, and no BT.CPP v3 "
            "name in a BTCPP_format=\"4\" file. Prints one 'file:line: problem' line per problem on stderr "
            "and exits 6 when there is any."
        ),
        epilog=(
            "examples:\n"
            "  twin tree validate trees/tree.xml\n"
            "  twin tree validate my_nav2_tree.xml --nodes nav2_behavior_tree/nav2_tree_nodes.xml\n"
            "  twin tree validate several_trees.xml --main-tree MainTree"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    validate.add_argument("file", type=Path, metavar="FILE", help="BT.CPP XML file")
    validate.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    validate.add_argument(
        "--main-tree",
        metavar="ID",
        help="the tree to execute, for a file of several trees without main_tree_to_execute (default: that attribute)",
    )
    _add_nodes_option(validate)
    validate.set_defaults(func=_validate)

    show = sub.add_parser(
        "show",
        help="print a tree as an indented outline (SubTrees expanded)",
        description="Load FILE and print its main tree (or --main-tree) with node types, names and ports.",
        epilog="example:\n  twin tree show trees/nav_tree_queue.xml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    show.add_argument("file", type=Path, metavar="FILE", help="BT.CPP XML file")
    show.add_argument("--main-tree", metavar="ID", help="the tree to show (default: main_tree_to_execute)")
    _add_nodes_option(show)
    show.set_defaults(func=_show)

    conformance = sub.add_parser(
        "conformance",
        help="run recorded BT.CPP conformance cases and compare (PASS/FAIL per case)",
        description=(
            "Run each CASE.json (the format of bt_conformance/README.md) with its scripted leaves, taking its "
            "sleeps as simulated time, and compare with the recorded BT.CPP 4.8.2 behaviour. Prints "
            "'PASS <id>' or 'FAIL <id>: <first difference>' per case; exit 0 only when all pass. A case's "
            "xml_v3, when present, must give the same result."
        ),
        epilog="example:\n  twin tree conformance ../shared/bt_conformance/cases/*.json --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    conformance.add_argument("cases", type=Path, nargs="+", metavar="CASE.json", help="case files")
    conformance.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    conformance.add_argument(
        "--mode",
        choices=("once", "exactly_once"),
        default="once",
        help="tickOnce (default) or tickExactlyOnce, compared with the case's alt_modes",
    )
    conformance.add_argument("--no-v3", action="store_true", help="do not run the cases' xml_v3")
    conformance.set_defaults(func=_conformance)

    log = sub.add_parser(
        "log",
        help="run a tree on the simulated clock and print its status timeline",
        description=(
            "Tick FILE's main tree every --period-ms of simulated time and print every status change with "
            "its time. GoToPose uses a stand-in navigator that reaches each goal after --polls-to-arrive "
            "polls; node types without implementation are scripted leaves (--scripts, default SUCCESS). "
            "FILE may also be a conformance case (.json, run with its scripts and sleeps) or a log saved "
            "with --save (.jsonl, printed)."
        ),
        epilog=(
            "examples:\n"
            "  twin tree log trees/tree.xml\n"
            '  twin tree log trees/search_naive.xml --scripts \'{"look_for_obj_in_location1": ["FAILURE"]}\'\n'
            "  twin tree log run.jsonl"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    log.add_argument("file", type=Path, metavar="FILE", help="XML tree, case .json or saved .jsonl log")
    log.add_argument("--main-tree", metavar="ID", help="the tree to run (default: main_tree_to_execute)")
    log.add_argument("--period-ms", type=int, default=500, help="simulated time between root ticks (default 500)")
    log.add_argument("--ticks", type=int, default=200, help="at most this many root ticks (default 200)")
    log.add_argument("--keep-going", action="store_true", help="keep ticking after the root completes")
    log.add_argument("--seed", type=int, default=0, help="seed of SetLocations' shuffle (default 0)")
    log.add_argument("--polls-to-arrive", type=int, default=3, help="navigator polls per goal (default 3)")
    log.add_argument(
        "--location-file",
        type=Path,
        default=_DEFAULT_LOCATIONS,
        help="location file put on the blackboard as location_file (default trees/sim_house_locations.yaml)",
    )
    log.add_argument(
        "--scripts", metavar="JSON", help="scripted leaves: node path -> list of statuses (JSON text or a .json file)"
    )
    log.add_argument("--save", type=Path, metavar="LOG.jsonl", help="also save the log as JSON lines")
    log.add_argument("--json", action="store_true", help="print the log as JSON on stdout instead of the timeline")
    log.set_defaults(func=_log_command)


def _add_nodes_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--nodes",
        type=Path,
        action="append",
        default=[],
        metavar="PALETTE.xml",
        help=(
            "declare the node types of a <TreeNodesModel> file (a Groot palette, Nav2's nav2_tree_nodes.xml) "
            "without implementation, for checking; repeatable"
        ),
    )


def _factory(*, seed: int = 0, polls_to_arrive: int = 3, nodes: Sequence[Path] = ()) -> BehaviorTreeFactory:
    from twin.bt.status import NodeKind
    from twin.bt.validate import declare_node_models
    from twin.mission.bt_nodes import ScriptedNavigator, register_mission_nodes
    from twin.nav.bt_navigator.factory import nav2_factory

    factory = nav2_factory()
    register_mission_nodes(
        factory, navigator=ScriptedNavigator(polls_to_arrive=polls_to_arrive), rng=random.Random(seed)
    )
    # No camera here: the demos' vision node is declared (no ports), so `log` scripts it like a leaf.
    factory.declare_node_type("LookForObject", NodeKind.ACTION, description="the behaviour demos' vision node")
    factory.load_plugins()
    for palette in nodes:
        declare_node_models(factory, palette)
    return factory


# -- validate ----------------------------------------------------------------------------------


def _validate(args: argparse.Namespace) -> int:
    from twin.bt.validate import validate_file

    report = validate_file(args.file, _factory(nodes=args.nodes), main_tree=args.main_tree)
    if args.json:
        print(
            json.dumps(
                {
                    "file": report.source,
                    "ok": report.ok,
                    "problems": list(report.problems),
                    "trees": list(report.trees),
                    "main_tree": report.main_tree,
                    "btcpp_format": report.version,
                    "declared_only": list(report.declared_only),
                },
                indent=2,
            )
        )
    else:
        for problem in report.problems:
            print(problem, file=sys.stderr)
        if report.ok:
            trees = ", ".join(report.trees)
            print(f"{report.source}: ok (BTCPP_format {report.version}; trees {trees}; main {report.main_tree})")
            if report.declared_only:
                from twin.nav.bt_navigator.leaves import IMPLEMENTED

                run = [n for n in report.declared_only if n in IMPLEMENTED]
                never = [n for n in report.declared_only if n not in IMPLEMENTED]
                if run:  # Nav2's nodes, bound to the navigation servers only in a run
                    print(f"  Nav2 nodes run by `twin simulate` (declared only here): {', '.join(run)}")
                if never:
                    print(f"  declared without implementation (a run cannot create them): {', '.join(never)}")
        else:
            count = len(report.problems)
            print(f"{report.source}: {count} problem{'s' if count != 1 else ''}", file=sys.stderr)
    return 0 if report.ok else TreeError.exit_code


# -- show --------------------------------------------------------------------------------------


def _label(node: TreeNode) -> str:
    from twin.bt.status import NodeKind

    config = node.config
    text = node.registration_id
    if node.kind is NodeKind.SUBTREE:
        text = f"SubTree {getattr(node, 'subtree_id', '')}"
    if node.name != node.registration_id:
        text += f' "{node.name}"'
    ports = {**config.input_ports, **{k: v for k, v in config.output_ports.items() if k not in config.input_ports}}
    text += "".join(f' {name}="{value}"' for name, value in ports.items())
    scripts = zip(
        ("_failureIf", "_successIf", "_skipIf", "_while", "_onHalted", "_onFailure", "_onSuccess", "_post"),
        (*config.pre_conditions, *config.post_conditions),
        strict=True,
    )
    text += "".join(f' {name}="{script.source}"' for name, script in scripts if script is not None)
    if config.manifest is not None and not config.manifest.bound:
        text += "  [declared only]"
    return text


def render_outline(tree: Tree) -> str:
    """The tree as an indented outline with box-drawing branches."""
    lines: list[str] = []

    def visit(node: TreeNode, prefix: str, last: bool, root: bool) -> None:
        lines.append(_label(node) if root else f"{prefix}{'└── ' if last else '├── '}{_label(node)}")
        children = node.children_nodes()
        inner = "" if root else prefix + ("    " if last else "│   ")
        for index, child in enumerate(children):
            visit(child, inner, index == len(children) - 1, False)

    visit(tree.root, "", True, True)
    return "\n".join(lines)


def _show(args: argparse.Namespace) -> int:
    from twin.bt.validate import load_for_display

    tree = load_for_display(args.file, _factory(nodes=args.nodes), main_tree=args.main_tree)
    main = tree.subtrees[0].tree_id
    print(f"{args.file}: tree {main}, {len(tree.nodes)} nodes")
    print(render_outline(tree))
    return 0


# -- conformance -------------------------------------------------------------------------------


def _conformance(args: argparse.Namespace) -> int:
    from twin.bt.conformance import check_case, load_case

    results: list[dict[str, Any]] = []
    failed = 0
    for path in args.cases:
        try:
            case = load_case(path)
            result = check_case(case, mode=args.mode, check_v3=not args.no_v3)
        except TreeError as err:
            failed += 1
            results.append({"id": str(path), "passed": False, "problems": [str(err)]})
            if not args.json:
                print(f"FAIL {path}: {err}")
            continue
        problems = [*result.problems, *(f"xml_v3: {p}" for p in result.v3_problems or ())]
        results.append(
            {
                "id": case.id,
                "name": case.name,
                "file": str(path),
                "passed": result.passed,
                "v3_checked": result.v3_problems is not None,
                "problems": problems,
            }
        )
        if not result.passed:
            failed += 1
        if not args.json:
            first = result.first_difference.replace("\n", " ")
            print(f"PASS {case.id}" if result.passed else f"FAIL {case.id}: {first}")
    if args.json:
        print(
            json.dumps(
                {"mode": args.mode, "passed": len(results) - failed, "failed": failed, "cases": results}, indent=2
            )
        )
    else:
        sys.stdout.flush()
        print(f"{len(results) - failed} of {len(results)} cases pass", file=sys.stderr)
    return 0 if failed == 0 else 1


# -- log ---------------------------------------------------------------------------------------


def _read_scripts(text: str | None) -> dict[str, tuple[Step, ...]]:
    from twin.bt.conformance import Step
    from twin.bt.status import NodeStatus

    if not text:
        return {}
    if not text.lstrip().startswith("{"):  # a file name
        source = Path(text)
        try:
            text = source.read_text(encoding="utf-8")
        except FileNotFoundError:
            msg = f"--scripts: {source}: file not found; give a .json file or the JSON text itself"
            raise TreeError(msg) from None
        except (OSError, UnicodeDecodeError) as err:
            msg = f"--scripts: cannot read {source} ({err})"
            raise TreeError(msg) from None
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as err:
        msg = f"--scripts: not a JSON object of node path -> statuses ({err})"
        raise TreeError(msg) from None
    if not isinstance(raw, dict):
        msg = "--scripts: expected a JSON object of node path -> list of statuses"
        raise TreeError(msg)
    scripts: dict[str, tuple[Step, ...]] = {}
    for path, given in raw.items():
        steps = given if isinstance(given, list) else [given]
        try:
            scripts[path] = tuple(Step(status=NodeStatus[str(s)], outputs={}) for s in steps)
        except KeyError:
            msg = f"--scripts[{path!r}]: statuses are SUCCESS, FAILURE or RUNNING"
            raise TreeError(msg) from None
    return scripts


def _script_unknown_types(file: Path, factory: BehaviorTreeFactory, scripts: dict[str, tuple[Step, ...]]) -> None:
    """Register scripted leaves for the node types of `file` that have no implementation."""
    from twin.bt.conformance import LeafCallRecorder, ScriptedAction, ScriptedCondition, Step, scripted_node_class
    from twin.bt.factory import BehaviorTreeFactory
    from twin.bt.loader import TreeParser
    from twin.bt.ports import bidirectional_port, is_allowed_port_name
    from twin.bt.status import NodeKind, NodeStatus

    parser = TreeParser(BehaviorTreeFactory(builtins=False), strict=True)
    problems: list[str] = []
    parser.report = lambda location, message: problems.append(message)
    parser.load_file(file)
    recorder = LeafCallRecorder()
    default = (Step(status=NodeStatus.SUCCESS, outputs={}),)
    for tree, _ in parser.tree_roots.values():
        for element in tree.iter():
            name = element.type_name
            if element is tree or element.tag == "SubTree" or not name:
                continue
            manifest = factory.manifests.get(name)
            if manifest is not None and manifest.bound:
                continue
            model = manifest or parser.node_models.get(name)
            if model is None and element.children:
                continue  # not a leaf: the loader reports the unknown node type, as validate does
            kind = model.kind if model is not None else NodeKind.ACTION
            if kind not in (NodeKind.ACTION, NodeKind.CONDITION):
                continue
            if model is not None:  # declared ports only: the loader reports unknown ones, as validate does
                ports = dict(model.ports)
            else:
                ports = {attr: bidirectional_port(attr) for attr in element.attrs if is_allowed_port_name(attr)}
            base = ScriptedAction if kind is NodeKind.ACTION else ScriptedCondition
            cls = scripted_node_class(base, tuple(ports.values()), name)
            if manifest is not None:
                factory.unregister(name)
            elif name in factory.manifests:
                continue
            factory.register_node_type(cls, name, _Defaulting(scripts, default), recorder)


class _Defaulting(dict[str, tuple["Step", ...]]):
    """Leaf scripts where an unscripted path plays `default`."""

    def __init__(self, scripts: dict[str, tuple[Step, ...]], default: tuple[Step, ...]) -> None:
        super().__init__(scripts)
        self._default = default

    def get(self, key: str, fallback: Any = None) -> Any:
        return super().get(key, self._default)


def _run_xml(args: argparse.Namespace) -> StatusLog:
    from twin.bt.log import StatusLog
    from twin.bt.tree import ManualClock
    from twin.core.clock import NS_PER_S
    from twin.mission.bt_nodes import LOCATION_FILE_KEY, load_locations

    # usage errors: exit 2, as argparse's (they were tree errors, exit 6)
    if not (args.period_ms > 0 and args.ticks > 0):  # NaN too
        msg = f"--period-ms and --ticks must be positive, got {args.period_ms} and {args.ticks}"
        raise ConfigError(msg)
    if args.polls_to_arrive < 1:
        msg = f"--polls-to-arrive must be at least 1 (navigator polls per goal), got {args.polls_to_arrive}"
        raise ConfigError(msg)
    if args.seed < 0:
        msg = f"--seed must be a non-negative whole number, got {args.seed}"
        raise ConfigError(msg)
    try:
        load_locations(args.location_file)  # one line now, not a warning per node and a FAILURE later
    except ConfigError as err:
        raise err.with_context(before="--location-file: ") from None
    factory = _factory(seed=args.seed, polls_to_arrive=args.polls_to_arrive)
    scripts = _read_scripts(args.scripts)
    _script_unknown_types(args.file, factory, scripts)
    clock = ManualClock()
    tree = factory.create_tree_from_file(args.file, main_tree=args.main_tree, clock=clock)
    _warn_unused_scripts(tree, scripts)
    tree.root_blackboard.set(LOCATION_FILE_KEY, str(args.location_file))
    log = StatusLog()
    tree.add_listener(log)
    for _ in range(args.ticks):
        status = tree.tick_once()
        log.mark_tick(tree.now_ns, status)
        if status.is_completed and not args.keep_going:
            break
        clock.advance(args.period_ms * NS_PER_S // 1000)
    return log


def _warn_unused_scripts(tree: Any, scripts: dict[str, tuple[Step, ...]]) -> None:
    """Warn of each --scripts path that names no scripted leaf (a node with an implementation runs it)."""
    from twin.bt.conformance import ScriptedAction, ScriptedCondition

    leaves = sorted(n.full_path for n in tree.nodes if isinstance(n, ScriptedAction | ScriptedCondition))
    for path in scripts:
        if path not in leaves:
            scripted = ", ".join(leaves) if leaves else "none: every leaf of this tree has an implementation"
            logging.getLogger("twin.cli.tree").warning(
                "--scripts: %r names no scripted leaf, so its script is not played (scripted leaves: %s)",
                path,
                scripted,
            )


def _run_case(path: Path) -> StatusLog:
    from twin.bt.conformance import load_case, run_case
    from twin.bt.log import StatusLog

    case = load_case(path)
    log = StatusLog()
    run = run_case(case, listeners=(log,), tick_listener=log.mark_tick)
    if run.load_error:
        raise TreeError(run.load_error)
    return log


def _log_command(args: argparse.Namespace) -> int:
    from twin.bt.log import read_jsonl, render_timeline

    suffix = args.file.suffix.lower()
    if suffix == ".jsonl":
        log = read_jsonl(args.file)
    elif suffix == ".json":
        log = _run_case(args.file)
    else:
        log = _run_xml(args)
    if args.save:
        try:
            log.write_jsonl(args.save)
        except OSError as err:
            msg = (
                f"--save: cannot write {args.save} ({err.strerror or err}); give a path in an existing, writable folder"
            )
            raise TreeError(msg) from None
        print(f"saved {len(log.changes)} changes to {args.save}", file=sys.stderr)
    if args.json:
        changes = [
            {"t_ns": c.t_ns, "path": c.path, "uid": c.uid, "prev": c.prev.name, "new": c.new.name} for c in log.changes
        ]
        ticks = [{"tick": m.tick, "t_ns": m.t_ns, "status": m.status.name} for m in log.ticks]
        print(json.dumps({"changes": changes, "ticks": ticks}, indent=2))
    else:
        print(render_timeline(log))
    return 0
