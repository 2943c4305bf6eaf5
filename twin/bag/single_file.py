"""A storage file on its own: a `.mcap` or `.db3` without the bag folder and `metadata.yaml` around it.

`ros2 bag` reads a single storage file since rosbag2 0.15.3, and such files are what many
projects publish. An MCAP file carries its schemas, channels and message counts in its summary
section; a sqlite3 file has its `topics` and `messages` tables. This module turns either into the
`BagMetadata` a `metadata.yaml` would hold, so the rest of the reading side treats a single file
like a folder. It also reads the `rosbag2` Metadata record rosbag2 puts into MCAP files (the
distro, and from Iron on the whole metadata), which `twin bag recover` uses too.
"""

from __future__ import annotations

import functools
import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from twin.bag.mcap_file import read_mcap_summary
from twin.bag.metadata import BagMetadata, FileInformation, TopicMetadata
from twin.bag.qos import parse_qos_profiles
from twin.bag.sqlite_file import connect_readonly, sqlite_topic_stats
from twin.core.errors import BagError
from twin.core.yaml_numbers import safe_load

__all__ = ["STORAGE_SUFFIXES", "rosbag2_record", "storage_file_metadata"]

#: Storage file suffixes and the storage plugin that writes them.
STORAGE_SUFFIXES: Mapping[str, str] = {".mcap": "mcap", ".db3": "sqlite3"}


def rosbag2_record(metadata: Sequence[tuple[str, Mapping[str, str]]]) -> dict[str, Any]:
    """What rosbag2's MCAP `rosbag2` Metadata records say: the bag metadata (Iron and later) and `ros_distro`.

    Humble's record holds only `ROS_DISTRO`; later ones hold `serialized_metadata`, the metadata
    as written when the file was opened or closed (the last record wins). A record that does not
    parse adds nothing.
    """
    out: dict[str, Any] = {}
    for name, values in metadata:
        if name != "rosbag2":
            continue
        if values.get("ROS_DISTRO"):
            out["ros_distro"] = values["ROS_DISTRO"]
        try:
            parsed = safe_load(values.get("serialized_metadata", "")) or {}
        except (yaml.YAMLError, ValueError, RecursionError):
            continue
        if isinstance(parsed, Mapping):
            parsed = parsed.get("rosbag2_bagfile_information", parsed)
            out.update({str(k): v for k, v in parsed.items() if v is not None} if isinstance(parsed, Mapping) else {})
    return out


def storage_file_metadata(path: Path) -> BagMetadata:
    """The metadata of a single `.mcap` or `.db3` file, read from the file itself.

    Raises:
        BagError: If the file is not a readable storage file; an MCAP file without its summary
            (a killed recording) says to run `twin bag recover`.
    """
    stat = path.stat()
    return _cached(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _cached(path: str, _mtime_ns: int, _size: int) -> BagMetadata:
    file = Path(path)
    if file.suffix == ".mcap":
        return _mcap_metadata(file)
    return _sqlite_metadata(file)


def _text(record: Mapping[str, Any], key: str) -> str:
    value = record.get(key, "")
    return "" if value is None else str(value)


def _mcap_metadata(path: Path) -> BagMetadata:
    try:
        summary = read_mcap_summary(path)
    except ValueError as err:
        hint = f"; `twin bag recover {path}` completes it" if "footer" in str(err) else ""
        msg = f"{path}: {err}{hint}"
        raise BagError(msg) from None
    except OSError as err:
        msg = f"{path}: cannot read: {err.strerror}"
        raise BagError(msg) from None
    counts: dict[tuple[str, str], int] = {}
    topics: dict[tuple[str, str], TopicMetadata] = {}
    for cid, channel in sorted(summary.channels.items()):
        schema = summary.schemas.get(channel.schema_id)
        key = (channel.topic, schema.name if schema else "")
        counts[key] = counts.get(key, 0) + summary.channel_counts.get(cid, 0)
        if key in topics:
            continue
        try:
            qos = parse_qos_profiles(channel.metadata.get("offered_qos_profiles", ""))
        except ValueError:
            qos = ()
        topics[key] = TopicMetadata(
            name=channel.topic,
            msgtype=key[1],
            serialization_format=channel.message_encoding,
            offered_qos_profiles=qos,
            type_description_hash=channel.metadata.get("topic_type_hash", ""),
        )
    record = rosbag2_record(summary.metadata)
    distro = _text(record, "ros_distro") or next(
        (values.get("ros_distro", "") for name, values in summary.metadata if name == "twin"), ""
    )
    return _metadata(
        path,
        storage="mcap",
        topics=[_counted(t, counts[key]) for key, t in topics.items()],
        start_ns=summary.start_ns,
        end_ns=summary.end_ns,
        count=summary.message_count,
        record=record,
        distro=distro,
    )


def _sqlite_metadata(path: Path) -> BagMetadata:
    try:
        db = connect_readonly(path)
        try:
            tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            if not {"topics", "messages"} <= tables:
                msg = f"{path}: not a rosbag2 sqlite3 file (no topics and messages tables)"
                raise BagError(msg)
            rows = sqlite_topic_stats(db)
            distro = ""
            if "schema" in tables:
                row = db.execute("SELECT ros_distro FROM schema").fetchone()
                distro = str(row[0]) if row else ""
            record: dict[str, Any] = {}
            if "metadata" in tables:
                row = db.execute("SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1").fetchone()
                record = rosbag2_record([("rosbag2", {"serialized_metadata": str(row[0])})]) if row else {}
        finally:
            db.close()
    except sqlite3.Error as err:
        msg = f"{path}: cannot read the sqlite3 file: {err}; if its recording was killed, run `twin bag recover {path}`"
        raise BagError(msg) from None
    live = [r for r in rows if r.count]
    topics = [
        TopicMetadata(
            name=r.name,
            msgtype=r.msgtype,
            serialization_format=r.serialization_format,
            offered_qos_profiles=_qos_or_none(r.qos),
            type_description_hash=r.type_hash,
            message_count=r.count,
        )
        for r in rows
    ]
    return _metadata(
        path,
        storage="sqlite3",
        topics=topics,
        start_ns=min((r.start_ns for r in live), default=0),
        end_ns=max((r.end_ns for r in live), default=0),
        count=sum(r.count for r in live),
        record=record,
        distro=distro or _text(record, "ros_distro"),
    )


def _qos_or_none(text: str) -> tuple[Any, ...]:
    try:
        return parse_qos_profiles(text)
    except ValueError:
        return ()


def _counted(topic: TopicMetadata, count: int) -> TopicMetadata:
    return TopicMetadata(
        name=topic.name,
        msgtype=topic.msgtype,
        serialization_format=topic.serialization_format,
        offered_qos_profiles=topic.offered_qos_profiles,
        type_description_hash=topic.type_description_hash,
        message_count=count,
    )


def _metadata(
    path: Path,
    *,
    storage: str,
    topics: Sequence[TopicMetadata],
    start_ns: int,
    end_ns: int,
    count: int,
    record: Mapping[str, Any],
    distro: str,
) -> BagMetadata:
    try:
        version = int(record.get("version", 0))
    except (TypeError, ValueError):
        version = 0
    # Only per-message compression concerns the file itself: a file-compressed bag's record
    # describes the compressed file this one was unpacked from.
    per_message = _text(record, "compression_mode").lower() == "message"
    return BagMetadata(
        version=version,
        storage_identifier=storage,
        relative_file_paths=(path.name,),
        starting_time_ns=start_ns,
        duration_ns=end_ns - start_ns if count else 0,
        message_count=count,
        topics=tuple(topics),
        files=(
            FileInformation(
                path=path.name, starting_time_ns=start_ns, duration_ns=end_ns - start_ns, message_count=count
            ),
        ),
        compression_format=_text(record, "compression_format") if per_message else "",
        compression_mode="message" if per_message else "",
        ros_distro=distro,
    )
