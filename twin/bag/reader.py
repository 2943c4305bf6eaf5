"""Reading bags: what a bag holds (`open_bag`), and its messages decoded (`read_messages`).

Works on any rosbag2 folder rosbags reads (metadata versions 1 to 9, sqlite3 and MCAP), the
twin's own and real robots'. Messages are decoded with the definitions embedded in the bag when
it has them, otherwise with Humble's standard types (plus nav2_msgs and twin_msgs). A topic whose
type is defined nowhere is listed as undecodable, never a crash.

```python
from twin.bag import open_bag, read_messages

info = open_bag("bags/run1")
print(info.duration_ns, [t.name for t in info.topics])
for m in read_messages("bags/run1", ["/odom", "/imu"]):
    print(m.topic, m.t_ns, m.msg.header.stamp.sec)
```
"""

from __future__ import annotations

import functools
import logging
import os
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from apsw import Error as _SqliteError  # rosbags reads sqlite3 through apsw (a damaged page: apsw.CorruptError)
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import get_types_from_idl, get_types_from_msg
from rosbags.typesys.base import TypesysError

from twin.bag.mcap_file import ZSTD_MAGIC, _decompress, mcap_has_footer
from twin.bag.metadata import METADATA_FILE, BagMetadata, read_metadata
from twin.bag.qos import QosProfile
from twin.bag.single_file import STORAGE_SUFFIXES, storage_file_metadata
from twin.bag.typesys import MessageDefinition, TypeRegistry, message_type_name
from twin.core.errors import BagError
from twin.core.numbers import INT64_MAX

__all__ = [
    "BagFile",
    "BagInfo",
    "BagMessage",
    "TopicInfo",
    "message_definitions",
    "open_bag",
    "read_messages",
    "robot_namespaces",
    "undecodable",
]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True, slots=True)
class TopicInfo:
    """One topic of a bag."""

    name: str
    msgtype: str
    message_count: int
    serialization_format: str
    qos: tuple[QosProfile, ...]
    type_hash: str
    #: Where its definition comes from: `embedded` (in the bag), `type store` (Humble's standard
    #: types, nav2_msgs, twin_msgs) or `none` (its messages cannot be decoded).
    definition: str

    @property
    def decodable(self) -> bool:
        """Whether `read_messages` can decode this topic."""
        return self.definition != "none"


@dataclass(frozen=True, kw_only=True, slots=True)
class BagFile:
    """One storage file of a bag."""

    path: str
    size_bytes: int
    message_count: int


@dataclass(frozen=True, kw_only=True, slots=True)
class BagInfo:
    """What `ros2 bag info` reports, plus where each topic's definition comes from."""

    path: Path
    version: int
    storage: str
    ros_distro: str
    files: tuple[BagFile, ...]
    size_bytes: int
    start_ns: int
    end_ns: int
    message_count: int
    topics: tuple[TopicInfo, ...]
    compression_format: str
    compression_mode: str
    custom_data: tuple[tuple[str, str], ...]

    @property
    def duration_ns(self) -> int:
        """Time from the first to the last message."""
        return self.end_ns - self.start_ns

    def topic(self, name: str) -> TopicInfo:
        """The topic `name`.

        Raises:
            BagError: Listing the bag's topics, if it has no such topic.
        """
        for topic in self.topics:
            if topic.name == name:
                return topic
        msg = f"{self.path}: no topic {name!r}; it has {', '.join(t.name for t in self.topics) or 'no topics'}"
        raise BagError(msg)


class BagMessage(NamedTuple):
    """One message read from a bag."""

    topic: str
    msgtype: str
    t_ns: int  #: the bag's time stamp (the recorder's receive time)
    msg: Any  #: the decoded message (rosbags dataclass), or the raw CDR bytes with `decode=False`


def _bag_dir(path: str | os.PathLike[str]) -> Path:
    """The bag at `path`: a rosbag2 folder, or a single `.mcap` or `.db3` file outside one.

    A storage file inside a bag folder stands for the folder.

    Raises:
        BagError: If `path` is neither.
    """
    bag = Path(path)
    if bag.is_file():
        if (bag.parent / METADATA_FILE).exists():
            return bag.parent  # a storage file inside a bag folder
        if bag.suffix in STORAGE_SUFFIXES:
            return bag
        if bag.suffix == ".zstd" and Path(bag.stem).suffix in STORAGE_SUFFIXES:
            msg = f"{bag}: a zstd-compressed storage file without its metadata.yaml; unpack it with `zstd -d {bag}`"
            raise BagError(msg)
        msg = f"{bag}: not a bag; expected a rosbag2 folder (metadata.yaml and storage files) or a .mcap or .db3 file"
        raise BagError(msg)
    if not bag.exists():
        msg = f"{bag}: no such bag folder or file"
        raise BagError(msg)
    if not bag.is_dir():
        msg = f"{bag}: not a bag; expected a rosbag2 folder (metadata.yaml and storage files) or a .mcap or .db3 file"
        raise BagError(msg)
    return bag


def bag_metadata(bag: Path) -> BagMetadata:
    """The metadata of the bag `bag` (from `_bag_dir`): its metadata.yaml, or a single storage file's own.

    Raises:
        BagError: If the metadata is missing or unreadable, or a storage file it lists is not there.
    """
    if bag.is_file():
        return storage_file_metadata(bag)
    meta = read_metadata(bag)
    missing = [Path(rel).name for rel in meta.relative_file_paths if not (bag / Path(rel).name).is_file()]
    if missing:
        files = ", ".join(missing)
        its = "its storage file" if len(missing) == 1 else "its storage files"
        verb = "is" if len(missing) == 1 else "are"
        msg = (
            f"{bag}: {its} {files} (listed in {METADATA_FILE}) {verb} not there; "
            f"copy {files} into {bag}: {METADATA_FILE} alone holds no messages"
        )
        raise BagError(msg)
    return meta


def storage_paths(bag: Path, meta: BagMetadata) -> list[Path]:
    """The storage files of the bag `bag` (from `_bag_dir`)."""
    if bag.is_file():
        return [bag]
    return [bag / Path(rel).name for rel in meta.relative_file_paths]


@functools.lru_cache(maxsize=1024)
def _parsed_definition(msgtype: str, msg_format: MessageDefinitionFormat, data: str) -> dict[str, Any]:
    """The types an embedded definition declares (parsed once per process: every bag of a sweep has the same).

    Raises:
        TypesysError, ValueError, IndexError: If the definition does not parse.
    """
    if msg_format == MessageDefinitionFormat.MSG:
        return dict(get_types_from_msg(data, msgtype))
    sep = "=" * 80 + "\n"
    types: dict[str, Any] = {}
    chunks = data.split(sep)[1:] if data.startswith(sep) else [data]
    for chunk in chunks:
        idl = chunk.split("\n", 1)[1] if chunk.startswith("IDL: ") else chunk
        types.update(get_types_from_idl(idl))
    return types


@functools.cache
def _warn_once(bag: Path, msgtype: str, reason: str, fallback: bool) -> None:
    """Say that the bag's definition of `msgtype` is not used, once per process (each pass over the bag meets it)."""
    then = "decoding with the type store's" if fallback else "its topics cannot be decoded"
    _log.warning("%s: the definition of %s in the bag is not used (%s); %s", bag, msgtype, reason, then)


def _one_line(err: Exception, limit: int = 100) -> str:
    """The first line of an error's text, cut to `limit` characters (a parser may quote a whole definition)."""
    text = (str(err).strip().splitlines() or [type(err).__name__])[0]
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _typestore_for(bag: Path, connections: Sequence[Connection]) -> tuple[TypeRegistry, set[str]]:
    """A registry holding the bag's embedded definitions over the standard ones; and the embedded types' full names."""
    registry = TypeRegistry()
    embedded: set[str] = set()
    for conn in connections:
        if message_type_name(conn.msgtype) in embedded or conn.msgdef.format == MessageDefinitionFormat.NONE:
            continue
        try:
            types = dict(_parsed_definition(conn.msgtype, conn.msgdef.format, conn.msgdef.data))
            known = registry.store.fielddefs
            # Definitions equal to the store's (every type of a bag the twin wrote) add nothing to
            # it; registering them would generate and compile their classes again (~50 ms a bag).
            if any(known.get(name) != tuple(definition[:2]) for name, definition in types.items()):
                registry.store.register(types)
        except (TypesysError, ValueError, IndexError) as err:
            # rosbags quotes the whole text it could not parse: say what is wrong instead
            if str(err).startswith("Could not parse"):
                reason = "not .msg text rosbags parses"
            elif "already present with different definition" in str(err):
                reason = "it differs from the type store's"
            else:
                reason = _one_line(err)
            _warn_once(bag, conn.msgtype, reason, registry.knows(message_type_name(conn.msgtype)))
            continue
        embedded.add(message_type_name(conn.msgtype))
    return registry, embedded


def _storage_types(reader: Reader) -> dict[str, Connection]:
    """Each topic's connection as the bag folder's storage files name it (one type per topic); {} for a single file.

    A single storage file has no metadata.yaml: its connections are its own already.
    """
    storages = getattr(reader.storage, "storages", None)
    if storages is None:
        return {}
    found: dict[str, dict[str, Connection]] = {}
    for storage in storages:
        for conn in storage.connections:
            found.setdefault(conn.topic, {}).setdefault(conn.msgtype, conn)
    return {topic: next(iter(types.values())) for topic, types in found.items() if len(types) == 1}


@functools.cache
def _warn_retyped(bag: Path, topic: str, listed: str, stored: str) -> None:
    """Say once per process that metadata.yaml and the storage disagree on a topic's type."""
    _log.warning(
        "%s: %s names %s's type %s, its storage %s; reading it as %s, the storage's",
        bag,
        METADATA_FILE,
        topic,
        listed,
        stored,
        stored,
    )


def _connections(bag: Path, reader: Reader) -> list[Connection]:
    """The bag's connections, each with the type its storage file gives it.

    metadata.yaml is a copy of what the storage says, and copies go wrong (edited by hand, written
    by another tool); the MCAP schema or the sqlite3 topics table is what the messages were
    written as. Trusting metadata.yaml would read such a topic as no message at all.
    """
    stored = _storage_types(reader)
    out = []
    for listed in reader.connections:
        actual = stored.get(listed.topic)
        if actual is not None and actual.msgtype != listed.msgtype:
            _warn_retyped(bag, listed.topic, listed.msgtype, actual.msgtype)
            digest = actual.digest or listed.digest
            out.append(listed._replace(msgtype=actual.msgtype, msgdef=actual.msgdef, digest=digest))
        else:
            out.append(listed)
    return out


def _open_reader(bag: Path) -> Reader:
    try:
        reader = Reader(bag)
        reader.open()
    except (
        FileNotFoundError,
        ReaderError,
        OSError,
        ValueError,
        KeyError,
        TypeError,
        MemoryError,
        OverflowError,
        struct.error,
    ) as err:
        # ValueError (UnicodeDecodeError among them), KeyError, TypeError: rosbags meets storage
        # tables whose text is damaged (a QoS string without its fields, bytes that are not UTF-8);
        # MemoryError, OverflowError: a damaged MCAP record length (rosbags reads that many bytes at once)
        meta = bag_metadata(bag)  # names a missing metadata.yaml or storage file, the usual causes
        if isinstance(err, FileNotFoundError):
            raise
        if isinstance(err, (ValueError, KeyError, TypeError, MemoryError, OverflowError, struct.error)):
            msg = (
                f"{bag}: cannot read the bag: its storage's tables or records do not parse "
                f"({_parse_failure(err)}); they may be damaged: run `twin bag recover {bag}`"
            )
        else:
            hint = _killed_hint(bag, meta) or _damage_hint(bag, err)
            msg = f"{bag}: cannot read the bag: {str(err).rstrip('.')}{hint}"
        raise BagError(msg) from None
    return reader


def _parse_failure(err: Exception) -> str:
    if isinstance(err, (MemoryError, OverflowError)):  # rosbags reads a record's stated length at once
        return "a record states a length larger than the file"
    return f"{type(err).__name__}: {_one_line(err)}"


def _killed_hint(bag: Path, meta: BagMetadata | None) -> str:
    """The recover hint, if a storage file shows what a killed recording leaves; else "".

    A killed recording leaves an MCAP file without its footer, a sqlite3 file with its journal.
    Anything else (an unsupported format, a damaged message) is not helped by `twin bag recover`.
    """
    files = [bag] if bag.is_file() else ([] if meta is None else storage_paths(bag, meta))
    for file in files:
        try:
            if file.suffix == ".mcap" and not mcap_has_footer(file):
                return f"; if its recording was killed, run `twin bag recover {bag}`"
        except OSError:
            continue
        if file.suffix == ".db3" and any(file.with_name(file.name + end).exists() for end in ("-journal", "-wal")):
            return f"; if its recording was killed, run `twin bag recover {bag}`"
    return ""


def _damage_hint(bag: Path, err: Exception) -> str:
    """The recover hint, if SQLite says the database itself is damaged (a file cut or overwritten); else ""."""
    text = str(err)
    if "malformed" in text or "not a database" in text:
        return f"; its storage is damaged: `twin bag recover {bag}` keeps the rows that still read"
    return ""


def open_bag(path: str | os.PathLike[str]) -> BagInfo:
    """Describe the bag at `path`: a rosbag2 folder (or a storage file inside one), or a single .mcap or .db3 file.

    Raises:
        BagError: If it is not a readable bag (e.g. no metadata.yaml: run `twin bag recover`).
    """
    bag = _bag_dir(path)
    meta = bag_metadata(bag)
    embedded, known, types = _definitions(bag, meta)
    files = []
    for file in storage_paths(bag, meta):
        count = next((f.message_count for f in meta.files if Path(f.path).name == file.name), 0)
        files.append(BagFile(path=file.name, size_bytes=file.stat().st_size, message_count=count))
    size_bytes = bag.stat().st_size if bag.is_file() else sum(p.stat().st_size for p in bag.iterdir() if p.is_file())
    topics = tuple(
        TopicInfo(
            name=t.name,
            msgtype=(msgtype := types.get(t.name, t.msgtype)),
            message_count=t.message_count,
            serialization_format=t.serialization_format,
            qos=t.offered_qos_profiles,
            type_hash=t.type_description_hash,
            definition=(
                "embedded"
                if message_type_name(msgtype) in embedded
                else ("type store" if message_type_name(msgtype) in known else "none")
            ),
        )
        for t in meta.topics
    )
    return BagInfo(
        path=bag,
        version=meta.version,
        storage=meta.storage_identifier,
        ros_distro=meta.ros_distro,
        files=tuple(files),
        size_bytes=size_bytes,
        start_ns=meta.starting_time_ns,
        end_ns=meta.starting_time_ns + meta.duration_ns,
        message_count=meta.message_count,
        topics=topics,
        compression_format=meta.compression_format,
        compression_mode=meta.compression_mode,
        custom_data=meta.custom_data,
    )


def _definitions(bag: Path, meta: BagMetadata) -> tuple[set[str], set[str], dict[str, str]]:
    """Types with definitions embedded in the bag, all types that can be decoded, and each topic's type.

    A topic's type is its storage's (see `_connections`), or metadata.yaml's if the storage cannot be read.
    """
    try:
        reader = _open_reader(bag)
    except BagError as err:
        _log.warning("%s", err)
        registry = TypeRegistry()
        known = {name for t in meta.topics if registry.knows(name := message_type_name(t.msgtype))}
        return set(), known, {t.name: t.msgtype for t in meta.topics}
    try:
        connections = _connections(bag, reader)
        registry, embedded = _typestore_for(bag, connections)
    finally:
        reader.close()
    types = {c.topic: c.msgtype for c in connections}
    return embedded, {name for t in types.values() if registry.knows(name := message_type_name(t))}, types


def undecodable(
    bag: Path, data: bytes | memoryview, err: Exception, *, topic: str, t_ns: int, msgtype: str
) -> BagError:
    """The error for a message whose bytes do not parse as its type, with the likely cause."""
    if bytes(data[:4]) == ZSTD_MAGIC:
        cause = (
            "its bytes are a zstd frame: the bag is compressed per message but its metadata does not say so; "
            f"`twin bag recover {bag}` records the compression"
        )
    else:
        cause = "the bag's messages are damaged, or are not CDR of the type its metadata names"
    return BagError(f"{bag}: a message on {topic} at {t_ns} ns does not parse as {msgtype} ({err}); {cause}")


def _storage_messages(
    reader: Reader, wanted: Sequence[Connection], start_ns: int | None, stop_ns: int | None, *, zstd_messages: bool
) -> Iterator[tuple[Connection, int, bytes | memoryview]]:
    """The messages of the `wanted` connections, each storage file's connections matched by topic and type.

    rosbags matches metadata.yaml's connections to a storage file's by equality, offered QoS
    included, so a bag whose metadata.yaml writes the QoS differently from its storage file (a
    Foxy recording: `deadline 0 s` in one, `2147483647 s` in the other) would read no message.
    The QoS describes the publishers, not which messages belong to a topic: here only the topic
    and the type decide.
    """
    storages = getattr(reader.storage, "storages", None)
    if storages is None:  # a single storage file: the reader's connections are the file's own
        for conn, t_ns, data in reader.messages(wanted, start=start_ns, stop=stop_ns):
            yield conn, t_ns, _decompress("zstd", data, 0) if zstd_messages else data
        return
    by_key = {(c.topic, c.msgtype): c for c in wanted}
    per_message_zstd = reader.compression_mode == "message"
    for storage in storages:
        own = {c.id: by_key[(c.topic, c.msgtype)] for c in storage.connections if (c.topic, c.msgtype) in by_key}
        if not own:
            continue
        chosen = [c for c in storage.connections if c.id in own]
        for conn, t_ns, data in storage.messages(chosen, start_ns, stop_ns):
            yield own[conn.id], t_ns, _decompress("zstd", data, 0) if per_message_zstd else data


def read_messages(
    path: str | os.PathLike[str],
    topics: Sequence[str] | None = None,
    *,
    start_ns: int | None = None,
    stop_ns: int | None = None,
    decode: bool = True,
) -> Iterator[BagMessage]:
    """Yield the bag's messages in time order, decoded.

    Args:
        path: A rosbag2 folder (or a storage file inside one), or a single .mcap or .db3 file.
        topics: Topics to read; None reads every topic that can be decoded (the others are
            skipped with a warning).
        start_ns: Only messages at or after this bag time.
        stop_ns: Only messages before this bag time.
        decode: False yields the raw CDR bytes (any topic, definition or not).

    Raises:
        BagError: If a requested topic is missing (listing the bag's topics) or has no
            definition, or a message does not decode.
    """
    bag = _bag_dir(path)
    # rosbags unpacks per-message compression in a folder (its metadata.yaml says so), not in a single file
    zstd_messages = bag.is_file() and storage_file_metadata(bag).compression_mode == "message"
    reader = _open_reader(bag)
    try:
        connections = _connections(bag, reader)
        registry, _ = _typestore_for(bag, connections)
        by_topic: dict[str, list[Connection]] = {}
        for conn in connections:
            by_topic.setdefault(conn.topic, []).append(conn)
        if topics is None:
            wanted = [c for c in connections if not decode or registry.knows(message_type_name(c.msgtype))]
            skipped = sorted({f"{c.topic} ({c.msgtype})" for c in connections if c not in wanted})
            if skipped:
                _log.warning("%s: no definition for %s; skipping", bag, ", ".join(skipped))
        else:
            wanted = []
            for name in topics:
                if name not in by_topic:
                    msg = f"{bag}: no topic {name!r}; it has {', '.join(sorted(by_topic)) or 'no topics'}"
                    raise BagError(msg)
                for conn in by_topic[name]:
                    if decode and not registry.knows(message_type_name(conn.msgtype)):
                        msg = (
                            f"{bag}: topic {name} has type {conn.msgtype}, whose definition is neither in the bag "
                            "nor in the type store; read it with decode=False"
                        )
                        raise BagError(msg)
                    wanted.append(conn)
        if not wanted:
            return
        store = registry.store
        for conn, t_ns, data in _storage_messages(reader, wanted, start_ns, stop_ns, zstd_messages=zstd_messages):
            # a damaged storage: MCAP stores uint64 (a ROS time is int64); SQLite gives what a flipped page holds
            if type(t_ns) is not int or t_ns > INT64_MAX or not isinstance(data, (bytes, memoryview)):
                msg = f"a message on {conn.topic} has time {t_ns!r:.40} and data of type {type(data).__name__}"
                raise ValueError(msg)
            if not decode:
                yield BagMessage(conn.topic, conn.msgtype, t_ns, bytes(data))
                continue
            try:
                msg_obj = store.deserialize_cdr(data, message_type_name(conn.msgtype))
            except (SerdeError, ValueError, IndexError, KeyError, struct.error) as err:
                raise undecodable(bag, data, err, topic=conn.topic, t_ns=t_ns, msgtype=conn.msgtype) from None
            yield BagMessage(conn.topic, conn.msgtype, t_ns, msg_obj)
    except ReaderError as err:
        hint = _killed_hint(bag, _metadata_or_none(bag)) or _damage_hint(bag, err)
        msg = f"{bag}: cannot read the bag: {str(err).rstrip('.')}{hint}"
        raise BagError(msg) from None
    except (
        _SqliteError,
        MemoryError,
        struct.error,
        EOFError,
        OverflowError,
        ValueError,
        KeyError,
        IndexError,
        TypeError,
    ) as err:
        # rosbags meeting a damaged storage file: a page SQLite finds malformed, an MCAP length
        # that runs past the file or asks for more memory than there is, a column of another type
        what = _one_line(err) if str(err).strip() else type(err).__name__
        msg = f"{bag}: cannot read the bag ({what}); its storage is damaged: run `twin bag recover {bag}`"
        raise BagError(msg) from None
    finally:
        reader.close()


def _metadata_or_none(bag: Path) -> BagMetadata | None:
    try:
        return bag_metadata(bag)
    except BagError:
        return None


def message_definitions(path: str | os.PathLike[str]) -> dict[str, MessageDefinition]:
    """Return the `ros2msg` definition of each message type in the bag that can be decoded.

    A definition embedded in the bag wins over the type store's (Humble's standard types,
    nav2_msgs, twin_msgs); types defined nowhere are left out. The text is what a rosbag2 MCAP
    embeds, whatever the bag's own format (MCAP `ros2msg`/`ros2idl`, or none in sqlite3).

    Raises:
        BagError: If the folder is not a readable bag.
    """
    bag = _bag_dir(path)
    reader = _open_reader(bag)
    try:
        connections = _connections(bag, reader)
        registry, _ = _typestore_for(bag, connections)
        definitions: dict[str, MessageDefinition] = {}
        for conn in connections:
            if conn.msgtype in definitions or not registry.knows(message_type_name(conn.msgtype)):
                continue
            try:
                definitions[conn.msgtype] = registry.definition(message_type_name(conn.msgtype))
            except (BagError, TypesysError, KeyError, ValueError) as err:
                _log.warning("%s: no usable definition of %s (%s)", bag, conn.msgtype, err)
    finally:
        reader.close()
    return definitions


#: Topics besides the odometry that show a namespace holds a robot (one of them is enough).
_ROBOT_SIBLINGS = ("/cmd_vel", "/scan", "/tf", "/amcl_pose", "/joint_states", "/imu", "/robot_description")


def robot_namespaces(info: BagInfo) -> list[str]:
    """The namespaces of the robots in a bag (`robot1`, `fleet/robot2`), sorted; empty for a single robot.

    A namespace holds a robot when it has an Odometry topic `<ns>/odom` or `<ns>/ground_truth/odom`
    and one more of a robot's topics (`<ns>/cmd_vel`, `<ns>/scan`, `<ns>/tf`...): nav2_bringup's
    multi-robot naming. A lone `/wheel/odom` is not a robot.
    """
    names = {t.name for t in info.topics}
    found: set[str] = set()
    for t in info.topics:
        if message_type_name(t.msgtype) != "nav_msgs/msg/Odometry":
            continue
        for tail in ("/ground_truth/odom", "/odom"):
            if t.name.endswith(tail):
                prefix = t.name[: -len(tail)]
                break
        else:
            continue
        if not prefix.strip("/") or prefix.endswith("/ground_truth"):
            continue
        if any(prefix + s in names for s in _ROBOT_SIBLINGS):
            found.add(prefix.strip("/"))
    return sorted(found)
