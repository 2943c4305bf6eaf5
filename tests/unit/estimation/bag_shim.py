"""Test-only stand-in for `twin.bag` (built on rosbags) while the real one is on another branch.

It offers only what `twin ekf replay` calls: `open_bag(path).topics[*].name`, `read_messages(path,
topics)`, `Recorder(path, storage=, distro=)` with `add_topic` / `write`, and `OdometryEncoder`. The
tests use the real `twin.bag` as soon as it can be imported (see `bag_module` in conftest).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import SimpleNamespace, TracebackType
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

_STORE = get_typestore(Stores.ROS2_HUMBLE)


def open_bag(path: Path) -> SimpleNamespace:
    with AnyReader([Path(path)], default_typestore=_STORE) as reader:
        topics = tuple(SimpleNamespace(name=c.topic, msgtype=c.msgtype) for c in reader.connections)
    return SimpleNamespace(topics=topics)


def read_messages(path: Path, topics: Sequence[str]) -> Iterator[tuple[str, str, int, Any]]:
    with AnyReader([Path(path)], default_typestore=_STORE) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        for conn, t_ns, raw in reader.messages(connections=conns):
            yield conn.topic, conn.msgtype, t_ns, reader.deserialize(raw, conn.msgtype)


class OdometryEncoder:
    msgtype = "nav_msgs/msg/Odometry"

    def __init__(self, frame_id: str = "odom", child_frame_id: str = "base_footprint") -> None:
        self.frame_id, self.child_frame_id = frame_id, child_frame_id

    def encode(
        self,
        stamp_ns: int,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        vx_m_s: float,
        wz_rad_s: float,
        pose_covariance: Any,
        twist_covariance: Any,
    ) -> bytes:
        t = _STORE.types
        stamp = t["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=self.frame_id)
        point = t["geometry_msgs/msg/Point"](x=x_m, y=y_m, z=0.0)
        quat = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2))
        pose = t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](position=point, orientation=quat),
            covariance=np.asarray(pose_covariance, dtype=np.float64),
        )
        vec = t["geometry_msgs/msg/Vector3"]
        twist = t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=vec(x=vx_m_s, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=wz_rad_s)
            ),
            covariance=np.asarray(twist_covariance, dtype=np.float64),
        )
        msg = t["nav_msgs/msg/Odometry"](header=header, child_frame_id=self.child_frame_id, pose=pose, twist=twist)
        return bytes(_STORE.serialize_cdr(msg, self.msgtype))


class Recorder:
    def __init__(self, path: Path, *, storage: str = "mcap", distro: str = "humble") -> None:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self._writer = Writer(Path(path), version=8, storage_plugin=plugin)
        self._writer.open()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._writer.close()

    def add_topic(self, topic: str, msgtype: str) -> Any:
        return self._writer.add_connection(topic, msgtype, typestore=_STORE)

    def write(self, handle: Any, t_ns: int, data: bytes) -> None:
        self._writer.write(handle, t_ns, data)
