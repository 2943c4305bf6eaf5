"""`twin graph [SCENARIO]`: a scenario's node graph, as `ros2 node list`, `ros2 topic list -v` and rqt_graph show it."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

_WATCHDOG_S = 10.0

_EPILOG = """\
examples:
  twin graph                                   the default scenario's nodes and topics
  twin graph examples/nodes/wall_follower.yaml a user's node driving the robot
  twin graph --json                            the same as JSON, for scripts
  twin graph --dot > graph.dot && dot -Tpng graph.dot -o graph.png   (Graphviz draws it)
  twin graph scenarios/house_two_waffles.yaml  a fleet: nodes and topics grouped by robot namespace

A fleet's graph (`robots:`) is grouped by robot namespace (/robot1, /robot2, then what is under
none: /clock, /rosout): blocks in the text, `namespaces` in --json, clusters in --dot.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `graph` command."""
    parser = subparsers.add_parser(
        "graph",
        help="show a scenario's nodes, topics, types and rates",
        description=(
            "Build the scenario's node graph and run it for a few simulated seconds (nothing is recorded) "
            "to measure each topic's rate; print each node with what it publishes and subscribes, and each "
            "topic with its type, rate, publishers and subscribers."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument(
        "scenario", nargs="?", type=Path, metavar="SCENARIO", help="scenario YAML (default: the default scenario)"
    )
    parser.add_argument("--json", action="store_true", help="print the graph as JSON")
    parser.add_argument(
        "--dot", action="store_true", help="print Graphviz dot text (nodes as boxes, topics as ellipses)"
    )
    parser.add_argument(
        "--measure-s",
        type=float,
        default=5.0,
        metavar="S",
        help="simulated seconds to run to measure rates (default 5; 0: none)",
    )
    parser.add_argument(
        "--watchdog-s",
        type=float,
        default=_WATCHDOG_S,
        metavar="S",
        help=f"end (exit 8) when a step or a node's constructor has not returned for S wall seconds "
        f"(default {_WATCHDOG_S:g}; inf: no watchdog)",
    )
    parser.set_defaults(func=_graph)


def graph_data(
    scenario_path: Path | None, measure_s: float, *, watchdog_s: float = _WATCHDOG_S, debug: bool = False
) -> dict[str, Any]:
    """Return {"nodes": [...], "topics": [...]} of a scenario, with rates measured over `measure_s`.

    Runs under the watchdog, as `twin simulate` does: a node that spins in a callback or its
    constructor ends the command (exit 8) instead of hanging it.

    Raises:
        TwinError: The scenario's error, or a SimulationError naming what was stuck.
    """
    from twin.cli.watch import Guard, build_watched
    from twin.core.errors import ConfigError
    from twin.core.numbers import number_problem
    from twin.sim.check import check_scenario
    from twin.sim.scenario import default_scenario_path
    from twin.sim.scenario_file import load_scenario
    from twin.sim.simulation import Simulation
    from twin.sim.watchdog import Watchdog, WatchdogAbort

    if not measure_s >= 0.0 or measure_s == float("inf"):
        msg = f"--measure-s must be a finite number of seconds >= 0, got {measure_s}"
        raise ConfigError(msg)
    problem = number_problem(measure_s, "--measure-s", unit="s")
    if problem is not None:
        msg = f"--measure-s {problem}"
        raise ConfigError(msg)
    if not watchdog_s > 0:  # NaN too; inf turns the stuck-step check off
        msg = f"--watchdog-s must be a positive number of seconds (inf: no watchdog), got {watchdog_s}"
        raise ConfigError(msg)
    path = scenario_path or default_scenario_path()
    scenario = load_scenario(path)
    check_scenario(scenario, path)
    simulation = build_watched(
        lambda: Simulation(scenario, bag_path=None, duration_s=measure_s), timeout_s=watchdog_s, debug=debug
    )
    guard = Guard(simulation, debug=debug)
    try:
        with simulation as sim:
            if measure_s > 0:
                watchdog = Watchdog(
                    lambda: sim.t_s, timeout_s=watchdog_s, on_stuck=guard.on_stuck, on_signal=guard.on_signal
                )
                with watchdog:
                    sim.run()
    except WatchdogAbort:
        if guard.report is None:  # not ours: never hide an exception
            raise
        raise guard.error() from None
    finally:
        guard.done.set()
    data = _describe(scenario.name, sim, measure_s)
    namespaces = [ns for ns, _ in scenario.robot_scenarios() if ns]
    if namespaces:  # a fleet: its nodes and topics grouped by robot (a one-robot graph stays as it was)
        data["namespaces"] = _groups(data, namespaces)
    return data


def _group_of(name: str, namespaces: list[str]) -> str:
    """The robot namespace (`/robot1`) a node or topic name is under, or "" when under none."""
    return next((f"/{ns}" for ns in namespaces if name.startswith(f"/{ns}/")), "")


def _groups(data: dict[str, Any], namespaces: list[str]) -> list[dict[str, Any]]:
    """Each robot namespace's nodes and topics, then those under none (namespace "")."""
    groups: dict[str, dict[str, Any]] = {
        g: {"namespace": g, "nodes": [], "topics": []} for g in [f"/{ns}" for ns in namespaces] + [""]
    }
    for node in data["nodes"]:
        groups[_group_of(node["node"], namespaces)]["nodes"].append(node["node"])
    for topic in data["topics"]:
        groups[_group_of(topic["topic"], namespaces)]["topics"].append(topic["topic"])
    return list(groups.values())


def _describe(scenario_name: str, sim: Any, measure_s: float) -> dict[str, Any]:
    """The graph of a simulation that ran `measure_s`."""
    executor = sim.executor
    topics = []
    for name, topic in sorted(executor.topics.items()):
        rate = topic.count / measure_s if measure_s > 0 and topic.publishers else None
        topics.append(
            {
                "topic": name,
                "type": topic.msgtype,
                "rate_hz": round(rate, 2) if rate is not None else None,
                "publishers": topic.publishers,
                "subscribers": topic.subscribers,
                "latched": topic.latch_depth > 0,
            }
        )
    return {"scenario": scenario_name, "measured_s": measure_s, "nodes": executor.describe(), "topics": topics}


def _dot(data: dict[str, Any]) -> str:
    lines = [f'digraph "{data["scenario"]}" {{', "  rankdir=LR;", "  node [fontname=Helvetica];"]
    nodes = {node["node"]: f'"{node["node"]}" [shape=box, style=rounded];' for node in data["nodes"]}
    topics = {}
    for topic in data["topics"]:
        name = topic["topic"]
        rate = f"\\n{topic['rate_hz']:g} Hz" if topic["rate_hz"] else ""
        topics[name] = f'"{name}" [shape=ellipse, label="{name}\\n{topic["type"]}{rate}"];'
    if "namespaces" in data:  # a fleet: one cluster per robot namespace, as rqt_graph groups them
        for k, group in enumerate(data["namespaces"]):
            if not group["namespace"]:
                continue
            lines += [f"  subgraph cluster_{k} {{", f'    label="{group["namespace"]}";']
            lines += [f"    {nodes.pop(n)}" for n in group["nodes"]]
            lines += [f"    {topics.pop(t)}" for t in group["topics"]]
            lines.append("  }")
    lines += [f"  {n}" for n in nodes.values()]
    for topic in data["topics"]:
        if topic["topic"] in topics:
            lines.append(f"  {topics[topic['topic']]}")
        for pub in topic["publishers"]:
            lines.append(f'  "{pub}" -> "{topic["topic"]}";')
        for sub in topic["subscribers"]:
            lines.append(f'  "{topic["topic"]}" -> "{sub}";')
    lines.append("}")
    return "\n".join(lines)


def _text(data: dict[str, Any]) -> str:
    out = [f"scenario {data['scenario']}: {len(data['nodes'])} nodes, {len(data['topics'])} topics"]
    if "namespaces" in data:
        return "\n".join(out + _grouped_text(data))
    out.append("")
    out.append("nodes:")
    for node in data["nodes"]:
        out += _node_lines(node, "  ")
    out.append("")
    out.append(f"topics (rates over {data['measured_s']:g} simulated s):")
    width = max((len(t["topic"]) for t in data["topics"]), default=10)
    for topic in data["topics"]:
        out.append(_topic_line(topic, width, "  "))
    return "\n".join(out)


def _grouped_text(data: dict[str, Any]) -> list[str]:
    """A fleet's graph, one block per robot namespace, then what is under none."""
    nodes = {n["node"]: n for n in data["nodes"]}
    topics = {t["topic"]: t for t in data["topics"]}
    width = max((len(t) for t in topics), default=10)
    out: list[str] = []
    for group in data["namespaces"]:
        title = f"namespace {group['namespace']}" if group["namespace"] else "outside the robots' namespaces"
        out += ["", f"{title}: {len(group['nodes'])} nodes, {len(group['topics'])} topics", "  nodes:"]
        for name in group["nodes"]:
            out += _node_lines(nodes[name], "    ")
        out.append(f"  topics (rates over {data['measured_s']:g} simulated s):")
        out += [_topic_line(topics[t], width, "    ") for t in group["topics"]]
    return out


def _node_lines(node: dict[str, Any], indent: str) -> list[str]:
    out = [f"{indent}{node['node']}  ({node['class']})"]
    for pub in node["publishes"]:
        out.append(f"{indent}  publishes  {pub['topic']} [{pub['type']}]")
    for sub in node["subscribes"]:
        out.append(f"{indent}  subscribes {sub['topic']} [{sub['type']}]")
    rates = [f"{r:g} Hz" if r else "once" for r in node["timers_hz"]]
    if rates:
        out.append(f"{indent}  timers     {', '.join(rates)}")
    return out


def _topic_line(topic: dict[str, Any], width: int, indent: str) -> str:
    rate = "latched" if topic["latched"] else f"{topic['rate_hz']:g} Hz" if topic["rate_hz"] is not None else "-"
    return (
        f"{indent}{topic['topic']:<{width}}  {topic['type']:<36} {rate:>9}  "
        f"pub: {', '.join(topic['publishers']) or '-'}; sub: {', '.join(topic['subscribers']) or '-'}"
    )


def _graph(args: argparse.Namespace) -> int:
    data = graph_data(
        args.scenario, args.measure_s, watchdog_s=args.watchdog_s, debug=bool(getattr(args, "debug", False))
    )
    if args.json:
        print(json.dumps(data, indent=2))
    elif args.dot:
        print(_dot(data))
    else:
        print(_text(data))
    return 0
