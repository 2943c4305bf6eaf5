from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from twin.core.geometry import Pose, matrix_from_pose
from twin.world import load_robot, urdf_from_robot
from twin.world.robot_model import RobotModelSpec
from twin.world.types import JointType

REPO = Path(__file__).resolve().parents[3]
FIXTURES = REPO.parent / "shared" / "fixtures"
SEPARATION = {"burger": 0.160, "waffle": 0.287, "waffle_pi": 0.287}


def _fixture_models() -> list[tuple[Path, str]]:
    out = []
    for tree in ("gazebo_classic", "gz_sim"):
        for folder in sorted((FIXTURES / tree / "models").glob("turtlebot3_*")):
            kind = folder.name.removeprefix("turtlebot3_").removesuffix("_cam")
            if kind not in SEPARATION:
                continue
            out.extend((sdf, kind) for sdf in sorted(folder.glob("*.sdf")))
    return out


@pytest.mark.parametrize(("path", "kind"), _fixture_models(), ids=lambda v: str(v).split("fixtures/")[-1])
def test_every_turtlebot3_model_has_the_published_drive_and_lds01(path: Path, kind: str) -> None:
    robot = load_robot(path, model_path=[path.parent.parent])
    assert robot.drive is not None
    assert robot.drive.wheel_radius_m == pytest.approx(0.033)
    assert robot.drive.wheel_separation_m == pytest.approx(SEPARATION[kind])
    assert (robot.drive.left_joint, robot.drive.right_joint) == ("wheel_left_joint", "wheel_right_joint")
    lidar = robot.lidar
    assert lidar is not None
    assert (lidar.samples, lidar.angle_min_rad, lidar.angle_max_rad) == (360, 0.0, 6.28)
    assert (lidar.range_min_m, lidar.range_max_m, lidar.range_resolution_m) == (0.12, 3.5, 0.015)
    assert (lidar.noise_mean_m, lidar.noise_std_m) == (0.0, 0.01)
    assert lidar.frame_id == "base_scan"
    # The gz-sim Waffle and Waffle Pi files run their gpu_lidar at 10 Hz; every other file at 5 Hz.
    gz_fast = "gz_sim" in str(path) and kind != "burger" and path.name == "model.sdf"
    assert lidar.rate_hz == (10.0 if gz_fast else 5.0)
    assert robot.imu is not None and robot.imu.rate_hz == 200.0
    assert [n.stddev for n in robot.imu.angular_velocity_noise] == [2e-4] * 3
    assert [n.stddev for n in robot.imu.linear_acceleration_noise] == [1.7e-2] * 3
    assert robot.base_height_m == pytest.approx(0.010, abs=1e-4)  # wheels reach 1 cm below the model frame


def _urdf_frames(path: Path) -> dict[str, np.ndarray]:
    """Compose a URDF's joint origins into poses relative to its root link."""
    root = etree.parse(str(path)).getroot()
    joints = {}
    for joint in root.iter("joint"):
        origin = joint.find("origin")
        xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()] if origin is not None else [0.0] * 3
        rpy = [float(v) for v in origin.get("rpy", "0 0 0").split()] if origin is not None else [0.0] * 3
        joints[joint.find("child").get("link")] = (joint.find("parent").get("link"), matrix_from_pose(Pose(*xyz, *rpy)))
    out: dict[str, np.ndarray] = {}

    def pose(link: str) -> np.ndarray:
        if link not in joints:
            return np.eye(4)
        parent, T = joints[link]
        return pose(parent) @ T

    for link in joints:
        out[link] = pose(link)
    return out


@pytest.mark.parametrize("kind", ["burger", "waffle"])
def test_project_models_reproduce_the_robotis_urdf_frames_and_masses(kind: str) -> None:
    robot = load_robot(f"turtlebot3_{kind}", model_path=[REPO / "sdf" / "models"])
    urdf = _urdf_frames(FIXTURES / "gazebo_classic" / "urdf" / f"turtlebot3_{kind}.urdf")
    assert robot.base_frame == "base_footprint"
    shared = {f.name for f in robot.frames} & set(urdf)
    assert {"base_link", "wheel_left_link", "wheel_right_link", "imu_link", "base_scan"} <= shared
    for name in shared:
        assert robot.T_base(name) == pytest.approx(urdf[name], abs=1e-9), name
    assert robot.mass_kg == pytest.approx({"burger": 1.0017, "waffle": 1.5539}[kind], abs=1e-4)
    assert robot.base_height_m == pytest.approx(0.0, abs=1e-4)  # base_footprint is on the floor
    wheel = robot.frame("wheel_left_link")
    assert wheel.joint_type is JointType.CONTINUOUS and wheel.axis == (0.0, 0.0, 1.0)
    assert robot.drive is not None and robot.drive.max_wheel_acceleration_mps2 == 1.0
    assert robot.joint_states is not None and robot.joint_states.rate_hz == 30.0


def test_scenario_values_override_with_replace() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    assert robot.lidar is not None
    faster = dataclasses.replace(robot, lidar=dataclasses.replace(robot.lidar, rate_hz=10.0, noise_std_m=0.0))
    assert isinstance(faster, RobotModelSpec)
    assert faster.lidar is not None and (faster.lidar.rate_hz, faster.lidar.noise_std_m) == (10.0, 0.0)
    assert robot.lidar.rate_hz == 5.0


def test_generated_urdf_has_every_frame_and_the_same_transforms(tmp_path: Path) -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    text = urdf_from_robot(robot)
    root = etree.fromstring(text.encode())
    links = {link.get("name") for link in root.iter("link")}
    assert links == {robot.base_frame, *(f.name for f in robot.frames)}
    joint_types = {j.find("child").get("link"): j.get("type") for j in root.iter("joint")}
    assert joint_types["wheel_left_link"] == "continuous" and joint_types["base_scan"] == "fixed"
    path = tmp_path / "waffle.urdf"
    path.write_text(text)
    frames = _urdf_frames(path)
    for frame in robot.frames:
        assert frames[frame.name] == pytest.approx(robot.T_base(frame.name), abs=1e-8)
    base = next(link for link in root.iter("link") if link.get("name") == "base_link")
    assert base.find("collision/geometry/box").get("size") == "0.266 0.266 0.094"


def test_fixture_robot_urdf_keeps_mesh_visuals_as_file_uris() -> None:
    robot = load_robot("turtlebot3_burger", model_path=[FIXTURES / "gazebo_classic" / "models"])
    root = etree.fromstring(urdf_from_robot(robot).encode())
    meshes = [m.get("filename") for m in root.iter("mesh")]
    assert any(uri.startswith("file:///") and uri.endswith("burger_base.dae") for uri in meshes)


@pytest.mark.parametrize("name", ["wheel", 'say "hi"', "it's", "both \"'", "a<b>&c", "tab\tline\nend\r", ""])
def test_urdf_attributes_are_quoted_as_the_standard_library_quotes_them(name: str) -> None:
    from xml.sax.saxutils import quoteattr

    from twin.world.urdf import _quoteattr

    assert _quoteattr(name) == quoteattr(name)


def _burger_with_drive(tmp_path: Path, old: str, new: str) -> Path:
    """The project's Burger with its diff drive plugin's text changed."""
    model = tmp_path / "burger"
    shutil.copytree(REPO / "sdf" / "models" / "turtlebot3_burger", model)
    sdf = model / "model.sdf"
    text = sdf.read_text()
    assert old in text
    sdf.write_text(text.replace(old, new, 1))
    return sdf


def test_every_turtlebot3_diff_drive_takes_cmd_vel_and_publishes_odom() -> None:
    for path, _ in _fixture_models():
        drive = load_robot(path, model_path=[path.parent.parent]).drive
        assert drive is not None
        assert (drive.command_topic, drive.odometry_topic) == ("cmd_vel", "odom"), path


@pytest.mark.parametrize(
    ("ros", "command", "odom"),
    [
        ("<remapping>cmd_vel:=cmd_vel_raw</remapping>", "cmd_vel_raw", "odom"),
        ("<namespace>/tb3</namespace><remapping>odom:=wheel_odom</remapping>", "tb3/cmd_vel", "tb3/wheel_odom"),
        ("<namespace>tb3</namespace><remapping>cmd_vel:=/teleop/cmd_vel</remapping>", "/teleop/cmd_vel", "tb3/odom"),
    ],
)
def test_gazebo_ros_diff_drive_topics_follow_its_ros_remappings(
    tmp_path: Path, ros: str, command: str, odom: str
) -> None:
    # In ROS 2 the plugin subscribes cmd_vel and publishes odom in its <ros> namespace, remapped there.
    sdf = _burger_with_drive(
        tmp_path, "<update_rate>30</update_rate>", f"<ros>{ros}</ros><update_rate>30</update_rate>"
    )
    robot = load_robot(sdf)
    assert robot.drive is not None
    assert (robot.drive.command_topic, robot.drive.odometry_topic) == (command, odom)
    assert not [w for w in robot.warnings if "ROS 1" in w]


def test_a_ros1_command_topic_is_ignored_as_humble_ignores_it_and_said(tmp_path: Path) -> None:
    sdf = _burger_with_drive(tmp_path, "<command_topic>cmd_vel<", "<command_topic>tb3_cmd<")
    robot = load_robot(sdf)
    assert robot.drive is not None and robot.drive.command_topic == "cmd_vel"
    (warning,) = [w for w in robot.warnings if "command_topic" in w]
    assert "model.sdf" in warning and "<remapping>cmd_vel:=tb3_cmd</remapping>" in warning


def test_gz_sim_diff_drive_topics_are_its_topic_and_odom_topic(tmp_path: Path) -> None:
    source = FIXTURES / "gz_sim" / "models" / "turtlebot3_burger" / "model.sdf"
    text = source.read_text().replace("<topic>cmd_vel</topic>", "<topic>drive/cmd</topic>", 1)
    text = text.replace("<odom_topic>odom</odom_topic>", "<odom_topic>/drive/odom</odom_topic>", 1)
    model = tmp_path / "turtlebot3_burger"
    shutil.copytree(source.parent, model)
    (model / "model.sdf").write_text(text)
    robot = load_robot(model / "model.sdf", model_path=[FIXTURES / "gz_sim" / "models"])
    assert robot.drive is not None
    assert (robot.drive.command_topic, robot.drive.odometry_topic) == ("drive/cmd", "/drive/odom")
