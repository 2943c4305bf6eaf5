"""The camera in a run, tested from the bag: where a block appears, its depth, occlusion, clip, stamps, seeds."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader

from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation
from twin.world import load_robot

REPO = Path(__file__).resolve().parents[2]
W, H = 160, 120

WORLD = """<?xml version="1.0"?>
<sdf version="1.7"><world name="yard">
  <scene><ambient>1 1 1 1</ambient><background>0 0 0 1</background></scene>
  <model name="ground"><static>true</static><link name="l">
    <collision name="c"><geometry><plane><normal>0 0 1</normal><size>40 40</size></plane></geometry></collision>
    <visual name="v"><geometry><plane><normal>0 0 1</normal><size>40 40</size></plane></geometry>
      <material><diffuse>0.5 0.5 0.5 1</diffuse></material></visual></link></model>
  <model name="wall"><static>true</static><link name="l"><pose>3.0 -1.0 0.5 0 0 0</pose>
    <collision name="c"><geometry><box><size>0.1 1.0 1.0</size></box></geometry></collision>
    <visual name="v"><geometry><box><size>0.1 1.0 1.0</size></box></geometry>
      <material><diffuse>0.6 0.6 0.6 1</diffuse></material></visual></link></model>
</world></sdf>
"""

# (x, y) of 0.1 m boxes in the world; the robot stands at the origin facing +x.
BLOCKS = [(1.5, 0.0), (2.0, 0.55), (1.2, -0.5), (4.0, -1.0)]  # the last stands behind the wall


def _scenario(tmp_path: Path, *, noise: bool, seed: int = 3, compressed: bool = False) -> Path:
    (tmp_path / "yard.sdf").write_text(WORLD)
    data = {
        "name": "camera",
        "seed": seed,
        "world": {"sdf": str(tmp_path / "yard.sdf")},
        "mission": {"type": "none"},
        "odometry": "ground_truth",
        "sensors": {
            "camera": {
                "enabled": True,
                "width": W,
                "height": H,
                "rate_hz": 5.0,
                "depth": True,
                "noise": noise,
                "compressed": compressed,
            }
        },
        "obstacles": [
            {
                "shape": "box",
                "size_m": [0.1, 0.1, 0.1],
                "pose": {"x_m": x, "y_m": y, "yaw_rad": 0.0},
                "name": f"block{i}",
                "color_rgba": [0.0, 0.0, 0.8, 1.0],
            }
            for i, (x, y) in enumerate(BLOCKS)
        ],
    }
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _record(tmp_path: Path, scenario: Path, name: str = "bag") -> dict[str, list[tuple[int, object]]]:
    bag = tmp_path / name
    with Simulation(load_scenario(scenario), bag_path=bag, duration_s=1.0) as sim:
        sim.run()
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([bag]) as reader:
        cons = [c for c in reader.connections if c.topic.startswith("/camera/")]
        for c, t, raw in reader.messages(connections=cons):
            out.setdefault(c.topic, []).append((t, reader.deserialize(raw, c.msgtype)))
    return out


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[int, object]]]:
    tmp = tmp_path_factory.mktemp("camera")
    return _record(tmp, _scenario(tmp, noise=False))


def test_images_and_camera_info_at_the_sensors_rate_in_sim_time(clean) -> None:
    images, infos = clean["/camera/image_raw"], clean["/camera/camera_info"]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in images]
    assert stamps == [0, 200_000_000, 400_000_000, 600_000_000, 800_000_000]  # 5 Hz over the first second
    image = images[0][1]
    assert (image.width, image.height, image.encoding, image.step) == (W, H, "rgb8", 3 * W)
    assert image.header.frame_id == "camera_rgb_optical_frame"
    info = infos[0][1]
    f = (W / 2) / math.tan(1.02974 / 2)
    assert list(info.k) == pytest.approx([f, 0, (W + 1) / 2, 0, f, (H + 1) / 2, 0, 0, 1])
    assert list(info.p) == pytest.approx([f, 0, (W + 1) / 2, 0, 0, f, (H + 1) / 2, 0, 0, 0, 1, 0])
    assert info.distortion_model == "plumb_bob" and not np.any(info.d)
    depth = clean["/camera/depth/image_raw"][0][1]
    assert (depth.encoding, depth.step) == ("32FC1", 4 * W)


def _arrays(clean) -> tuple[np.ndarray, np.ndarray, tuple[float, ...]]:
    image = clean["/camera/image_raw"][0][1]
    rgb = np.asarray(image.data).reshape(H, W, 3)
    depth_msg = clean["/camera/depth/image_raw"][0][1]
    depth = np.frombuffer(np.asarray(depth_msg.data).tobytes(), dtype="<f4").reshape(H, W)
    return rgb, depth, tuple(clean["/camera/camera_info"][0][1].k)


@pytest.mark.parametrize("block", [0, 1, 2])
def test_a_block_appears_where_K_predicts_at_the_distance_along_the_axis(clean, block: int) -> None:
    rgb, depth, K = _arrays(clean)
    (camera,) = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"]).cameras
    T = np.asarray(camera.T_base_sensor)  # the robot stands at the world origin
    x, y = BLOCKS[block]
    front = np.array([x - 0.05, y, 0.05]) - T[:3, 3]  # the front face's centre, from the sensor
    X, Y, Z = -front[1], -front[2], front[0]  # optical frame
    u, v = K[0] * X / Z + K[2], K[4] * Y / Z + K[5]  # K counts pixels from 1
    col, row = round(u - 1), round(v - 1)
    assert 0 <= col < W and 0 <= row < H
    window = depth[row - 1 : row + 2, col - 1 : col + 2]
    assert np.abs(window - Z).min() < 1e-3  # the depth image: the distance along the optical axis
    assert tuple(rgb[row, col]) == (0, 0, 204)
    # The face's pixels centre on (u, v) within a pixel.
    rows, cols = np.nonzero(np.abs(depth - Z) < 1e-3)
    near = (np.abs(rows - row) < 6) & (np.abs(cols - col) < 6)
    assert cols[near].mean() + 1 == pytest.approx(u, abs=1.0)
    assert rows[near].mean() + 1 == pytest.approx(v, abs=1.0)


def test_the_point_cloud_holds_each_pixels_point_in_the_optical_frame(clean) -> None:
    rgb, depth, K = _arrays(clean)
    cloud = clean["/camera/points"][0][1]
    assert (cloud.width, cloud.height, cloud.point_step, cloud.is_dense) == (W, H, 32, False)
    assert [(f.name, f.offset) for f in cloud.fields] == [("x", 0), ("y", 4), ("z", 8), ("rgb", 16)]
    points = np.frombuffer(np.asarray(cloud.data).tobytes(), dtype="<f4").reshape(H, W, 8)
    finite = np.isfinite(depth)
    assert np.array_equal(points[..., 2][finite], depth[finite])
    assert np.all(np.isnan(points[..., 2][~finite]))
    # A pixel's point lies on its ray through K: x / z = (u - cx) / fx with u counted from 1.
    row, col = np.argwhere(finite)[len(np.argwhere(finite)) // 2]
    assert points[row, col, 0] / points[row, col, 2] == pytest.approx((col + 1 - K[2]) / K[0], abs=1e-6)
    packed = points.view("<u4")[row, col, 4]
    assert (packed >> 16 & 255, packed >> 8 & 255, packed & 255) == tuple(rgb[row, col])


def test_the_wall_hides_the_block_behind_it_and_the_sky_is_background_beyond_the_far_clip(clean) -> None:
    rgb, depth, _ = _arrays(clean)
    blue = (rgb[..., 0] == 0) & (rgb[..., 1] == 0) & (rgb[..., 2] == 204)
    # Three blocks in view; the fourth behind the wall adds no pixels at its depth.
    assert not np.any(np.abs(depth[blue] - (4.0 - 0.05 - 0.069)) < 0.05)
    # Above the horizon nothing is within the far clip: +inf and the scene's background.
    assert np.all(np.isposinf(depth[0]))
    assert np.all(rgb[0] == 0)


def test_the_same_seed_gives_byte_identical_noisy_images(tmp_path: Path) -> None:
    one = _record(tmp_path, _scenario(tmp_path, noise=True, seed=5), "one")
    two = _record(tmp_path, _scenario(tmp_path, noise=True, seed=5), "two")
    other = _record(tmp_path, _scenario(tmp_path, noise=True, seed=6), "three")
    frames = [[bytes(m.data) for _, m in run["/camera/image_raw"]] for run in (one, two, other)]
    assert frames[0] == frames[1]
    assert frames[0] != frames[2]


def test_the_default_mission_has_no_camera(tmp_path: Path) -> None:
    scenario = load_scenario(REPO / "scenarios" / "default.yaml")
    assert not scenario.sensors.camera.enabled
    with Simulation(scenario, bag_path=tmp_path / "bag", duration_s=0.2) as sim:
        sim.run()
    with AnyReader([tmp_path / "bag"]) as reader:
        assert not [c.topic for c in reader.connections if c.topic.startswith("/camera")]


def test_compressed_images_are_the_jpeg_of_the_raw_ones(tmp_path: Path) -> None:
    import io

    from PIL import Image

    run = _record(tmp_path, _scenario(tmp_path, noise=True, compressed=True))
    raw = run["/camera/image_raw"]
    jpegs = run["/camera/image_raw/compressed"]
    assert len(jpegs) == len(raw) == 5
    message = jpegs[0][1]
    assert message.format == "rgb8; jpeg compressed bgr8"
    assert message.header.frame_id == "camera_rgb_optical_frame"
    decoded = np.asarray(Image.open(io.BytesIO(bytes(message.data))).convert("RGB")).astype(int)
    original = np.asarray(raw[0][1].data).reshape(H, W, 3).astype(int)
    assert np.abs(decoded - original).mean() < 3.0  # JPEG at quality 95


def test_bag_export_writes_each_frame_as_png(tmp_path: Path) -> None:
    from PIL import Image

    from tests.conftest import run_twin

    run = _record(tmp_path, _scenario(tmp_path, noise=True, compressed=True))
    out = tmp_path / "png"
    topics = ["/camera/image_raw", "/camera/image_raw/compressed", "/camera/depth/image_raw"]
    result = run_twin("bag", "export", str(tmp_path / "bag"), "--topics", *topics, "--format", "png", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "/camera/image_raw: 5 frames" in result.stdout
    t0, first = run["/camera/image_raw"][0]
    png = np.asarray(Image.open(out / "camera_image_raw" / f"{t0}.png"))
    assert np.array_equal(png, np.asarray(first.data).reshape(H, W, 3))
    depth_png = np.asarray(Image.open(out / "camera_depth_image_raw" / f"{t0}.png"))
    depth_msg = run["/camera/depth/image_raw"][0][1]
    depth = np.frombuffer(np.asarray(depth_msg.data).tobytes(), dtype="<f4").reshape(H, W)
    finite = np.isfinite(depth)
    assert np.array_equal(depth_png[finite], np.round(depth[finite] * 1000).astype(np.uint16))
    assert not depth_png[~finite].any()
    assert len(list((out / "camera_image_raw_compressed").glob("*.png"))) == 5
    bad = run_twin("bag", "export", str(tmp_path / "bag"), "--topics", "/camera/camera_info", "--format", "png")
    assert bad.returncode == 5
    assert "/camera/camera_info is sensor_msgs/msg/CameraInfo, not an image" in bad.stderr


def test_analyze_puts_the_camera_frames_into_the_report(tmp_path: Path) -> None:
    from twin.analysis.export_images import pick_frames
    from twin.analysis.report import analyze

    run = _record(tmp_path, _scenario(tmp_path, noise=False))
    report = analyze(tmp_path / "bag")
    section = next(s for s in report.sections if s.name == "camera")
    assert section.available
    assert section.plot == "camera.png"
    assert report.pngs["camera.png"].startswith(b"\x89PNG")
    # The sheet's frames are the bag's own: the first and the last.
    frames = pick_frames(
        tmp_path / "bag", "/camera/image_raw", "sensor_msgs/msg/Image", [("first", 0), ("last", 10**9)]
    )
    images = run["/camera/image_raw"]
    assert [label for label, _ in frames] == ["first", "last"]
    assert np.array_equal(frames[0][1], np.asarray(images[0][1].data).reshape(H, W, 3))
    assert np.array_equal(frames[1][1], np.asarray(images[-1][1].data).reshape(H, W, 3))


def test_a_users_node_subscribed_to_the_images_makes_the_camera_render(tmp_path: Path) -> None:
    (tmp_path / "watcher.py").write_text(
        """
from twin.node import Node


class Watcher(Node):
    seen = []

    def __init__(self) -> None:
        super().__init__("watcher")
        self.create_subscription("sensor_msgs/msg/Image", "/camera/image_raw", self.on_image, 10)

    def on_image(self, msg) -> None:
        Watcher.seen.append((msg.header.stamp.sec, msg.header.stamp.nanosec, msg.width, msg.height))
"""
    )
    path = _scenario(tmp_path, noise=False)
    data = yaml.safe_load(path.read_text())
    data["nodes"] = [{"plugin": "watcher:Watcher"}]
    data["recording"] = {"topics": {"exclude_regex": "/camera/.*"}}  # nothing of the camera recorded
    path.write_text(yaml.safe_dump(data))
    with Simulation(load_scenario(path), bag_path=tmp_path / "bag", duration_s=1.0) as sim:
        sim.run()
    import sys

    seen = sys.modules["watcher"].Watcher.seen
    assert seen == [(0, n * 200_000_000, W, H) for n in range(5)]


def test_a_search_for_a_colour_no_block_has_ends_in_failure_with_the_reason(tmp_path: Path) -> None:
    from tests.conftest import run_twin

    data = yaml.safe_load((REPO / "scenarios" / "house_search_queue.yaml").read_text())
    data["mission"]["tree"] = str(REPO / "trees" / "search_queue.xml")
    data["blocks"] = {"count": 2}  # red and green only
    data["recording"] = {"topics": {"exclude_regex": "/camera/.*"}}
    path = tmp_path / "search.yaml"
    path.write_text(yaml.safe_dump(data))
    result = run_twin("simulate", str(path), "--out", str(tmp_path / "bag"), "-v")
    assert result.returncode == 1, result.stderr
    lines = result.stderr.splitlines()
    looked = [line for line in lines if "INFO" in line and "look_for_obj: no blue object in view" in line]
    assert len(looked) == 4  # every location was looked at
    assert "no blue object in view" in lines[-1]  # the run's summary names the demos' reason


def test_the_camera_draws_nothing_while_nobody_takes_its_images(tmp_path: Path, monkeypatch) -> None:
    from twin.world.render import Renderer

    calls: list[int] = []
    draw = Renderer.render

    def counted(self, *args, **kwargs):
        calls.append(1)
        return draw(self, *args, **kwargs)

    monkeypatch.setattr(Renderer, "render", counted)
    path = _scenario(tmp_path, noise=True)
    data = yaml.safe_load(path.read_text())
    data["recording"] = {"topics": {"exclude_regex": "/camera/.*"}}
    path.write_text(yaml.safe_dump(data))
    with Simulation(load_scenario(path), bag_path=tmp_path / "bag", duration_s=1.0) as sim:
        sim.run()
    assert calls == []  # no recorder, no subscriber, no LookForObject: no frame drawn
    _record(tmp_path, _scenario(tmp_path, noise=True), "recorded")
    assert len(calls) == 5  # recorded: every period
