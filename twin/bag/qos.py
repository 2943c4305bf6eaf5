"""QoS profiles as a ROS 2 recorder stores them, and the two ways rosbag2 writes them down.

`ros2 bag record` stores, per topic, the QoS profiles its publishers *offered*. DDS reports an
offered profile with history UNKNOWN and depth 0 (history is not part of the wire contract), and
with "infinite" durations as `{sec: 9223372036, nsec: 854775807}` (`RMW_DURATION_INFINITE`).

rosbag2 writes the list as YAML in two forms:

* metadata version <= 8 (Humble, Iron): a YAML *string* holding a list whose policies are the
  integer values of the rmw enums. Humble's parser (`rosbag2_transport/qos.cpp`) only reads this.
* metadata version 9 (Jazzy and later): a YAML *sequence* with the policies as names
  (`reliable`, `transient_local`, ...). Jazzy's parser reads both forms.
"""

from __future__ import annotations

import enum
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

__all__ = [
    "QOS_BEST_EFFORT",
    "QOS_LATCHED",
    "QOS_RELIABLE",
    "QOS_ROSOUT",
    "Durability",
    "History",
    "Liveliness",
    "QosDuration",
    "QosProfile",
    "Reliability",
    "default_qos",
    "is_infinite",
    "parse_qos_profiles",
    "qos_profiles_to_yaml",
    "qos_summary",
]


class History(enum.IntEnum):
    """`rmw_qos_history_policy_e`."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Reliability(enum.IntEnum):
    """`rmw_qos_reliability_policy_e` (BEST_AVAILABLE exists from Iron on)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Durability(enum.IntEnum):
    """`rmw_qos_durability_policy_e` (BEST_AVAILABLE exists from Iron on)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Liveliness(enum.IntEnum):
    """`rmw_qos_liveliness_policy_e` (2 was MANUAL_BY_NODE, deprecated; BEST_AVAILABLE from Iron on)."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_NODE = 2
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


class QosDuration(NamedTuple):
    """An rmw duration: whole seconds and nanoseconds."""

    sec: int
    nsec: int


#: `RMW_DURATION_INFINITE` as ROS 2 writes it into bags.
INFINITE = QosDuration(9223372036, 854775807)
#: Durations that mean the same in older bags: Foxy's rmw wrote infinity as the largest 32-bit
#: seconds and nanoseconds, and 0 is `RMW_DURATION_UNSPECIFIED`, the default, which for deadline,
#: lifespan and liveliness lease is infinite.
_ALSO_INFINITE = frozenset({QosDuration(2147483647, 4294967295), QosDuration(0, 0)})


def is_infinite(duration: QosDuration) -> bool:
    """Whether a recorded QoS duration means "no limit", in any distro's spelling."""
    return duration == INFINITE or duration in _ALSO_INFINITE


@dataclass(frozen=True, kw_only=True, slots=True)
class QosProfile:
    """One offered QoS profile, field for field as rosbag2 records it."""

    history: History = History.UNKNOWN
    depth: int = 0
    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    deadline: QosDuration = INFINITE
    lifespan: QosDuration = INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease_duration: QosDuration = INFINITE
    avoid_ros_namespace_conventions: bool = False


#: What most publishers offer (`rclcpp::QoS(10)`): reliable, volatile.
QOS_RELIABLE = QosProfile()
#: Latched topics (`/tf_static`, `/map`, `/robot_description`): reliable, transient local.
QOS_LATCHED = QosProfile(durability=Durability.TRANSIENT_LOCAL)
#: Sensor-data style publishers (Gazebo's `/clock`, AMCL's particle cloud): best effort, volatile.
QOS_BEST_EFFORT = QosProfile(reliability=Reliability.BEST_EFFORT)
#: rcl's `/rosout` publisher: reliable, transient local, 10 s lifespan.
QOS_ROSOUT = QosProfile(durability=Durability.TRANSIENT_LOCAL, lifespan=QosDuration(10, 0))

# What a TurtleBot3 Gazebo + Nav2 (Humble) system offers on its topics; the fixture bag
# `tb3_waffle_gazebo_humble` shows the Gazebo side (best-effort /clock, latched /tf_static and
# /robot_description, rcl's /rosout), Nav2's sources show the rest (map_server, costmaps and
# amcl_pose latched; particle_cloud with SensorDataQoS).
_DEFAULT_QOS: Mapping[str, QosProfile] = {
    "/clock": QOS_BEST_EFFORT,
    "/tf_static": QOS_LATCHED,
    "/robot_description": QOS_LATCHED,
    "/map": QOS_LATCHED,
    "/global_costmap/costmap": QOS_LATCHED,
    "/local_costmap/costmap": QOS_LATCHED,
    "/amcl_pose": QOS_LATCHED,
    "/particle_cloud": QOS_BEST_EFFORT,
    "/rosout": QOS_ROSOUT,
}


def default_qos(topic: str) -> tuple[QosProfile, ...]:
    """Return the offered QoS profiles a TB3 + Nav2 system records for `topic`.

    Latched topics are transient local; everything not listed is reliable and volatile.
    """
    return (_DEFAULT_QOS.get(topic, QOS_RELIABLE),)


_NAMES: Mapping[type[enum.IntEnum], Mapping[int, str]] = {
    History: {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"},
    Reliability: {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"},
    Durability: {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"},
    Liveliness: {
        0: "system_default",
        1: "automatic",
        2: "manual_by_node",
        3: "manual_by_topic",
        4: "unknown",
        5: "best_available",
    },
}


def _policy_name(value: enum.IntEnum) -> str:
    return _NAMES[type(value)][int(value)]


def _duration_lines(key: str, value: QosDuration, indent: str) -> list[str]:
    return [f"{indent}{key}:", f"{indent}  sec: {value.sec}", f"{indent}  nsec: {value.nsec}"]


def _profile_lines(profile: QosProfile, *, named: bool) -> list[str]:
    """Lines of one profile as a YAML block mapping (the first line carries the `- `)."""

    def policy(value: enum.IntEnum) -> str:
        return _policy_name(value) if named else str(int(value))

    lines = [
        f"history: {policy(profile.history)}",
        f"depth: {profile.depth}",
        f"reliability: {policy(profile.reliability)}",
        f"durability: {policy(profile.durability)}",
        *_duration_lines("deadline", profile.deadline, ""),
        *_duration_lines("lifespan", profile.lifespan, ""),
        f"liveliness: {policy(profile.liveliness)}",
        *_duration_lines("liveliness_lease_duration", profile.liveliness_lease_duration, ""),
        f"avoid_ros_namespace_conventions: {'true' if profile.avoid_ros_namespace_conventions else 'false'}",
    ]
    return [("- " if i == 0 else "  ") + line for i, line in enumerate(lines)]


def qos_profiles_to_yaml(profiles: Sequence[QosProfile], *, named: bool) -> str:
    """Render profiles as the YAML list rosbag2 stores (no trailing newline; "" for none).

    Args:
        profiles: The offered profiles.
        named: Policies as names (metadata version 9) instead of integers (version <= 8).
    """
    lines: list[str] = []
    for profile in profiles:
        lines.extend(_profile_lines(profile, named=named))
    return "\n".join(lines)


def qos_yaml_string_scalar(profiles: Sequence[QosProfile]) -> str:
    """The version <= 8 form: the integer-policy YAML list as one double-quoted YAML scalar."""
    return json.dumps(qos_profiles_to_yaml(profiles, named=False))


def _policy(enum_type: type[enum.IntEnum], value: Any) -> Any:
    if isinstance(value, bool):
        raise ValueError(value)
    if isinstance(value, int):
        return enum_type(value)
    text = str(value).strip().lower()
    for number, name in _NAMES[enum_type].items():
        if name == text:
            return enum_type(number)
    raise ValueError(value)


def _duration(value: Any) -> QosDuration:
    if not isinstance(value, Mapping):
        raise ValueError(value)
    return QosDuration(int(value["sec"]), int(value["nsec"]))


def parse_qos_profiles(value: Any) -> tuple[QosProfile, ...]:
    """Parse offered QoS profiles in any form rosbag2 has written.

    Args:
        value: A YAML string (metadata <= 8, sqlite3 `topics` rows, MCAP channel metadata) or an
            already parsed list (metadata version 9); policies as integers or names.

    Raises:
        ValueError: If the value is not a list of QoS profiles.
    """
    from twin.core.yaml_numbers import safe_load

    items: Any = safe_load(value) if isinstance(value, str) else value
    if items is None or items == "":
        return ()
    if not isinstance(items, Iterable) or isinstance(items, str | bytes | Mapping):
        msg = f"expected a list of QoS profiles, got {type(items).__name__}"
        raise ValueError(msg)
    profiles = []
    for item in items:
        if not isinstance(item, Mapping):
            msg = f"expected a QoS profile mapping, got {item!r}"
            raise ValueError(msg)
        try:
            profiles.append(
                QosProfile(
                    history=_policy(History, item.get("history", 3)),
                    depth=int(item.get("depth", 0)),
                    reliability=_policy(Reliability, item.get("reliability", 1)),
                    durability=_policy(Durability, item.get("durability", 2)),
                    deadline=_duration(item.get("deadline", INFINITE._asdict())),
                    lifespan=_duration(item.get("lifespan", INFINITE._asdict())),
                    liveliness=_policy(Liveliness, item.get("liveliness", 1)),
                    liveliness_lease_duration=_duration(item.get("liveliness_lease_duration", INFINITE._asdict())),
                    avoid_ros_namespace_conventions=bool(item.get("avoid_ros_namespace_conventions", False)),
                )
            )
        except (KeyError, TypeError, ValueError) as err:
            msg = f"unreadable QoS profile {dict(item)!r}: {err}"
            raise ValueError(msg) from None
    return tuple(profiles)


def qos_summary(profiles: Sequence[QosProfile]) -> str:
    """One human-readable line, e.g. `reliable, transient_local` or `best_effort, volatile, lifespan 10s`."""
    if not profiles:
        return "-"
    parts = []
    for profile in profiles:
        words = [_policy_name(profile.reliability), _policy_name(profile.durability)]
        if not is_infinite(profile.lifespan):
            words.append(f"lifespan {profile.lifespan.sec + profile.lifespan.nsec / 1e9:g}s")
        if not is_infinite(profile.deadline):
            words.append(f"deadline {profile.deadline.sec + profile.deadline.nsec / 1e9:g}s")
        parts.append(", ".join(words))
    unique = list(dict.fromkeys(parts))
    return " | ".join(unique) if len(unique) > 1 else f"{unique[0]}" + (f" (x{len(parts)})" if len(parts) > 1 else "")
