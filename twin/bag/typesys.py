"""Message types the twin records: Humble's standard definitions plus nav2_msgs and twin_msgs.

Every bag the twin writes embeds the full definition of each type it uses (MCAP schemas,
sqlite3 `message_definitions`), so a reader that has never heard of `twin_msgs` decodes them.
This module owns the definitions and turns them into what the storages need: the `ros2msg`
text (the type followed by each dependency after a `MSG:` separator) and the RIHS01 type hash
that Iron and later record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError

from twin.core.config import suggest
from twin.core.errors import BagError
from twin.core.msgdefs import EXTRA_DEFINITIONS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["EXTRA_DEFINITIONS", "MessageDefinition", "TypeRegistry"]


@dataclass(frozen=True, kw_only=True, slots=True)
class MessageDefinition:
    """What a bag stores about a message type."""

    msgtype: str  #: e.g. `sensor_msgs/msg/Imu`
    encoding: str  #: `ros2msg`
    text: str  #: the type's fields, then each dependency after a separator line and `MSG: pkg/Type`
    type_hash: str  #: `RIHS01_<sha256>`, as Iron and later compute it


class TypeRegistry:
    """Humble's standard types plus nav2_msgs and twin_msgs, with definitions and hashes on demand.

    Each registry owns its own rosbags type store, so registering a type in one never changes
    another.
    """

    def __init__(self, extra: Mapping[str, str] = EXTRA_DEFINITIONS) -> None:
        self.store: Typestore = get_typestore(Stores.ROS2_HUMBLE)
        self._cache: dict[str, MessageDefinition] = {}
        for msgtype, text in extra.items():
            self.register(msgtype, text)

    def register(self, msgtype: str, text: str) -> None:
        """Add a type from its `.msg` text (or from a full `ros2msg` text with its dependencies).

        Raises:
            BagError: If the text does not parse.
        """
        try:
            self.store.register(get_types_from_msg(text, msgtype))
        except (TypesysError, ValueError) as err:
            msg = f"message definition of {msgtype} does not parse: {err}"
            raise BagError(msg) from None
        self._cache.pop(msgtype, None)

    def knows(self, msgtype: str) -> bool:
        """Whether the registry can describe (and so decode) `msgtype`."""
        return msgtype in self.store.fielddefs

    def definition(self, msgtype: str) -> MessageDefinition:
        """Return the embedded definition of `msgtype`.

        Raises:
            BagError: If the type is unknown, with the closest known name.
        """
        cached = self._cache.get(msgtype)
        if cached is not None:
            return cached
        if not self.knows(msgtype):
            hint = suggest(msgtype, sorted(self.store.fielddefs))
            hint = hint if hint.startswith("; did you mean") else ""
            msg = f"unknown message type {msgtype!r}{hint} (for a custom type, pass its .msg text as msgdef=)"
            raise BagError(msg)
        text, _ = self.store.generate_msgdef(msgtype, ros_version=2)
        definition = MessageDefinition(
            msgtype=msgtype, encoding="ros2msg", text=text, type_hash=self.store.hash_rihs01(msgtype)
        )
        self._cache[msgtype] = definition
        return definition
