"""`twin map save WORLD --out DIR/map.yaml`: a map_server map made from an SDF world, without SLAM."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path
from typing import Any

_EPILOG = """\
examples:
  twin map save ../shared/fixtures/gazebo_classic/worlds/turtlebot3_world.world \\
      --model-path ../shared/fixtures/gazebo_classic/models --out /tmp/tb3_world/map.yaml
  twin map save sdf/worlds/house.sdf --out maps/house/map.yaml --free 0.0 0.0   (where the default scenario spawns)
  twin map save sdf/worlds/house.sdf --out /tmp/house/map.yaml --height 0.182   (burger's lidar)

The world's static geometry is cut at the lidar's height (default 0.132 m, the TurtleBot3 waffle's
LDS-01) and rasterised at 0.05 m; the free space the robot drives in is free, the walls it sees are
occupied, everything else unknown, as a SLAM map would be. The output is map_server's trinary
format (PGM + YAML, free_thresh 0.196, occupied_thresh 0.65), which Nav2's map_server and the
scenario's `map:` key read. Exit status: 0 written, 2 bad option or unwritable output, 3 world
cannot be loaded.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `map` command group."""
    parser = subparsers.add_parser(
        "map",
        help="make maps in map_server format",
        description="Occupancy maps in Nav2 map_server format (YAML + PGM).",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="map_command", metavar="SUBCOMMAND", required=True)
    save = sub.add_parser(
        "save",
        help="rasterise a world at the lidar's height into map.yaml + map.pgm",
        description="Make a SLAM-like map of WORLD and write it as map_server does (map_saver's trinary format).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    save.add_argument("world", type=Path, metavar="WORLD", help="SDF world file (.world/.sdf)")
    save.add_argument(
        "--out", type=Path, required=True, metavar="DIR/map.yaml", help="the YAML to write; the PGM goes beside it"
    )
    save.add_argument(
        "--model-path",
        action="append",
        default=[],
        metavar="DIR",
        help=f"folder holding model folders, for model://NAME (repeatable, or {os.pathsep}-separated)",
    )
    save.add_argument(
        "--skip-missing",
        action="store_true",
        help="skip a model:// include not on the model path, with a warning, as Gazebo Classic does "
        "(default: refuse the world, as the map would lack its walls)",
    )
    save.add_argument(
        "--height", type=float, default=0.132, metavar="M", help="lidar beam height above the floor (default 0.132)"
    )
    save.add_argument("--resolution", type=float, default=0.05, metavar="M", help="cell size (default 0.05)")
    save.add_argument(
        "--free",
        type=float,
        nargs=2,
        metavar=("X", "Y"),
        help="a point in the space the robot drives in (default: the largest region inside the walls)",
    )
    save.add_argument("--format", choices=("pgm", "png"), default="pgm", help="image format (default pgm)")
    save.set_defaults(func=_save)


# Cell sizes `map save` takes: the planner's finest (a finer grid of a house is hundreds of MB) to 10 m.
_MIN_RESOLUTION_M = 0.005
_MAX_RESOLUTION_M = 10.0


def _reaches_edge(data: Any) -> bool:
    """Whether a map's free space reaches its border (it is outside, or the world has no outer walls)."""
    import numpy as np

    return bool((np.concatenate([data[0], data[-1], data[:, 0], data[:, -1]]) == 0).any())


def _default_map(map_from_scene: Any, scene: Any, args: argparse.Namespace) -> Any:
    """The map without --free (the largest enclosed region, in a world with outer walls)."""
    return map_from_scene(scene, height_m=args.height, resolution_m=args.resolution).data


def _save(args: argparse.Namespace) -> int:

    from twin.cli.world import model_path_folders
    from twin.core.errors import ConfigError
    from twin.core.numbers import number_problem
    from twin.nav.map_server.map_io import map_from_scene, save_map
    from twin.world import build_scene, load_world

    if not (_MIN_RESOLUTION_M <= args.resolution <= _MAX_RESOLUTION_M):  # NaN too
        msg = (
            f"--resolution must be a cell size from {_MIN_RESOLUTION_M:g} to {_MAX_RESOLUTION_M:g} m "
            f"(Nav2 maps use 0.05), got {args.resolution}"
        )
        raise ConfigError(msg)
    problem = number_problem(args.height, "--height", unit="m")
    if problem is not None or args.height < 0.0:
        msg = f"--height must be a height >= 0 m: {problem or f'got {args.height}'}"
        raise ConfigError(msg)
    for axis, value in zip("XY", args.free or (), strict=False):
        problem = number_problem(value, f"--free {axis}", unit="m")
        if problem is not None:
            msg = f"--free {axis} (of the point X Y, m): {problem}"
            raise ConfigError(msg)
    if args.out.suffix not in (".yaml", ".yml"):
        msg = f"--out {str(args.out)!r} must name the map's YAML file (DIR/map.yaml)"
        raise ConfigError(msg)
    world = load_world(
        args.world,
        model_path=model_path_folders(args.model_path),
        missing_includes="warn" if args.skip_missing else "error",
    )
    for warning in world.warnings:  # what the map leaves out (skipped includes, unsupported shapes)
        logging.getLogger("twin.cli.map").warning("%s", warning)
    occupancy = map_from_scene(
        build_scene(world),
        height_m=args.height,
        resolution_m=args.resolution,
        free_xy_m=tuple(args.free) if args.free else None,
    )
    data = occupancy.data
    if args.free and _reaches_edge(data) and not _reaches_edge(_default_map(map_from_scene, build_scene(world), args)):
        logging.getLogger("twin.cli.map").warning(
            "--free %g %g: that point's free space reaches the map's edge, so it lies outside the world's walls "
            "and what they enclose stays unknown; give a point inside (or leave --free out: the largest enclosed "
            "region)",
            *args.free,
        )
    image = save_map(occupancy, args.out, image_format=args.format)
    print(
        f"{args.out}: {occupancy.width} x {occupancy.height} cells at {occupancy.resolution_m} m, origin "
        f"({occupancy.origin_x_m:.3f}, {occupancy.origin_y_m:.3f}); free {int((data == 0).sum())}, "
        f"occupied {int((data == 100).sum())}, unknown {int((data < 0).sum())}; image {image.name}",
        file=sys.stdout,
    )
    return 0
