"""Layer 1: the node API, shaped like rclpy, on the simulation clock.

    from twin.node import Node
    from twin.msgs import Twist

    class Spinner(Node):
        def __init__(self):
            super().__init__("spinner")
            self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
            self.create_timer(0.1, self.on_timer)

        def on_timer(self):
            msg = Twist()
            msg.angular.z = 0.5
            self.pub.publish(msg)

A scenario adds it with `nodes: [{plugin: spinner:Spinner}]`; see docs/nodes.md. The executor
that runs nodes is `twin.sim`'s; this package only declares.
"""

from twin.node.node import (
    PRIORITY_CLOCK,
    PRIORITY_COMMAND,
    PRIORITY_SENSOR,
    PRIORITY_STATE,
    PRIORITY_TREE,
    PRIORITY_USER,
    Clock,
    Encoded,
    LaunchArguments,
    Node,
    NodeLogger,
    Parameter,
    ParameterNotDeclaredError,
    Publisher,
    QoSProfile,
    Subscription,
    Time,
    Timer,
    in_robot_namespace,
    launch_context,
    logger_name,
    node_logger,
    resolve_topic_name,
    validate_topic_name,
)

__all__ = [
    "PRIORITY_CLOCK",
    "PRIORITY_COMMAND",
    "PRIORITY_SENSOR",
    "PRIORITY_STATE",
    "PRIORITY_TREE",
    "PRIORITY_USER",
    "Clock",
    "Encoded",
    "LaunchArguments",
    "Node",
    "NodeLogger",
    "Parameter",
    "ParameterNotDeclaredError",
    "Publisher",
    "QoSProfile",
    "Subscription",
    "Time",
    "Timer",
    "in_robot_namespace",
    "launch_context",
    "logger_name",
    "node_logger",
    "resolve_topic_name",
    "validate_topic_name",
]
