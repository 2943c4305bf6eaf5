"""Fast encoders: one class per message type, created once, called with plain numbers and arrays.

Each encoder precomputes everything that does not change between messages (frame ids, array
sizes, padding, constant covariances) when it is constructed; `encode()` then only fills in the
stamp and the values, usually with a single `struct.pack`. The bytes are exactly what rosbags'
serializer produces for the same message (the tests check this byte for byte).

Frame ids are taken as given, or under the frame prefix in force when the encoder is made
(`twin.bag.frames.frame_prefix`: a fleet robot's frames on one shared `/tf`).

Times are integer nanoseconds (`stamp_ns`); angles are radians; poses are `(x, y, z, qx, qy, qz,
qw)`. Every encoder has a `msgtype` class attribute to pass to `Recorder.add_topic`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.bag.cdr import ENCAPSULATION, CdrWriter, Layout, string_bytes
from twin.bag.frames import prefixed
from twin.core.errors import BagError

__all__ = [
    "BehaviorTreeLogEncoder",
    "CameraInfoEncoder",
    "ClockEncoder",
    "CompressedImageEncoder",
    "ContactEncoder",
    "ImageEncoder",
    "ImuEncoder",
    "JointStateEncoder",
    "LogEncoder",
    "MarkerArrayEncoder",
    "MotorStateEncoder",
    "NavigationFeedbackEncoder",
    "OccupancyGridEncoder",
    "OdometryEncoder",
    "ParticleCloudEncoder",
    "PathEncoder",
    "PointCloud2Encoder",
    "PoseStampedEncoder",
    "PoseWithCovarianceStampedEncoder",
    "ScanEncoder",
    "StringEncoder",
    "TFEncoder",
    "TwistEncoder",
]

_NS = 1_000_000_000
_F64 = np.dtype("<f8")
_F32 = np.dtype("<f4")
_TIME = struct.Struct("<iI")


def _fixed_f64(values: ArrayLike | None, size: int, what: str) -> tuple[float, ...]:
    """`size` floats from an array-like (zeros for None), or a BagError naming `what`."""
    if values is None:
        return (0.0,) * size
    flat = np.asarray(values, dtype=np.float64).reshape(-1)
    if flat.size != size:
        msg = f"{what} needs {size} values, got {flat.size}"
        raise BagError(msg)
    return tuple(float(v) for v in flat)


def _f64_bytes(values: ArrayLike, size: int, what: str) -> bytes:
    raw = np.ascontiguousarray(values, dtype=_F64).tobytes()
    if len(raw) != 8 * size:
        msg = f"{what} needs {size} values, got {len(raw) // 8}"
        raise BagError(msg)
    return raw


def _planar_quat(yaw_rad: float) -> tuple[float, float]:
    half = 0.5 * yaw_rad
    return math.sin(half), math.cos(half)


class ClockEncoder:
    """`rosgraph_msgs/msg/Clock`: the sim time itself."""

    msgtype: ClassVar[str] = "rosgraph_msgs/msg/Clock"
    _pack = struct.Struct("<4siI").pack

    def encode(self, stamp_ns: int) -> bytes:
        """Encode the clock at `stamp_ns`."""
        sec, nanosec = divmod(stamp_ns, _NS)
        return self._pack(ENCAPSULATION, sec, nanosec)


class TwistEncoder:
    """`geometry_msgs/msg/Twist` (e.g. `/cmd_vel`)."""

    msgtype: ClassVar[str] = "geometry_msgs/msg/Twist"
    _pack = struct.Struct("<4s6d").pack

    def encode(self, linear_x_m_s: float, angular_z_rad_s: float) -> bytes:
        """Encode a planar twist: forward speed and yaw rate."""
        return self._pack(ENCAPSULATION, linear_x_m_s, 0.0, 0.0, 0.0, 0.0, angular_z_rad_s)

    def encode_full(self, linear: Sequence[float], angular: Sequence[float]) -> bytes:
        """Encode a full twist from `(x, y, z)` linear (m/s) and angular (rad/s) vectors."""
        return self._pack(ENCAPSULATION, *linear, *angular)


class ImuEncoder:
    """`sensor_msgs/msg/Imu` with constant covariances (as Gazebo's IMU plugin publishes them)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/Imu"

    def __init__(
        self,
        frame_id: str = "imu_link",
        *,
        orientation_covariance: ArrayLike | None = None,
        angular_velocity_covariance: ArrayLike | None = None,
        linear_acceleration_covariance: ArrayLike | None = None,
    ) -> None:
        """Precompute the layout.

        Args:
            frame_id: The IMU frame.
            orientation_covariance: 3x3 row-major, rad² (zeros if None).
            angular_velocity_covariance: 3x3 row-major, (rad/s)² (zeros if None).
            linear_acceleration_covariance: 3x3 row-major, (m/s²)² (zeros if None).
        """
        layout = Layout()
        layout.var_time()
        layout.const_string(prefixed(frame_id))
        layout.var("orientation", "d", 4)
        orientation_at = layout.size - 32
        layout.const("d", *_fixed_f64(orientation_covariance, 9, "orientation_covariance"))
        layout.var("angular_velocity", "d", 3)
        angular_velocity_at = layout.size - 24
        layout.const("d", *_fixed_f64(angular_velocity_covariance, 9, "angular_velocity_covariance"))
        layout.var("linear_acceleration", "d", 3)
        linear_acceleration_at = layout.size - 24
        layout.const("d", *_fixed_f64(linear_acceleration_covariance, 9, "linear_acceleration_covariance"))
        packer, self._c = layout.build()
        self._pack = packer.pack
        #: Byte offsets in a message of the stamp (int32 sec, uint32 nanosec), the orientation (4
        #: doubles), the angular velocity and the linear acceleration (3 each), for code that writes
        #: them into `encode`'s bytes in place.
        self.offsets = (4, orientation_at, angular_velocity_at, linear_acceleration_at)

    def encode(  # noqa: PLR0917 - the hot path takes plain numbers positionally
        self,
        stamp_ns: int,
        qx: float,
        qy: float,
        qz: float,
        qw: float,
        wx: float,
        wy: float,
        wz: float,
        ax: float,
        ay: float,
        az: float,
    ) -> bytes:
        """Encode orientation (quaternion), angular velocity (rad/s) and linear acceleration (m/s²)."""
        sec, nanosec = divmod(stamp_ns, _NS)
        c = self._c
        return self._pack(c[0], sec, nanosec, c[1], qx, qy, qz, qw, c[2], wx, wy, wz, c[3], ax, ay, az, c[4])


class OdometryEncoder:
    """`nav_msgs/msg/Odometry` of a planar robot (z, roll and pitch are zero)."""

    msgtype: ClassVar[str] = "nav_msgs/msg/Odometry"

    def __init__(
        self,
        frame_id: str = "odom",
        child_frame_id: str = "base_footprint",
        *,
        pose_covariance: ArrayLike | None = None,
        twist_covariance: ArrayLike | None = None,
    ) -> None:
        """Precompute the layout.

        Args:
            frame_id: The pose's frame.
            child_frame_id: The twist's frame (the robot).
            pose_covariance: Default 6x6 row-major pose covariance (zeros if None).
            twist_covariance: Default 6x6 row-major twist covariance (zeros if None).
        """
        layout = Layout()
        layout.var_time()
        layout.const_string(prefixed(frame_id))
        layout.const_string(prefixed(child_frame_id))
        layout.var("position.xy", "d", 2)
        layout.const("d", 0.0, 0.0, 0.0)  # position.z, orientation.x, orientation.y
        layout.var("orientation.zw", "d", 2)
        layout.var_bytes("pose.covariance", 288, 8)
        layout.var("linear.x", "d")
        layout.const("d", 0.0, 0.0, 0.0, 0.0)  # linear.y, linear.z, angular.x, angular.y
        layout.var("angular.z", "d")
        layout.var_bytes("twist.covariance", 288, 8)
        packer, self._c = layout.build()
        self._pack = packer.pack
        self._pose_cov = _f64_bytes(_fixed_f64(pose_covariance, 36, "pose_covariance"), 36, "pose_covariance")
        self._twist_cov = _f64_bytes(_fixed_f64(twist_covariance, 36, "twist_covariance"), 36, "twist_covariance")

    def encode(  # noqa: PLR0917 - the hot path takes plain numbers positionally
        self,
        stamp_ns: int,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        vx_m_s: float,
        wz_rad_s: float,
        pose_covariance: ArrayLike | None = None,
        twist_covariance: ArrayLike | None = None,
    ) -> bytes:
        """Encode a planar pose and body twist; covariances (6x6) default to the constructor's."""
        sec, nanosec = divmod(stamp_ns, _NS)
        qz, qw = _planar_quat(yaw_rad)
        pose_cov = self._pose_cov if pose_covariance is None else _f64_bytes(pose_covariance, 36, "pose_covariance")
        twist_cov = (
            self._twist_cov if twist_covariance is None else _f64_bytes(twist_covariance, 36, "twist_covariance")
        )
        c = self._c
        return self._pack(c[0], sec, nanosec, c[1], x_m, y_m, c[2], qz, qw, pose_cov, vx_m_s, c[3], wz_rad_s, twist_cov)


class TFEncoder:
    """`tf2_msgs/msg/TFMessage` for a fixed list of (parent, child) frame pairs, all at one stamp."""

    msgtype: ClassVar[str] = "tf2_msgs/msg/TFMessage"

    def __init__(self, pairs: Sequence[tuple[str, str]]) -> None:
        """Precompute the layout.

        Args:
            pairs: `(parent_frame, child_frame)` for each transform, in message order.
        """
        if not pairs:
            msg = "TFEncoder needs at least one (parent, child) frame pair"
            raise BagError(msg)
        self.pairs = tuple((prefixed(parent), prefixed(child)) for parent, child in pairs)
        layout = Layout()
        layout.const_count(len(pairs))
        for parent, child in self.pairs:
            layout.var_time()
            layout.const_string(parent)
            layout.const_string(child)
            layout.var("transform", "d", 7)
        # Constant runs: the encapsulation and count, then the frame ids before each transform.
        packer, self._c = layout.build()
        self._pack = packer.pack

    def encode(self, stamp_ns: int, poses: Sequence[Sequence[float]] | NDArray[np.float64]) -> bytes:
        """Encode one pose `(x, y, z, qx, qy, qz, qw)` per frame pair."""
        sec, nanosec = divmod(stamp_ns, _NS)
        c = self._c
        try:
            # The common cases (one transform from odometry, two wheels) without a loop.
            if len(c) == 2:
                (p0,) = poses
                return self._pack(c[0], sec, nanosec, c[1], *p0)
            if len(c) == 3:
                p0, p1 = poses
                return self._pack(c[0], sec, nanosec, c[1], *p0, sec, nanosec, c[2], *p1)
            args: list[Any] = [c[0]]
            for const, pose in zip(c[1:], poses, strict=True):
                args.append(sec)
                args.append(nanosec)
                args.append(const)
                args.extend(pose)
            return self._pack(*args)
        except (ValueError, struct.error):
            msg = f"TFEncoder for {len(self.pairs)} frame pairs needs as many poses of 7 values, got {len(poses)}"
            raise BagError(msg) from None

    def encode_planar(self, stamp_ns: int, x_m: float, y_m: float, yaw_rad: float) -> bytes:
        """Encode a single planar transform (e.g. odom → base_footprint); needs one frame pair."""
        if len(self.pairs) != 1:
            msg = f"encode_planar needs a TFEncoder with one frame pair, this one has {len(self.pairs)}"
            raise BagError(msg)
        sec, nanosec = divmod(stamp_ns, _NS)
        qz, qw = _planar_quat(yaw_rad)
        c = self._c
        return self._pack(c[0], sec, nanosec, c[1], x_m, y_m, 0.0, 0.0, 0.0, qz, qw)


class JointStateEncoder:
    """`sensor_msgs/msg/JointState` for fixed joints (effort left empty, as Gazebo publishes it)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/JointState"

    def __init__(self, names: Sequence[str], frame_id: str = "", *, with_effort: bool = False) -> None:
        """Precompute the layout.

        Args:
            names: Joint names, in array order.
            frame_id: Header frame (Gazebo leaves it empty).
            with_effort: Whether messages carry efforts (N·m) too.
        """
        n = len(names)
        layout = Layout()
        layout.var_time()
        layout.const_string(frame_id)
        layout.const_count(n)
        for name in names:
            layout.const_string(name)
        layout.const_count(n)
        layout.var("position", "d", n)
        layout.const_count(n)
        layout.var("velocity", "d", n)
        layout.const_count(n if with_effort else 0)
        if with_effort:
            layout.var("effort", "d", n)
        packer, self._c = layout.build()
        self._pack = packer.pack
        self.names = tuple(names)
        self.with_effort = with_effort

    def encode(
        self,
        stamp_ns: int,
        position: Sequence[float] | NDArray[np.float64],
        velocity: Sequence[float] | NDArray[np.float64],
        effort: Sequence[float] | NDArray[np.float64] = (),
    ) -> bytes:
        """Encode positions (rad), velocities (rad/s) and, if configured, efforts (N·m) per joint."""
        sec, nanosec = divmod(stamp_ns, _NS)
        c = self._c
        try:
            if self.with_effort:
                return self._pack(c[0], sec, nanosec, c[1], *position, c[2], *velocity, c[3], *effort)
            return self._pack(c[0], sec, nanosec, c[1], *position, c[2], *velocity, c[3])
        except struct.error:
            msg = f"JointStateEncoder for {len(self.names)} joints got arrays of another length"
            raise BagError(msg) from None


class MotorStateEncoder:
    """`twin_msgs/msg/MotorState`: voltage, current, torque and speed per drive joint."""

    msgtype: ClassVar[str] = "twin_msgs/msg/MotorState"

    def __init__(self, names: Sequence[str], frame_id: str = "") -> None:
        """Precompute the layout for the joints `names` (in array order)."""
        n = len(names)
        layout = Layout()
        layout.var_time()
        layout.const_string(frame_id)
        layout.const_count(n)
        for name in names:
            layout.const_string(name)
        for field in ("voltage_v", "current_a", "torque_nm", "velocity_rad_s", "velocity_command_rad_s"):
            layout.const_count(n)
            layout.var(field, "d", n)
        layout.const_count(n)
        layout.var("saturated", "?", n)
        packer, self._c = layout.build()
        self._pack = packer.pack
        self.names = tuple(names)

    def encode(
        self,
        stamp_ns: int,
        voltage_v: Sequence[float] | NDArray[np.float64],
        current_a: Sequence[float] | NDArray[np.float64],
        torque_nm: Sequence[float] | NDArray[np.float64],
        velocity_rad_s: Sequence[float] | NDArray[np.float64],
        *,
        velocity_command_rad_s: Sequence[float] | NDArray[np.float64] | None = None,
        saturated: Sequence[bool] | None = None,
    ) -> bytes:
        """Encode one value per joint for each quantity (the command defaults to NaN, saturated to false)."""
        sec, nanosec = divmod(stamp_ns, _NS)
        c = self._c
        n = len(self.names)
        command = (math.nan,) * n if velocity_command_rad_s is None else velocity_command_rad_s
        flags = (False,) * n if saturated is None else saturated
        try:
            return self._pack(
                c[0],
                sec,
                nanosec,
                c[1],
                *voltage_v,
                c[2],
                *current_a,
                c[3],
                *torque_nm,
                c[4],
                *velocity_rad_s,
                c[5],
                *command,
                c[6],
                *flags,
            )
        except struct.error:
            msg = f"MotorStateEncoder for {len(self.names)} joints got arrays of another length"
            raise BagError(msg) from None


class ScanEncoder:
    """`sensor_msgs/msg/LaserScan` with a fixed geometry (as a lidar driver publishes it)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/LaserScan"

    def __init__(
        self,
        frame_id: str,
        *,
        angle_min_rad: float,
        angle_max_rad: float,
        angle_increment_rad: float,
        time_increment_s: float,
        scan_time_s: float,
        range_min_m: float,
        range_max_m: float,
        samples: int,
        with_intensities: bool = True,
    ) -> None:
        """Precompute everything but the stamp and the ranges.

        Args:
            frame_id: The lidar frame (`base_scan` on a TurtleBot3).
            angle_min_rad: Angle of the first beam.
            angle_max_rad: Angle of the last beam.
            angle_increment_rad: Angle between beams.
            time_increment_s: Time between beams.
            scan_time_s: Time between scans.
            range_min_m: Shortest valid range.
            range_max_m: Longest valid range.
            samples: Beams per scan.
            with_intensities: Whether scans carry intensities; Gazebo's plugin sends `samples`
                zeros when the sensor has none.
        """
        self.samples = samples
        self.with_intensities = with_intensities
        self._prefix_pack = struct.Struct("<4siI").pack
        # Everything after the stamp up to the ranges' data is constant: all 4-byte aligned.
        body = string_bytes(prefixed(frame_id))
        body += bytes((-(8 + len(body))) % 4)
        body += struct.pack(
            "<7fI",
            angle_min_rad,
            angle_max_rad,
            angle_increment_rad,
            time_increment_s,
            scan_time_s,
            range_min_m,
            range_max_m,
            samples,
        )
        self._body = body
        self._intensity_count = struct.pack("<I", samples if with_intensities else 0)
        self._zero_intensities = bytes(4 * samples) if with_intensities else b""

    def encode(
        self,
        stamp_ns: int,
        ranges_m: NDArray[np.float32] | NDArray[np.float64],
        intensities: NDArray[np.float32] | None = None,
    ) -> bytes:
        """Encode one scan; `ranges_m` has `samples` values (float32 is copied without conversion)."""
        sec, nanosec = divmod(stamp_ns, _NS)
        ranges = ranges_m.astype(_F32, copy=False).tobytes()
        if len(ranges) != 4 * self.samples:
            msg = f"ScanEncoder for {self.samples} beams got {len(ranges) // 4} ranges"
            raise BagError(msg)
        if intensities is None:
            values = self._zero_intensities
        else:
            values = intensities.astype(_F32, copy=False).tobytes()
            if len(values) != len(self._zero_intensities):
                msg = f"ScanEncoder got {len(values) // 4} intensities, expected {len(self._zero_intensities) // 4}"
                raise BagError(msg)
        return b"".join(
            (self._prefix_pack(ENCAPSULATION, sec, nanosec), self._body, ranges, self._intensity_count, values)
        )


class ImageEncoder:
    """`sensor_msgs/msg/Image` of a fixed size and encoding (a camera's frames)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/Image"

    def __init__(self, frame_id: str, *, width: int, height: int, encoding: str) -> None:
        """Precompute everything but the stamp and the pixels.

        Args:
            frame_id: The optical frame the image is in.
            width: Pixels per row.
            height: Rows.
            encoding: `rgb8`, `mono8` or `32FC1` (the bytes per pixel follow from it).
        """
        channels = {"rgb8": 3, "bgr8": 3, "mono8": 1, "32FC1": 4}
        if encoding not in channels:
            msg = f"ImageEncoder: encoding {encoding!r} is not one of {', '.join(channels)}"
            raise BagError(msg)
        self.size = width * height * channels[encoding]
        w = CdrWriter()
        w.string(prefixed(frame_id))
        w.pack("I", height, width)
        w.string(encoding)
        w.pack("B", 0)  # is_bigendian: little-endian float depth, as gazebo_ros publishes it
        w.pack("I", width * channels[encoding], self.size)
        self._body = w.getvalue()[len(ENCAPSULATION) :]
        self._prefix_pack = struct.Struct("<4siI").pack

    def encode(self, stamp_ns: int, pixels: NDArray[np.uint8] | NDArray[np.float32]) -> bytes:
        """Encode one frame; `pixels` is C-contiguous (height, width[, channels]) of the encoding's type."""
        data = pixels.tobytes()
        if len(data) != self.size:
            msg = f"ImageEncoder for {self.size} bytes got {len(data)}"
            raise BagError(msg)
        sec, nanosec = divmod(stamp_ns, _NS)
        # The frame id string starts right after the 8-byte stamp: every later alignment is fixed.
        return b"".join((self._prefix_pack(ENCAPSULATION, sec, nanosec), self._body, data))


class CompressedImageEncoder:
    """`sensor_msgs/msg/CompressedImage` (image_transport's compressed plugin: `format` names the encodings)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/CompressedImage"

    def __init__(self, frame_id: str, *, format: str) -> None:
        """Precompute the frame id and format.

        Args:
            frame_id: The optical frame.
            format: e.g. `rgb8; jpeg compressed bgr8`, as image_transport's compressed plugin writes it.
        """
        w = CdrWriter()
        w.string(prefixed(frame_id))
        w.string(format)
        body = w.getvalue()[len(ENCAPSULATION) :]
        self._body = body + bytes((-(8 + len(body))) % 4)
        self._prefix_pack = struct.Struct("<4siI").pack
        self._count = struct.Struct("<I").pack

    def encode(self, stamp_ns: int, data: bytes) -> bytes:
        """Encode one compressed frame."""
        sec, nanosec = divmod(stamp_ns, _NS)
        return b"".join((self._prefix_pack(ENCAPSULATION, sec, nanosec), self._body, self._count(len(data)), data))


class PointCloud2Encoder:
    """`sensor_msgs/msg/PointCloud2` of a fixed layout (an organised cloud from a depth camera)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/PointCloud2"

    FLOAT32: ClassVar[int] = 7  # sensor_msgs/PointField.FLOAT32

    def __init__(
        self,
        frame_id: str,
        *,
        width: int,
        height: int,
        fields: Sequence[tuple[str, int, int, int]],
        point_step: int,
        is_dense: bool = False,
    ) -> None:
        """Precompute everything but the stamp and the data.

        Args:
            frame_id: The frame of the points.
            width: Points per row.
            height: Rows (1 for an unorganised cloud).
            fields: (name, offset, datatype, count) per field.
            point_step: Bytes per point.
            is_dense: True when no point is invalid.
        """
        self.size = width * height * point_step
        w = CdrWriter()
        w.string(prefixed(frame_id))
        w.pack("I", height, width)
        w.count(len(fields))
        for name, offset, datatype, count in fields:
            w.string(name)
            w.pack("I", offset)
            w.pack("B", datatype)
            w.pack("I", count)
        w.pack("?", False)
        w.pack("I", point_step, point_step * width, self.size)
        self._body = w.getvalue()[len(ENCAPSULATION) :]
        self._dense = b"\x01" if is_dense else b"\x00"
        self._prefix_pack = struct.Struct("<4siI").pack

    def encode(self, stamp_ns: int, data: bytes) -> bytes:
        """Encode one cloud; `data` is `width * height * point_step` bytes."""
        if len(data) != self.size:
            msg = f"PointCloud2Encoder for {self.size} bytes got {len(data)}"
            raise BagError(msg)
        sec, nanosec = divmod(stamp_ns, _NS)
        return b"".join((self._prefix_pack(ENCAPSULATION, sec, nanosec), self._body, data, self._dense))


class CameraInfoEncoder:
    """`sensor_msgs/msg/CameraInfo` of a pinhole camera without distortion (as gazebo_ros_camera fills it)."""

    msgtype: ClassVar[str] = "sensor_msgs/msg/CameraInfo"

    def __init__(self, frame_id: str, *, width: int, height: int, K: Sequence[float], P: Sequence[float]) -> None:
        """Precompute the whole message but its stamp.

        Args:
            frame_id: The optical frame.
            width: Image width, pixels.
            height: Image height, pixels.
            K: The 3x3 camera matrix, row-major.
            P: The 3x4 projection matrix, row-major.
        """
        w = CdrWriter()
        w.string(prefixed(frame_id))
        w.pack("I", height, width)
        w.string("plumb_bob")
        w.count(5)
        w.pack("d", 0.0, 0.0, 0.0, 0.0, 0.0)
        w.pack("d", *_fixed_f64(K, 9, "K"))
        w.pack("d", 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        w.pack("d", *_fixed_f64(P, 12, "P"))
        w.pack("I", 0, 0, 0, 0, 0, 0)  # binning x, y; roi x_offset, y_offset, height, width
        w.pack("?", False)  # roi.do_rectify
        self._body = w.getvalue()[len(ENCAPSULATION) :]
        self._prefix_pack = struct.Struct("<4siI").pack

    def encode(self, stamp_ns: int) -> bytes:
        """Encode the camera info at a stamp."""
        sec, nanosec = divmod(stamp_ns, _NS)
        return self._prefix_pack(ENCAPSULATION, sec, nanosec) + self._body


class StringEncoder:
    """`std_msgs/msg/String` (e.g. `/robot_description`)."""

    msgtype: ClassVar[str] = "std_msgs/msg/String"

    def encode(self, text: str) -> bytes:
        """Encode `text`."""
        return ENCAPSULATION + string_bytes(text)


class LogEncoder:
    """`rcl_interfaces/msg/Log` (`/rosout`) for one logger name."""

    msgtype: ClassVar[str] = "rcl_interfaces/msg/Log"

    DEBUG: ClassVar[int] = 10
    INFO: ClassVar[int] = 20
    WARN: ClassVar[int] = 30
    ERROR: ClassVar[int] = 40
    FATAL: ClassVar[int] = 50

    def __init__(self, name: str = "twin") -> None:
        """Log lines from the logger `name` (the ROS node name in a ROS system)."""
        self.name = name

    def encode(
        self, stamp_ns: int, level: int, message: str, *, file: str = "", function: str = "", line: int = 0
    ) -> bytes:
        """Encode one log line; `level` is one of the class constants (10 DEBUG … 50 FATAL)."""
        w = CdrWriter()
        w.time(stamp_ns)
        w.pack("B", level)
        w.string(self.name)
        w.string(message)
        w.string(file)
        w.string(function)
        w.pack("I", line)
        return w.getvalue()

    def encode_line(self, stamp_ns: int, level: int, message: str, where: tuple[str, str, int]) -> bytes:
        """`encode` with the source location as one (file, function, line) argument."""
        file, function, line = where
        return self.encode(stamp_ns, level, message, file=file, function=function, line=line)


class BehaviorTreeLogEncoder:
    """`nav2_msgs/msg/BehaviorTreeLog` (Humble layout): status changes since the last message."""

    msgtype: ClassVar[str] = "nav2_msgs/msg/BehaviorTreeLog"

    def encode(self, stamp_ns: int, events: Sequence[tuple[int, str, str, str]]) -> bytes:
        """Encode `(t_ns, node_name, previous_status, current_status)` events (statuses: IDLE, RUNNING, …)."""
        w = CdrWriter()
        w.time(stamp_ns)
        w.count(len(events))
        for t_ns, node_name, previous, current in events:
            w.time(t_ns)
            w.string(node_name)
            w.string(previous)
            w.string(current)
        return w.getvalue()


class ContactEncoder:
    """`twin_msgs/msg/Contact`: the robot starting or ending a contact with the world."""

    msgtype: ClassVar[str] = "twin_msgs/msg/Contact"
    BEGIN: ClassVar[int] = 1
    END: ClassVar[int] = 2

    def __init__(self, frame_id: str = "odom") -> None:
        """Contacts with positions and normals in `frame_id`."""
        self.frame_id = prefixed(frame_id)

    def encode(
        self,
        stamp_ns: int,
        event: int,
        *,
        robot_collision: str,
        world_collision: str,
        position_m: Sequence[float],
        normal: Sequence[float],
        depth_m: float,
    ) -> bytes:
        """Encode one contact event (`BEGIN` or `END`)."""
        w = CdrWriter()
        w.header(stamp_ns, self.frame_id)
        w.pack("B", event)
        w.string(robot_collision)
        w.string(world_collision)
        w.pack("d", *position_m, *normal, depth_m)
        return w.getvalue()


class _StampedPoseLayout:
    """Shared by the pose encoders: header, then a planar or full pose, then an optional covariance."""

    def __init__(self, frame_id: str, *, covariance: ArrayLike | None, with_covariance: bool) -> None:
        layout = Layout()
        layout.var_time()
        layout.const_string(prefixed(frame_id))
        layout.var("pose", "d", 7)
        if with_covariance:
            layout.var_bytes("covariance", 288, 8)
        packer, self.consts = layout.build()
        self.pack = packer.pack
        self.covariance = _f64_bytes(_fixed_f64(covariance, 36, "covariance"), 36, "covariance")


class PoseWithCovarianceStampedEncoder:
    """`geometry_msgs/msg/PoseWithCovarianceStamped` (e.g. `/amcl_pose`, `/initialpose`)."""

    msgtype: ClassVar[str] = "geometry_msgs/msg/PoseWithCovarianceStamped"

    def __init__(self, frame_id: str = "map", *, covariance: ArrayLike | None = None) -> None:
        """Poses in `frame_id`; `covariance` (6x6 row-major) is the default per message."""
        self._l = _StampedPoseLayout(frame_id, covariance=covariance, with_covariance=True)

    def encode(
        self, stamp_ns: int, x_m: float, y_m: float, yaw_rad: float, covariance: ArrayLike | None = None
    ) -> bytes:
        """Encode a planar pose with its 6x6 covariance (the constructor's if None)."""
        sec, nanosec = divmod(stamp_ns, _NS)
        qz, qw = _planar_quat(yaw_rad)
        cov = self._l.covariance if covariance is None else _f64_bytes(covariance, 36, "covariance")
        c = self._l.consts
        return self._l.pack(c[0], sec, nanosec, c[1], x_m, y_m, 0.0, 0.0, 0.0, qz, qw, cov)


class PoseStampedEncoder:
    """`geometry_msgs/msg/PoseStamped` (e.g. `/goal_pose`)."""

    msgtype: ClassVar[str] = "geometry_msgs/msg/PoseStamped"

    def __init__(self, frame_id: str = "map") -> None:
        """Poses in `frame_id`."""
        self._l = _StampedPoseLayout(frame_id, covariance=None, with_covariance=False)

    def encode(self, stamp_ns: int, x_m: float, y_m: float, yaw_rad: float) -> bytes:
        """Encode a planar pose."""
        sec, nanosec = divmod(stamp_ns, _NS)
        qz, qw = _planar_quat(yaw_rad)
        c = self._l.consts
        return self._l.pack(c[0], sec, nanosec, c[1], x_m, y_m, 0.0, 0.0, 0.0, qz, qw)


def _planar_poses(poses: ArrayLike) -> NDArray[np.float64]:
    """`(N, 3)` planar `(x, y, yaw)` or `(N, 7)` full poses → `(N, 7)` float64."""
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim == 2 and arr.shape[1] == 7:
        return arr
    if arr.ndim == 2 and arr.shape[1] == 3:
        out = np.zeros((arr.shape[0], 7))
        out[:, 0:2] = arr[:, 0:2]
        out[:, 5] = np.sin(0.5 * arr[:, 2])
        out[:, 6] = np.cos(0.5 * arr[:, 2])
        return out
    if arr.size == 0:
        return np.zeros((0, 7))
    msg = f"poses must be an (N, 3) array of x, y, yaw or (N, 7) of x, y, z, qx, qy, qz, qw; got shape {arr.shape}"
    raise BagError(msg)


class PathEncoder:
    """`nav_msgs/msg/Path` (e.g. `/plan`): every pose carries the path's stamp and frame."""

    msgtype: ClassVar[str] = "nav_msgs/msg/Path"

    def __init__(self, frame_id: str = "map") -> None:
        """Paths in `frame_id`."""
        self.frame_id = frame_id = prefixed(frame_id)
        # The path's header, the pose count and the first PoseStamped (4-aligned after the count, so
        # its doubles may need padding that the others do not) are one struct.
        frame = string_bytes(frame_id)
        size = len(frame)
        pad_count = (-(8 + size)) % 4
        first_at = 8 + size + pad_count + 4
        pad_first = (-(first_at + 8 + size)) % 8
        self._empty = struct.Struct(f"<4siI{size}s{pad_count}xI").pack
        self._prefix = struct.Struct(f"<4siI{size}s{pad_count}xIiI{size}s{pad_first}x7d").pack
        self._frame_string = frame
        # Every PoseStamped after the first starts 8-aligned: stamp, frame id, padding, 7 doubles. A
        # block is a whole number of doubles: the header's bytes are written as doubles (a view).
        frame += bytes((-(8 + size)) % 8)
        self._frame = frame
        self._head = (8 + len(frame)) // 8  # doubles of header in a block

    def encode(self, stamp_ns: int, poses: ArrayLike) -> bytes:
        """Encode poses given as `(N, 3)` x, y, yaw or `(N, 7)` x, y, z, qx, qy, qz, qw."""
        arr = np.asarray(poses, dtype=np.float64)
        n = arr.shape[0] if arr.ndim == 2 else 0
        planar = arr.ndim == 2 and arr.shape[1] == 3
        if not planar:
            arr = _planar_poses(arr)
        sec, nanosec = divmod(stamp_ns, _NS)
        frame = self._frame_string
        if n == 0:
            return self._empty(ENCAPSULATION, sec, nanosec, frame, 0)
        if planar:
            x, y, yaw = arr[0].tolist()
            first = (x, y, 0.0, 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))
        else:
            first = tuple(arr[0].tolist())
        prefix = self._prefix(ENCAPSULATION, sec, nanosec, frame, n, sec, nanosec, frame, *first)
        if n == 1:
            return prefix
        head = np.frombuffer(_TIME.pack(sec, nanosec) + self._frame, dtype=_F64)
        h = self._head
        blocks = np.zeros((n - 1, h + 7))
        blocks[:, :h] = head
        if planar:
            blocks[:, h : h + 2] = arr[1:, :2]
            half = 0.5 * arr[1:, 2]
            blocks[:, h + 5] = np.sin(half)
            blocks[:, h + 6] = np.cos(half)
        else:
            blocks[:, h:] = arr[1:]
        return prefix + blocks.tobytes()


class NavigationFeedbackEncoder:
    """`twin_msgs/msg/NavigationFeedback` (`/navigate_to_pose/feedback`): NavigateToPose's feedback fields."""

    msgtype: ClassVar[str] = "twin_msgs/msg/NavigationFeedback"

    def __init__(self, frame_id: str = "map") -> None:
        """The current pose in `frame_id`."""
        layout = Layout()
        layout.var_time()
        layout.const_string(prefixed(frame_id))
        layout.var("pose", "d", 7)
        layout.var_time("navigation_time")
        layout.var_time("estimated_time_remaining")
        layout.var("number_of_recoveries", "h")
        layout.var("distance_remaining", "f")
        packer, self._consts = layout.build()
        self._pack = packer.pack

    def encode(
        self,
        stamp_ns: int,
        pose: tuple[float, float, float],
        times_ns: tuple[int, int],
        recoveries: int,
        distance_remaining_m: float,
    ) -> bytes:
        """Encode the feedback.

        Args:
            stamp_ns: The header stamp.
            pose: The robot's planar map pose (x m, y m, yaw rad).
            times_ns: Navigation time and estimated time remaining, ns.
            recoveries: Behaviours run for this goal.
            distance_remaining_m: Along the current path.
        """
        navigation_time_ns, eta_ns = times_ns
        sec, nanosec = divmod(stamp_ns, _NS)
        nav_sec, nav_ns = divmod(navigation_time_ns, _NS)
        eta_sec, eta_ns_part = divmod(eta_ns, _NS)
        qz, qw = _planar_quat(pose[2])
        c = self._consts
        return self._pack(
            c[0], sec, nanosec, c[1], pose[0], pose[1], 0.0, 0.0, 0.0, qz, qw,
            nav_sec, nav_ns, eta_sec, eta_ns_part, recoveries, distance_remaining_m,
        )  # fmt: skip


class ParticleCloudEncoder:
    """`nav2_msgs/msg/ParticleCloud` (`/particle_cloud`): weighted poses of AMCL's particles."""

    msgtype: ClassVar[str] = "nav2_msgs/msg/ParticleCloud"

    def __init__(self, frame_id: str = "map") -> None:
        """Particles in `frame_id`."""
        self.frame_id = frame_id = prefixed(frame_id)
        frame = string_bytes(frame_id)
        # stamp, frame id, (pad to 4) particle count, then padding so the particles start 8-aligned
        count_pad = (-(8 + len(frame))) % 4
        self._pad = (-(8 + len(frame) + count_pad + 4)) % 8
        self._prefix = struct.Struct(f"<4siI{len(frame)}s{count_pad}xI{self._pad}x")
        self._frame = frame

    def encode(self, stamp_ns: int, poses: ArrayLike, weights: ArrayLike) -> bytes:
        """Encode `(N, 3)` x, y, yaw (or `(N, 7)`) poses with their `N` weights."""
        arr = np.asarray(poses, dtype=np.float64)
        weight = np.asarray(weights, dtype=np.float64).reshape(-1)
        n = arr.shape[0] if arr.ndim == 2 else 0
        if arr.ndim != 2 or arr.shape[1] not in (3, 7) or weight.shape[0] != n:
            msg = (
                "ParticleCloudEncoder needs (N, 3) x, y, yaw or (N, 7) poses and N weights; "
                f"got poses of shape {arr.shape} and {weight.shape[0]} weights"
            )
            raise BagError(msg)
        # Each Particle is 8 doubles (pose, weight), 8-aligned: the sequence is one float64 block.
        block = np.zeros((n, 8))
        if arr.shape[1] == 7:
            block[:, :7] = arr
        else:
            block[:, 0:2] = arr[:, 0:2]
            half = 0.5 * arr[:, 2]
            block[:, 5] = np.sin(half)
            block[:, 6] = np.cos(half)
        block[:, 7] = weight
        sec, nanosec = divmod(stamp_ns, _NS)
        prefix = self._prefix.pack(ENCAPSULATION, sec, nanosec, self._frame, n)
        if n == 0:  # no particles, nothing to align
            return prefix[: len(prefix) - self._pad]
        return prefix + block.tobytes()


class OccupancyGridEncoder:
    """`nav_msgs/msg/OccupancyGrid` (e.g. `/map`): a fixed geometry, cells as int8 (-1 unknown, 0..100)."""

    msgtype: ClassVar[str] = "nav_msgs/msg/OccupancyGrid"

    def __init__(
        self,
        frame_id: str,
        resolution_m: float,
        width: int,
        height: int,
        origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        """A grid of `width` x `height` cells of `resolution_m`, its cell (0, 0) corner at `origin` (x, y, yaw)."""
        self.frame_id = prefixed(frame_id)
        self.resolution_m = resolution_m
        self.width = width
        self.height = height
        qz, qw = _planar_quat(origin[2])
        self._origin = (origin[0], origin[1], 0.0, 0.0, 0.0, qz, qw)

    def encode(self, stamp_ns: int, cells: NDArray[np.int8], *, map_load_time_ns: int | None = None) -> bytes:
        """Encode `height` rows of `width` cells (row-major, row 0 at the origin)."""
        data = np.ascontiguousarray(cells, dtype=np.int8).reshape(-1)
        if data.size != self.width * self.height:
            msg = f"OccupancyGridEncoder for {self.width}x{self.height} cells got {data.size}"
            raise BagError(msg)
        w = CdrWriter()
        w.header(stamp_ns, self.frame_id)
        w.time(stamp_ns if map_load_time_ns is None else map_load_time_ns)
        w.pack("f", self.resolution_m)
        w.pack("I", self.width, self.height)
        w.pack("d", *self._origin)
        w.count(data.size)
        w.raw(data.tobytes(), align=1)
        return w.getvalue()


class MarkerArrayEncoder:
    """`visualization_msgs/msg/MarkerArray` of solid shapes (e.g. `/obstacles`), the whole set each message.

    Each message starts with a DELETEALL marker, then one ADD marker per shape, so a viewer that
    reads only the latest message (a latched topic) draws exactly the shapes present then. A
    marker's bytes are one `struct` pack (stamp and pose vary, the rest is constant), built once
    per marker and alignment and reused.
    """

    msgtype: ClassVar[str] = "visualization_msgs/msg/MarkerArray"
    CUBE: ClassVar[int] = 1
    CYLINDER: ClassVar[int] = 3
    _ADD: ClassVar[int] = 0
    _DELETEALL: ClassVar[int] = 3
    _COUNT = struct.Struct("<I")

    def __init__(self, frame_id: str = "map", namespace: str = "obstacles") -> None:
        """Markers in `frame_id`, in marker namespace `namespace`."""
        self.frame_id = prefixed(frame_id)
        self.namespace = namespace
        self._layouts: dict[tuple[object, ...], tuple[Callable[..., bytes], bytes, bytes, int]] = {}

    def encode(
        self,
        stamp_ns: int,
        markers: Sequence[
            tuple[int, int, Sequence[float], Sequence[float], Sequence[float], str]
        ],  # (id, type, pose x y z qx qy qz qw, scale x y z, rgba, text)
    ) -> bytes:
        """Encode a DELETEALL, then each marker as (id, type, pose (7), scale (3), rgba (4), text)."""
        sec, nanosec = divmod(stamp_ns, _NS)
        parts = [ENCAPSULATION, self._COUNT.pack(len(markers) + 1)]
        offset = 4
        delete_all = (0, 0, (0.0,) * 6 + (1.0,), (0.0,) * 3, (0.0,) * 4, "")
        for action, marker in [(self._DELETEALL, delete_all)] + [(self._ADD, m) for m in markers]:
            marker_id, kind, pose, scale, rgba, text = marker
            key = (marker_id, kind, action, tuple(scale), tuple(rgba), text, offset % 8)
            layout = self._layouts.get(key)
            if layout is None:
                layout = self._layouts[key] = self._layout(key, offset % 8)
            pack, head, tail, size = layout
            parts.append(pack(sec, nanosec, head, *pose, tail))
            offset += size
        return b"".join(parts)

    def _layout(self, key: tuple[object, ...], start: int) -> tuple[Callable[..., bytes], bytes, bytes, int]:
        """One marker's struct at `start` (mod 8) from the CDR origin: (pack, constant runs, its size)."""
        marker_id, kind, action, scale, rgba, text, _ = key
        assert isinstance(scale, tuple) and isinstance(rgba, tuple) and isinstance(text, str)
        # Start at 8 + start so the leading padding to 4 is counted from the right place.
        origin = 8 + start
        layout = Layout(offset=origin)
        layout.var_time()
        layout.const_string(self.frame_id)
        layout.const_string(self.namespace)
        layout.const("i", int(marker_id), int(kind), int(action))  # type: ignore[call-overload]
        layout.var("pose", "d", 7)
        layout.const("d", *scale)
        layout.const("f", *rgba)
        layout.const("i", 0)  # lifetime: 0, forever
        layout.const("I", 0)
        layout.const("B", 0)  # frame_locked
        layout.const_count(0)  # points
        layout.const_count(0)  # colors
        layout.const_string("")  # texture_resource
        layout.const("i", 0)  # texture: an empty sensor_msgs/CompressedImage (header, format, data)
        layout.const("I", 0)
        layout.const_string("")
        layout.const_string("")
        layout.const_count(0)
        layout.const_count(0)  # uv_coordinates
        layout.const_string(text)
        layout.const_string("")  # mesh_resource
        layout.const_string("")  # mesh_file: filename, data
        layout.const_count(0)
        layout.const("B", 0)  # mesh_use_embedded_materials
        packer, consts = layout.build()
        assert layout.slots == ["stamp.sec", "stamp.nanosec", "const"] + ["pose"] * 7 + ["const"], layout.slots
        return packer.pack, consts[0], consts[1], layout.offset - origin
