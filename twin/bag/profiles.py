"""Distro profiles: what a bag looks like when the given ROS 2 distro's rosbag2 records it.

| distro | metadata | QoS in metadata | MCAP channel metadata | MCAP `rosbag2` record |
|---|---|---|---|---|
| humble, iron | 8 | YAML string, integer policies | offered_qos_profiles | `ROS_DISTRO` |
| jazzy, kilted, rolling | 9 | YAML list, named policies | + topic_type_hash | `serialized_metadata` |

Humble's own recorder writes version 5, but its parser reads any version whose topics carry the
QoS as a string, so version 8 is the newest form every distro from Humble on reads. Version 9
moved the QoS to a list with named policies, which Humble's parser rejects.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from twin.core.config import suggest
from twin.core.errors import BagError

__all__ = ["DISTROS", "DistroProfile", "distro_profile"]


@dataclass(frozen=True, kw_only=True, slots=True)
class DistroProfile:
    """How one distro's rosbag2 writes a bag."""

    name: str
    metadata_version: int  #: 8 or 9
    named_qos: bool  #: QoS policies as names (version 9) instead of integers
    mcap_type_hash: bool  #: MCAP channels carry `topic_type_hash`
    mcap_serialized_metadata: bool  #: the MCAP `rosbag2` metadata record holds the full metadata
    sqlite_schema_version: int = 4  #: with `message_definitions` (Humble's own writer has 3)


DISTROS: Mapping[str, DistroProfile] = {
    "humble": DistroProfile(
        name="humble", metadata_version=8, named_qos=False, mcap_type_hash=False, mcap_serialized_metadata=False
    ),
    "iron": DistroProfile(
        name="iron", metadata_version=8, named_qos=False, mcap_type_hash=True, mcap_serialized_metadata=False
    ),
    "jazzy": DistroProfile(
        name="jazzy", metadata_version=9, named_qos=True, mcap_type_hash=True, mcap_serialized_metadata=True
    ),
    "kilted": DistroProfile(
        name="kilted", metadata_version=9, named_qos=True, mcap_type_hash=True, mcap_serialized_metadata=True
    ),
    "rolling": DistroProfile(
        name="rolling", metadata_version=9, named_qos=True, mcap_type_hash=True, mcap_serialized_metadata=True
    ),
}


def distro_profile(name: str) -> DistroProfile:
    """Return the profile of distro `name`.

    Raises:
        BagError: If the distro is unknown, with the closest known one.
    """
    try:
        return DISTROS[name]
    except KeyError:
        msg = f"unknown ROS 2 distro {name!r}{suggest(name, list(DISTROS))}"
        raise BagError(msg) from None
