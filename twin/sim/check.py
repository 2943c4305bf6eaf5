"""What `twin simulate` refuses, checked before anything runs: `twin scenario check` and `simulate` share it.

`check_scenario(scenario, path)` raises a `ConfigError` naming the file, the key and the fix for
the first value that cannot be honoured (NaN or infinite numbers, negative seeds, zero or negative
rates, `range_min_m >= range_max_m`, sample counts below one, rates above the physics rate, more
blocks than the mission has locations) and for the first referenced file that is missing or does
not parse (locations, FMU mapping, FMU file, and any other path the scenario names). It is cheap
(no world is loaded) so `simulate` runs it before it creates the bag folder. `check_inputs(scenario)`
also loads what the run would load (world, robot, behaviour tree) for `twin scenario check`.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.core.config import key_location, suggest
from twin.core.errors import ConfigError, FmuError, TreeError, TwinError
from twin.core.numbers import number_problem
from twin.sim.scenario import BehaviorTreeMission, Scenario, in_entry, names_a_key, runs_amcl, runs_nav2

if TYPE_CHECKING:
    from twin.world import RobotModelSpec

__all__ = ["check_inputs", "check_scenario", "in_scenario"]

# Numbers that may be infinite (none today: every number of a scenario must be finite).
_MAY_BE_INFINITE: frozenset[str] = frozenset()
# Below this a publication would fire less than once in 16 minutes: surely a typo (and 1/rate must fit in ns).
_MIN_RATE_HZ = 1e-3
# More rays per scan than any real lidar has (the TB3's LDS-01 has 360); each costs memory and time.
_MAX_SAMPLES = 100_000
# A LaserScan carries the lidar's angles and ranges as float32: a larger number cannot be recorded.
_FLOAT32_MAX = 3.4028234663852886e38
# Numbers that cannot be negative: durations, distances, rates, gains, limits, noise levels.
_UNSIGNED_SUFFIXES = ("_hz", "_s", "_m", "_kgm2", "_per_rev", "gain", "samples", "precision", "_fraction")
_SIGNED_PREFIXES = ("x_", "y_", "z_")  # coordinates: x_m, x_min_m, y_max_m, ...


def _values(value: Any, key: str) -> Iterator[tuple[str, Any]]:
    """Yield (dotted key, value) of every leaf of a scenario."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from _values(getattr(value, f.name), f"{key}.{f.name}" if key else f.name)
    elif isinstance(value, tuple | list):
        for i, item in enumerate(value):
            yield from _values(item, f"{key}[{i}]")
    elif isinstance(value, dict):
        for k, item in value.items():
            yield from _values(item, f"{key}.{k}")
    else:
        yield key, value


def _refuse(path: Path, key: str, problem: str, *, value: object = None) -> ConfigError:
    return ConfigError(f"{key_location(path, key, value=value)}: {key}: {problem}")


def check_scenario(scenario: Scenario, path: Path) -> None:
    """Refuse a scenario whose values cannot be honoured or whose files are missing or broken.

    Args:
        scenario: The loaded scenario.
        path: Its file (for the messages).

    Raises:
        ConfigError: `FILE: key: problem; fix` for the first problem.
    """
    physics_hz = 1.0 / scenario.physics.step_s
    for key, value in _values(scenario, ""):
        if isinstance(value, int | float) and key not in _MAY_BE_INFINITE:
            problem = number_problem(value, key)  # what the loader checks, for values set in code (--seed)
            if problem is not None:
                raise _refuse(path, key, problem, value=value)
        if key.endswith("_hz") and isinstance(value, int | float) and not isinstance(value, bool):
            if not value >= _MIN_RATE_HZ:
                raise _refuse(path, key, f"must be a rate of at least {_MIN_RATE_HZ:g} Hz, got {value}")
            if value > physics_hz + 1e-9:
                raise _refuse(
                    path,
                    key,
                    f"{value:g} Hz is above the physics rate ({physics_hz:g} Hz, physics.step_s "
                    f"{scenario.physics.step_s:g}); lower it or shorten physics.step_s",
                )
        if isinstance(value, int | float) and not isinstance(value, bool) and value < 0:
            leaf = key.rsplit(".", 1)[-1]
            unsigned = leaf.endswith(_UNSIGNED_SUFFIXES) or "std" in leaf or leaf.startswith("max_")
            if unsigned and not leaf.startswith(_SIGNED_PREFIXES) and "[" not in leaf:
                raise _refuse(path, key, f"must not be negative, got {value}")
    if scenario.seed < 0:
        raise _refuse(path, "seed", f"must be a non-negative whole number, got {scenario.seed}", value=scenario.seed)
    if not scenario.max_duration_s > 0:
        raise _refuse(path, "max_duration_s", f"must be a positive number of seconds, got {scenario.max_duration_s}")
    _check_lidar(scenario, path, "")  # the top level's, named as written (a fleet lays it under each entry)
    for i, (namespace, robot) in enumerate(scenario.robot_scenarios()):
        entry = f"robots[{i}]." if namespace else ""  # a fleet's robot: its entry's key
        _check_builtin_fmu(robot, path, entry)
        if namespace:
            _check_lidar(robot, path, entry, base=scenario.sensors.lidar)
        _check_lidar_of_robot(robot, path, entry)
    _check_files(scenario, path)
    _check_blocks(scenario, path)
    _check_camera_of_robot(scenario, path)


def _check_builtin_fmu(scenario: Scenario, path: Path, entry: str) -> None:
    """Refuse a `drive.fmu: builtin:NAME` the twin does not ship, naming the key (not an FMU error without it)."""
    from twin.cosim.build import BUILTIN_PREFIX, builtin_variants

    drive = scenario.drive
    fmu = getattr(drive, "fmu", None)
    if getattr(drive, "fmu_file", None) is not None or not isinstance(fmu, str) or not fmu.startswith(BUILTIN_PREFIX):
        return
    name, variants = fmu[len(BUILTIN_PREFIX) :], builtin_variants()
    if name not in variants:
        problem = f"unknown built-in FMU {name!r}{suggest(name, sorted(variants))}"
        raise _refuse(path, f"{entry}drive.fmu", problem)


def _check_lidar(scenario: Scenario, path: Path, entry: str, *, base: Any = None) -> None:
    """The lidar's overrides: float32 values, a sample count, a range and a span (a fleet's robot: its `entry`).

    `base`: the top level's lidar section, which a fleet's entry is laid over; of two values that
    disagree, the one the entry sets (that differs from the top level's) is named.
    """
    lidar = scenario.sensors.lidar

    def disorder(first: str, second: str) -> tuple[str, str]:
        """The key to name for `first` not below `second`, and what is wrong (the entry's own value named)."""
        low, high = getattr(lidar, first), getattr(lidar, second)
        inherited = base is not None and low == getattr(base, first)
        if inherited and high != getattr(base, second):
            return f"{entry}sensors.lidar.{second}", f"{high} is not above {first} {low}"
        return f"{entry}sensors.lidar.{first}", f"{low} is not below {second} {high}"

    for key, value in _values(lidar, f"{entry}sensors.lidar"):
        if isinstance(value, float) and abs(value) > _FLOAT32_MAX:
            raise _refuse(path, key, f"{value!r} does not fit a LaserScan's float32 fields; give at most 3.4e+38")
    if lidar.samples is not None and not 1 <= lidar.samples <= _MAX_SAMPLES:
        key = f"{entry}sensors.lidar.samples"
        raise _refuse(path, key, f"must be between 1 and {_MAX_SAMPLES}, got {lidar.samples}")
    if lidar.range_min_m is not None and lidar.range_max_m is not None and lidar.range_min_m >= lidar.range_max_m:
        key, wrong = disorder("range_min_m", "range_max_m")
        raise _refuse(path, key, f"{wrong}; make range_min_m < range_max_m")
    if (
        lidar.angle_min_rad is not None
        and lidar.angle_max_rad is not None
        and lidar.angle_min_rad >= lidar.angle_max_rad
    ):
        key, wrong = disorder("angle_min_rad", "angle_max_rad")
        raise _refuse(path, key, wrong)


def _check_camera_of_robot(scenario: Scenario, path: Path) -> None:
    """An enabled camera needs a camera sensor in the robot's SDF (and a rate); a fleet's names the entry."""
    from twin.sim.camera import camera_spec
    from twin.sim.robot_group import scenario_robot

    for i, (namespace, robot) in enumerate(scenario.robot_scenarios()):
        if not robot.sensors.camera.enabled:
            continue
        try:
            camera_spec(scenario_robot(robot), robot.sensors.camera)
        except TwinError as err:
            raise err.with_context(before=f"{path}: robots[{i}]." if namespace else f"{path}: ") from None


def _check_blocks(scenario: Scenario, path: Path) -> None:
    """Refuse blocks without a mission's locations to stand at, or more blocks than locations."""
    if scenario.blocks.count == 0:
        return
    import numpy as np

    from twin.sim.obstacles import scenario_obstacles

    try:
        scenario_obstacles(scenario, np.random.default_rng(0))  # the draw does not matter here
    except ConfigError as err:
        raise err.with_context(before=f"{path}: ") from None


def _check_lidar_of_robot(scenario: Scenario, path: Path, entry: str = "") -> None:
    """Check the lidar overrides against the robot's own SDF values (one override may contradict the other)."""
    lidar = scenario.sensors.lidar
    if lidar.range_min_m is None and lidar.range_max_m is None:
        return
    from twin.sim.robot_group import scenario_robot

    try:
        robot = scenario_robot(scenario, entry=entry)
    except TwinError as err:
        raise err.with_context(before=f"{path}: ") from None
    if robot.lidar is None:
        return  # simulate names this itself
    range_min = lidar.range_min_m if lidar.range_min_m is not None else robot.lidar.range_min_m
    range_max = lidar.range_max_m if lidar.range_max_m is not None else robot.lidar.range_max_m
    if not range_min < range_max:
        key = "sensors.lidar.range_min_m" if lidar.range_min_m is not None else "sensors.lidar.range_max_m"
        raise _refuse(
            path,
            entry + key,
            f"the lidar's range would be {range_min:g} .. {range_max:g} m (the robot's SDF gives the other end); "
            "make range_min_m < range_max_m",
        )


def _check_files(scenario: Scenario, path: Path) -> None:
    for key, value in _values(scenario, ""):
        in_model_path = key.startswith("world.model_path")
        if key == "source_path":  # where the scenario came from (a bag's re-run may name a file gone since)
            continue
        if isinstance(value, Path) and not in_model_path and not value.exists():
            raise _refuse(path, key, f"{value}: file not found; fix the path (relative to {path.parent})")
        if isinstance(value, Path) and not in_model_path and not (value.is_file() or value.is_dir()):
            raise _refuse(path, key, f"{value}: not a regular file (a device, pipe or socket); give a file")
    for key, folder in _values(scenario.world.model_path, "world.model_path"):
        if isinstance(folder, Path) and not folder.is_dir():
            raise _refuse(path, key, f"{folder}: no such folder; fix the model path")
    mission = scenario.mission
    if isinstance(mission, BehaviorTreeMission) and mission.locations is not None:
        from twin.mission.bt_nodes import load_locations

        try:
            locations = load_locations(mission.locations)
        except ConfigError as err:
            raise err.with_context(before=f"{path}: mission.locations: ") from None
        if not locations:
            raise _refuse(path, "mission.locations", f"{mission.locations}: holds no locations; add name: [x, y, yaw]")
    drive = scenario.drive
    fmu_file = getattr(drive, "fmu_file", None)
    if isinstance(fmu_file, Path):
        _check_fmu_file(fmu_file, path)
    mapping = getattr(drive, "mapping", None)
    if isinstance(mapping, Path):
        resolved = getattr(drive, "resolved_mapping", None)
        if resolved is not None:
            try:
                resolved()
            except ConfigError as err:
                raise err.with_context(before=f"{path}: drive.mapping: ") from None


def _check_fmu_file(fmu_file: Path, path: Path) -> None:
    """Refuse an FMU file whose description does not read or whose binary does not load here."""
    from twin.cosim.description import binary_problem, read_fmu_info

    try:
        problem = binary_problem(read_fmu_info(fmu_file))
    except FmuError as err:
        raise err.with_context(before=f"{path}: drive.fmu_file: ") from None
    if problem is not None:
        msg = f"{path}: drive.fmu_file: {fmu_file}: {problem}"
        raise FmuError(msg)


def check_inputs(scenario: Scenario, path: Path) -> list[str]:
    """Load what the run would load (world, robot, tree) and raise its first error, naming `path`.

    Returns:
        The names of the robot models as loaded (one per robot, in `robot_scenarios` order): what
        `fmu: auto` and the packaged Nav2 params go by.

    Raises:
        TwinError: The loader's error (WorldError, TreeError, ...) with the scenario file in front.
    """
    from twin.core.clock import s_to_ns
    from twin.sim.fleet import overlap_problem
    from twin.sim.launch import check_node_plugins
    from twin.sim.navigation import check_map_extent, lidar_problem
    from twin.sim.rng import RngStreams
    from twin.sim.robot_group import driven_robot, far_from_world, floor_problem, spawn_monitor
    from twin.sim.simulation import obstacle_fields
    from twin.world import build_scene, load_world

    floor = floor_problem(scenario.world.floor_height_m)
    if floor is not None:
        logging.getLogger("twin.sim.simulation").warning("%s", floor)  # as the run warns

    robots = scenario.robot_scenarios()  # a fleet's each with its own sections, as the run takes them
    try:
        world = load_world(
            scenario.world.sdf,
            model_path=scenario.world.model_path,
            missing_includes=scenario.world.missing_includes,
        )
        for warning in world.warnings:  # as the run warns: a skipped include, an unsupported element
            logging.getLogger("twin.sim.simulation").warning("%s", warning)
        models = [driven_robot(sc, entry=f"robots[{i}]." if ns else "") for i, (ns, sc) in enumerate(robots)]
        exclude = tuple(dict.fromkeys(robot.name for robot in models))
        scene = build_scene(world, exclude_models=exclude, floor_height_m=scenario.world.floor_height_m)
    except TwinError as err:
        raise _named(err, path) from None
    bodies = []
    far: list[str] = []
    for index, ((ns, sc), robot) in enumerate(zip(robots, models, strict=True)):
        try:
            body, _ = spawn_monitor(scene, robot, sc.robot.initial_pose, floor_height_m=scenario.world.floor_height_m)
            bodies.append(body)
            problem = lidar_problem(sc, robot)
            if problem is not None:
                raise ConfigError(problem)
            check_map_extent(sc, robot, scene)
            if isinstance(sc.mission, BehaviorTreeMission):
                _load_tree(sc.mission, camera=sc.sensors.camera.enabled)
            _load_navigation(sc, robot, namespace=ns or "")
        except TwinError as err:  # a fleet's names its entry, as the run does
            raise _named(in_entry(err, f"robots[{index}]." if ns else ""), path) from None
        _check_drive(sc, path, robot.name, entry=f"robots[{index}]." if ns else "")
        problem = far_from_world(scene, robot, sc.robot.initial_pose)
        if problem is not None:
            far.append(f"robots[{index}].{problem}" if ns else problem)
    poses = [(ns, sc.robot.initial_pose) for ns, sc in robots]
    try:
        if len(robots) > 1:
            overlap = overlap_problem(
                [(ns, (p.x_m, p.y_m, p.yaw_rad), body) for (ns, p), body in zip(poses, bodies, strict=True)]
            )
            if overlap is not None:
                raise ConfigError(overlap)
        # the obstacles and blocks the run would place (its seed's `blocks` stream), none on a spawn pose
        obstacle_fields(
            scenario, poses, bodies, RngStreams(scenario.seed).stream("blocks"), s_to_ns(scenario.physics.step_s)
        )
        check_node_plugins(scenario)
    except TwinError as err:
        raise _named(err, path) from None
    for problem in far:  # (last: a refused scenario keeps its one line)
        logging.getLogger("twin.sim.simulation").warning("%s", problem)
    return [robot.name for robot in models]


def _named(err: TwinError, path: Path) -> TwinError:
    """`err` with the scenario file (and the key's line) in front, unless it names its file already."""
    text = str(err)
    if text.startswith((str(path), str(path.resolve()))):
        return err
    return err.with_context(before=f"{key_location(path, _leading_key(text))}: ")


def _leading_key(text: str) -> str:
    """The scenario key a message starts with (`robot.model: ...` gives `robot.model`), or ''."""
    head = text.split(": ", 1)[0]
    return head if head and " " not in head and "/" not in head else ""


def in_scenario(err: TwinError, path: Path) -> TwinError:
    """`err` as `twin simulate` reports it for the scenario at `path`.

    A ConfigError about one of the scenario's keys (`drive.motor: ...`) gets the file in front; an
    error that names its own file (a mapping file, an FMU) is left as it is.
    """
    text = str(err)
    fleet = text.startswith("robots[")  # a fleet robot's (`twin.sim.scenario.in_entry`): the entry names it
    if not fleet and (not isinstance(err, ConfigError) or text.startswith(("/", str(path)))):
        return err
    if not fleet and (not text.split(" ", 1)[0].endswith(":") or ".yaml:" in text):
        return err
    return err.with_context(before=f"{key_location(path, _leading_key(text))}: ")


def _check_drive(scenario: Scenario, path: Path, robot_name: str, *, entry: str = "") -> None:
    """Bind the FMU drive as `simulate` does before its first step (contract, motor model, speed loop).

    A fleet robot's errors name its entry (`entry`, `robots[1].`), as the run names them.
    """
    from twin.core.clock import s_to_ns
    from twin.robot.fmu_drive import FmuDrive, check_fmu_drive
    from twin.sim.robot_group import fmu_drive_section
    from twin.sim.scenario import fmu_fallback

    if not isinstance(scenario.drive, FmuDrive) or fmu_fallback(scenario.drive) is not None:
        return
    try:
        drive = fmu_drive_section(scenario)
        check_fmu_drive(drive, step_ns=s_to_ns(scenario.physics.step_s), robot_name=robot_name)
    except ConfigError as err:
        keyed = entry and names_a_key(str(err))
        raise in_scenario(err.with_context(before=entry) if keyed else err, path) from None
    except TwinError as err:
        raise in_scenario(err, path) from None


def _load_tree(mission: BehaviorTreeMission, *, camera: bool = True) -> None:
    import random

    from twin.mission.bt_nodes import ScriptedNavigator, register_mission_nodes, unknown_literal_location
    from twin.mission.look_for_object import ImageSlot, register_vision_nodes
    from twin.nav.bt_navigator.factory import nav2_factory

    factory = nav2_factory()
    register_mission_nodes(factory, navigator=ScriptedNavigator(), rng=random.Random(0))
    register_vision_nodes(factory, slot=ImageSlot(), target_color=mission.target_color)
    factory.load_plugins()
    tree = factory.create_tree_from_file(mission.tree, main_tree=mission.main_tree, clock=lambda: 0)
    looks = [node.full_path for node in tree.nodes if type(node).__name__ == "LookForObject"]
    if looks and not camera:  # each fails at its first tick in the run (no image)
        logging.getLogger("twin.sim.simulation").warning(
            "%s: %s look for objects with the camera, which is off: each fails; enable sensors.camera",
            mission.tree,
            ", ".join(looks),
        )
    if mission.locations is not None:
        problem = unknown_literal_location(tree, mission.locations)
        if problem is not None:
            raise TreeError(problem)


def _load_navigation(scenario: Scenario, robot: RobotModelSpec, *, namespace: str = "") -> None:
    """Read the map, the Nav2 params file (with `navigation.set`) and the navigator tree the run would read."""
    from twin.bt.validate import validate_file
    from twin.nav.bt_navigator.factory import nav2_factory, unimplemented_leaf, unloaded_behavior
    from twin.nav.map_server.map_io import load_map
    from twin.nav.param_checks import check_nav2_inputs
    from twin.nav.params import default_params_path, load_nav2_params
    from twin.nav.server_params import nav2_config
    from twin.sim.navigation import DEFAULT_BT_XML, check_poses_on_map, frame_problem

    occupancy = load_map(Path(scenario.map)) if scenario.map != "from_world" else None
    nav = scenario.navigation
    amcl = runs_amcl(scenario) and robot.lidar is not None
    nav2 = runs_nav2(scenario) and nav.type == "nav2" and robot.lidar is not None
    if amcl or nav2 or nav.params is not None:
        try:
            path = nav.params if nav.params is not None else default_params_path(robot.name)
        except ConfigError as err:
            raise err.with_context(before="navigation.params: ") from None
        params = load_nav2_params(path, overrides=dict(nav.set), namespace=namespace)
        map_source = None if scenario.map == "from_world" else str(scenario.map)
        step_s = scenario.physics.step_s
        check_nav2_inputs(params, occupancy, map_source=map_source, amcl=amcl, nav2=nav2, physics_step_s=step_s)
        problem = frame_problem(params, robot, amcl=amcl, nav2=nav2, namespace=namespace)
        if problem is not None:
            raise ConfigError(problem)
        if occupancy is not None and robot.lidar is not None and (amcl or nav2):
            check_poses_on_map(scenario, occupancy, amcl=amcl)  # (a map made from the world covers them)
        if nav2:
            config = nav2_config(params)
            problem = unloaded_behavior(nav.bt_xml or DEFAULT_BT_XML, config.behavior_servers)
            if problem is not None:
                raise ConfigError(problem)
    if nav.type == "nav2" and nav.bt_xml is not None:
        # as the run reads it: valid against Nav2's palette, and every Nav2 node one the twin runs
        report = validate_file(nav.bt_xml, nav2_factory())
        problem = report.problems[0] if report.problems else unimplemented_leaf(nav.bt_xml)
        if problem is not None:
            raise TreeError(problem)
