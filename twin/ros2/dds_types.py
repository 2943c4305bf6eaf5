"""ROS 2 message types as DDS types: the names rosidl gives them and a structure DDS can describe.

A ROS 2 topic `/scan` of `sensor_msgs/msg/LaserScan` is the DDS topic `rt/scan` of the type
`sensor_msgs::msg::dds_::LaserScan_`. The bridge never serialises through these types: it sends the
CDR the twin already made for the bag. They exist so Cyclone DDS can announce the topic with the
type's name and an XTypes description that matches what rosidl generates (peers that check
assignability then accept it).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["dds_topic_name", "dds_type_name", "is_ros_topic_name", "struct_type"]


def is_ros_topic_name(name: str) -> bool:
    """Whether `name` is a valid absolute ROS 2 topic name (`/scan`, `/robot1/odom`)."""
    if not name.startswith("/") or name.endswith("/") or name == "/":
        return False
    parts = name[1:].split("/")
    return all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", p) and "__" not in p for p in parts)


def dds_topic_name(topic: str) -> str:
    """The DDS topic of a ROS 2 topic: `/scan` -> `rt/scan` (rmw's prefix for topics)."""
    return "rt" + topic


def dds_type_name(msgtype: str) -> str:
    """The DDS type of a ROS 2 message type: `sensor_msgs/msg/LaserScan` -> `sensor_msgs::msg::dds_::LaserScan_`."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def struct_type(msgtype: str, store: Typestore, _made: dict[str, Any] | None = None) -> Any:
    """A Cyclone DDS struct class for `msgtype`, built from the type store's field definitions."""
    from cyclonedds.idl import make_idl_struct, types

    made = {} if _made is None else _made
    if msgtype in made:
        return made[msgtype]
    base = {
        "bool": bool,
        "byte": types.byte,
        "char": types.uint8,
        "int8": types.int8,
        "uint8": types.uint8,
        "int16": types.int16,
        "uint16": types.uint16,
        "int32": types.int32,
        "uint32": types.uint32,
        "int64": types.int64,
        "uint64": types.uint64,
        "float32": types.float32,
        "float64": types.float64,
    }

    array: Any = types.array  # indexed as IDL annotations are: array[float64, 36]
    sequence: Any = types.sequence
    bounded_str: Any = types.bounded_str

    def field_type(node: tuple[Any, Any]) -> Any:
        kind, detail = node
        if kind == 1:  # a base type: (name, string bound)
            name, bound = detail
            if name == "string":
                return bounded_str[bound] if bound else str
            if name == "wstring":
                msg = f"{msgtype}: wstring fields cannot be bridged"
                raise ValueError(msg)
            return base[name]
        if kind == 2:  # another message
            return struct_type(detail, store, made)
        sub, size = detail
        if kind == 3:  # a fixed array
            return array[field_type(sub), size]
        return sequence[field_type(sub), size] if size else sequence[field_type(sub)]

    _, fields = store.fielddefs[msgtype]
    members = {name: field_type(node) for name, node in fields}
    pkg, _, name = msgtype.split("/")
    made[msgtype] = make_idl_struct(f"{pkg}_{name}", dds_type_name(msgtype), members)
    return made[msgtype]
