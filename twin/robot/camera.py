"""The camera node: a Gazebo camera (or depth) sensor with gazebo_ros_camera publishing it.

| node | publishes |
|---|---|
| `camera` | `/camera/image_raw` (sensor_msgs/Image, rgb8 or mono8), `/camera/camera_info` |
| | with depth: `/camera/depth/image_raw` (32FC1, metres), `/camera/points` (PointCloud2) |
| | compressed: `/camera/image_raw/compressed` (sensor_msgs/CompressedImage, JPEG quality 95) |

(the topic names as the sensor's gazebo_ros_camera plugin sets them; these are the defaults)

Each frame is drawn from the world's visuals, the scenario's obstacles and a fleet's other robots
(`twin.world.render`) at the sensor's pose on the robot, stamped in sim time at the sensor's rate. Like a Gazebo camera
nobody subscribes to, it renders only while someone wants its images: always when the recorder
records its image topic, otherwise only while a `LookForObject` node waits for a frame
(`CameraFeed.want`). Data (in-process): the image array, (height, width, 3) uint8 or (height, width).
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from twin.bag import CameraInfoEncoder, CompressedImageEncoder, ImageEncoder, PointCloud2Encoder
from twin.node import PRIORITY_SENSOR, Encoded, Node, QoSProfile
from twin.robot.chassis import ChassisState
from twin.world.meshes import MeshCache
from twin.world.obstacles import ObstacleField
from twin.world.render import Body, CameraModel, ColouredMesh, Lighting, Renderer, join_meshes, shapes_mesh
from twin.world.robot_model import CameraSpec
from twin.world.types import Box, Cylinder

__all__ = ["CameraFeed", "CameraNode", "camera_model"]

SENSOR_DATA = QoSProfile(depth=5, reliability="best_effort")


def camera_model(spec: CameraSpec) -> CameraModel:
    """The renderer's pinhole camera of a camera sensor."""
    return CameraModel(
        width=spec.width, height=spec.height, hfov_rad=spec.hfov_rad, near_m=spec.near_m, far_m=spec.far_m
    )


class CameraFeed:
    """The camera's in-process side: who wants images now, and the last frame (a `LookForObject` source)."""

    def __init__(self) -> None:
        self._wants = 0
        self.frame: tuple[int, NDArray[np.uint8]] | None = None

    def want(self, on: bool) -> None:
        """Count one more (True) or one fewer (False) reader waiting for images."""
        self._wants = max(0, self._wants + (1 if on else -1))

    @property
    def wanted(self) -> bool:
        """True while a reader waits for images."""
        return self._wants > 0

    def latest(self) -> tuple[int, NDArray[np.uint8]] | None:
        """The last frame drawn: (stamp ns, image)."""
        return self.frame


_JPEG_QUALITY = 95  # image_transport's compressed plugin's default jpeg_quality


def _jpeg(image: NDArray[np.uint8]) -> bytes:
    """JPEG bytes of an RGB or mono image (Pillow/libjpeg: the same image gives the same bytes)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="JPEG", quality=_JPEG_QUALITY)
    return buf.getvalue()


_POINT_FIELDS = (("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 16, 7, 1))  # 7: FLOAT32
_POINT_STEP = 32  # x, y, z, padding, rgb, padding: PCL's PointXYZRGB layout, as gazebo_ros fills it


def cloud_bytes(image: NDArray[np.uint8], depth_m: NDArray[np.float32], f_px: float) -> bytes:
    """An organised XYZRGB cloud in the optical frame from a depth image (NaN where no depth)."""
    h, w = depth_m.shape
    z = depth_m.astype(np.float32)
    u = ((np.arange(w, dtype=np.float32) + 0.5 - w / 2) / np.float32(f_px))[None, :]
    v = ((np.arange(h, dtype=np.float32) + 0.5 - h / 2) / np.float32(f_px))[:, None]
    valid = np.isfinite(z)
    out = np.zeros((h, w, _POINT_STEP // 4), dtype=np.float32)
    out[..., 0] = np.where(valid, u * z, np.nan)
    out[..., 1] = np.where(valid, v * z, np.nan)
    out[..., 2] = np.where(valid, z, np.nan)
    rgb = image if image.ndim == 3 else np.repeat(image[:, :, None], 3, axis=2)
    packed = (rgb[..., 0].astype(np.uint32) << 16) | (rgb[..., 1].astype(np.uint32) << 8) | rgb[..., 2]
    out.view(np.uint32)[..., 4] = packed
    return out.tobytes()


def _mono(rgb: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Luma (ITU-R BT.601) of an RGB image, rounded, as an L8 camera gives it."""
    luma = rgb.astype(np.float32) @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    return np.ascontiguousarray(np.floor(luma + 0.5).astype(np.uint8))


def _planar(s: ChassisState) -> NDArray[np.float64]:
    """The base's pose in the world (on the ground plane) as a 4x4 transform."""
    c, sn = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
    return np.array([[c, -sn, 0.0, s.x_m], [sn, c, 0.0, s.y_m], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


class CameraNode(Node):
    """gazebo_ros_camera on the robot's camera sensor (see the module's doc).

    Args:
        spec: The sensor, as read from the robot's SDF with the scenario's overrides.
        renderer: Draws the world from a pose (the static visuals; obstacles are added per frame).
        lighting: To light the obstacles as the world is lit.
        chassis: The robot's planar pose now.
        feed: Where readers ask for frames and find the last one.
        obstacles: The scenario's obstacles and blocks (None without any).
        rng: The camera's noise stream (one seed drawn per frame drawn).
        depth: Also publish the depth image.
        compressed: Also publish the JPEG image (compressed only when a sink takes it).
        body: The robot's own visuals in its base frame (drawn where the robot stands).
        others: The other robots of a fleet: each one's visuals in its base frame and its planar
            pose now (drawn where it stands when a frame is drawn).
        recorded: The recorder records the image topic: render every period.
    """

    def __init__(
        self,
        spec: CameraSpec,
        renderer: Renderer,
        lighting: Lighting,
        chassis: Callable[[], ChassisState],
        feed: CameraFeed,
        *,
        obstacles: ObstacleField | None,
        rng: np.random.Generator,
        depth: bool,
        compressed: bool = False,
        recorded: bool,
        body: Body | None = None,
        others: Sequence[tuple[Body, Callable[[], ChassisState]]] = (),
    ) -> None:
        super().__init__(spec.name)
        w, h = spec.width, spec.height
        image_encode = ImageEncoder(spec.frame_id, width=w, height=h, encoding=spec.encoding).encode
        cam = renderer.camera
        info_encode = CameraInfoEncoder(spec.frame_id, width=w, height=h, K=cam.K(), P=cam.P()).encode
        depth_encode = ImageEncoder(spec.frame_id, width=w, height=h, encoding="32FC1").encode
        image_pub = self.create_publisher(ImageEncoder.msgtype, spec.image_topic, SENSOR_DATA)
        info_pub = self.create_publisher(CameraInfoEncoder.msgtype, spec.info_topic, SENSOR_DATA)
        depth_pub = self.create_publisher(ImageEncoder.msgtype, spec.depth_topic, SENSOR_DATA) if depth else None
        points_pub = (
            self.create_publisher(PointCloud2Encoder.msgtype, spec.points_topic, SENSOR_DATA) if depth else None
        )
        cloud_encode = PointCloud2Encoder(
            spec.frame_id, width=w, height=h, fields=_POINT_FIELDS, point_step=_POINT_STEP
        ).encode
        f_px = renderer.camera.f_px

        def points_encode(t_ns: int, image: NDArray[np.uint8], depth_m: NDArray[np.float32]) -> bytes:
            return cloud_encode(t_ns, cloud_bytes(image, depth_m, f_px))

        jpeg_pub = None
        if compressed:
            fmt = f"{spec.encoding}; jpeg compressed {'mono8' if spec.encoding == 'mono8' else 'bgr8'}"
            compressed_encode = CompressedImageEncoder(spec.frame_id, format=fmt).encode

            def jpeg_encode(t_ns: int, image: NDArray[np.uint8]) -> bytes:
                return compressed_encode(t_ns, _jpeg(image))

            topic = f"{spec.image_topic}/compressed"
            jpeg_pub = self.create_publisher(CompressedImageEncoder.msgtype, topic, SENSOR_DATA)
        T_base_sensor = np.asarray(spec.T_base_sensor)
        mono = spec.encoding == "mono8"
        noise_mean, noise_std = spec.noise_mean, spec.noise_std
        cache = MeshCache()
        shown: list[tuple[int, ColouredMesh | None]] = [(-1, None)]

        def obstacle_mesh() -> ColouredMesh | None:
            if obstacles is None:
                return None
            if shown[0][0] != obstacles.version:
                shapes: list[tuple[Box | Cylinder, NDArray[np.float64], tuple[float, float, float]]] = []
                for marker in obstacles.markers():
                    x, y, z, _, _, qz, qw = marker.pose
                    yaw = 2.0 * math.atan2(qz, qw)
                    T = np.array(
                        [[math.cos(yaw), -math.sin(yaw), 0.0, x], [math.sin(yaw), math.cos(yaw), 0.0, y],
                         [0.0, 0.0, 1.0, z], [0.0, 0.0, 0.0, 1.0]]
                    )  # fmt: skip
                    sx, sy, sz = marker.scale
                    geometry: Box | Cylinder = (
                        Box(size_m=(sx, sy, sz)) if marker.shape == "box" else Cylinder(radius_m=sx / 2, length_m=sz)
                    )
                    shapes.append((geometry, T, marker.color_rgba[:3]))
                shown[0] = (obstacles.version, shapes_mesh(shapes, lighting, cache) if shapes else None)
            return shown[0][1]

        def on_timer(t_ns: int) -> None:
            if not (recorded or feed.wanted):
                return
            T_world_base = _planar(chassis())
            seed = int(rng.integers(0, 2**63))
            parts = [] if body is None else [body.placed(T_world_base, lighting)]
            parts += [other.placed(_planar(pose()), lighting) for other, pose in others]
            extra = obstacle_mesh()
            if extra is not None:
                parts.append(extra)
            frame = renderer.render(
                T_world_base @ T_base_sensor,
                join_meshes(parts),
                noise_mean=noise_mean,
                noise_std=noise_std,
                seed=seed,
            )
            image: NDArray[np.uint8] = _mono(frame.rgb) if mono else frame.rgb
            feed.frame = (t_ns, image)
            image_pub.publish(Encoded((image_encode, (t_ns, image), image)))
            info_pub.publish(Encoded((info_encode, (t_ns,), cam)))
            if jpeg_pub is not None:
                jpeg_pub.publish(Encoded((jpeg_encode, (t_ns, image), image)))
            if depth_pub is not None:
                depth_pub.publish(Encoded((depth_encode, (t_ns, frame.depth_m), frame.depth_m)))
            if points_pub is not None:
                points_pub.publish(Encoded((points_encode, (t_ns, image, frame.depth_m), frame.depth_m)))

        self.create_rate_timer(spec.rate_hz, on_timer, priority=PRIORITY_SENSOR)
