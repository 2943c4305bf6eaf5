"""The scenario's map, localization and Nav2 stack: built once per run, turned into nodes per graph.

`NavigationStack.build` reads `map:`, `localization:` and `navigation:` (the Nav2 params file with
the scenario's single-value overrides), loads or makes the map, and builds the parts that cost
time to make (AMCL's likelihood field, the global costmap's first full layer); `nodes` makes the
map_server, initial_pose, amcl, costmap and navigation-server nodes around them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import inspect
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.core.cache import cached_arrays
from twin.core.errors import ConfigError
from twin.nav.amcl.amcl_node import AmclNode, InitialPoseNode
from twin.nav.amcl.filter import Amcl
from twin.nav.behaviors.behavior_server import BehaviorServerNode
from twin.nav.bt_navigator.action_servers import Nav2Servers
from twin.nav.bt_navigator.bt_navigator_node import BtNavigatorNode
from twin.nav.bt_navigator.factory import unloaded_behavior
from twin.nav.bt_navigator.navigator import BtNavigator
from twin.nav.controller.controller_server import ControllerServerNode
from twin.nav.costmap_2d.costmap_node import CostmapNode
from twin.nav.costmap_2d.layered_costmap import Costmap
from twin.nav.frames import Frames, LaserGeometry
from twin.nav.map_server.map_io import OccupancyMap, load_map, map_from_scene
from twin.nav.map_server.map_server_node import MapServerNode
from twin.nav.param_checks import check_nav2_inputs
from twin.nav.params import Nav2Params, default_params_path, is_packaged_params, load_nav2_params
from twin.nav.planner.planner_server import PlannerServerNode
from twin.nav.server_params import Nav2Config, nav2_config
from twin.nav.velocity_smoother.velocity_smoother import VelocitySmootherNode
from twin.node import Node
from twin.sim.scenario import BehaviorTreeMission, Scenario, runs_amcl, runs_nav2
from twin.world import RobotModelSpec
from twin.world.scene import Scene

__all__ = ["DEFAULT_BT_XML", "LocalizationLog", "NavigationStack", "check_map_extent"]

_log = logging.getLogger(__name__)

DEFAULT_BT_XML = (
    Path(__file__).resolve().parent.parent
    / "data"
    / "nav2"
    / "behavior_trees"
    / "navigate_to_pose_w_replanning_and_recovery.xml"
)

Pose = tuple[float, float, float]


@dataclass(slots=True)
class LocalizationLog:
    """AMCL's estimate against the true pose at each filter update: (t_s, position error m, yaw error rad)."""

    samples: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, t_ns: int, estimate: Pose, truth: Pose) -> None:
        """Record one update."""
        err = math.hypot(estimate[0] - truth[0], estimate[1] - truth[1])
        yaw = abs((estimate[2] - truth[2] + math.pi) % (2.0 * math.pi) - math.pi)
        self.samples.append((t_ns / 1e9, err, yaw))

    def summary(self) -> dict[str, Any]:
        """Median, max and final errors and the series (empty before the first update)."""
        if not self.samples:
            return {}
        import statistics  # with its fractions and decimal: for the summary at the end only

        pos = [s[1] for s in self.samples]
        yaw = [s[2] for s in self.samples]
        return {
            "updates": len(self.samples),
            "position_error_median_m": round(statistics.median(pos), 4),
            "position_error_max_m": round(max(pos), 4),
            "position_error_final_m": round(pos[-1], 4),
            "yaw_error_median_rad": round(statistics.median(yaw), 5),
            "yaw_error_max_rad": round(max(yaw), 5),
            "series": [[round(t, 3), round(e, 4), round(y, 5)] for t, e, y in self.samples],
        }


def _params_path(scenario: Scenario, robot: RobotModelSpec) -> Path:
    if scenario.navigation.params is not None:
        return scenario.navigation.params
    try:
        return default_params_path(robot.name)
    except ConfigError as err:
        msg = f"navigation.params: {err}"
        raise ConfigError(msg) from None


class NavigationStack:
    """What the scenario's localization and navigation need, built once (see the module docstring)."""

    def __init__(
        self,
        *,
        occupancy: OccupancyMap,
        params: Nav2Params,
        laser: LaserGeometry | None,
        amcl: Amcl | None,
        scan_topic: str = "scan",
        initial_pose: tuple[Pose, float, float] | None,
        global_costmap: Costmap | None,
        local_costmap: Costmap | None,
        config: Nav2Config | None,
        bt_xml: Path | None,
    ) -> None:
        self.occupancy = occupancy
        self.params = params
        self.laser = laser
        self.scan_topic = scan_topic  # the lidar's, in the robot's namespace
        self.amcl = amcl
        self.initial_pose = initial_pose
        self.global_costmap = global_costmap
        self.local_costmap = local_costmap
        self.config = config
        self.bt_xml = bt_xml
        self.log = LocalizationLog()
        self.frames = Frames()
        self.navigator: BtNavigator | None = None

    @property
    def localizes(self) -> bool:
        """True when AMCL runs (map→odom is its estimate, not a static identity)."""
        return self.amcl is not None

    @property
    def navigates(self) -> bool:
        """True when Nav2's servers carry out the mission's goals."""
        return self.config is not None

    @classmethod
    def build(
        cls,
        scenario: Scenario,
        robot: RobotModelSpec,
        scene: Scene,
        rng: np.random.Generator,
        *,
        log: logging.Logger = _log,
        namespace: str = "",
    ) -> NavigationStack | None:
        """Build the stack the scenario asks for, or None when it runs neither AMCL nor Nav2.

        Its warnings (parameters the twin does not use, sources it does not simulate) go to `log`: a
        fleet robot's names the robot.

        Raises:
            ConfigError: A params file, map or initial pose that cannot be used (one line naming it).
            TreeError: A navigator tree the twin cannot run.
        """
        sc = scenario
        wants_amcl = runs_amcl(sc)
        wants_nav2 = runs_nav2(sc)
        if not (wants_amcl or wants_nav2):
            return None
        problem = lidar_problem(sc, robot)
        if problem is not None:
            raise ConfigError(problem)
        assert robot.lidar is not None
        params_path = _params_path(sc, robot)
        params = load_nav2_params(params_path, overrides=dict(sc.navigation.set), namespace=namespace)
        problem = frame_problem(params, robot, amcl=wants_amcl, nav2=wants_nav2, namespace=namespace)
        if problem is not None:
            raise ConfigError(problem)
        laser = LaserGeometry.from_spec(robot.lidar)
        occupancy = cls._map(sc, robot, scene)
        map_source = None if sc.map == "from_world" else str(sc.map)
        check_nav2_inputs(
            params, occupancy, map_source=map_source, amcl=wants_amcl, nav2=wants_nav2, physics_step_s=sc.physics.step_s
        )
        pose = sc.robot.initial_pose
        amcl = None
        initial = None
        estimate = check_poses_on_map(sc, occupancy, amcl=wants_amcl)
        if wants_amcl:
            amcl = Amcl(params.amcl, occupancy, laser, rng)
            est = sc.localization.initial_pose
            if est is not None and estimate is not None:
                initial = (estimate, est.xy_variance_m2, est.yaw_variance_rad2)
        global_costmap = local_costmap = None
        config = None
        bt_xml = None
        if wants_nav2:
            config = nav2_config(params)
            global_costmap = Costmap(params.global_costmap, static_map=occupancy)
            local_costmap = Costmap(params.local_costmap, robot_xy_m=(pose.x_m, pose.y_m))
            for costmap in (global_costmap, local_costmap):  # composed before the first plan asks
                costmap.update(pose.x_m, pose.y_m, pose.yaw_rad, ())
            bt_xml = sc.navigation.bt_xml or DEFAULT_BT_XML
            problem = unloaded_behavior(bt_xml, config.behavior_servers)
            if problem is not None:
                raise ConfigError(problem)
        warning = params.warning(config.used if config is not None else None)
        if warning:  # the packaged TB3 files hold keys Humble ignores: a fact, said with -v; a user's file: a warning
            packaged = sc.navigation.params is None or is_packaged_params(sc.navigation.params)
            log.log(logging.INFO if packaged else logging.WARNING, "%s", warning)
        if wants_nav2:
            for line in unsimulated_sources(params):
                log.warning("%s", line)
        unread = _unread_map_file(params, sc)
        if unread is not None:
            log.warning("%s", unread)
        if wants_amcl and not any(name.rsplit("/", 1)[-1] == "amcl" for name in params.raw):
            log.warning(
                "%s: holds no amcl section: AMCL runs on Nav2's defaults, as Nav2's would with this file "
                "(a split bringup keeps it in its localization file: merge that in)",
                params.source,
            )
        if occupancy.origin_yaw_rad != 0.0:
            log.warning(
                "%s: the map's origin yaw (%g rad) is published on /map but, as in Nav2, the costmaps and AMCL "
                "read the map unrotated (x along its rows); give yaw 0 and a map drawn that way",
                sc.map,
                occupancy.origin_yaw_rad,
            )
        return cls(
            occupancy=occupancy,
            params=params,
            laser=laser,
            amcl=amcl,
            scan_topic=robot.lidar.scan_topic,
            initial_pose=initial,
            global_costmap=global_costmap,
            local_costmap=local_costmap,
            config=config,
            bt_xml=bt_xml,
        )

    @staticmethod
    def _map(sc: Scenario, robot: RobotModelSpec, scene: Scene) -> OccupancyMap:
        if sc.map != "from_world":
            occupancy = load_map(Path(sc.map))
        else:
            assert robot.lidar is not None
            pose = sc.robot.initial_pose
            height = max(0.01, robot.base_height_m + robot.lidar.mount.z_m)  # the beam plane, as the lidar casts it
            occupancy = _map_from_world(scene, height, (pose.x_m, pose.y_m), _map_bounds(sc, scene))
        dx, dy = sc.localization.map_offset_m
        if dx or dy:
            occupancy = dataclasses.replace(
                occupancy, origin_x_m=occupancy.origin_x_m + dx, origin_y_m=occupancy.origin_y_m + dy
            )
        return occupancy

    def nodes(self, *, now: Any, truth: Any) -> list[Node]:
        """The stack's nodes for one graph, in launch order (map_server, initial_pose, amcl, costmaps, servers).

        Args:
            now: The executor's clock (ns) for the navigator's tree.
            truth: Returns the true pose now, for the localization error log.
        """
        frames = self.frames = Frames(localized=self.amcl is None)
        if self.amcl is None:
            frames.map_odom = (0.0, 0.0, 0.0)
        nodes: list[Node] = [MapServerNode(self.occupancy)]
        if self.amcl is not None:
            if self.initial_pose is not None:
                pose, xy_var, yaw_var = self.initial_pose
                nodes.append(InitialPoseNode(pose, xy_variance_m2=xy_var, yaw_variance_rad2=yaw_var))
            log = self.log
            nodes.append(
                AmclNode(
                    self.amcl,
                    frames,
                    transform_tolerance_s=self.params.amcl.transform_tolerance_s,
                    on_estimate=log.add,
                    truth=truth,
                    lidar_topic=self.scan_topic,
                )
            )
        if self.config is not None:
            assert self.global_costmap is not None and self.local_costmap is not None and self.bt_xml is not None
            for name, costmap in (("global_costmap", self.global_costmap), ("local_costmap", self.local_costmap)):
                nodes.append(CostmapNode(name, costmap, frames, self.laser, lidar_topic=self.scan_topic))
            servers = Nav2Servers(self.config, frames, self.global_costmap, self.local_costmap, now=now)
            navigator = self.navigator = BtNavigator(servers, self.bt_xml, now=now)
            nodes += [
                PlannerServerNode(servers),
                ControllerServerNode(servers),
                VelocitySmootherNode(self.config.smoother),
                BehaviorServerNode(servers),
                BtNavigatorNode(navigator, frames),
            ]
        return nodes


MAX_MAP_SPAN_M = 300.0
"""The largest side of a map made from the world (6000 cells at 5 cm); beyond it, a map file is the way."""


def _unread_map_file(params: Nav2Params, sc: Scenario) -> str | None:
    """A warning when the params' `map_server.yaml_filename` names a map file other than the one the run uses.

    The run's map is the scenario's `map:` (made from the world when unset), as nav2_bringup's `map:=`
    argument overrides yaml_filename. A name that is no file (TB3's placeholder `map.yaml`, Nav2's
    `""`) is what the launch replaces, and is not said.
    """
    named = params.node("map_server").get("yaml_filename")
    if not isinstance(named, str) or not named.strip() or not Path(named).is_file():
        return None
    if sc.map != "from_world" and Path(named).resolve() == Path(sc.map).resolve():
        return None
    used = "made from the world" if sc.map == "from_world" else f"{sc.map}"
    node = next((k for k in params.raw if k.rsplit("/", 1)[-1] == "map_server"), "map_server")
    where = params.origin.locate(node, "yaml_filename") if params.origin else f"{params.source}: {node}.yaml_filename"
    return (
        f"{where} names {named}, which the twin does not load: the map is the "
        f"scenario's map: ({used}), as nav2_bringup's map:= argument overrides yaml_filename; set map: {named} "
        "in the scenario to use it"
    )


def _map_bounds(sc: Scenario, scene: Scene, *, margin_m: float = 1.0) -> tuple[float, float, float, float]:
    """What a SLAM map of the mission covers: the world's obstacles, and the places the robot goes.

    The obstacles' bounds 0.5 m around, and `margin_m` around the spawn point and every place the
    mission names, so that the robot's way across an open floor is on the map (a world of one box
    is not mapped around the box alone).

    Raises:
        ConfigError: If that covers more than `MAX_MAP_SPAN_M` a side, naming the place that lies farthest out.
    """
    points = [("robot.initial_pose", sc.robot.initial_pose.x_m, sc.robot.initial_pose.y_m)]
    if isinstance(sc.mission, BehaviorTreeMission) and sc.mission.locations is not None:
        from twin.mission.bt_nodes import load_locations

        with contextlib.suppress(OSError, ValueError, TypeError):  # the mission reports a bad file itself
            locations = load_locations(sc.mission.locations)
            points += [(f"{sc.mission.locations}: {name}", p.x_m, p.y_m) for name, p in locations.items()]
    xs = [x for _, x, _ in points]
    ys = [y for _, _, y in points]
    x0, y0, x1, y1 = min(xs) - margin_m, min(ys) - margin_m, max(xs) + margin_m, max(ys) + margin_m
    box = scene.bounds
    if box is not None:
        pad = 0.5
        x0, y0 = min(x0, box[0][0] - pad), min(y0, box[0][1] - pad)
        x1, y1 = max(x1, box[1][0] + pad), max(y1, box[1][1] + pad)
    if max(x1 - x0, y1 - y0) > MAX_MAP_SPAN_M:
        if box is not None and max(box[1][0] - box[0][0], box[1][1] - box[0][1]) + 2 * pad > MAX_MAP_SPAN_M:
            w, h = box[1][0] - box[0][0], box[1][1] - box[0][1]
            msg = (
                f"{sc.world.sdf}: the world's obstacles span {w:.6g} x {h:.6g} m, "
                f"too large for a map made from the world (at most {MAX_MAP_SPAN_M:.0f} m a side at its resolution); "
                "give `map:` a map_server YAML of the area the robot drives in"
            )
            raise ConfigError(msg)
        if box is not None:
            (bx0, by0, _), (bx1, by1, _) = box
        else:
            bx0 = bx1 = points[0][1]
            by0 = by1 = points[0][2]

        def outside(point: tuple[str, float, float]) -> float:
            _, x, y = point
            return math.hypot(max(bx0 - x, 0.0, x - bx1), max(by0 - y, 0.0, y - by1))

        label, x, y = max(points, key=outside)
        msg = (
            f"{label}: ({x:.6g}, {y:.6g}) lies {outside((label, x, y)):.6g} m from the world's obstacles, so a map "
            f"made from the world would span {x1 - x0:.6g} x {y1 - y0:.6g} m (at most {MAX_MAP_SPAN_M:.0f} m a side); "
            "put it inside the world, or give `map:` a map file that covers it"
        )
        raise ConfigError(msg)
    return (x0, y0, x1, y1)


_MAP_CODE = Path(inspect.getfile(map_from_scene))
"""The file of the code that makes a map from the world: its bytes key the cached maps."""


@functools.cache
def _map_code() -> bytes:
    return _MAP_CODE.read_bytes()


def _map_from_world(
    scene: Scene, height_m: float, free_xy_m: tuple[float, float], bounds_xy_m: tuple[float, float, float, float]
) -> OccupancyMap:
    """`map_from_scene` at 0.05 m, through the derived-artefact cache.

    The key is what the map is made of: the world's cross-section at the beam height (the ray
    caster's segments and circles, which the lidar builds anyway), the parameters, and the code that
    makes it (map_from_scene's module), so a changed world, mesh, pose or algorithm is a new entry.
    """
    resolution_m = 0.05
    caster = scene.ray_caster(height_m)
    source = _map_code()
    parts = (source, caster.segments, caster.circles, height_m, resolution_m, free_xy_m, bounds_xy_m)

    def build() -> dict[str, np.ndarray]:
        made = map_from_scene(
            scene, height_m=height_m, resolution_m=resolution_m, free_xy_m=free_xy_m, bounds_xy_m=bounds_xy_m
        )
        return {"data": made.data, "frame": np.array([made.resolution_m, made.origin_x_m, made.origin_y_m])}

    arrays = cached_arrays("world_map", 1, parts, build)
    res, x0, y0 = (float(v) for v in arrays["frame"])
    return OccupancyMap(resolution_m=res, origin_x_m=x0, origin_y_m=y0, data=arrays["data"].astype(np.int8))


def check_map_extent(sc: Scenario, robot: RobotModelSpec, scene: Scene) -> None:
    """Refuse a scenario whose map made from the world would be too large, as `NavigationStack.build` would.

    Raises:
        ConfigError: As `_map_bounds`.
    """
    if sc.map == "from_world" and robot.lidar is not None and (runs_amcl(sc) or runs_nav2(sc)):
        x0, y0, x1, y1 = _map_bounds(sc, scene)
        est = sc.localization.initial_pose  # AMCL's estimate: on the map the run makes (its bounds, at least)
        if runs_amcl(sc) and est is not None:
            pose = sc.robot.initial_pose
            x = pose.x_m if est.x_m is None else est.x_m
            y = pose.y_m if est.y_m is None else est.y_m
            if not (x0 <= x <= x1 and y0 <= y <= y1):
                msg = (
                    f"localization.initial_pose: ({x:.3f}, {y:.3f}) lies outside the map "
                    f"(x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}); give a pose on the map"
                )
                raise ConfigError(msg)


def frame_problem(
    params: Nav2Params, robot: RobotModelSpec, *, amcl: bool, nav2: bool, namespace: str = ""
) -> str | None:
    """A frame the params have Nav2 look up that the run's TF tree does not hold, or None.

    The tree holds `map`, `odom` and the robot's own frames (its base frame and every link and
    `<frame>`). Of the frames the twin reads (each can be set in `navigation.set`), Nav2's
    costmaps, navigator and AMCL wait for a transform to a frame nobody
    publishes (the TurtleBot3 params' `base_link` on a robot whose base is `chassis`), so the
    mission could never start; the twin says so instead of navigating anyway.
    """
    frames = {"map", "odom", robot.base_frame, *(f.name for f in robot.frames)}
    checks: list[tuple[str, str, str]] = []  # (node, key, its value)
    if nav2:
        for costmap in (params.local_costmap, params.global_costmap):
            checks.append((costmap.name, "robot_base_frame", costmap.robot_base_frame))
            checks.append((costmap.name, "global_frame", costmap.global_frame))
        value = params.node("bt_navigator").get("robot_base_frame")  # (the behavior server's the twin does not read)
        if isinstance(value, str):
            checks.append(("bt_navigator", "robot_base_frame", value))
    if amcl:
        checks += [
            ("amcl", "base_frame_id", params.amcl.base_frame_id),
            ("amcl", "odom_frame_id", params.amcl.odom_frame_id),
        ]
    own = f"{namespace.strip('/')}/" if namespace else ""
    for node, key, frame in checks:
        # (a fleet robot's frame may be named with its prefix, `robot1/base_link`, as frame_prefix names it)
        if frame in frames or (own and frame.startswith(own) and frame[len(own) :] in frames):
            continue
        full = next((k for k in params.raw if k.rsplit("/", 1)[-1] == node), node)  # as the file names it
        where = params.origin.locate(full, key) if params.origin is not None else f"{params.source}: {full}.{key}"
        known = ", ".join(sorted(frames - {"map", "odom"}))
        return (
            f"{where}: {frame!r} is no frame of the run's TF tree (map, odom and the frames of robot "
            f"{robot.name}: {known}); "
            f"Nav2 would wait for it forever: name one of them (the robot's base frame is {robot.base_frame!r})"
        )
    return None


def lidar_problem(sc: Scenario, robot: RobotModelSpec) -> str | None:
    """Why a robot without a lidar cannot run the scenario's navigation or localization (None when it can)."""
    if robot.lidar is not None:
        return None
    if runs_nav2(sc):
        return (
            f"robot.model: {robot.name!r} has no lidar: Nav2's costmaps and AMCL need /scan to carry out the "
            "mission's goals; give the robot a ray sensor in its SDF, or choose a mission that does not "
            "navigate (cmd_vel_script, waypoints, none)"
        )
    if runs_amcl(sc):
        return (
            f"localization: AMCL needs /scan but robot {robot.name!r} has no lidar; give the robot a ray "
            "sensor in its SDF, or set localization: {type: none}"
        )
    return None


def unsimulated_sources(params: Nav2Params) -> list[str]:
    """One line per costmap observation source the twin feeds nothing: a sensor type it does not simulate.

    The twin's robots have a lidar (and a camera whose images no costmap reads): a PointCloud2 source
    (a depth camera's points, a 3D lidar) stays empty, so its layer marks nothing from it.
    """
    lines = []
    for costmap in (params.global_costmap, params.local_costmap):
        for layer in costmap.obstacle_layers:
            for source in layer.sources:
                if source.data_type != "LaserScan":
                    lines.append(
                        f"{params.source}: {costmap.name}.{layer.name}.{source.name}: a {source.data_type} source "
                        f"({source.topic or 'no topic'}) gets no data: the twin simulates the robot's lidar "
                        "(LaserScan) only, so that layer marks nothing from it"
                    )
    return lines


def check_poses_on_map(sc: Scenario, occupancy: OccupancyMap, *, amcl: bool) -> tuple[float, float, float] | None:
    """Refuse an AMCL initial estimate or a mission location off the map; return the estimate (x, y, yaw).

    Raises:
        ConfigError: Naming the pose (`localization.initial_pose`, or the locations file and entry)
            and the map's extent.
    """
    estimate = None
    est = sc.localization.initial_pose
    if amcl and est is not None:
        pose = sc.robot.initial_pose
        x = pose.x_m if est.x_m is None else est.x_m
        y = pose.y_m if est.y_m is None else est.y_m
        yaw = pose.yaw_rad if est.yaw_rad is None else est.yaw_rad
        if occupancy.world_to_cell(x, y) is None:
            msg = (
                f"localization.initial_pose: ({x:.3f}, {y:.3f}) lies outside the map ({_extent(occupancy)}); "
                "give a pose on the map"
            )
            raise ConfigError(msg)
        estimate = (x, y, yaw)
    if isinstance(sc.mission, BehaviorTreeMission) and sc.mission.locations is not None:
        _check_locations_on_map(sc.mission.locations, occupancy)
    return estimate


def _check_locations_on_map(path: Path, occupancy: OccupancyMap) -> None:
    """Refuse a mission location the robot could never be sent to: one off the map."""
    from twin.mission.bt_nodes import load_locations

    try:
        locations = load_locations(path)
    except (OSError, ValueError, TypeError):
        return  # the mission reports a file it cannot read itself
    for name, pose in locations.items():
        if occupancy.world_to_cell(pose.x_m, pose.y_m) is None:
            msg = (
                f"{path}: {name}: goal ({pose.x_m:.2f}, {pose.y_m:.2f}) lies outside the map "
                f"({_extent(occupancy)}); move it onto the map or give a map that covers it"
            )
            raise ConfigError(msg)


def _extent(occupancy: OccupancyMap) -> str:
    x0, y0 = occupancy.origin_x_m, occupancy.origin_y_m
    x1 = x0 + occupancy.width * occupancy.resolution_m
    y1 = y0 + occupancy.height * occupancy.resolution_m
    return f"x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}"
