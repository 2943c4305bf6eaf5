"""`twin world info WORLD`: what an SDF world (or model) holds, as twin loads it."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.world import World

_EPILOG = """\
examples:
  twin world info ../shared/fixtures/gazebo_classic/worlds/turtlebot3_house.world \\
      --model-path ../shared/fixtures/gazebo_classic/models
  twin world info sdf/worlds/house.sdf --json
  twin world info sdf/models/turtlebot3_waffle/model.sdf

model://NAME resolves against TWIN_MODEL_PATH, then --model-path, then GAZEBO_MODEL_PATH and
GZ_SIM_RESOURCE_PATH. Fuel includes that cannot be fetched offline are skipped with a warning
(Ground Plane and Sun have built-in stand-ins). Exit status: 0 when the world loads (warnings
included), 2 when a --model-path folder does not exist, 3 when the world cannot be loaded.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `world` command group."""
    parser = subparsers.add_parser(
        "world",
        help="inspect SDF worlds and models",
        description="SDF worlds and models (SDFormat 1.3 to 1.11, Gazebo Classic and gz-sim).",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="world_command", metavar="SUBCOMMAND", required=True)
    info = sub.add_parser(
        "info",
        help="load a world or model and list its models, links, collision shapes, bounds and warnings",
        description=(
            "Load WORLD (a .world/.sdf file, a model.sdf or a model folder) as the simulation would and "
            "print its models, links, collision shapes by type, the bounding box of its obstacles and "
            "every warning."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    info.add_argument("world", type=Path, metavar="WORLD", help="SDF world or model file, or a model folder")
    info.add_argument(
        "--model-path",
        action="append",
        default=[],
        metavar="DIR",
        help=f"folder holding model folders, for model://NAME (repeatable, or {os.pathsep}-separated)",
    )
    info.add_argument(
        "--strict",
        action="store_true",
        help="fail on a model:// include that is not on the model path (default: warn and skip, as Gazebo Classic)",
    )
    info.add_argument("--json", action="store_true", help="print the summary as JSON")
    info.set_defaults(func=_info)


def model_path_folders(values: Sequence[str | Path]) -> list[Path]:
    """Return the folders given with `--model-path` (repeatable, each may be os.pathsep-separated).

    Raises:
        ConfigError: Naming the first one that is not a folder (a typo would otherwise only show
            as a warning per include it failed to find).
    """
    from twin.core.errors import ConfigError

    folders = [Path(part) for item in values for part in str(item).split(os.pathsep) if part]
    for folder in folders:
        if not folder.is_dir():
            problem = "not a folder" if folder.exists() else "no such folder"
            msg = f"--model-path {folder}: {problem}; give folders that hold model folders"
            raise ConfigError(msg)
    return folders


def summarize(world: World) -> dict[str, Any]:
    """Return the facts `world info` prints, as plain data."""
    from twin.world.scene import obstacle_extent
    from twin.world.types import geometry_kind

    obstacles, bounds = obstacle_extent(world)
    shapes = Counter(geometry_kind(c.geometry) for c in world.all_collisions())
    models = []
    for model in world.all_models():
        models.append(
            {
                "name": model.scoped_name,
                "static": model.static,
                "links": len(model.links),
                "joints": len(model.joints),
                "collisions": sum(len(link.collisions) for link in model.links),
                "plugins": [p.filename for p in model.plugins],
                "source": str(model.source) if model.source else None,
            }
        )
    return {
        "file": str(world.source),
        "name": world.name,
        "sdf_version": world.sdf_version,
        "models": models,
        "links": sum(len(m.links) for m in world.all_models()),
        "collisions": dict(sorted(shapes.items())),
        "obstacles": obstacles,
        "bounds_m": None if bounds is None else {"min": list(bounds[0]), "max": list(bounds[1])},
        "physics": {
            "max_step_size_s": world.physics.max_step_size_s,
            "real_time_update_rate_hz": world.physics.real_time_update_rate_hz,
        },
        "plugins": [p.filename for p in world.plugins],
        "warnings": list(world.warnings),
    }


def _info(args: argparse.Namespace) -> int:
    from twin.world import load_world

    model_path = model_path_folders(args.model_path)
    world = load_world(args.world, model_path=model_path, missing_includes="error" if args.strict else "warn")
    facts = summarize(world)
    robot = _robot_facts(args.world, model_path) if _is_model(args.world) else None
    if robot is not None:
        facts["robot"] = robot
    if args.json:
        print(json.dumps(facts, indent=2))
        return 0
    out = sys.stdout
    kind = "model" if robot is not None else "world"
    print(f"{facts['file']}: {kind} {facts['name']!r} (SDF {facts['sdf_version']})", file=out)
    print(f"  models      {len(facts['models'])} ({sum(m['static'] for m in facts['models'])} static)", file=out)
    width = max((len(m["name"]) for m in facts["models"]), default=0)
    for model in facts["models"]:
        flag = " static" if model["static"] else ""
        print(
            f"    {model['name']:<{width}}  links {model['links']:>3}  joints {model['joints']:>3}  "
            f"collisions {model['collisions']:>3}{flag}",
            file=out,
        )
    shapes = ", ".join(f"{kind} {count}" for kind, count in facts["collisions"].items()) or "none"
    print(f"  links       {facts['links']}", file=out)
    print(f"  collisions  {sum(facts['collisions'].values())} ({shapes})", file=out)
    print(f"  obstacles   {facts['obstacles']} (planes and floor-level shapes excluded)", file=out)
    if facts["bounds_m"] is not None:
        lo, hi = facts["bounds_m"]["min"], facts["bounds_m"]["max"]
        print(
            f"  bounds      x [{lo[0]:.3f}, {hi[0]:.3f}]  y [{lo[1]:.3f}, {hi[1]:.3f}]  z [{lo[2]:.3f}, {hi[2]:.3f}] m",
            file=out,
        )
    if facts["plugins"]:
        print(f"  plugins     {', '.join(facts['plugins'])}", file=out)
    if robot is not None:
        for key in ("base", "drive", "lidar", "imu", "mass"):
            print(f"  {key:<11} {robot[key]}", file=out)
        facts["warnings"] += robot["warnings"]
    print(f"  warnings    {len(facts['warnings'])}", file=out)
    for warning in facts["warnings"]:
        print(f"    {warning}", file=out)
    return 0


def _is_model(path: Path) -> bool:
    """Whether `path` is a model (a folder, or an SDF file holding a <model> and no <world>)."""
    if path.is_dir():
        return True
    try:
        head = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False
    return "<model" in head and "<world" not in head


def _robot_facts(path: Path, model_path: Sequence[Path]) -> dict[str, Any] | None:
    """What a run reads of a model as the robot (its drive, lidar and IMU), or None when it is none."""
    from twin.core.errors import WorldError
    from twin.world import load_robot

    try:
        robot = load_robot(path, model_path=model_path)
    except WorldError:
        return None  # the world's own summary says what loads
    drive, lidar, imu = robot.drive, robot.lidar, robot.imu
    return {
        "base": robot.base_frame,
        "drive": "none (no diff-drive plugin or wheel joints)"
        if drive is None
        else f"{drive.left_joint} / {drive.right_joint}, wheel radius {drive.wheel_radius_m:g} m, separation "
        f"{drive.wheel_separation_m:g} m, listens on {drive.command_topic}",
        "lidar": "none"
        if lidar is None
        else f"{lidar.name} on {lidar.scan_topic} ({lidar.frame_id}), {lidar.samples} beams, {lidar.rate_hz:g} Hz, "
        f"{lidar.range_min_m:g} to {lidar.range_max_m:g} m",
        "imu": "none" if imu is None else f"{imu.name} ({imu.frame_id}), {imu.rate_hz:g} Hz",
        "mass": f"{robot.mass_kg:.3f} kg",
        "warnings": list(robot.warnings),
    }
