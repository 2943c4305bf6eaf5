"""The Simulation: a Scenario composed into nodes on one executor, as a launch file starts a ROS 2 system.

It builds the world once (the SDF world, its scene, the scenario's obstacles), then one group of
nodes per robot (`twin.sim.robot_group.RobotGroup`: drive, sensors, robot_state_publisher, EKF,
localization, navigation, mission, under the robot's namespace), adds the world's clock and the
scenario's own nodes; the executor (`twin.sim.executor`) runs them on the simulation clock and the
recorder records every topic. Nothing here knows what a topic means.

Node order (it fixes which timer fires first among equals, and which subscriber hears first):
rosout, the robot's group (robot_state_publisher, [map_server, initial_pose, amcl, costmaps, Nav2's
servers, bt_navigator], [mission], [obstacles], lidar, joint_states, [gazebo_odometry],
ground_truth, imu, diff_drive, [ekf_odometry]), clock, then the scenario's nodes in their order.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.bag import Recorder
from twin.bag.frames import frame_prefix
from twin.bag.provenance import PROVENANCE_TOPIC
from twin.core.clock import NS_PER_S, s_to_ns
from twin.core.closing import Closing
from twin.core.errors import ConfigError, TwinError
from twin.core.gcpolicy import resume_collection
from twin.node import Node, launch_context
from twin.robot.drivetrain import Drivetrain
from twin.robot.fmu_drivetrain import FmuDrivetrain
from twin.robot.nodes import ClockNode
from twin.sim.camera import build_camera, robot_body
from twin.sim.executor import Executor, RecordFilter, Sink
from twin.sim.fleet import AllDone, Fleet
from twin.sim.launch import load_nodes
from twin.sim.obstacles import scenario_obstacles
from twin.sim.provenance import fmu_record, run_provenance
from twin.sim.rng import RngStreams
from twin.sim.robot_group import RobotGroup, far_from_world, floor_problem
from twin.sim.rosout import RosoutBridge
from twin.sim.scenario import InitialPose, Scenario, in_entry
from twin.world import RobotModelSpec, World, build_scene, load_world
from twin.world.obstacles import ObstacleField
from twin.world.render import Body
from twin.world.scene import RobotBody, Scene

if TYPE_CHECKING:
    import numpy as np

    from twin.robot.lidar import Lidar
    from twin.sim.navigation import NavigationStack
    from twin.sim.robot_group import Mission

__all__ = ["RunSummary", "Simulation", "obstacle_fields"]

_log = logging.getLogger(__name__)

# Obstacles appear and vanish on this grid (the /clock period); walkers near the robot step at it (5 mm at 0.5 m/s).
_OBSTACLE_PERIOD_NS = 10_000_000


def obstacle_fields(
    scenario: Scenario,
    robots: Sequence[tuple[str, InitialPose]],
    bodies: Sequence[RobotBody],
    blocks_rng: np.random.Generator,
    step_ns: int,
) -> list[ObstacleField | None]:
    """The scenario's obstacles and blocks as each robot (namespace, spawn pose, body) meets them.

    One field per robot: the obstacles are the same (their paths depend on time alone), each field
    checks its own robot's shapes against them. Nones without any obstacle.

    Raises:
        ConfigError: An obstacle or block that covers a robot's spawn pose at t = 0.
    """
    specs = scenario_obstacles(scenario, blocks_rng)
    if not specs:
        return [None] * len(bodies)
    period_ns = step_ns * max(1, round(_OBSTACLE_PERIOD_NS / step_ns))
    fields: list[ObstacleField | None] = []
    for i, ((namespace, pose), body) in enumerate(zip(robots, bodies, strict=True)):
        field = ObstacleField(specs, body, update_period_ns=period_ns)
        _, contacts = field.update(0, (pose.x_m, pose.y_m, pose.yaw_rad))
        if contacts:
            c = contacts[0]
            index = next(ob.index for ob in field.obstacles if ob.name == c.model)
            key = f"obstacles[{index}]" if index < len(scenario.obstacles) else "blocks"
            whose = f"robots[{i}] ({namespace})'s" if namespace else "the robot's"
            msg = (
                f"{key}: {c.model} stands on {whose} spawn pose ({pose.x_m}, {pose.y_m}) at t = 0; "
                "move it, or the robot's initial_pose"
            )
            raise ConfigError(msg)
        fields.append(field)
    return fields


def _drive_notes(group: RobotGroup) -> str:
    """What the robot's drive did of note (commands clamped to its motors' reach), '' when nothing."""
    drive = group.drive
    return drive.saturation.describe() if isinstance(drive, FmuDrivetrain) else ""


@dataclass(frozen=True, kw_only=True, slots=True)
class RunSummary:
    """What a run did, for the one-line summary and for scripts (`--json`)."""

    scenario: str
    bag_path: Path | None
    storage: str
    sim_s: float
    wall_s: float
    real_time_factor: float
    messages: int  # the bag's (what the recording takes), or every publication without a bag
    topics: dict[str, int]
    contacts: int
    ended_by: str
    mission_result: str
    seed: int
    breakdown_s: dict[str, float]
    # The drive that ran, e.g. `fmu xm430_w210_servo (FMI 2, velocity-servo)` or `kinematic`; a fleet's
    # when all robots' are alike, else each robot's (`robot1: ...; robot2: ...`), as `drive_notes`.
    drive: str = ""
    drive_notes: str = ""  # e.g. commands clamped to the motors' reach ('' when none)
    # AMCL against the true pose ({} without AMCL); a fleet's by namespace.
    localization: dict[str, Any] = field(default_factory=dict)
    refused_messages: dict[str, int] = field(default_factory=dict)  # topic -> non-finite messages from users' nodes
    robots: dict[str, str] = field(default_factory=dict)  # a fleet's robots: namespace -> its mission's result


class Simulation(Closing):
    """One run of a scenario, recording into a new bag. Use as a context manager.

    Args:
        scenario: The scenario to run.
        bag_path: The bag folder to create (must not exist or be empty); None records nothing.
        duration_s: Stop after this much sim time even if the mission goes on (default: the
            mission's end, at most `scenario.max_duration_s`).
        profile: Time each timer callback and the physics (for benchmarks; adds a little overhead).
        write_log: For crash tests: the recorder appends `topic t_ns monotonic_ns` per message here.
        sinks: More places every recorded topic goes to (a live view), after the recorder.

    Raises:
        TwinError: If any input (world, robot, scenario values, nodes) is wrong; nothing is left open.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        bag_path: Path | None,
        duration_s: float | None = None,
        profile: bool = False,
        write_log: Path | None = None,
        sinks: Sequence[Sink] = (),
    ) -> None:
        self.scenario = scenario
        self.step_ns = s_to_ns(scenario.physics.step_s)
        self._profile = profile
        self._rng = RngStreams(scenario.seed)

        t0 = time.perf_counter()
        # The world, once.
        world = load_world(
            scenario.world.sdf,
            model_path=scenario.world.model_path,
            missing_includes=scenario.world.missing_includes,
        )
        for warning in world.warnings:
            _log.warning("%s", warning)
        floor = floor_problem(scenario.world.floor_height_m)
        if floor is not None:
            _log.warning("%s", floor)
        # One group per robot (one robot, no namespace: the thesis's system, topic for topic).
        self.groups = [
            RobotGroup.load(sc, namespace=ns, entry=f"robots[{i}]." if ns else "")
            for i, (ns, sc) in enumerate(scenario.robot_scenarios())
        ]
        exclude = tuple(dict.fromkeys(g.robot.name for g in self.groups))
        scene = build_scene(world, exclude_models=exclude, floor_height_m=scenario.world.floor_height_m)
        bodies = [self._spawn(i, g, scene) for i, g in enumerate(self.groups)]
        self.fleet = Fleet(self.groups) if len(self.groups) > 1 else None
        if self.fleet is not None:
            self.fleet.check_spawn()
        fields = self._make_obstacles(bodies)  # each robot's view of the world's obstacles (None: none)
        self.obstacles = fields[0]
        self.recorder: Recorder | None = None
        self.executor = Executor(self.step_ns, profile=profile, non_finite=scenario.non_finite_messages)
        built: list[RobotGroup] = []
        try:  # a group that fails releases its own drive; the ones built before it are released here
            for i, g in enumerate(self.groups):
                try:
                    g.build(
                        scene,
                        obstacles=fields[i],
                        rng=self._rng.under(g.namespace),
                        step_ns=self.step_ns,
                        now=self._now,
                        fleet=self.fleet,
                        obstacle_markers=i == 0,
                    )
                except TwinError as err:  # a fleet's names its entry (`robots[1].robot.model: ...`)
                    if not g.namespace:
                        raise
                    raise in_entry(err, f"robots[{i}].") from None
                built.append(g)
        except BaseException:
            for g in built:
                g.close()
            raise
        for i, g in enumerate(self.groups):  # (after the checks: a refused scenario keeps its one line)
            far = far_from_world(scene, g.robot, g.scenario.robot.initial_pose)
            if far is not None:
                _log.warning("%s%s", f"robots[{i}]." if g.namespace else "", far)
        try:  # from here on, a failure must release the drives (FMU instances) the groups hold
            user_nodes = load_nodes(scenario)
            self._run_to_limit = duration_s is not None
            limit_ns = s_to_ns(scenario.max_duration_s if duration_s is None else duration_s)
            self.end_k = -(-limit_ns // self.step_ns)
            self._setup_s = time.perf_counter() - t0
            selection = scenario.recording.topics
            keep = RecordFilter(
                include=selection.include,
                include_regex=selection.include_regex,
                exclude=selection.exclude,
                exclude_regex=selection.exclude_regex,
            )
            # The robots' cameras: each renders only while something takes its images (the recorder, a
            # user's node, its mission's LookForObject), so they join after the user's nodes are known.
            user_nodes = [*user_nodes, *self._cameras(world, keep, user_nodes)]
            # Wire the graph once without sinks: a node that cannot join (a duplicate name, a topic of
            # another type) is refused before a bag folder exists.
            scratch = Executor(self.step_ns)
            for node in [RosoutBridge(), *self._launch_nodes(), *user_nodes]:
                scratch.add_node(node)
            # A sink that also takes topics from a ROS 2 domain (twin.ros2.Ros2Bridge) adds the node that
            # publishes them into the run, last, typed by the graph just wired (docs/ros2.md).
            for sink in sinks:
                inbound = getattr(sink, "inbound_node", None)
                node_in = inbound(scratch.topics) if inbound is not None else None
                if node_in is not None:
                    user_nodes.append(node_in)
            if bag_path is not None:
                self.recorder = Recorder(
                    bag_path, storage=scenario.recording.storage, distro=scenario.recording.distro, write_log=write_log
                )
                self.recorder.add_provenance(run_provenance(scenario, duration_s=duration_s, fmus=self._fmu_records()))
            for sink in ([self.recorder] if self.recorder is not None else []) + list(sinks):
                self.executor.add_sink(sink, keep)
            self._rosout = RosoutBridge()
            self.executor.add_node(self._rosout)
            for node in [*self._launch_nodes(), *user_nodes]:
                self.executor.add_node(node)
            for node in user_nodes:
                unused = node.undeclared_overrides()
                if unused:
                    _log.warning("node %s never declares parameter(s) %s", node.get_name(), ", ".join(unused))
            if self.fleet is None:
                drive_node = self.groups[0].drive_node
                self.executor.set_physics(drive_node.advance, drive_node.after_advance, pending=drive_node.tracker)
            else:
                self.executor.set_physics(self.fleet.advance, self.fleet.after_advance, pending=self.fleet)
        except BaseException:
            try:
                for g in self.groups:
                    g.close()
            finally:
                if self.recorder is not None:
                    self.recorder.close()
            raise

    def _recorded_count(self) -> int:
        """The messages the bag holds (those of the topics the recording takes), or all published without one."""
        recorder = self.recorder
        if recorder is None:
            return self.executor.message_count
        published = sum(
            t.count
            for t in self.executor.topics.values()
            if any(getattr(write, "__self__", None) is recorder for write, _ in t.sinks)
        )
        # (a sqlite3 bag holds its provenance as one message more; an MCAP bag as a metadata record)
        return published + (1 if PROVENANCE_TOPIC in recorder.topics else 0)

    def _spawn(self, index: int, group: RobotGroup, scene: Scene) -> RobotBody:
        """Spawn one group's robot; a fleet's error names its entry (`robots[1].robot.initial_pose: ...`)."""
        try:
            return group.spawn(scene)
        except ConfigError as err:
            if not group.namespace:
                raise
            raise in_entry(err, f"robots[{index}].") from None

    def _cameras(self, world: World, keep: RecordFilter, user_nodes: Sequence[Node]) -> list[Node]:
        """One camera node per robot whose `sensors.camera` enables it, each feeding its robot's tree.

        A fleet's camera is under its robot's namespace and frame prefix, draws from its own stream
        (`robot1/camera`) and sees the other robots' visuals where they stand.

        Raises:
            ConfigError: A robot without a camera sensor (a fleet's names its entry).
            WorldError: If a visual's mesh cannot be read.
        """
        from twin.sim.mission import TreeMission

        if not any(g.scenario.sensors.camera.enabled for g in self.groups):
            return []

        def recorded(topic: str) -> bool:
            return keep.takes(topic) or any(s.topic == topic for n in user_nodes for s in n.subscriptions)

        bodies: dict[int, Body] = {}

        def body(i: int) -> Body:
            if i not in bodies:
                bodies[i] = robot_body(self.groups[i].robot)
            return bodies[i]

        exclude = tuple(dict.fromkeys(g.robot.name for g in self.groups))
        nodes: list[Node] = []
        for i, g in enumerate(self.groups):
            if not g.scenario.sensors.camera.enabled:
                continue
            assert g.drive is not None
            others = [
                (body(j), drive.chassis_state)
                for j, other in enumerate(self.groups)
                if j != i and (drive := other.drive) is not None
            ]
            try:
                with launch_context(g.launch), frame_prefix(g.frame_prefix):
                    camera = build_camera(
                        g.scenario.sensors.camera,
                        g.robot,
                        world,
                        g.drive.chassis_state,
                        obstacles=g.obstacles,
                        rng=self._rng.under(g.namespace).stream("camera"),
                        recorded=recorded,
                        namespace=g.namespace,
                        exclude_models=exclude,
                        body=body(i),
                        others=others,
                    )
            except ConfigError as err:
                if not g.namespace:
                    raise
                raise err.with_context(before=f"robots[{i}].") from None
            assert camera is not None
            nodes.append(camera.node)
            if isinstance(g.mission, TreeMission):
                g.mission.images.source = camera.feed
        return nodes

    def _now(self) -> int:
        return self.executor.now_ns

    # -- the robot, for callers of a one-robot run ------------------------------------------------

    @property
    def robot(self) -> RobotModelSpec:
        """The robot's model."""
        return self.groups[0].robot

    @property
    def drive(self) -> Drivetrain:
        """The robot's drivetrain."""
        drive = self.groups[0].drive
        assert drive is not None
        return drive

    @property
    def lidar(self) -> Lidar | None:
        """The robot's lidar model (None without a lidar)."""
        return self.groups[0].lidar

    @property
    def navigation(self) -> NavigationStack | None:
        """The robot's map, localization and Nav2 stack (None when the scenario uses none of them)."""
        return self.groups[0].navigation

    @property
    def mission(self) -> Mission | None:
        """The robot's mission (None for `mission: {type: none}`)."""
        return self.groups[0].mission

    # -- the world -------------------------------------------------------------------------------

    def _make_obstacles(self, bodies: Sequence[RobotBody]) -> list[ObstacleField | None]:
        """The scenario's obstacles and blocks as each robot meets them (Nones without any).

        One field per robot: the obstacles are the same (their paths depend on time alone), each
        field checks its own robot's shapes against them. Refused where they cover a spawn pose.
        """
        robots = [(g.namespace, g.scenario.robot.initial_pose) for g in self.groups]
        return obstacle_fields(self.scenario, robots, bodies, self._rng.stream("blocks"), self.step_ns)

    def _fmu_records(self) -> list[dict[str, str]]:
        """Provenance of the FMUs the drives loaded (none for the kinematic drive)."""
        records = []
        for g in self.groups:
            if isinstance(g.drive, FmuDrivetrain):
                info = g.drive.fmu_info
                records.append(fmu_record(g.drive.fmu_path, model_name=info.model_name, guid=info.guid))
        return records

    # -- the nodes -------------------------------------------------------------------------------

    def _launch_nodes(self) -> list[Node]:
        """Each robot's group, then the world's clock, in the documented order (a new set on each call)."""
        nodes: list[Node] = []
        for g in self.groups:
            nodes += g.nodes()
        nodes.append(ClockNode(self.scenario.sensors.clock.rate_hz))
        return nodes

    @property
    def t_s(self) -> float:
        """Sim time reached so far, s."""
        return self.executor.k * self.step_ns / NS_PER_S

    @property
    def contacts(self) -> int:
        """Contacts reported so far."""
        return sum(g.drive_node.contacts for g in self.groups)

    # -- context manager -------------------------------------------------------------------------

    def close(self) -> None:
        """Close the drive and the bag (idempotent); what was recorded stays a complete, readable bag."""
        logging.getLogger("twin").removeHandler(self._rosout.handler)
        try:
            for g in self.groups:
                g.close()
        finally:
            if self.recorder is not None:
                self.recorder.close()

    def _per_robot(self, phrase: Callable[[RobotGroup], str]) -> str:
        """A summary phrase of the robot; a fleet's: one when every robot's is the same, else each robot's."""
        phrases = {g.namespace: phrase(g) for g in self.groups}
        if len(set(phrases.values())) == 1:
            return next(iter(phrases.values()))
        return "; ".join(f"{ns}: {text or '-'}" for ns, text in phrases.items())

    def _localization(self) -> dict[str, Any]:
        """AMCL against the true pose ({} without AMCL); a fleet's by namespace (robots without AMCL left out)."""
        if self.fleet is None:
            return self.navigation.log.summary() if self.navigation is not None else {}
        return {g.namespace: g.navigation.log.summary() for g in self.groups if g.navigation is not None}

    def _robot_results(self) -> dict[str, str]:
        """Each robot's mission result by namespace ({} for one robot)."""
        if self.fleet is None:
            return {}
        return {g.namespace: g.mission.result if g.mission is not None else "none" for g in self.groups}

    def _mission_result(self) -> str:
        """The mission's result; a fleet's is FAILURE when any robot's is, else every robot's when they agree.

        Robots whose missions ended well in different ways (a tree's SUCCESS, a script's complete,
        none) give `complete`; while any robot's goes on, `running`.
        """
        if self.fleet is None:
            return self.mission.result if self.mission is not None else "none"
        results = set(self._robot_results().values())
        if "FAILURE" in results:
            return "FAILURE"
        if len(results) == 1:
            return results.pop()
        return "running" if "running" in results else "complete"

    @property
    def failure(self) -> str:
        """Why the mission failed ('' unless it did): a fleet's names each robot that failed and its goal."""
        if self.fleet is None:
            if self.mission is None or self.mission.result != "FAILURE":
                return ""
            return getattr(self.mission, "failure", "") or "the mission returned FAILURE"
        reasons = [
            f"{g.namespace}: {getattr(g.mission, 'failure', '') or 'the mission returned FAILURE'}"
            for g in self.groups
            if g.mission is not None and g.mission.result == "FAILURE"
        ]
        return "; ".join(reasons)

    # -- the loop --------------------------------------------------------------------------------

    def run(
        self,
        *,
        should_stop: Callable[[], bool] = lambda: False,
        progress: Callable[[float, int], None] | None = None,
    ) -> RunSummary:
        """Run until the mission ends, the duration is reached or `should_stop()` turns true.

        Args:
            should_stop: Polled between events (e.g. set by a SIGINT handler).
            progress: Called about every simulated second with (sim seconds, messages so far).

        Raises:
            TwinError: From any node; the bag stays readable (close it with `close`).
        """
        logging.getLogger("twin").addHandler(self._rosout.handler)
        robots = (
            f"robot {self.robot.name}"
            if self.fleet is None
            else f"{len(self.groups)} robots ({', '.join(f'{g.namespace} {g.robot.name}' for g in self.groups)})"
        )
        _log.info(
            "scenario %s: world %s, %s, seed %d",
            self.scenario.name,
            self.scenario.world.sdf.name,
            robots,
            self.scenario.seed,
        )
        missions = [g.mission for g in self.groups if g.mission_node is not None and g.mission is not None]
        mission = missions[0] if missions else None
        done: Any = None
        if missions and not self._run_to_limit:  # its `done` ends the run (every robot's, for a fleet)
            done = mission if len(missions) == 1 else AllDone(missions)
        resume_collection()  # `twin simulate` built all this without the cyclic collector: freeze it, resume
        if self.recorder is not None:
            # Start the recorder's wall-clock flush interval with the loop, not when the recorder was made:
            # what setup took before (longer on a cold cache) must not decide where its first chunk ends.
            self.recorder.flush()
        wall0 = time.perf_counter()
        why = self.executor.spin(self.end_k, done=done, should_stop=should_stop, progress=progress)
        wall_s = time.perf_counter() - wall0
        ended_by = {
            # the mission (every robot's) has ended: well, or in FAILURE (the summary says which robot)
            "done": "mission failed" if self._mission_result() == "FAILURE" else "mission complete",
            "interrupted": "interrupted",
            "duration": "duration"
            if self._run_to_limit or mission is None
            else "max_duration_s reached before the mission ended",
        }[why]
        sim_s = self.t_s
        breakdown = dict(self.executor.timings_s)
        if self._profile:
            breakdown["setup"] = self._setup_s
        _log.info("run ended (%s) at t=%.3f s", ended_by, sim_s)
        return RunSummary(
            scenario=self.scenario.name,
            bag_path=self.recorder.path if self.recorder is not None else None,
            storage=self.scenario.recording.storage,
            sim_s=sim_s,
            wall_s=wall_s,
            real_time_factor=sim_s / wall_s if wall_s > 0 else math.inf,
            messages=self._recorded_count(),
            topics={name: t.count for name, t in self.executor.topics.items() if t.publishers},
            contacts=self.contacts,
            ended_by=ended_by,
            mission_result=self._mission_result(),
            seed=self.scenario.seed,
            breakdown_s=breakdown,
            drive=self._per_robot(lambda g: g.drive.label if g.drive is not None else ""),
            drive_notes=self._per_robot(_drive_notes),
            localization=self._localization(),
            refused_messages=dict(self.executor.refused),
            robots=self._robot_results(),
        )
