"""A user's node publishing a message with a field its type cannot hold.

Found by probing: `cmd.linear.x = "fast"` ended the run with "timer callback Bad.tick raised error:
required argument is not a float" (the serialiser's words, naming no field). Now the one line names
the node, the topic, the type, the field, its value and the type it needs; exit 8 as for any node
fault; the bag up to then reads back.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from twin.cli import main
from twin.msgs import LaserScan, PoseWithCovarianceStamped, Twist, misfit_field

_MODULE = """
from twin.msgs import Twist
from twin.node import Node

class Filler(Node):
    def __init__(self):
        super().__init__("filler")
        self.declare_parameter("field", "linear.x")
        self.declare_parameter("value", "fast")
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        msg = Twist()
        part, name = self.get_parameter("field").value.split(".")
        setattr(getattr(msg, part), name, self.get_parameter("value").value)
        self.pub.publish(msg)
"""


@pytest.mark.parametrize("recorded", [True, False])
def test_a_field_of_the_wrong_type_is_named_with_its_value(
    recorded: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Recorded, the serialiser meets it first; not recorded, the drive's arithmetic does.
    (tmp_path / "filler.py").write_text(_MODULE)
    scenario = tmp_path / "scenario.yaml"
    exclude = "" if recorded else "recording: {topics: {exclude_regex: /cmd_vel}}\n"
    scenario.write_text(
        "name: misfit\n"
        + textwrap.dedent("""\
        mission: {type: none}
        localization: {type: none}
        drive: {type: kinematic}
        nodes: [{plugin: filler:Filler, parameters: {field: angular.z, value: fast}}]
        """)
        + exclude
    )
    bag = tmp_path / "bag"
    code = main(["simulate", str(scenario), "--duration", "2", "--out", str(bag)])
    _, err = capsys.readouterr()
    assert code == 8, err
    assert_one_line_error(
        err,
        contains="node filler published a geometry_msgs/msg/Twist on /cmd_vel whose angular.z is 'fast' (str), "
        "not a float64 at t=0.100 s",
    )
    assert_bag_reads_back(bag)


def test_misfit_field_names_the_first_field_its_type_cannot_hold() -> None:
    twist = Twist()
    assert misfit_field(twist, "geometry_msgs/msg/Twist") is None
    twist.linear = 3  # type: ignore[assignment]
    assert misfit_field(twist, "geometry_msgs/msg/Twist") == "linear is 3 (int), not a geometry_msgs/msg/Vector3"
    scan = LaserScan()
    scan.ranges = [1.0, "x"]
    assert misfit_field(scan, "sensor_msgs/msg/LaserScan") == "ranges[1] is 'x' (str), not a float32"
    scan = LaserScan()
    scan.header.frame_id = 5  # type: ignore[assignment]
    assert misfit_field(scan, "sensor_msgs/msg/LaserScan") == "header.frame_id is 5 (int), not a string"
    scan = LaserScan()
    scan.header.stamp.sec = 2**40
    assert misfit_field(scan, "sensor_msgs/msg/LaserScan") == (
        "header.stamp.sec is 1099511627776, outside int32's -2147483648 to 2147483647"
    )
    pose = PoseWithCovarianceStamped()
    pose.pose.covariance = [0.0] * 35  # type: ignore[assignment]
    assert misfit_field(pose, "geometry_msgs/msg/PoseWithCovarianceStamped") == (
        "pose.covariance has 35 items, not the 36 its type fixes"
    )
    pose.pose.covariance = [0] * 36  # type: ignore[assignment]  # ints where floats go: the serialiser takes them
    assert misfit_field(pose, "geometry_msgs/msg/PoseWithCovarianceStamped") is None
