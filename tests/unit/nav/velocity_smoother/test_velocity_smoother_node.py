"""The velocity_smoother node on the executor: its timer's period, odometry in CLOSED_LOOP, invalid twists."""

from __future__ import annotations

from typing import Any

import pytest

from twin.bag import OdometryEncoder
from twin.msgs import Twist, Vector3
from twin.nav.velocity_smoother.velocity_smoother import Feedback, SmootherParams, VelocitySmootherNode
from twin.node import Encoded, Node
from twin.sim.executor import Executor

MS = 1_000_000


class Robot(Node):
    """Publishes cmd_vel_nav as a user node would (decoded Twists) and odom as the EKF does; hears cmd_vel."""

    builtin = True

    def __init__(self, odom_topic: str = "odom") -> None:
        super().__init__("robot")
        self.cmd = self.create_publisher(Twist, "cmd_vel_nav", 10)
        self.odom = self.create_publisher(OdometryEncoder.msgtype, odom_topic, 10)
        self.encode = OdometryEncoder().encode
        self.heard: list[tuple[int, float, float, float]] = []

        def on_cmd_vel(msg: Any) -> None:
            v, w = msg[2]
            self.heard.append((self._graph_now(), v, 0.0, w))

        self.create_subscription("geometry_msgs/msg/Twist", "cmd_vel", on_cmd_vel, 10, raw=True)

    def send(self, vx: float, wz: float, *, linear_z: float = 0.0) -> None:
        self.cmd.publish(Twist(linear=Vector3(x=vx, y=0.0, z=linear_z), angular=Vector3(x=0.0, y=0.0, z=wz)))

    def odometry(self, t_ns: int, v: float, w: float) -> None:
        zeros = [0.0] * 36
        self.odom.publish(Encoded((self.encode, (t_ns, 0.0, 0.0, 0.0, v, w, zeros, zeros), (0.0, 0.0, 0.0, v, w))))


def _run(params: SmootherParams, odom_topic: str = "odom") -> tuple[Executor, Robot]:
    ex = Executor(MS)
    robot = Robot(odom_topic)
    ex.add_node(robot)
    ex.add_node(VelocitySmootherNode(params))
    return ex, robot


def test_at_30_hz_the_node_ticks_every_33_ms_as_nav2s_whole_millisecond_timer() -> None:
    ex, robot = _run(SmootherParams(smoothing_frequency_hz=30.0))
    robot.send(0.2, 0.0)
    ex.spin(200)
    assert [t for t, *_ in robot.heard] == [0, 33 * MS, 66 * MS, 99 * MS, 132 * MS, 165 * MS, 198 * MS]


def test_in_closed_loop_the_node_starts_from_the_odometry() -> None:
    ex, robot = _run(SmootherParams(feedback=Feedback.CLOSED_LOOP))
    robot.odometry(0, 0.3, -0.2)  # the robot already moves: the next output is one cycle from there
    robot.send(0.5, 0.0)
    ex.spin(1)
    assert robot.heard == [(0, pytest.approx(0.3 + 0.125), 0.0, pytest.approx(-0.2 + 0.16))]


@pytest.mark.parametrize("published_on", ["odometry/filtered", "odom"])
def test_in_closed_loop_the_node_reads_the_odometry_on_its_odom_topic(published_on: str) -> None:
    ex, robot = _run(SmootherParams(feedback=Feedback.CLOSED_LOOP, odom_topic="odometry/filtered"), published_on)
    robot.odometry(0, 0.3, -0.2)
    robot.send(0.5, 0.0)
    ex.spin(1)
    if published_on == "odom":  # not its topic: no odometry heard, the first output is one cycle from rest
        assert robot.heard == [(0, pytest.approx(0.125), 0.0, 0.0)]
    else:
        assert robot.heard == [(0, pytest.approx(0.3 + 0.125), 0.0, pytest.approx(-0.2 + 0.16))]


def test_the_node_drops_a_twist_with_a_nan_in_a_component_it_does_not_use() -> None:
    ex, robot = _run(SmootherParams())
    robot.send(0.2, 0.0)
    robot.send(0.0, 0.0, linear_z=float("nan"))  # Nav2's validateTwist rejects it: 0.2 stays the command
    ex.spin(51)
    assert [v for _, v, _, _ in robot.heard] == [0.125, 0.2]
