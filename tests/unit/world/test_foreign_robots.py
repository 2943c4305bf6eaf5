"""Robots that are not TurtleBot3s: included sensors, nested drives, other plugin spellings, odd sensors.

Each model here is written for the test in the shapes public robots use (an `<include>`d lidar
fastened by a joint to `hokuyo::link`, a base whose wheels and diff drive are those of an included
base model, gz-sim's versioned library names, a Create's one-beam cliff sensors).
"""

from __future__ import annotations

import logging
import textwrap
from pathlib import Path

import numpy as np
import pytest

from twin.core.errors import WorldError
from twin.world import load_robot
from twin.world.types import plugin_kind

_LIDAR_MODEL = """\
<?xml version="1.0"?>
<sdf version="1.6">
  <model name="scanner">
    <link name="link">
      <collision name="c"><geometry><cylinder><radius>0.03</radius><length>0.05</length></cylinder></geometry></collision>
      <sensor name="laser" type="ray">
        <pose>0.01 0 0.02 0 0 0</pose>
        <update_rate>10</update_rate>
        <ray>
          <scan><horizontal><samples>180</samples><min_angle>-1.5</min_angle><max_angle>1.5</max_angle></horizontal></scan>
          <range><min>0.1</min><max>8</max></range>
        </ray>
        <plugin name="scanner_plugin" filename="libgazebo_ros_ray_sensor.so">
          <ros><namespace>/bot</namespace><remapping>~/out:=laser_scan</remapping></ros>
        </plugin>
      </sensor>
    </link>
  </model>
</sdf>
"""

_WHEEL = """\
    <link name="{name}">
      <pose>{x} {y} 0.05 -1.5708 0 0</pose>
      <collision name="c"><geometry><cylinder><radius>0.05</radius><length>0.02</length></cylinder></geometry></collision>
    </link>
    <joint name="{name}_joint" type="revolute">
      <parent>body</parent><child>{name}</child><axis><xyz>0 0 1</xyz></axis>
    </joint>
"""

_BASE_MODEL = f"""\
<?xml version="1.0"?>
<sdf version="1.6">
  <model name="base">
    <link name="body">
      <pose>0 0 0.1 0 0 0</pose>
      <collision name="c"><geometry><box><size>0.3 0.3 0.1</size></box></geometry></collision>
    </link>
{_WHEEL.format(name="left", x=0.0, y=0.15)}
{_WHEEL.format(name="right", x=0.0, y=-0.15)}
    <plugin name="drive" filename="libgz-sim8-diff-drive-system.so">
      <left_joint>left_joint</left_joint>
      <right_joint>right_joint</right_joint>
      <wheel_separation>0.3</wheel_separation>
      <wheel_radius>0.05</wheel_radius>
    </plugin>
  </model>
</sdf>
"""


# A robot of the two: the scanner 0.3 m above the base's frame, fastened to its body.
_BASE_AND_SCANNER = """\
<?xml version="1.0"?>
<sdf version="1.6">
  <model name="robot">
    <include><uri>model://base</uri></include>
    <include><uri>model://scanner</uri><pose>0 0 0.3 0 0 0</pose></include>
    <joint name="j" type="fixed"><parent>base::body</parent><child>scanner::link</child></joint>
  </model>
</sdf>
"""


def _models(tmp_path: Path, robot: str) -> Path:
    """Write the scanner and base models beside a robot model; returns the robot's model.sdf."""
    for name, text in (("scanner", _LIDAR_MODEL), ("base", _BASE_MODEL)):
        (tmp_path / name).mkdir(exist_ok=True)
        (tmp_path / name / "model.sdf").write_text(text)
    (tmp_path / "robot").mkdir(exist_ok=True)
    path = tmp_path / "robot" / "model.sdf"
    path.write_text(textwrap.dedent(robot))
    return path


def test_an_included_lidar_is_where_its_include_puts_it_and_its_joint_holds_it(tmp_path: Path) -> None:
    path = _models(
        tmp_path,
        """\
        <?xml version="1.0"?>
        <sdf version="1.6">
          <model name="robot">
            <include><uri>model://base</uri></include>
            <include><uri>model://scanner</uri><name>hokuyo</name><pose>0.2 0 0.3 0 0 0</pose></include>
            <joint name="hokuyo_joint" type="fixed"><parent>base::body</parent><child>hokuyo::link</child></joint>
          </model>
        </sdf>
        """,
    )
    robot = load_robot(path, model_path=[tmp_path])
    frame = robot.frame("hokuyo::link")
    assert frame.parent == "base::body" and frame.joint == "hokuyo_joint"
    # In the robot's frame: the include's pose (the body is 0.1 up, its frame the parent's)
    np.testing.assert_allclose(robot.T_base("hokuyo::link")[:3, 3] - robot.T_base("base::body")[:3, 3], [0.2, 0, 0.2])
    assert robot.lidar is not None
    lidar_at = np.array([robot.lidar.mount.x_m, robot.lidar.mount.y_m, robot.lidar.mount.z_m])
    np.testing.assert_allclose(lidar_at - robot.T_base("base::body")[:3, 3], [0.21, 0.0, 0.22], atol=1e-12)
    assert robot.lidar.frame_id == "hokuyo::link"
    assert not [w for w in robot.warnings if "no joint" in w]


def test_a_nested_bases_wheels_and_diff_drive_drive_the_robot(tmp_path: Path) -> None:
    path = _models(
        tmp_path,
        """\
        <?xml version="1.0"?>
        <sdf version="1.6">
          <model name="robot"><include><uri>model://base</uri><pose>1 2 0 0 0 0</pose></include></model>
        </sdf>
        """,
    )
    robot = load_robot(path, model_path=[tmp_path])
    assert robot.drive is not None
    assert (robot.drive.left_joint, robot.drive.right_joint) == ("base::left_joint", "base::right_joint")
    assert robot.drive.wheel_separation_m == pytest.approx(0.3)
    assert robot.drive.wheel_radius_m == pytest.approx(0.05)
    assert robot.frame("base::left").parent == "base::body"


@pytest.mark.parametrize(
    ("filename", "kind"),
    [
        ("libgz-sim8-diff-drive-system.so", "gz-sim-diff-drive-system"),
        ("gz-sim-diff-drive-system", "gz-sim-diff-drive-system"),
        ("libignition-gazebo6-diff-drive-system.so", "gz-sim-diff-drive-system"),
        ("ignition-gazebo-joint-state-publisher-system", "gz-sim-joint-state-publisher-system"),
        ("libgazebo_ros_diff_drive.so", "gazebo_ros_diff_drive"),
        ("/opt/ros/humble/lib/libgazebo_ros_ray_sensor.so", "gazebo_ros_ray_sensor"),
        ("libDiffDrivePlugin.so", "DiffDrivePlugin"),  # Gazebo Classic's own (the Pioneer 2DX's)
    ],
)
def test_a_plugin_is_known_by_any_spelling_gazebo_loads(filename: str, kind: str) -> None:
    assert plugin_kind(filename) == kind


def _one_link_robot(tmp_path: Path, sensors: str) -> Path:
    wheels = _WHEEL.format(name="left", x=0.0, y=0.15) + _WHEEL.format(name="right", x=0.0, y=-0.15)
    text = f"""<?xml version="1.0"?>
<sdf version="1.7">
  <model name="probe">
    <link name="body">
      <collision name="c"><geometry><box><size>0.3 0.3 0.1</size></box></geometry></collision>
      {sensors}
    </link>
{wheels}
  </model>
</sdf>
"""
    path = tmp_path / "probe.sdf"
    path.write_text(text)
    return path


def _ray(name: str, samples: int, topic: str = "") -> str:
    plugin = f'<plugin name="{name}_p" filename="libgazebo_ros_ray_sensor.so"><ros><remapping>~/out:={topic}</remapping></ros></plugin>'
    return (
        f'<sensor name="{name}" type="ray"><update_rate>10</update_rate><ray><scan><horizontal>'
        f"<samples>{samples}</samples><min_angle>-0.1</min_angle><max_angle>0.1</max_angle></horizontal></scan>"
        f"<range><min>0.01</min><max>2</max></range></ray>{plugin if topic else ''}</sensor>"
    )


def test_one_beam_ray_sensors_are_range_finders_not_the_lidar(tmp_path: Path) -> None:
    robot = load_robot(_one_link_robot(tmp_path, _ray("cliff", 1) + _ray("front_scan", 90, "scan")))
    assert robot.lidar is not None and robot.lidar.name == "front_scan"
    assert any("'cliff'" in w and "not simulated" in w for w in robot.warnings)
    only_cliffs = load_robot(_one_link_robot(tmp_path, _ray("cliff", 1)))
    assert only_cliffs.lidar is None


def test_a_second_lidar_is_named_in_a_warning(tmp_path: Path) -> None:
    robot = load_robot(_one_link_robot(tmp_path, _ray("front", 90, "scan") + _ray("rear", 90, "scan_rear")))
    assert robot.lidar is not None and robot.lidar.name == "front"
    assert any("'rear' (scan_rear)" in w for w in robot.warnings)


def test_a_sensor_plugins_ros_namespace_prefixes_its_topic(tmp_path: Path) -> None:
    path = _models(
        tmp_path,
        _BASE_AND_SCANNER,
    )
    robot = load_robot(path, model_path=[tmp_path])
    assert robot.lidar is not None and robot.lidar.scan_topic == "bot/laser_scan"


def test_differing_drive_numbers_are_warned_with_what_gazebo_would_do(tmp_path: Path) -> None:
    text = _BASE_MODEL.replace("<wheel_separation>0.3</wheel_separation>", "<wheel_separation>0.6</wheel_separation>")
    path = tmp_path / "wide.sdf"
    path.write_text(text)
    robot = load_robot(path)
    (warning,) = [w for w in robot.warnings if "separation" in w]
    assert "0.6 m differs from the joints' 0.3000 m" in warning and "2.00x the commanded rate" in warning


def test_a_model_without_any_drive_loads_and_says_nothing_of_one(tmp_path: Path) -> None:
    path = tmp_path / "box.sdf"
    path.write_text(
        '<?xml version="1.0"?><sdf version="1.6"><model name="box"><link name="b">'
        "<collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision></link></model></sdf>"
    )
    assert load_robot(path).drive is None
    with pytest.raises(WorldError, match="no links"):
        path.write_text('<?xml version="1.0"?><sdf version="1.6"><model name="empty"/></sdf>')
        load_robot(path)


def test_world_info_on_a_model_says_what_a_run_reads_of_it_as_the_robot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.cli import main

    path = _models(
        tmp_path,
        _BASE_AND_SCANNER,
    )
    assert main(["world", "info", str(path), "--model-path", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: model 'robot'")
    assert "drive       base::left_joint / base::right_joint, wheel radius 0.05 m, separation 0.3 m" in out
    assert "lidar       laser on bot/laser_scan (scanner::link), 180 beams, 10 Hz, 0.1 to 8 m" in out


def test_a_merged_bases_diff_drive_is_the_robots(tmp_path: Path) -> None:
    # SDF 1.9's <include merge="true">: the base's links, joints and plugins become the robot's own.
    path = _models(
        tmp_path,
        """\
        <?xml version="1.0"?>
        <sdf version="1.9">
          <model name="robot"><include merge="true"><uri>model://base</uri></include></model>
        </sdf>
        """,
    )
    robot = load_robot(path, model_path=[tmp_path])
    assert robot.drive is not None
    assert (robot.drive.left_joint, robot.drive.right_joint) == ("left_joint", "right_joint")
    assert robot.drive.wheel_separation_m == pytest.approx(0.3)


@pytest.mark.parametrize(
    "ros",
    [
        "<remapping>~/out:=front_scan</remapping>",
        "<argument>~/out:=front_scan</argument>",
        "<argument>--ros-args -r ~/out:=front_scan</argument>",
    ],
)
def test_a_sensor_plugins_remapping_is_read_in_each_ros2_spelling(tmp_path: Path, ros: str) -> None:
    ray = (
        '<sensor name="laser" type="ray"><update_rate>5</update_rate><ray><scan><horizontal><samples>90</samples>'
        "<min_angle>-1</min_angle><max_angle>1</max_angle></horizontal></scan><range><min>0.1</min><max>3</max>"
        f'</range></ray><plugin name="laser_plugin" filename="libgazebo_ros_ray_sensor.so"><ros>{ros}</ros></plugin>'
        "</sensor>"
    )
    robot = load_robot(_one_link_robot(tmp_path, ray))
    assert robot.lidar is not None and robot.lidar.scan_topic == "front_scan"


def test_a_classic_skid_steer_drives_its_front_pair_and_turns_its_rear_with_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # Gazebo Classic's SkidSteerDrivePlugin (a Pioneer 3AT's) names four joints and no geometry.
    wheels = "".join(
        _WHEEL.format(name=name, x=x, y=y)
        for name, x, y in (("lf", 0.1, 0.15), ("rf", 0.1, -0.15), ("lr", -0.1, 0.15), ("rr", -0.1, -0.15))
    )
    plugin = (
        '<plugin name="skid" filename="libSkidSteerDrivePlugin.so"><left_front>lf_joint</left_front>'
        "<right_front>rf_joint</right_front><left_rear>lr_joint</left_rear><right_rear>rr_joint</right_rear></plugin>"
    )
    path = tmp_path / "skid.sdf"
    path.write_text(
        '<?xml version="1.0"?><sdf version="1.5"><model name="skid"><link name="body"><collision name="c">'
        f"<geometry><box><size>0.3 0.3 0.1</size></box></geometry></collision></link>{wheels}{plugin}</model></sdf>"
    )
    with caplog.at_level(logging.WARNING):
        robot = load_robot(path)
    assert robot.drive is not None
    assert (robot.drive.left_joint, robot.drive.right_joint) == ("lf_joint", "rf_joint")
    assert robot.drive.more_wheels == (("lr_joint", 0), ("rr_joint", 1))
    assert robot.drive.wheel_separation_m == pytest.approx(0.3) and robot.drive.wheel_radius_m == pytest.approx(0.05)
    assert not [r for r in caplog.records if "not run by the twin" in r.getMessage()]  # it is run
