"""The rclpy-shaped node API: names, remappings, parameters, clock and message classes."""

from __future__ import annotations

import math
import re

import pytest

import twin.msgs as msgs
from twin.core.errors import ConfigError
from twin.msgs import Header, LaserScan, PoseWithCovarianceStamped, Twist
from twin.node import (
    LaunchArguments,
    Node,
    ParameterNotDeclaredError,
    Time,
    launch_context,
    node_logger,
    resolve_topic_name,
)


class Talker(Node):
    def __init__(self) -> None:
        super().__init__("talker")
        self.gain = self.declare_parameter("gain", 0.5).value
        self.count = self.declare_parameter("count", 3).value
        self.pub = self.create_publisher(Twist, "cmd_vel", 10)


def test_relative_private_and_absolute_topic_names_resolve_as_rcl_does() -> None:
    assert resolve_topic_name("scan", node_name="n", namespace="") == "/scan"
    assert resolve_topic_name("scan", node_name="n", namespace="/robot1") == "/robot1/scan"
    assert resolve_topic_name("~/debug", node_name="n", namespace="/robot1") == "/robot1/n/debug"
    assert resolve_topic_name("/tf", node_name="n", namespace="/robot1") == "/tf"


@pytest.mark.parametrize("bad", ["", "/", "2scan", "/a//b", "scan/", "sc an", "a-b"])
def test_invalid_topic_names_are_refused(bad: str) -> None:
    with pytest.raises(ConfigError):
        resolve_topic_name(bad, node_name="n", namespace="")


def test_launch_arguments_reach_a_node_built_with_no_arguments() -> None:
    args = LaunchArguments(name="driver", namespace="robot1", parameters={"gain": 2}, remappings={"cmd_vel": "/raw"})
    with launch_context(args):
        node = Talker()
    assert node.get_name() == "driver"
    assert node.get_fully_qualified_name() == "/robot1/driver"
    assert node.gain == 2.0 and isinstance(node.gain, float)  # an int given for a float parameter
    assert node.count == 3  # the default where nothing is given
    assert node.pub.topic_name == "/raw"  # /robot1/cmd_vel remapped


class SubNamespaced(Node):
    def __init__(self) -> None:
        super().__init__("costmap", namespace="local")
        self.pub = self.create_publisher(Twist, "out", 10)


@pytest.mark.parametrize(
    ("arguments", "namespace"),
    [
        (LaunchArguments(push_namespace="robot1"), "/robot1/local"),  # a group's namespace leads the node's own
        (LaunchArguments(push_namespace="/robot1/"), "/robot1/local"),
        (LaunchArguments(push_namespace="robot1", namespace="arm"), "/robot1/arm"),  # the entry's replaces the code's
        (LaunchArguments(push_namespace="robot1", namespace="/abs"), "/abs"),  # an absolute one stays as given
        (LaunchArguments(), "/local"),
    ],
)
def test_a_pushed_namespace_leads_the_nodes_own_as_a_launch_group_does(
    arguments: LaunchArguments, namespace: str
) -> None:
    with launch_context(arguments):
        node = SubNamespaced()
    assert node.get_namespace() == namespace
    assert node.pub.topic_name == f"{namespace}/out"


def test_a_namespaced_nodes_logger_is_named_as_rcl_names_it(caplog: pytest.LogCaptureFixture) -> None:
    # rcl: /robot1/amcl logs as `robot1.amcl`, /fleet/a/amcl as `fleet.a.amcl`; a node in no namespace as `amcl`.
    with launch_context(LaunchArguments(push_namespace="robot1")):
        node = Node("amcl")
        inner = node_logger("planner_server")  # a part of a node built in the group: the group's namespace
    assert node.get_logger().name == "twin.node.robot1.amcl"
    assert inner.name == "twin.node.robot1.planner_server"
    assert Node("amcl", namespace="/fleet/a").get_logger().name == "twin.node.fleet.a.amcl"
    assert Node("amcl").get_logger().name == "twin.node.amcl"
    assert node_logger("bt_navigator").name == "twin.node.bt_navigator"
    with caplog.at_level("INFO", logger="twin.node"):
        node.get_logger().warn("lost")
    assert [(r.name, r.getMessage()) for r in caplog.records] == [("twin.node.robot1.amcl", "lost")]


def test_a_group_remapping_moves_an_absolute_topic_into_the_namespace() -> None:
    with launch_context(LaunchArguments(push_namespace="robot1", remappings={"/tf": "tf"})):
        node = Node("broadcaster")
        pub = node.create_publisher("tf2_msgs/msg/TFMessage", "/tf", 10)
        clock = node.create_publisher("rosgraph_msgs/msg/Clock", "/clock", 10)
    assert pub.topic_name == "/robot1/tf"
    assert clock.topic_name == "/clock"  # absolute names not remapped stay where they are


def test_a_parameter_of_the_wrong_type_is_refused_with_its_name() -> None:
    with launch_context(LaunchArguments(parameters={"count": "three"})), pytest.raises(ConfigError, match="count"):
        Talker()


def test_reading_an_undeclared_parameter_names_it() -> None:
    node = Talker()
    with pytest.raises(ParameterNotDeclaredError, match="'speed'"):
        node.get_parameter("speed")
    assert node.get_parameter("gain").value == 0.5


def test_remapping_to_a_name_that_is_not_a_topic_name_is_refused() -> None:
    with (
        launch_context(LaunchArguments(remappings={"/cmd_vel": "cmd vel"})),
        pytest.raises(ConfigError, match="cmd vel"),
    ):
        Talker()


def test_publishing_before_the_node_is_in_a_graph_says_so() -> None:
    node = Talker()
    with pytest.raises(RuntimeError, match="not in a running graph"):
        node.pub.publish(Twist())


def test_time_converts_to_a_ros_time_message() -> None:
    t = Time(seconds=1.25)
    assert t.nanoseconds == 1_250_000_000
    msg = t.to_msg()
    assert (msg.sec, msg.nanosec) == (1, 250_000_000)
    assert Time(nanoseconds=3_000_000_000) - t == pytest.approx(1.75)


def test_message_classes_have_rclpy_defaults_and_round_trip_through_cdr() -> None:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = "map"
    msg.pose.pose.position.x = -2.0
    msg.pose.pose.orientation.w = math.cos(0.25)
    msg.pose.covariance = [0.25 if i in (0, 7, 35) else 0.0 for i in range(36)]  # a list, as rclpy users write
    back = msgs.deserialize(msgs.serialize(msg), "geometry_msgs/msg/PoseWithCovarianceStamped")
    assert back.header.frame_id == "map"
    assert back.pose.pose.position.x == -2.0
    assert back.pose.covariance[35] == 0.25
    assert len(LaserScan().ranges) == 0
    assert Header().stamp.sec == 0


def test_short_and_full_message_names_and_a_misspelling() -> None:
    assert msgs.get_message("Twist") is msgs.get_message("geometry_msgs/msg/Twist")
    assert msgs.get_message("geometry_msgs/Twist").__msgtype__ == "geometry_msgs/msg/Twist"
    assert msgs.get_message("ParticleCloud").__msgtype__ == "nav2_msgs/msg/ParticleCloud"
    with pytest.raises(ConfigError, match="did you mean 'LaserScan'"):
        msgs.get_message("LaserScn")


@pytest.mark.parametrize("period", [1e300, 1e12])
def test_a_timer_period_longer_than_any_run_is_refused_in_words(period: float) -> None:
    # 1e300 s was an OverflowError (no integer of nanoseconds): the same refusal as any too long a period.
    from twin.core.errors import ConfigError

    with pytest.raises(
        ConfigError, match=rf"node slow: timer period {re.escape(repr(period))} s is longer than any run"
    ):
        Node("slow").create_timer(period, lambda: None)
