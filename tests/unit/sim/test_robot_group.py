"""A robot is a group of nodes under a namespace: every topic and node of the group lands in it, and without one
the graph is the single robot's as it always was."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from twin.node import Node
from twin.sim.rng import RngStreams
from twin.sim.robot_group import RobotGroup
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation
from twin.world import build_scene, load_world

# The default mission's graph, node by node in launch order (it fixes which timer fires first among equals).
DEFAULT_NODES = [
    "/rosout",
    "/robot_state_publisher",
    "/map_server",
    "/initial_pose",
    "/amcl",
    "/global_costmap/global_costmap",
    "/local_costmap/local_costmap",
    "/planner_server",
    "/controller_server",
    "/velocity_smoother",
    "/behavior_server",
    "/bt_navigator",
    "/mission",
    "/lidar",
    "/joint_states",
    "/ground_truth",
    "/imu",
    "/diff_drive",
    "/ekf_odometry",
    "/clock",
]


def _group_nodes(namespace: str) -> Iterator[list[Node]]:
    scenario = load_scenario(default_scenario_path())
    group = RobotGroup.load(scenario, namespace=namespace)
    world = load_world(scenario.world.sdf, model_path=scenario.world.model_path)
    scene = build_scene(world, exclude_models=(group.robot.name,))
    group.spawn(scene)
    group.build(scene, obstacles=None, rng=RngStreams(0), step_ns=1_000_000, now=lambda: 0)
    try:
        yield group.nodes()
    finally:
        group.close()


@pytest.fixture(scope="module")
def namespaced() -> Iterator[list[Node]]:
    yield from _group_nodes("robot1")


def _topics(nodes: list[Node]) -> set[str]:
    return {p.topic for n in nodes for p in n.publishers} | {s.topic for n in nodes for s in n.subscriptions}


def test_one_robot_without_a_namespace_is_the_default_graph_node_for_node() -> None:
    with Simulation(load_scenario(default_scenario_path()), bag_path=None, duration_s=0.1) as sim:
        assert list(sim.executor.nodes) == DEFAULT_NODES
        topics = {name for name, t in sim.executor.topics.items() if t.publishers}
    assert {"/scan", "/odom", "/cmd_vel", "/tf", "/tf_static", "/map", "/amcl_pose", "/plan"} <= topics
    assert {"/global_costmap/costmap", "/local_costmap/costmap", "/clock", "/rosout"} <= topics


def test_every_topic_of_a_namespaced_robot_is_under_its_namespace(namespaced: list[Node]) -> None:
    topics = _topics(namespaced)
    assert topics, "the group made no topics"
    outside = sorted(t for t in topics if not t.startswith("/robot1/"))
    assert outside == []
    # nav2_bringup's multi-robot names: the TF tree on the robot's own /<ns>/tf, costmaps in their node's namespace
    assert {"/robot1/tf", "/robot1/tf_static", "/robot1/scan", "/robot1/cmd_vel", "/robot1/amcl_pose"} <= topics
    assert {"/robot1/global_costmap/costmap", "/robot1/local_costmap/costmap"} <= topics


def test_a_namespaced_costmap_listens_to_its_own_robots_scan_and_odometry(namespaced: list[Node]) -> None:
    (costmap,) = [n for n in namespaced if n.get_name() == "global_costmap"]
    assert costmap.get_namespace() == "/robot1/global_costmap"
    assert {s.topic for s in costmap.subscriptions} == {"/robot1/odom", "/robot1/scan"}


def test_every_node_of_a_namespaced_robot_is_in_its_namespace(namespaced: list[Node]) -> None:
    names = [n.get_fully_qualified_name() for n in namespaced]
    assert all(name.startswith("/robot1/") for name in names), names
    assert len(set(names)) == len(names)
    bare = [name.removeprefix("/robot1") for name in names]
    assert bare == [n for n in DEFAULT_NODES if n not in ("/rosout", "/clock")]  # the same group, pushed down


@pytest.mark.parametrize(
    ("namespace", "topic", "expected"),
    [
        ("", "cmd_vel", "cmd_vel"),
        ("", "/tb3/cmd_vel", "tb3/cmd_vel"),
        ("robot1", "cmd_vel", "cmd_vel"),
        ("robot1", "robot1/cmd_vel", "cmd_vel"),  # the plugin's <ros><namespace>/robot1: the robot's own
        ("robot1", "robot10/cmd_vel", "robot10/cmd_vel"),
    ],
)
def test_a_drive_plugins_namespace_naming_the_robots_own_is_not_doubled(
    namespace: str, topic: str, expected: str
) -> None:
    from types import SimpleNamespace

    assert RobotGroup._drive_topic(SimpleNamespace(namespace=namespace), topic, "cmd_vel") == expected  # type: ignore[arg-type]
