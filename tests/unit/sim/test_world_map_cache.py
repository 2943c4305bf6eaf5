"""The map made from the world is cached on disk by what it is made of: reused when nothing changed, never stale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import twin.sim.navigation as navigation
from twin.sim.navigation import NavigationStack
from twin.sim.robot_group import RobotGroup
from twin.sim.scenario_file import load_scenario
from twin.world import build_scene, load_world

_STL = """solid pillar
facet normal 0 0 1
 outer loop
  vertex 0 0 0
  vertex {s} 0 0
  vertex 0 {s} 1
 endloop
endfacet
facet normal 0 0 1
 outer loop
  vertex {s} 0 0
  vertex {s} {s} 1
  vertex 0 {s} 1
 endloop
endfacet
endsolid pillar
"""


def _write_world(folder: Path, *, east_wall_x: float = 2.0, pillar_size: float = 0.3) -> Path:
    """A 4 x 4 m room of box walls with a mesh pillar (an ASCII STL beside the world) in a corner."""
    (folder / "pillar.stl").write_text(_STL.format(s=pillar_size))
    walls = [("n", 0.0, 2.0, 4.2, 0.1), ("s", 0.0, -2.0, 4.2, 0.1), ("w", -2.0, 0.0, 0.1, 4.2)]
    walls.append(("e", east_wall_x, 0.0, 0.1, 4.2))
    models = "".join(
        f"<model name='{n}'><static>1</static><pose>{x} {y} 0.5 0 0 0</pose><link name='l'><collision name='c'>"
        f"<geometry><box><size>{sx} {sy} 1</size></box></geometry></collision></link></model>"
        for n, x, y, sx, sy in walls
    )
    models += (
        "<model name='pillar'><static>1</static><pose>1.0 1.0 0 0 0 0</pose><link name='l'><collision name='c'>"
        f"<geometry><mesh><uri>file://{folder / 'pillar.stl'}</uri></mesh></geometry></collision></link></model>"
    )
    world = folder / "room.world"
    world.write_text(f"<sdf version='1.6'><world name='room'>{models}</world></sdf>")
    return world


def _map(folder: Path, world: Path, *, x_m: float = 0.0) -> np.ndarray:
    """The map a run of `world` localises on (AMCL under a scripted drive, so no Nav2 stack is built)."""
    scenario_file = folder / "run.yaml"
    scenario_file.write_text(
        f"name: room\nworld: {{sdf: {world}}}\nrobot: {{initial_pose: {{x_m: {x_m}, y_m: 0.0}}}}\n"
        "localization: {type: amcl}\n"
        "mission: {type: cmd_vel_script, segments: [{duration_s: 1, linear_mps: 0.1}]}\n"
    )
    scenario = load_scenario(scenario_file)
    robot = RobotGroup.load(scenario).robot
    scene = build_scene(load_world(world, model_path=scenario.world.model_path), exclude_models=(robot.name,))
    stack = NavigationStack.build(scenario, robot, scene, np.random.default_rng(0))
    assert stack is not None
    return stack.occupancy.data


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv("TWIN_CACHE_DIR", str(folder))
    return folder


def _entries(cache: Path) -> list[Path]:
    return sorted((cache / "derived" / "world_map").glob("*.npz"))


def _forbid_building(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the map was made again although its cache entry holds it")

    monkeypatch.setattr(navigation, "map_from_scene", refuse)


def test_a_second_run_of_the_same_world_reuses_the_map(
    tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    world = _write_world(tmp_path)
    first = _map(tmp_path, world)
    assert len(_entries(cache)) == 1 and {int(v) for v in np.unique(first)} == {-1, 0, 100}
    _forbid_building(monkeypatch)
    assert np.array_equal(_map(tmp_path, world), first)


@pytest.mark.parametrize("change", ["world file", "model mesh", "spawn pose"])
def test_a_changed_input_never_reuses_a_stale_map(tmp_path: Path, cache: Path, change: str) -> None:
    world = _write_world(tmp_path)
    before = _map(tmp_path, world)
    if change == "world file":
        world = _write_world(tmp_path, east_wall_x=1.5)  # the east wall 0.5 m further in
    elif change == "model mesh":
        world = _write_world(tmp_path, pillar_size=0.6)  # the same world file, a larger pillar mesh
    after = _map(tmp_path, world, x_m=-0.5 if change == "spawn pose" else 0.0)
    assert len(_entries(cache)) == 2  # a new entry beside the old one
    if change == "spawn pose":
        assert np.array_equal(after, before)  # the same walls: only the point the free space holds moved
    else:
        assert not np.array_equal(after, before)


def test_a_corrupt_map_entry_is_made_again(tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    world = _write_world(tmp_path)
    first = _map(tmp_path, world)
    (entry,) = _entries(cache)
    entry.write_bytes(entry.read_bytes()[:100])  # cut short, as by a full disk
    assert np.array_equal(_map(tmp_path, world), first)
    _forbid_building(monkeypatch)  # and the entry written again is whole
    assert np.array_equal(_map(tmp_path, world), first)
