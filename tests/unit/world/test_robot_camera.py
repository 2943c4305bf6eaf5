"""Camera sensors read from a robot's SDF as Gazebo Classic and gazebo_ros_camera read them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.core.errors import WorldError
from twin.world import load_robot


def test_the_waffles_realsense_is_read_as_gazebo_reads_it() -> None:
    robot = load_robot("turtlebot3_waffle", model_path=[Path(__file__).parents[3] / "sdf" / "models"])
    (camera,) = robot.cameras
    assert (camera.name, camera.sensor_type, camera.depth) == ("camera", "camera", False)
    assert (camera.width, camera.height, camera.encoding) == (1920, 1080, "rgb8")
    assert camera.hfov_rad == pytest.approx(1.02974)
    assert (camera.near_m, camera.far_m) == (0.02, 300.0)
    assert (camera.rate_hz, camera.noise_mean, camera.noise_std) == (30.0, 0.0, 0.007)
    assert camera.frame_id == "camera_rgb_optical_frame"
    assert (camera.image_topic, camera.info_topic) == ("/camera/image_raw", "/camera/camera_info")
    # camera_rgb_frame in base_footprint: camera_link (0.064, -0.065, 0.094) + (0.005, 0.018, 0.013)
    # on base_link, 0.010 above base_footprint.
    assert np.asarray(camera.T_base_sensor)[:3, 3] == pytest.approx([0.069, -0.047, 0.117])
    assert robot.frame(camera.frame_id).parent == "camera_rgb_frame"


def _robot(tmp_path: Path, camera: str, *, sensor_type: str = "camera", plugin: str = "") -> Path:
    folder = tmp_path / "bot"
    folder.mkdir()
    (folder / "model.sdf").write_text(
        f"""<?xml version="1.0"?>
<sdf version="1.7"><model name="bot">
  <link name="base_link">
    <collision name="c"><geometry><box><size>0.2 0.2 0.1</size></box></geometry></collision>
    <sensor name="cam" type="{sensor_type}">
      <pose>0.1 0 0.2 0 0 0</pose>
      <update_rate>10</update_rate>
      <camera>{camera}</camera>
      {plugin}
    </sensor>
  </link>
</model></sdf>"""
    )
    return folder / "model.sdf"


IMAGE = "<image><width>64</width><height>48</height></image>"
GOOD = "<horizontal_fov>1.0</horizontal_fov>" + IMAGE


def test_a_mono_camera_in_a_namespace_with_remapped_topics(tmp_path: Path) -> None:
    plugin = (
        '<plugin name="drv" filename="libgazebo_ros_camera.so"><ros><namespace>/front</namespace>'
        "<remapping>image_raw:=image_mono</remapping><remapping>cam/camera_info:=/info</remapping></ros>"
        "<frame_name>cam_optical</frame_name></plugin>"
    )
    camera = (
        "<horizontal_fov>1.0</horizontal_fov><image><width>64</width><height>48</height><format>L8</format></image>"
    )
    (spec,) = load_robot(_robot(tmp_path, camera, plugin=plugin)).cameras
    assert spec.encoding == "mono8"
    assert spec.image_topic == "/front/image_mono"
    assert spec.info_topic == "/info"
    assert spec.depth_topic == "/front/cam/depth/image_raw"
    assert spec.frame_id == "cam_optical"
    assert (spec.near_m, spec.far_m) == (0.1, 100.0)  # SDF's defaults


def test_a_depth_sensor_is_a_depth_camera(tmp_path: Path) -> None:
    (spec,) = load_robot(_robot(tmp_path, GOOD, sensor_type="depth")).cameras
    assert spec.depth
    assert spec.frame_id == "base_link"  # gazebo_ros_camera's default frame: the link


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        (
            "<image><width>64</width><height>48</height><format>B8G8R8</format></image>",
            r"image format 'B8G8R8' is not supported; use R8G8B8 \(rgb8\) or L8 \(mono8\)",
        ),
        ("<image><width>0</width><height>48</height></image>", "image width 0 must be a whole number from 1 to 8192"),
        ("<image><width>64</width><height>9000</height></image>", "image height 9000 must be"),
        ("<horizontal_fov>3.2</horizontal_fov>" + IMAGE, r"horizontal_fov 3.2 rad must be between 0 and pi"),
        (GOOD + "<clip><near>2</near><far>1</far></clip>", "clip near 2 m must be above 0 and below far 1 m"),
        (GOOD + "<noise><type>salt</type></noise>", "noise type 'salt' is not supported"),
    ],
)
def test_camera_parameters_gazebo_would_not_draw_are_refused_in_one_line(
    tmp_path: Path, camera: str, message: str
) -> None:
    with pytest.raises(WorldError, match=message) as err:
        load_robot(_robot(tmp_path, camera))
    text = str(err.value)
    assert "\n" not in text
    assert "model.sdf:" in text  # names the file and line


def test_the_waffles_fov_gives_gazebos_focal_length() -> None:
    from twin.world.render import CameraModel

    cam = CameraModel(width=640, height=480, hfov_rad=1.02974, near_m=0.02, far_m=300)
    assert cam.K()[0] == pytest.approx(320 / math.tan(1.02974 / 2))
