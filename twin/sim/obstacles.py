"""The scenario's obstacles: its `obstacles:` list and the behaviour demos' blocks, as `ObstacleSpec`s.

The blocks follow `block_spawner.py` of the TurtleBot3 behaviour demos (TB3_FACTS.md §5.3): a red,
a green and a blue 0.1 m cube, each at one of the mission's locations drawn without replacement,
`offset_m` along the location's heading theta and turned to theta, resting on the floor. The draw
uses the scenario seed's `blocks` stream, so the same seed places them alike and nothing else's
random numbers change.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from twin.core.errors import ConfigError
from twin.sim.scenario import BehaviorTreeMission, BlocksSection, Scenario
from twin.world.obstacles import ObstaclePose, ObstacleSpec

__all__ = ["BLOCK_COLORS", "block_obstacles", "scenario_obstacles"]

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
    mission = scenario.mission
    if not isinstance(mission, BehaviorTreeMission) or mission.locations is None:
        msg = (
            f"blocks.count: {scenario.blocks.count} blocks stand at the mission's locations, and this mission has "
            "none; use a behavior_tree mission with locations, or count: 0"
        )
        raise ConfigError(msg)
    from twin.mission.bt_nodes import load_locations

    locations = {name: (p.x_m, p.y_m, p.yaw_rad) for name, p in load_locations(mission.locations).items()}
    return specs + block_obstacles(scenario.blocks, locations, rng)
