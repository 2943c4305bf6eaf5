"""`metadata.yaml`: the rosbag2 bag description, written like rosbag2 writes it and read in any version.

rosbag2 writes the file with yaml-cpp from `rosbag2_storage/yaml.hpp` (`metadata_io.cpp` on
Humble). The fields by version: 3 added compression, 4 the offered QoS (as a string), 5 the
per-file list, 6 `custom_data`, 7 `type_description_hash`, 8 `ros_distro`, and 9 turned the QoS
into a list with named policies.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from twin.bag.qos import QosProfile, parse_qos_profiles, qos_profiles_to_yaml, qos_yaml_string_scalar
from twin.core.errors import BagError
from twin.core.numbers import number_problem
from twin.core.yaml_numbers import safe_load

__all__ = ["BagMetadata", "FileInformation", "TopicMetadata", "read_metadata", "render_metadata", "write_metadata"]

METADATA_FILE = "metadata.yaml"
_ROOT_KEY = "rosbag2_bagfile_information"


@dataclass(frozen=True, kw_only=True, slots=True)
class TopicMetadata:
    """One topic as the bag describes it."""

    name: str
    msgtype: str
    serialization_format: str = "cdr"
    offered_qos_profiles: tuple[QosProfile, ...] = ()
    type_description_hash: str = ""
    message_count: int = 0


@dataclass(frozen=True, kw_only=True, slots=True)
class FileInformation:
    """One storage file of the bag."""

    path: str
    starting_time_ns: int
    duration_ns: int
    message_count: int


@dataclass(frozen=True, kw_only=True, slots=True)
class BagMetadata:
    """The contents of `metadata.yaml`."""

    version: int
    storage_identifier: str
    relative_file_paths: tuple[str, ...]
    starting_time_ns: int
    duration_ns: int
    message_count: int
    topics: tuple[TopicMetadata, ...]
    files: tuple[FileInformation, ...] = ()
    compression_format: str = ""
    compression_mode: str = ""
    custom_data: tuple[tuple[str, str], ...] = field(default=())
    ros_distro: str = ""


_PLAIN = re.compile(r"^[A-Za-z0-9_/][A-Za-z0-9_/.\-~{}]*$")
_YAML_WORDS = {"null", "true", "false", "yes", "no", "on", "off", "y", "n", "~"}


def _scalar(text: str) -> str:
    """A YAML scalar for `text`: plain when unambiguous, otherwise double quoted."""
    if text and _PLAIN.match(text) and text.lower() not in _YAML_WORDS and not _looks_numeric(text):
        return text
    return json.dumps(text, ensure_ascii=False)


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _time_lines(key: str, sub: str, value: int, indent: str) -> list[str]:
    return [f"{indent}{key}:", f"{indent}  {sub}: {value}"]


def _body_lines(meta: BagMetadata, indent: str) -> list[str]:
    """The lines of the metadata mapping, each prefixed with `indent` (yaml-cpp's block style)."""
    named = meta.version >= 9
    i = indent
    lines = [
        f"{i}version: {meta.version}",
        f"{i}storage_identifier: {_scalar(meta.storage_identifier)}",
        *_time_lines("duration", "nanoseconds", meta.duration_ns, i),
        *_time_lines("starting_time", "nanoseconds_since_epoch", meta.starting_time_ns, i),
        f"{i}message_count: {meta.message_count}",
    ]
    if meta.topics:
        lines.append(f"{i}topics_with_message_count:")
        for topic in meta.topics:
            t = i + "      "
            lines += [
                f"{i}  - topic_metadata:",
                f"{t}name: {_scalar(topic.name)}",
                f"{t}type: {_scalar(topic.msgtype)}",
                f"{t}serialization_format: {_scalar(topic.serialization_format)}",
            ]
            if not named:
                lines.append(f"{t}offered_qos_profiles: {qos_yaml_string_scalar(topic.offered_qos_profiles)}")
            elif topic.offered_qos_profiles:
                lines.append(f"{t}offered_qos_profiles:")
                qos = qos_profiles_to_yaml(topic.offered_qos_profiles, named=True)
                lines += [f"{t}  {line}" for line in qos.splitlines()]
            else:
                lines.append(f"{t}offered_qos_profiles: []")
            if meta.version >= 7:
                lines.append(f"{t}type_description_hash: {_scalar(topic.type_description_hash)}")
            lines.append(f"{i}    message_count: {topic.message_count}")
    else:
        lines.append(f"{i}topics_with_message_count: []")
    lines += [
        f"{i}compression_format: {_scalar(meta.compression_format)}",
        f"{i}compression_mode: {_scalar(meta.compression_mode)}",
        f"{i}relative_file_paths:",
        *[f"{i}  - {_scalar(p)}" for p in meta.relative_file_paths],
    ]
    if meta.files:
        lines.append(f"{i}files:")
        for info in meta.files:
            f = i + "    "
            lines += [
                f"{i}  - path: {_scalar(info.path)}",
                *_time_lines("starting_time", "nanoseconds_since_epoch", info.starting_time_ns, f),
                *_time_lines("duration", "nanoseconds", info.duration_ns, f),
                f"{f}message_count: {info.message_count}",
            ]
    else:
        lines.append(f"{i}files: []")
    if meta.version >= 6:
        if meta.custom_data:
            lines.append(f"{i}custom_data:")
            lines += [f"{i}  {_scalar(k)}: {_scalar(v)}" for k, v in meta.custom_data]
        else:
            lines.append(f"{i}custom_data: ~")
    if meta.version >= 8:
        lines.append(f"{i}ros_distro: {_scalar(meta.ros_distro)}")
    return lines


def render_metadata(meta: BagMetadata, *, root: bool = True) -> str:
    """Render metadata as rosbag2 writes it.

    Args:
        meta: The metadata; its `version` decides the form (8: QoS as a string, 9: as a list).
        root: Under the `rosbag2_bagfile_information` key (the `metadata.yaml` file), or bare (what
            Jazzy stores in the MCAP `rosbag2` record and the sqlite3 `metadata` table).
    """
    if root:
        return "\n".join([f"{_ROOT_KEY}:", *_body_lines(meta, "  ")]) + "\n"
    return "\n".join(_body_lines(meta, ""))


def write_metadata(bag_dir: Path, meta: BagMetadata, *, fsync: bool = True) -> Path:
    """Write `metadata.yaml` into `bag_dir` atomically (a temporary file renamed over it).

    Args:
        bag_dir: The bag folder.
        meta: What to write.
        fsync: Sync the file before renaming it (survives power loss, costs a disk flush).
    """
    path = bag_dir / METADATA_FILE
    tmp = bag_dir / (METADATA_FILE + ".tmp")
    with tmp.open("w", encoding="utf-8") as out:
        out.write(render_metadata(meta))
        if fsync:
            out.flush()
            os.fsync(out.fileno())
    tmp.replace(path)
    return path


def _get(node: Mapping[str, Any], key: str, path: Path, version: int) -> Any:
    if key not in node:
        msg = f"{path}: version {version} metadata lacks the key {key!r}; run `twin bag recover {path.parent}`"
        raise BagError(msg)
    return node[key]


def _nanoseconds(node: Any, key: str, path: Path) -> int:
    try:
        value = int(node[key])
    except (KeyError, TypeError, ValueError, OverflowError):
        msg = f"{path}: expected a mapping with {key!r}, got {node!r}"
        raise BagError(msg) from None
    problem = number_problem(value, key)  # rosbag2 keeps these in int64 (a year-318857 start is not one)
    if problem is not None:
        msg = f"{path}: {key}: {problem}; not a time rosbag2 writes, `twin bag recover` rebuilds the metadata"
        raise BagError(msg)
    return value


def parse_metadata(text: str, path: Path) -> BagMetadata:
    """Parse `metadata.yaml` text of any version from 1 to 9.

    Raises:
        BagError: Naming `path` and the problem, if the text is not rosbag2 metadata.
    """
    try:
        return _parse_metadata(text, path)
    except (ValueError, TypeError, KeyError, AttributeError) as err:  # a value of the wrong kind
        msg = f"{path}: not valid rosbag2 metadata ({type(err).__name__}: {err}); `twin bag recover` rebuilds it"
        raise BagError(msg) from None
    except RecursionError:
        msg = f"{path}: not valid rosbag2 metadata (nested too deeply)"
        raise BagError(msg) from None


def _parse_metadata(text: str, path: Path) -> BagMetadata:
    try:
        doc = safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f":{mark.line + 1}" if mark is not None else ""
        msg = f"{path}{where}: not valid YAML ({getattr(err, 'problem', err)})"
        raise BagError(msg) from None
    if not isinstance(doc, Mapping) or not isinstance(doc.get(_ROOT_KEY), Mapping):
        msg = f"{path}: not rosbag2 metadata (no {_ROOT_KEY!r} mapping)"
        raise BagError(msg)
    node = doc[_ROOT_KEY]
    version = int(node.get("version", 1))
    topics = []
    for item in _get(node, "topics_with_message_count", path, version) or ():
        info = item.get("topic_metadata", {})
        qos_value = info.get("offered_qos_profiles", "") if version >= 4 else ""
        try:
            qos = parse_qos_profiles(qos_value)
        except ValueError as err:
            msg = f"{path}: topic {info.get('name')!r}: offered_qos_profiles: {err}"
            raise BagError(msg) from None
        topics.append(
            TopicMetadata(
                name=str(_get(info, "name", path, version)),
                msgtype=str(_get(info, "type", path, version)),
                serialization_format=str(info.get("serialization_format", "cdr")),
                offered_qos_profiles=qos,
                type_description_hash=str(info.get("type_description_hash", "") or ""),
                message_count=int(item.get("message_count", 0)),
            )
        )
    files = tuple(
        FileInformation(
            path=str(f["path"]),
            starting_time_ns=_nanoseconds(f.get("starting_time"), "nanoseconds_since_epoch", path),
            duration_ns=_nanoseconds(f.get("duration"), "nanoseconds", path),
            message_count=int(f.get("message_count", 0)),
        )
        for f in (node.get("files") or ())
    )
    custom = node.get("custom_data") or {}
    return BagMetadata(
        version=version,
        storage_identifier=str(_get(node, "storage_identifier", path, version)),
        relative_file_paths=tuple(str(p) for p in (_get(node, "relative_file_paths", path, version) or ())),
        starting_time_ns=_nanoseconds(_get(node, "starting_time", path, version), "nanoseconds_since_epoch", path),
        duration_ns=_nanoseconds(_get(node, "duration", path, version), "nanoseconds", path),
        message_count=int(_get(node, "message_count", path, version)),
        topics=tuple(topics),
        files=files,
        compression_format=str(node.get("compression_format", "") or ""),
        compression_mode=str(node.get("compression_mode", "") or ""),
        custom_data=tuple((str(k), str(v)) for k, v in custom.items()) if isinstance(custom, Mapping) else (),
        ros_distro=str(node.get("ros_distro", "") or ""),
    )


def read_metadata(bag_dir: Path) -> BagMetadata:
    """Read `bag_dir/metadata.yaml`.

    Raises:
        BagError: If it is missing (with the command that rebuilds it) or unreadable.
    """
    path = bag_dir / METADATA_FILE
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        if not any(p.suffix in (".mcap", ".db3") for p in bag_dir.glob("*")):
            msg = f"{bag_dir}: not a bag folder (no {METADATA_FILE}, no .mcap or .db3 file); give a bag folder or file"
            raise BagError(msg) from None
        msg = (
            f"{bag_dir}: no {METADATA_FILE}; if a recording was killed, "
            f"`twin bag recover {bag_dir}` rebuilds it from the storage files"
        )
        raise BagError(msg) from None
    except OSError as err:
        msg = f"{path}: cannot read: {err.strerror}"
        raise BagError(msg) from None
    except UnicodeDecodeError as err:
        msg = f"{path}: not UTF-8 text (byte offset {err.start}); not rosbag2 metadata"
        raise BagError(msg) from None
    return parse_metadata(text, path)


def topics_in(meta: BagMetadata) -> Sequence[str]:
    """Topic names of the bag, in its order."""
    return [t.name for t in meta.topics]
