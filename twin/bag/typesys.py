"""Message types the twin records: Humble's standard definitions plus nav2_msgs and twin_msgs.

Every bag the twin writes embeds the full definition of each type it uses (MCAP schemas,
sqlite3 `message_definitions`), so a reader that has never heard of `twin_msgs` decodes them.
This module owns the definitions and turns them into what the storages need: the `ros2msg`
text (the type followed by each dependency after a `MSG:` separator) and the RIHS01 type hash
that Iron and later record.

Building rosbags' Humble type store costs about a tenth of a second at start-up, so a registry
builds it only when it is asked for a type it has not described before: the definitions it hands
out are kept in the cache folder (`twin.core.native.cache_dir()`), keyed by the rosbags version and
the extra definitions, and read from there by later runs.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.core.config import suggest
from twin.core.errors import BagError
from twin.core.msgdefs import EXTRA_DEFINITIONS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["EXTRA_DEFINITIONS", "MessageDefinition", "TypeRegistry", "message_type_name"]


def message_type_name(msgtype: str) -> str:
    """The full name of a message type: `pkg/msg/Type` for the `pkg/Type` of early rosbag2 bags.

    Type stores (rosbags', the registry's) know message types by their full name only.
    """
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 and all(parts) else msgtype


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
        self._store: Typestore | None = None
        self._extra = dict(extra)
        self._registered: dict[str, str] = {}  # types registered since, by their text
        self._cache: dict[str, MessageDefinition] = {}
        self._disk: dict[str, Any] | None = None  # the cached definitions of this rosbags and these extras

    @property
    def store(self) -> Typestore:
        """The rosbags type store: Humble's types, the extra definitions and those registered since."""
        if self._store is None:
            from rosbags.typesys import Stores, get_typestore

            self._store = get_typestore(Stores.ROS2_HUMBLE)
            for msgtype, text in (*self._extra.items(), *self._registered.items()):
                self._add(msgtype, text)
        return self._store

    def _add(self, msgtype: str, text: str) -> None:
        from rosbags.typesys import get_types_from_msg
        from rosbags.typesys.base import TypesysError

        assert self._store is not None
        try:
            self._store.register(get_types_from_msg(text, msgtype))
        except (TypesysError, ValueError) as err:
            msg = f"message definition of {msgtype} does not parse: {err}"
            raise BagError(msg) from None

    def register(self, msgtype: str, text: str) -> None:
        """Add a type from its `.msg` text (or from a full `ros2msg` text with its dependencies).

        Raises:
            BagError: If the text does not parse.
        """
        if self._store is None:
            self._registered[msgtype] = text
            _ = self.store  # built now, with this type among those it registers (its text is checked here)
        else:
            self._add(msgtype, text)
            self._registered[msgtype] = text
        self._cache.pop(msgtype, None)

    def knows(self, msgtype: str) -> bool:
        """Whether the registry can describe (and so decode) `msgtype` (by its full name, see `message_type_name`)."""
        return msgtype in self.store.fielddefs

    def field_paths(self, msgtype: str) -> list[str]:
        """The dotted paths of a type's fields: nested messages spread out, each value, array or sequence one path.

        Raises:
            BagError: If the type is unknown.
        """
        from rosbags.interfaces import Nodetype

        fielddefs = self.store.fielddefs
        if msgtype not in fielddefs:
            msg = f"unknown message type {msgtype!r}"
            raise BagError(msg)

        def paths(name: str, prefix: str) -> list[str]:
            out: list[str] = []
            for field_name, (kind, detail) in fielddefs[name][1]:
                if kind == Nodetype.NAME and isinstance(detail, str):
                    out += paths(detail, f"{prefix}{field_name}.")
                else:
                    out.append(prefix + field_name)
            return out

        return paths(msgtype, "")

    def definition(self, msgtype: str) -> MessageDefinition:
        """Return the embedded definition of `msgtype`.

        Raises:
            BagError: If the type is unknown, with the closest known name.
        """
        cached = self._cache.get(msgtype)
        if cached is not None:
            return cached
        stored = None if msgtype in self._registered else self._from_disk().get(msgtype)
        if stored is not None:
            definition = MessageDefinition(msgtype=msgtype, encoding="ros2msg", text=stored[0], type_hash=stored[1])
            self._cache[msgtype] = definition
            return definition
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
        if msgtype not in self._registered:
            self._to_disk(msgtype, definition)
        return definition

    def _disk_path(self) -> Path:
        from twin.core.native import cache_dir

        key = hashlib.sha256(_rosbags_version().encode() + json.dumps(self._extra, sort_keys=True).encode())
        return cache_dir() / "msgdefs" / f"humble-{key.hexdigest()[:16]}.json"

    def _from_disk(self) -> dict[str, Any]:
        if self._disk is None:
            try:
                data = json.loads(self._disk_path().read_text(encoding="utf-8"))
                self._disk = data if isinstance(data, dict) else {}
            except (OSError, ValueError):
                self._disk = {}
        return self._disk

    def _to_disk(self, msgtype: str, definition: MessageDefinition) -> None:
        """Add a definition to the cache file (written whole and moved into place; a failure only costs time)."""
        disk = self._from_disk()
        disk[msgtype] = [definition.text, definition.type_hash]
        path = self._disk_path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".msgdefs-")
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(disk, f)
            os.replace(tmp, path)
        except OSError:
            pass


def _rosbags_version() -> str:
    """The installed rosbags' version, which keys the on-disk definitions.

    Read from the name of its dist-info folder beside the package (one directory listing), not through
    `importlib.metadata`, whose import alone costs 30-60 ms of every run's start-up; that is the
    fallback when the folder is not where pip puts it.
    """
    import os

    import rosbags

    for location in rosbags.__path__:
        parent = os.path.dirname(os.path.abspath(location))
        try:
            names = os.listdir(parent)
        except OSError:
            continue
        for name in names:
            if name.startswith("rosbags-") and name.endswith(".dist-info"):
                return name[len("rosbags-") : -len(".dist-info")]
    from importlib.metadata import version

    return version("rosbags")
