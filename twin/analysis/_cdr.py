"""Fast readers of the few CDR layouts analysis reads millions of times (odometry, poses, twists, scans, stamps).

Decoding every message of a long bag into rosbags dataclasses costs tens of microseconds each;
these read the fields analysis needs straight from the serialized bytes (XCDR1, as every ROS 2
distro records) in one or two `struct` calls. Offsets are relative to the byte after the 4-byte
encapsulation header, where CDR alignment is counted from.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag.typesys import TypeRegistry

__all__ = [
    "PoseSample",
    "clock_ns",
    "pose_reader",
    "scan_ranges",
    "stamp_kind",
    "stamp_reader",
    "tf_frames",
    "twist_reader",
    "type_store",
    "type_store_registry",
    "yaw_of",
]

_BASE = 4  # the encapsulation header


def _fmt(buf: bytes, code: str) -> str:
    return ("<" if buf[1] & 1 else ">") + code


def _align(off: int, n: int) -> int:
    return off + (-(off - _BASE)) % n


def _skip_string(buf: bytes, off: int) -> int:
    off = _align(off, 4)
    (n,) = struct.unpack_from(_fmt(buf, "I"), buf, off)
    return off + 4 + int(n)


def _stamp(buf: bytes, off: int) -> int:
    sec, nsec = struct.unpack_from(_fmt(buf, "iI"), buf, off)
    return int(sec) * 1_000_000_000 + int(nsec)


def _after_header(buf: bytes) -> int:
    return _skip_string(buf, _BASE + 8)


def yaw_of(qx: float, qy: float, qz: float, qw: float) -> float:
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


#: (header stamp ns, x m, y m, yaw rad, v m/s or nan, yaw rate rad/s or nan)
PoseSample = tuple[int, float, float, float, float, float]


def _odometry(buf: bytes) -> PoseSample:
    off = _align(_skip_string(buf, _after_header(buf)), 8)
    f = _fmt(buf, "7d")
    x, y, _z, qx, qy, qz, qw = struct.unpack_from(f, buf, off)
    vx, _vy, _vz, _wx, _wy, wz = struct.unpack_from(_fmt(buf, "6d"), buf, off + 56 + 288)
    return (_stamp(buf, _BASE), x, y, yaw_of(qx, qy, qz, qw), vx, wz)


def _pose_stamped(buf: bytes) -> PoseSample:
    off = _align(_after_header(buf), 8)
    x, y, _z, qx, qy, qz, qw = struct.unpack_from(_fmt(buf, "7d"), buf, off)
    return (_stamp(buf, _BASE), x, y, yaw_of(qx, qy, qz, qw), math.nan, math.nan)


_POSE_READERS: dict[str, Callable[[bytes], PoseSample]] = {
    "nav_msgs/msg/Odometry": _odometry,
    "geometry_msgs/msg/PoseWithCovarianceStamped": _pose_stamped,
    "geometry_msgs/msg/PoseStamped": _pose_stamped,
}


def pose_reader(msgtype: str) -> Callable[[bytes], PoseSample] | None:
    """The reader of a pose-carrying type (Odometry, PoseStamped, PoseWithCovarianceStamped), or None."""
    return _POSE_READERS.get(msgtype)


def _twist(buf: bytes) -> tuple[int | None, float, float]:
    vx, _vy, _vz, _wx, _wy, wz = struct.unpack_from(_fmt(buf, "6d"), buf, _BASE)
    return (None, vx, wz)


def _twist_stamped(buf: bytes) -> tuple[int | None, float, float]:
    off = _align(_after_header(buf), 8)
    vx, _vy, _vz, _wx, _wy, wz = struct.unpack_from(_fmt(buf, "6d"), buf, off)
    return (_stamp(buf, _BASE), vx, wz)


def twist_reader(msgtype: str) -> Callable[[bytes], tuple[int | None, float, float]] | None:
    """The reader of a velocity command type (Twist or TwistStamped): (stamp ns or None, v m/s, ω rad/s)."""
    return {"geometry_msgs/msg/Twist": _twist, "geometry_msgs/msg/TwistStamped": _twist_stamped}.get(msgtype)


def scan_ranges(buf: bytes) -> tuple[int, float, float, float, float, float, NDArray[np.float32]]:
    """(stamp ns, angle_min, angle_increment, range_min, range_max, unused, ranges) of a LaserScan."""
    off = _align(_after_header(buf), 4)
    a_min, _a_max, a_inc, _t_inc, _scan_t, r_min, r_max = struct.unpack_from(_fmt(buf, "7f"), buf, off)
    off += 28
    (n,) = struct.unpack_from(_fmt(buf, "I"), buf, off)
    ranges = np.frombuffer(buf, dtype=np.dtype(_fmt(buf, "f4")), count=int(n), offset=off + 4)
    return (_stamp(buf, _BASE), a_min, a_inc, r_min, r_max, 0.0, ranges)


def _first_stamp_tf(buf: bytes) -> int | None:
    (n,) = struct.unpack_from(_fmt(buf, "I"), buf, _BASE)
    return _stamp(buf, _BASE + 4) if n else None


def tf_frames(buf: bytes) -> tuple[str, str] | None:
    """(frame_id, child_frame_id) of a TFMessage's first transform, or None when it has none."""
    (n,) = struct.unpack_from(_fmt(buf, "I"), buf, _BASE)
    if not n:
        return None
    frame_end = _skip_string(buf, _BASE + 12)  # after the count and the stamp
    child_end = _skip_string(buf, frame_end)
    frame = bytes(buf[_BASE + 16 : frame_end - 1])  # without the terminating NUL
    child = bytes(buf[_align(frame_end, 4) + 4 : child_end - 1])
    return frame.decode("utf-8", "replace"), child.decode("utf-8", "replace")


def log_name(buf: bytes) -> str:
    """The logger name of an `rcl_interfaces/Log` (`/rosout`): `robot1.amcl`, `twin`."""
    at = _align(_BASE + 8 + 1, 4)  # after the stamp and the level byte
    (n,) = struct.unpack_from(_fmt(buf, "I"), buf, at)
    return bytes(buf[at + 4 : at + 4 + max(n - 1, 0)]).decode("utf-8", "replace")


def _first_stamp(buf: bytes) -> int | None:
    return _stamp(buf, _BASE)


def clock_ns(buf: bytes) -> int:
    """The time of a `rosgraph_msgs/Clock`, ns."""
    return _stamp(buf, _BASE)


@functools.cache
def type_store_registry() -> TypeRegistry:
    """The registry of Humble's standard types plus nav2_msgs and twin_msgs (built on first use, read-only after)."""
    return TypeRegistry()


def type_store() -> Any:
    """Humble's standard types plus nav2_msgs and twin_msgs (one store, built on first use, read-only after)."""
    return type_store_registry().store


def _fielddefs() -> dict[str, object]:
    fielddefs: dict[str, object] = type_store().fielddefs
    return fielddefs


def stamp_kind(msgtype: str) -> int:
    """Where a type's stamp is: 0 nowhere, 1 at the start (a header or Time), 2 TFMessage's first transform."""
    if msgtype == "tf2_msgs/msg/TFMessage":
        return 2
    return 1 if stamp_reader(msgtype) is not None else 0


def stamp_reader(msgtype: str) -> Callable[[bytes], int | None] | None:
    """The reader of a message's own time stamp (its header's, or a leading `builtin_interfaces/Time`).

    None for types that carry no stamp first (Twist, String, ...) or that the type store does
    not know.
    """
    if msgtype == "tf2_msgs/msg/TFMessage":
        return _first_stamp_tf
    fielddefs: Any = _fielddefs().get(msgtype)
    if not fielddefs or not fielddefs[1]:
        return None
    _name, (_kind, sub) = fielddefs[1][0]
    if sub in ("std_msgs/msg/Header", "builtin_interfaces/msg/Time"):
        return _first_stamp
    return None
