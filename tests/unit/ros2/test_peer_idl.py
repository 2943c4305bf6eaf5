"""The IDL the Fast DDS test peer's types are generated from (tests/ros2/idl/) is ROS 2 Humble's.

fastddsgen compiles these files for tests/integration/test_ros2_bridge.py; here, without DDS, each is
held to the message definition ROS 2 Humble ships (rosbags' Humble type store), so the peer decodes
with ROS 2's own layout and not one that merely agrees with the twin.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from rosbags.typesys import Stores, get_types_from_idl, get_typestore

from tests.conftest import REPO

IDL_DIR = REPO / "tests" / "ros2" / "idl"
# What the peer subscribes to (/scan, /odom, /tf, /clock) and publishes (/cmd_vel).
PEER_MESSAGES = {
    "sensor_msgs/msg/LaserScan",
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
    "rosgraph_msgs/msg/Clock",
    "geometry_msgs/msg/Twist",
}
INCLUDE = re.compile(r'^#include "([\w/]+)\.idl"$', re.MULTILINE)
HUMBLE = get_typestore(Stores.ROS2_HUMBLE)


def idl_files() -> dict[str, Path]:
    """Message name (package/msg/Name) -> its IDL file."""
    return {str(p.relative_to(IDL_DIR).with_suffix("")): p for p in sorted(IDL_DIR.rglob("*.idl"))}


def nested_names(fielddef: Any) -> set[str]:
    """The message types a rosbags field definition refers to, directly or as an element."""
    kind, detail = fielddef
    if kind.name == "NAME":
        return {detail}
    if kind.name in ("ARRAY", "SEQUENCE"):
        return nested_names(detail[0])
    return set()


def direct_dependencies(name: str) -> set[str]:
    _, fields = HUMBLE.fielddefs[name]
    return set().union(*(nested_names(f) for _, f in fields))


def test_there_is_one_file_for_each_message_the_peer_uses_and_each_type_nested_in_them() -> None:
    needed, todo = set(), list(PEER_MESSAGES)
    while todo:
        name = todo.pop()
        if name not in needed:
            needed.add(name)
            todo += direct_dependencies(name)
    assert set(idl_files()) == needed


def test_each_file_declares_the_message_its_path_names_with_humble_s_fields_and_types() -> None:
    for name, path in idl_files().items():
        # rosbags' IDL parser takes no preprocessor lines; the includes are checked below.
        text = "".join(line for line in path.read_text().splitlines(keepends=True) if not line.startswith("#"))
        declared = get_types_from_idl(text)
        assert list(declared) == [name], path
        assert declared[name] == HUMBLE.fielddefs[name], f"{path} differs from ROS 2 Humble's {name}"


def test_each_file_includes_exactly_the_messages_it_nests_as_rosidl_adapter_writes_them() -> None:
    files = idl_files()
    for name, path in files.items():
        included = set(INCLUDE.findall(path.read_text()))
        assert included == direct_dependencies(name), path
        assert included <= set(files), path
