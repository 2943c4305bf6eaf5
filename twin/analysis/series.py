"""Time series of the standard message types a bag carries, for a plot each (any robot's bag).

The report's fixed sections read the TurtleBot3 topics (`/odom`, `/cmd_vel`, `/scan`); this module
adds a plot for every topic of a standard type those leave out: an IMU's rates and accelerations,
joint positions and velocities, a battery, a GNSS fix, other Twist and LaserScan topics. Each topic
is decoded at a stride that keeps a few thousand samples, so a long bag costs what a short one does.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["SERIES_KINDS", "TopicSeries", "series_kind"]

F64 = NDArray[np.float64]

#: Samples kept per topic (about): the plots thin to 4000 points anyway.
_SAMPLES = 3000
_MAX_JOINTS = 6


def _imu(msg: Any) -> list[float]:
    w, a = msg.angular_velocity, msg.linear_acceleration
    return [w.x, w.y, w.z, a.x, a.y, a.z]


def _twist(msg: Any) -> list[float]:
    t = msg.twist if hasattr(msg, "twist") else msg
    return [t.linear.x, t.linear.y, t.angular.z]


def _battery(msg: Any) -> list[float]:
    return [msg.voltage, msg.current, msg.percentage]


def _fix(msg: Any) -> list[float]:
    return [msg.latitude, msg.longitude, msg.altitude]


def _scan(msg: Any) -> list[float]:
    r = np.asarray(msg.ranges, dtype=np.float64)
    ok = (r >= msg.range_min) & (r <= msg.range_max)
    return [float(r[ok].min()) if ok.any() else math.nan]


@dataclass(frozen=True, kw_only=True, slots=True)
class SeriesKind:
    """How one message type becomes a plot: its columns, grouped into panels (y label, column indices)."""

    name: str
    columns: tuple[str, ...]
    panels: tuple[tuple[str, tuple[int, ...]], ...]
    read: Callable[[Any], list[float]] | None  # None: JointState, whose columns come from its names


SERIES_KINDS: dict[str, SeriesKind] = {
    "sensor_msgs/msg/Imu": SeriesKind(
        name="imu",
        columns=("ω x", "ω y", "ω z", "a x", "a y", "a z"),
        panels=(("angular velocity (rad/s)", (0, 1, 2)), ("linear acceleration (m/s²)", (3, 4, 5))),
        read=_imu,
    ),
    "sensor_msgs/msg/JointState": SeriesKind(name="joints", columns=(), panels=(), read=None),
    "geometry_msgs/msg/Twist": SeriesKind(
        name="twist",
        columns=("linear x", "linear y", "angular z"),
        panels=(("linear (m/s)", (0, 1)), ("angular z (rad/s)", (2,))),
        read=_twist,
    ),
    "geometry_msgs/msg/TwistStamped": SeriesKind(
        name="twist",
        columns=("linear x", "linear y", "angular z"),
        panels=(("linear (m/s)", (0, 1)), ("angular z (rad/s)", (2,))),
        read=_twist,
    ),
    "sensor_msgs/msg/BatteryState": SeriesKind(
        name="battery",
        columns=("voltage", "current", "percentage"),
        panels=(("voltage (V)", (0,)), ("current (A)", (1,)), ("charge (0-1)", (2,))),
        read=_battery,
    ),
    "sensor_msgs/msg/NavSatFix": SeriesKind(
        name="gnss",
        columns=("latitude", "longitude", "altitude"),
        panels=(("latitude (deg)", (0,)), ("longitude (deg)", (1,)), ("altitude (m)", (2,))),
        read=_fix,
    ),
    "sensor_msgs/msg/LaserScan": SeriesKind(
        name="scan", columns=("min range",), panels=(("min valid range (m)", (0,)),), read=_scan
    ),
}


def series_kind(msgtype: str) -> SeriesKind | None:
    """The plot a message type gets (by its full name), or None."""
    return SERIES_KINDS.get(msgtype)


@dataclass(kw_only=True, slots=True)
class TopicSeries:
    """One topic's decoded samples: record time and a row of floats per kept message."""

    topic: str
    kind: SeriesKind
    stride: int
    columns: tuple[str, ...] = ()
    panels: tuple[tuple[str, tuple[int, ...]], ...] = ()
    t_ns: array[int] = field(default_factory=lambda: array("q"))
    values: array[float] = field(default_factory=lambda: array("d"))
    seen: int = 0

    @classmethod
    def for_topic(cls, topic: str, kind: SeriesKind, message_count: int) -> TopicSeries:
        """A series keeping about `_SAMPLES` of the topic's messages."""
        stride = max(1, message_count // _SAMPLES)
        return cls(topic=topic, kind=kind, stride=stride, columns=kind.columns, panels=kind.panels)

    def wants(self) -> bool:
        """Count one message; whether it is one to keep (every `stride`-th)."""
        keep = self.seen % self.stride == 0
        self.seen += 1
        return keep

    def add(self, t_ns: int, msg: Any) -> None:
        """Keep one decoded message recorded at `t_ns`."""
        row = self.kind.read(msg) if self.kind.read is not None else self._joints(msg)
        if row is None:
            return
        self.t_ns.append(t_ns)
        self.values.extend(float(v) for v in row)

    def _joints(self, msg: Any) -> list[float] | None:
        names = [str(n) for n in msg.name]
        if not self.columns:
            if not names:
                return None
            chosen = tuple(names[:_MAX_JOINTS])
            n = len(chosen)
            self.columns = tuple(f"{j} position" for j in chosen) + tuple(f"{j} velocity" for j in chosen)
            self.panels = (
                ("position (rad or m)", tuple(range(n))),
                ("velocity (rad/s or m/s)", tuple(range(n, 2 * n))),
            )
        n = len(self.columns) // 2
        joints = [c.removesuffix(" position") for c in self.columns[:n]]
        index = {name: i for i, name in enumerate(names)}
        pos, vel = list(msg.position), list(msg.velocity)

        def at(values: list[float], joint: str) -> float:
            i = index.get(joint)
            return float(values[i]) if i is not None and i < len(values) else math.nan

        return [at(pos, j) for j in joints] + [at(vel, j) for j in joints]

    def arrays(self) -> tuple[NDArray[np.int64], F64]:
        """(record times ns, shape (N, columns) values)."""
        t = np.frombuffer(self.t_ns, dtype=np.int64) if self.t_ns else np.zeros(0, np.int64)
        width = max(len(self.columns), 1)
        v = np.frombuffer(self.values, dtype=np.float64).reshape(-1, width) if self.values else np.zeros((0, width))
        return t, v
