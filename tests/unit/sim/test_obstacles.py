"""The behaviour demos' blocks: drawn from the scenario seed, 0.6 m along each chosen location's heading."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from twin.core.errors import ConfigError
from twin.sim.obstacles import scenario_obstacles
from twin.sim.rng import RngStreams
from twin.sim.scenario import BlocksSection, NoMission
from twin.sim.scenario_file import load_scenario

REPO = Path(__file__).resolve().parents[3]
LOCATIONS = {  # trees/sim_house_locations.yaml (TB3_FACTS.md §5.2)
    "location1": (-1.0, -0.5, -2.25),
    "location2": (0.5, 4.0, 0.785),
    "location3": (4.0, 0.5, 1.571),
    "location4": (2.75, 2.5, -1.571),
}


def _blocks(seed: int, count: int = 3) -> list[tuple[str, float, float, float, tuple[float, ...]]]:
    scenario = load_scenario(REPO / "scenarios" / "default.yaml")
    scenario = dataclasses.replace(scenario, blocks=BlocksSection(count=count), seed=seed)
    specs = scenario_obstacles(scenario, RngStreams(seed).stream("blocks"))
    out = []
    for spec in specs:
        assert spec.pose is not None and spec.name is not None
        out.append((spec.name, spec.pose.x_m, spec.pose.y_m, spec.pose.yaw_rad, spec.size_m or ()))
    return out


def _location_of(x: float, y: float, yaw: float) -> str:
    """The location a block stands before: 0.6 m back along its heading."""
    back = (x - 0.6 * math.cos(yaw), y - 0.6 * math.sin(yaw))
    return next(name for name, (lx, ly, _) in LOCATIONS.items() if math.hypot(lx - back[0], ly - back[1]) < 1e-9)


def test_three_blocks_red_green_blue_each_0_6_m_along_a_distinct_locations_heading() -> None:
    blocks = _blocks(seed=0)
    assert [b[0] for b in blocks] == ["red_block", "green_block", "blue_block"]
    chosen = [_location_of(x, y, yaw) for _, x, y, yaw, _ in blocks]
    assert len(set(chosen)) == 3
    for (_, _, _, yaw, size), name in zip(blocks, chosen, strict=True):
        assert yaw == LOCATIONS[name][2]  # turned to the location's theta
        assert size == (0.1, 0.1, 0.1)


def test_same_seed_same_draw_and_other_seeds_other_draws() -> None:
    assert _blocks(seed=3) == _blocks(seed=3)
    draws = {tuple(_location_of(x, y, yaw) for _, x, y, yaw, _ in _blocks(seed)) for seed in range(8)}
    assert len(draws) >= 4  # 24 ordered draws of 3 of 4 locations: eight seeds give several


def test_no_blocks_by_default_and_more_blocks_than_locations_is_refused() -> None:
    assert _blocks(seed=0, count=0) == []
    with pytest.raises(ConfigError, match=r"blocks.count: 5 blocks need as many locations, the mission has 4"):
        _blocks(seed=0, count=5)
    scenario = dataclasses.replace(
        load_scenario(REPO / "scenarios" / "default.yaml"), blocks=BlocksSection(count=1), mission=NoMission()
    )
    with pytest.raises(ConfigError, match="stand at the mission's locations"):
        scenario_obstacles(scenario, RngStreams(0).stream("blocks"))


def _fleet_blocks(tmp_path: Path, second_locations: str, seed: int = 0) -> list[tuple[str, float, float]]:
    scenario = tmp_path / "fleet.yaml"
    scenario.write_text(
        f"name: fleet\nseed: {seed}\nblocks: {{count: 3}}\n"
        f"mission: {{locations: {REPO / 'trees' / 'sim_house_locations.yaml'}}}\n"
        "robots:\n  - {name: robot1}\n"
        f"  - {{name: robot2, robot: {{initial_pose: {{x_m: 1.5, y_m: -0.2}}}}, "
        f"mission: {{locations: {second_locations}}}}}\n"
    )
    fleet = load_scenario(scenario)
    specs = scenario_obstacles(fleet, RngStreams(seed).stream("blocks"))
    return [(s.name or "", s.pose.x_m, s.pose.y_m) for s in specs if s.pose is not None]


def test_a_fleet_touring_the_same_places_gets_the_blocks_one_robot_gets(tmp_path: Path) -> None:
    reversed_tour = REPO / "trees" / "sim_house_locations_reversed.yaml"
    for seed in range(4):
        one = [(name, x, y) for name, x, y, _, _ in _blocks(seed=seed)]
        assert _fleet_blocks(tmp_path, str(reversed_tour), seed) == one


def test_a_fleet_s_blocks_may_stand_at_a_place_only_the_second_robot_visits(tmp_path: Path) -> None:
    extra = tmp_path / "extra.yaml"
    extra.write_text("far: [6.0, -1.0, 0.0]\n")
    draws = [_fleet_blocks(tmp_path, str(extra), seed) for seed in range(12)]
    # Five places to draw three from: the far one (a block 0.6 m along its heading 0) comes up.
    assert any((x, y) == (6.6, -1.0) for draw in draws for _, x, y in draw)
