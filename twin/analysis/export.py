"""`twin bag export`: topics of a bag as tables, one file per topic, columns named by ROS field paths.

A message becomes one row: `t_ns` (the record time) then every field flattened by its path
(`pose.pose.position.x`, `header.stamp.sec`). Numeric arrays (`ranges`, `covariance`) stay one
column: space-separated numbers in CSV, a list column in Parquet. Sequences of messages (a
TFMessage's `transforms`, a Path's `poses`) are one JSON column. Rows stream to disk in blocks,
so memory does not grow with the bag.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin.bag import open_bag, read_messages
from twin.core.errors import BagError, ConfigError, TwinError

__all__ = ["FORMATS", "export_topics", "flatten"]

FORMATS = ("csv", "parquet", "png")
_BLOCK_ROWS = 10_000


def _fields(msg: Any) -> Iterator[tuple[str, Any]]:
    """A message's fields, without its constants (`Log.DEBUG`...: rosbags declares them `ClassVar`)."""
    for name, declared in getattr(msg, "__dataclass_fields__", {}).items():
        if name.startswith("__") or "ClassVar" in str(declared.type):
            continue
        yield name, getattr(msg, name)


def _plain(value: Any) -> Any:
    if hasattr(value, "__dataclass_fields__"):
        return {k: _plain(v) for k, v in _fields(value)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _of_messages(msg: Any, name: str, value: list[Any] | tuple[Any, ...]) -> bool:
    """Whether a sequence field holds messages (by its declared type: an empty one as well as a full one)."""
    if value:
        return hasattr(value[0], "__dataclass_fields__")
    declared = str(getattr(msg.__dataclass_fields__.get(name), "type", ""))
    return "__msg__" in declared or "__srv__" in declared or "__action__" in declared


def flatten(msg: Any, prefix: str = "") -> dict[str, Any]:
    """One message as {field path: value}; arrays as lists, sequences of messages as JSON text."""
    row: dict[str, Any] = {}
    for name, value in _fields(msg):
        key = f"{prefix}{name}"
        if hasattr(value, "__dataclass_fields__"):
            row.update(flatten(value, key + "."))
        elif isinstance(value, np.ndarray):
            row[key] = value.tolist()
        elif isinstance(value, list | tuple):
            if _of_messages(msg, name, value):  # JSON text in every row, an empty sequence too (one column type)
                row[key] = json.dumps(_plain(value))
            else:
                row[key] = list(value)
        elif isinstance(value, bytes):
            row[key] = value.hex()
        else:
            row[key] = value
    return row


def _file_name(topic: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", topic.strip("/")) or "root"


def _csv_cell(value: Any) -> Any:
    if isinstance(value, list):
        return " ".join(repr(v) if isinstance(v, float) else str(v) for v in value)
    return value


def _part(path: Path) -> Path:
    """Where a table is written until the export succeeds (a failed export leaves no file behind)."""
    return path.with_name(f".{path.name}.part")


class _CsvSink:
    def __init__(self, path: Path, header: Sequence[str]) -> None:
        self.path = path
        self._header = header
        self._file = _part(path).open("w", newline="")
        self._writer: csv.DictWriter[str] | None = None

    def write(self, rows: list[dict[str, Any]]) -> None:
        if not rows:
            return
        if self._writer is None:
            self._writer = csv.DictWriter(self._file, fieldnames=list(rows[0]), extrasaction="raise")
            self._writer.writeheader()
        self._writer.writerows({k: _csv_cell(v) for k, v in r.items()} for r in rows)

    def close(self) -> None:
        if self._writer is None and not self._file.closed:  # no message: the columns its type would have
            csv.writer(self._file).writerow(self._header)
        self._file.close()


class _ParquetSink:
    def __init__(self, path: Path, header: Sequence[str]) -> None:
        self.path = path
        self._writer: Any = None
        self._schema: Any = None
        self._closed = False

    def write(self, rows: list[dict[str, Any]]) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not rows:
            return
        columns = {k: [r.get(k) for r in rows] for k in rows[0]}
        if self._schema is None:
            table = pa.table(columns)
            self._schema = table.schema
            self._writer = pq.ParquetWriter(_part(self.path), self._schema)
        else:
            table = pa.table(columns, schema=self._schema)
        self._writer.write_table(table)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._writer is not None:
            self._writer.close()
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            pq.write_table(pa.table({"t_ns": pa.array([], pa.int64())}), _part(self.path))


def _header(msgtype: str) -> list[str]:
    """The columns of a topic without messages: `t_ns`, then the field paths `flatten` would give."""
    from twin.analysis._cdr import type_store_registry
    from twin.bag.typesys import message_type_name

    registry, full = type_store_registry(), message_type_name(msgtype)
    return ["t_ns", *registry.field_paths(full)] if registry.knows(full) else ["t_ns"]


def export_topics(
    bag: str | os.PathLike[str], topics: Sequence[str], out_dir: Path, *, fmt: str = "csv"
) -> dict[str, tuple[Path, int]]:
    """Write each topic of `bag` to `out_dir/<topic>.<fmt>`; return {topic: (file, rows)}.

    Raises:
        BagError: If the bag is unreadable or lacks a topic (listing its topics).
        ConfigError: If `fmt` is parquet and pyarrow is not installed.
    """
    if fmt not in FORMATS:
        msg = f"--format {fmt!r}: choose one of {', '.join(FORMATS)}"
        raise ConfigError(msg)
    if fmt == "png":  # image topics: one PNG per frame
        from twin.analysis.export_images import export_images

        return export_images(bag, topics, out_dir)
    if fmt == "parquet":
        try:
            import pyarrow.parquet  # noqa: F401
        except ImportError:
            msg = "--format parquet needs pyarrow: pip install 'twin[parquet]' (or use --format csv)"
            raise ConfigError(msg) from None
    info = open_bag(bag)
    names = [t.name for t in info.topics]
    for topic in topics:
        if topic not in names:
            msg = f"{info.path}: no topic {topic!r}; it has {', '.join(names)}"
            raise BagError(msg)
    blind = [f"{t.name} ({t.msgtype})" for t in info.topics if t.name in topics and not t.decodable]
    if blind:
        msg = (
            f"{info.path}: cannot decode {', '.join(blind)}: no definition in the bag nor in the type store "
            "(Humble's standard types, nav2_msgs, twin_msgs); export the other topics, or record the bag "
            "with its message definitions (rosbag2's MCAP storage embeds them)"
        )
        raise BagError(msg)
    out_dir.mkdir(parents=True, exist_ok=True)
    types = {t.name: t.msgtype for t in info.topics}
    sinks: dict[str, _CsvSink | _ParquetSink] = {}
    pending: dict[str, list[dict[str, Any]]] = {t: [] for t in topics}
    counts = dict.fromkeys(topics, 0)
    try:
        for topic in topics:
            path = out_dir / f"{_file_name(topic)}.{fmt}"
            make = _CsvSink if fmt == "csv" else _ParquetSink
            sinks[topic] = make(path, _header(types[topic]))
        for m in read_messages(bag, list(topics)):
            rows = pending[m.topic]
            rows.append({"t_ns": m.t_ns, **flatten(m.msg)})
            counts[m.topic] += 1
            if len(rows) >= _BLOCK_ROWS:
                sinks[m.topic].write(rows)
                rows.clear()
        for topic, rows in pending.items():
            sinks[topic].write(rows)
        for sink in sinks.values():
            sink.close()
    except BaseException as err:
        for sink in sinks.values():  # nothing half-written stays behind, whatever stopped the export
            with contextlib.suppress(Exception):
                sink.close()
            _part(sink.path).unlink(missing_ok=True)
        if isinstance(err, ValueError) and not isinstance(err, TwinError):
            msg = f"{info.path}: messages of one topic change shape ({err}); export that topic on its own"
            raise BagError(msg) from None
        raise
    for sink in sinks.values():
        _part(sink.path).replace(sink.path)
    return {t: (sinks[t].path, counts[t]) for t in topics}
