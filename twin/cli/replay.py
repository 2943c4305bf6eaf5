"""`twin replay BAG --world W`: drive the twin with a bag's recorded commands and compare the runs."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

_EPILOG = """\
examples:
  twin replay ../shared/fixtures/bags/tb3_waffle_gazebo_humble \\
      --world ../shared/fixtures/gazebo_classic/worlds/turtlebot3_world.world \\
      --model-path ../shared/fixtures/gazebo_classic/models --out /tmp/replay
  twin replay BAG --world W --model-path M --drive fmu      the robot's own motors instead of ideal wheels
  twin replay bags/fleet --world sdf/worlds/house.sdf --namespace robot2   one robot of a fleet

Writes into --out (default: bags/<BAG name>_replay): scenario.yaml (the replay as a scenario
`twin simulate` runs again), bag/ (the twin's run) and the comparison of the twin's
/ground_truth/odom against the bag's pose topic: comparison.json, overlay.png,
compare_error.png. The robot is the one the bag's /robot_description names, found on --model-path
or among the project's models, else the model whose wheels (joint names, separation, radius)
match the URDF's; a bag that matches none is refused: choose with --robot. A fleet's bag (robots
under namespaces) needs --namespace NS: that robot's /NS/cmd_vel, /NS/ground_truth/odom (else
/NS/odom) and /NS/robot_description are used; --topic and --pose-topic may be given without /NS. --drive fmu runs that
robot's own motors as `twin simulate` does (fmu: auto, velocity-servo); without --drive, a bag a twin
run made replays with the drive its provenance records, any other with ideal wheels. Exit codes: 0 done (and
within --max-position-error), 1 over it, 2 scenario error (or no robot matches the bag), 3 world
error, 4 FMU error, 5 bag error (e.g. no /cmd_vel to replay).
"""

# The robot's own motors (Burger XL430, Waffle XM430) in the project's default profile, as `simulate` runs them.
_FMU_DRIVE = "{type: fmu, fmu: auto, profile: velocity-servo}"


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `replay` command."""
    parser = subparsers.add_parser(
        "replay",
        help="drive the twin with a bag's /cmd_vel at its times, from its first pose, and compare",
        description=(
            "Replay a bag's velocity commands in the twin (at their recorded sim times, from the bag's "
            "first pose and velocity) and compare the twin's trajectory with the bag's."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag whose commands to replay")
    parser.add_argument("--world", type=Path, required=True, metavar="SDF", help="the world the bag was recorded in")
    parser.add_argument(
        "--model-path", type=Path, action="append", default=[], metavar="DIR", help="where model:// URIs resolve"
    )
    parser.add_argument(
        "--robot", metavar="MODEL", help="robot model (default: the model matching the bag's /robot_description)"
    )
    parser.add_argument(
        "--drive",
        choices=("kinematic", "fmu"),
        help="drivetrain (default: a twin bag's own, from its provenance; else kinematic)",
    )
    parser.add_argument("--topic", default="/cmd_vel", help="command topic in the bag (default: /cmd_vel)")
    parser.add_argument(
        "--pose-topic", metavar="TOPIC", help="the bag's pose topic (default: /ground_truth/odom, else /odom)"
    )
    parser.add_argument(
        "--namespace",
        metavar="NS",
        help="a fleet's bag: replay the robot under /NS/ (its cmd_vel, poses and robot_description)",
    )
    parser.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: bags/<BAG name>_replay)")
    parser.add_argument(
        "--max-position-error", type=float, metavar="M", help="exit 1 if the final or max error exceeds M"
    )
    parser.add_argument("--json", action="store_true", help="print the comparison as JSON on stdout")
    parser.set_defaults(func=_replay)


def _yaml_path(p: Path) -> str:
    return json.dumps(str(p.resolve()))


def _in_namespace(topic: str, namespace: str) -> str:
    prefix = f"/{namespace}/"
    return topic if topic.startswith(prefix) else prefix + topic.lstrip("/")


def _robot_topics(
    bag: Path, topic: str, pose_topic: str | None, namespace: str | None
) -> tuple[str, str | None, str | None]:
    """The command and pose topics to replay, and the robot's namespace (None: a one-robot bag).

    Raises:
        ConfigError: If a bag of several robots comes without --namespace (its robots named), or with one
            it lacks. A bag of one robot under a namespace needs none.
    """
    from twin.analysis.fleet import bag_robots, check_namespace
    from twin.core.errors import ConfigError

    info, robots = bag_robots(bag)
    if namespace is None:
        if len(robots) > 1:
            msg = f"{bag} holds {len(robots)} robots ({', '.join(robots)}): choose one with --namespace NS"
            raise ConfigError(msg)
        if not robots:
            return topic, pose_topic, None
        namespace = robots[0]  # one robot under a namespace (a bag of nav2_bringup's multi-robot launch): that one
    ns = check_namespace(info, namespace)
    names = {t.name for t in info.topics}
    if pose_topic is not None:
        pose_topic = _in_namespace(pose_topic, ns)
    else:  # the replay's own default (ground truth, else odometry), in the robot's namespace
        pose_topic = next((f"/{ns}{t}" for t in ("/ground_truth/odom", "/odom") if f"/{ns}{t}" in names), None)
    return _in_namespace(topic, ns), pose_topic, ns


def _drive(chosen: str | None, bag: Path, namespace: str | None, *, robot_given: bool) -> tuple[str, str, str]:
    """The replay's drive: its type, where it came from, and its section (flow YAML).

    `--drive` when given; else, unless `--robot` names another robot, the drive a twin run recorded
    in the bag's provenance (its own motor FMU, as it ran), so a twin bag replays as it was made
    (an FMU file the recorded drive names that is not on this machine: the robot's own motors);
    else ideal wheels (a Gazebo bag).
    """
    if chosen is not None:
        return chosen, "--drive", "{type: kinematic}" if chosen == "kinematic" else _FMU_DRIVE
    if robot_given:
        return "kinematic", "default", "{type: kinematic}"
    import yaml

    from twin.bag.provenance import read_provenance

    provenance = read_provenance(bag)
    recorded = yaml.safe_load(provenance.get("scenario_yaml", "")) if provenance else None
    section = recorded.get("drive") if isinstance(recorded, dict) else None
    if isinstance(recorded, dict) and namespace is not None:
        for entry in recorded.get("robots") or ():
            if isinstance(entry, dict) and namespace in (entry.get("namespace"), entry.get("name")):
                section = entry.get("drive", section)
    if not isinstance(section, dict) or section.get("type") not in ("kinematic", "fmu"):
        return "kinematic", "default", "{type: kinematic}"
    fmu_file = section.get("fmu_file")
    if section["type"] == "fmu" and fmu_file and not Path(str(fmu_file)).exists():
        return "fmu", f"the bag's provenance; its FMU {fmu_file} is not here: the robot's own motors", _FMU_DRIVE
    return str(section["type"]), "the bag's provenance", json.dumps(section)


def _fleet_robot(bag: Path, namespace: str, model_path: list[Path]) -> Any:
    """The model of a fleet robot, from its `/<namespace>/robot_description`."""
    from twin.bag import read_messages
    from twin.core.errors import ConfigError
    from twin.sim.bag_robot import robot_from_urdf

    topic = f"/{namespace}/robot_description"
    for m in read_messages(bag, [topic]):
        return robot_from_urdf(str(m.msg.data), model_path, where=f"{bag} {topic}")
    msg = f"{bag}: no {topic} says which robot /{namespace} is; choose a model with --robot"
    raise ConfigError(msg)


def _replay(args: argparse.Namespace) -> int:
    from twin.analysis.compare import compare_bags, write_comparison
    from twin.analysis.report import world_walls
    from twin.cli.analyze import check_threshold
    from twin.cli.world import model_path_folders
    from twin.core.errors import ConfigError
    from twin.sim.replay import check_bag
    from twin.sim.scenario import ReplayMission
    from twin.sim.scenario_file import load_scenario
    from twin.sim.simulation import Simulation

    model_path_folders(args.model_path)  # refuse a folder that does not exist before anything runs
    check_threshold(args.max_position_error)
    bag = args.bag
    out = args.out if args.out is not None else Path("bags") / f"{bag.resolve().name}_replay"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        msg = f"{out}: cannot create the output folder ({err.strerror or err}); choose another --out"
        raise ConfigError(msg) from None
    topic, pose_topic_arg, namespace = _robot_topics(bag, args.topic, args.pose_topic, args.namespace)
    check_bag(ReplayMission(bag=bag, topic=topic))  # no commands to replay is said before the robot
    if args.robot:
        robot, robot_reason = args.robot, "--robot"
    elif namespace is not None:
        chosen = _fleet_robot(bag, namespace, args.model_path)
        robot, robot_reason = chosen.model, chosen.reason
    else:
        from twin.sim.bag_robot import robot_from_bag

        chosen = robot_from_bag(bag, args.model_path)
        robot, robot_reason = chosen.model, chosen.reason
    drive_name, drive_from, drive = _drive(args.drive, bag, namespace, robot_given=bool(args.robot))
    model_path = "[" + ", ".join(_yaml_path(p) for p in args.model_path) + "]"
    pose_topic = json.dumps(pose_topic_arg) if pose_topic_arg else "null"
    scenario_file = out / "scenario.yaml"
    scenario_file.write_text(
        f"# Written by `twin replay`: {bag} replayed in {args.world.name}.\n"
        f"name: replay_{bag.resolve().name}\n"
        f"world: {{sdf: {_yaml_path(args.world)}, model_path: {model_path}}}\n"
        f"robot: {{model: {json.dumps(robot)}}}\n"
        f"drive: {drive}\n"
        f"mission: {{type: replay, bag: {_yaml_path(bag)}, topic: {json.dumps(topic)}, "
        f"pose_topic: {pose_topic}}}\n"
    )
    scenario = load_scenario(scenario_file)
    run_bag = out / "bag"
    if run_bag.exists():
        import shutil

        shutil.rmtree(run_bag)
    with Simulation(scenario, bag_path=run_bag) as sim:
        summary = sim.run()
        source_topic = sim.mission.commands.pose_topic  # type: ignore[union-attr]
    result = compare_bags(bag, run_bag, topics=(source_topic, "/ground_truth/odom"), namespaces=(namespace, None))
    walls = world_walls(args.world, args.model_path)
    write_comparison(result, out, walls=walls)
    over = args.max_position_error is not None and result.max_position_error_m > args.max_position_error
    d = result.to_dict()
    d.update(
        robot=robot,
        robot_reason=robot_reason,
        drive=drive_name,
        drive_from=drive_from,
        replay_bag=str(run_bag),
        scenario=str(scenario_file),
        sim_s=summary.sim_s,
        wall_s=summary.wall_s,
        threshold_m=args.max_position_error,
        within_threshold=None if args.max_position_error is None else not over,
    )
    (out / "comparison.json").write_text(json.dumps(d, indent=2) + "\n")
    if args.json:
        print(json.dumps(d, indent=2))
    else:
        source = "" if drive_from in ("--drive", "default") else f", from {drive_from}"
        print(
            f"replayed {bag} with {robot} ({drive_name} drive{source}): {summary.sim_s:.2f} s in {summary.wall_s:.2f} s"
        )
        print(f"robot: {robot} ({robot_reason})")
        print("\n".join(result.summary_lines()))
        print(f"output: {out} (scenario.yaml, bag/, comparison.json, overlay.png, compare_error.png)")
    return 1 if over else 0
