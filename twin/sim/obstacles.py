"""The scenario's obstacles: its `obstacles:` list and the behaviour demos' blocks, as `ObstacleSpec`s.

With several robots (`robots:`) the obstacles are the world's: every robot's lidar sees them and
every robot collides with them as one robot does (`JoinedSource` adds them to what a robot's lidar
sees of the others); the blocks stand at the locations of the robots' missions, taken together.

The blocks follow `block_spawner.py` of the TurtleBot3 behaviour demos (TB3_FACTS.md §5.3): a red,
a green and a blue 0.1 m cube, each at one of the mission's locations drawn without replacement,
`offset_m` along the location's heading theta and turned to theta, resting on the floor. The draw
uses the scenario seed's `blocks` stream, so the same seed places them alike and nothing else's
random numbers change.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from twin.core.errors import ConfigError
from twin.sim.scenario import BehaviorTreeMission, BlocksSection, Scenario
from twin.world.obstacles import ObstacleCaster, ObstaclePose, ObstacleSpec

if TYPE_CHECKING:
    from twin.robot.lidar import ObstacleSource

__all__ = ["BLOCK_COLORS", "JoinedSource", "block_obstacles", "scenario_obstacles"]

# The demos' block models' diffuse colours, in spawn order (red and blue from their model.sdf; green the analogue).
BLOCK_COLORS: tuple[tuple[str, tuple[float, float, float, float]], ...] = (
    ("red", (0.8, 0.0, 0.2, 1.0)),
    ("green", (0.0, 0.8, 0.0, 1.0)),
    ("blue", (0.0, 0.0, 0.8, 1.0)),
)


def block_obstacles(
    blocks: BlocksSection, locations: Mapping[str, Sequence[float]], rng: np.random.Generator
) -> tuple[ObstacleSpec, ...]:
    """Place `blocks.count` blocks at locations drawn from `rng` (in the file's order of names).

    Colours go red, green, blue (and round again past three); each block is named `<colour>_block`
    (`<colour>_block_<n>` from the fourth on), as the demos' models are.

    Raises:
        ConfigError: If there are fewer locations than blocks.
    """
    if blocks.count == 0:
        return ()
    names = list(locations)
    if blocks.count > len(names):
        msg = (
            f"blocks.count: {blocks.count} blocks need as many locations, the mission has {len(names)}; "
            f"give count {len(names)} or less"
        )
        raise ConfigError(msg)
    chosen = rng.choice(len(names), size=blocks.count, replace=False)
    out = []
    size = blocks.size_m
    for n, index in enumerate(chosen):
        x, y, theta = (float(v) for v in locations[names[int(index)]][:3])
        colour, rgba = BLOCK_COLORS[n % len(BLOCK_COLORS)]
        suffix = f"_{n // len(BLOCK_COLORS) + 1}" if n >= len(BLOCK_COLORS) else ""
        pose = ObstaclePose(
            x_m=x + blocks.offset_m * math.cos(theta), y_m=y + blocks.offset_m * math.sin(theta), yaw_rad=theta
        )
        name = f"{colour}_block{suffix}"
        out.append(ObstacleSpec(shape="box", size_m=(size, size, size), pose=pose, name=name, color_rgba=rgba))
    return tuple(out)


def scenario_obstacles(scenario: Scenario, rng: np.random.Generator) -> tuple[ObstacleSpec, ...]:
    """The scenario's `obstacles:` then its blocks (drawn from `rng`, the seed's `blocks` stream).

    Raises:
        ConfigError: If blocks are asked for without a behaviour-tree mission's locations, or more
            blocks than locations.
    """
    specs = tuple(scenario.obstacles)
    if scenario.blocks.count == 0:
        return specs
    files = []
    for _, view in scenario.robot_scenarios():  # the one robot, or each of a fleet's in order
        mission = view.mission
        if isinstance(mission, BehaviorTreeMission) and mission.locations is not None:
            files.append(mission.locations)
    if not files:
        whose = "the robots' missions have" if scenario.robots else "this mission has"
        msg = (
            f"blocks.count: {scenario.blocks.count} blocks stand at the mission's locations, and {whose} "
            "none; use a behavior_tree mission with locations, or count: 0"
        )
        raise ConfigError(msg)
    from twin.mission.bt_nodes import load_locations

    # The first robot's locations as its file lists them (one robot: exactly its own), then the places
    # only later robots visit (a robot touring the same places in another order adds none).
    first, *others = dict.fromkeys(files)
    locations = {name: (p.x_m, p.y_m, p.yaw_rad) for name, p in load_locations(first).items()}
    for path in others:
        for name, p in load_locations(path).items():
            place = (p.x_m, p.y_m, p.yaw_rad)
            if place in locations.values():
                continue
            key, n = name, 1
            while key in locations:
                n += 1
                key = f"{name}_{n}"
            locations[key] = place
    blocks = block_obstacles(scenario.blocks, locations, rng)
    mine = {spec.name or f"obstacle_{i}": i for i, spec in enumerate(specs)}
    for block in blocks:
        if block.name in mine:  # /contacts and the markers would not tell them apart
            msg = (
                f"obstacles[{mine[block.name]}]: its name {block.name!r} is a block's (blocks: names them "
                "red_block, green_block, blue_block...); rename the obstacle"
            )
            raise ConfigError(msg)
    return specs + blocks


class JoinedSource:
    """What a fleet robot's lidar sees besides the world: the scenario's obstacles and the other robots.

    Answers as an `ObstacleField` does for the lidar (`caster(height_m)`): one caster over both
    sources' shapes at that height, made again only when either source's caster changed.

    Args:
        obstacles: The robot's view of the scenario's obstacles (its `ObstacleField`).
        robots: What it sees of the other robots (`twin.sim.fleet.FleetView`).
    """

    def __init__(self, obstacles: ObstacleSource, robots: ObstacleSource) -> None:
        self.obstacles = obstacles
        self.robots = robots
        self._cache: dict[float, tuple[ObstacleCaster | None, ObstacleCaster | None, ObstacleCaster | None]] = {}

    def caster(self, height_m: float) -> ObstacleCaster | None:
        """A ray caster over the obstacles and the other robots at `height_m` now (None: nothing reaches it)."""
        a = self.obstacles.caster(height_m)
        b = self.robots.caster(height_m)
        if a is None or b is None:
            return a if b is None else b
        key = round(float(height_m), 9)
        cached = self._cache.get(key)
        if cached is not None and cached[0] is a and cached[1] is b:
            return cached[2]
        (seg_a, circ_a), (seg_b, circ_b) = a.shapes, b.shapes
        segments = [(s[0], s[1], s[2], s[3]) for s in np.vstack([seg_a, seg_b]).tolist()]
        circles = [(c[0], c[1], c[2]) for c in np.vstack([circ_a, circ_b]).tolist()]
        joined = ObstacleCaster(segments, circles, key)
        self._cache[key] = (a, b, joined)
        return joined
