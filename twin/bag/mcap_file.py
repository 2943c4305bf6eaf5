"""MCAP files: a streaming, crash-tolerant chunked writer, and the scanner that recovers killed files.

The layout (https://mcap.dev/spec) is magic, Header, a data section of records, DataEnd, a
summary section (schemas, channels, statistics, chunk and metadata indexes, summary offsets),
Footer, magic. The writer appends schema and channel records as topics appear and one Chunk
(uncompressed, as rosbag2's default) followed by its MessageIndex records per flush, each in a
single write, so a killed process leaves a file whose every complete record is valid. The
summary is only written by `finish()`; `recover_mcap()` rebuilds it from what a kill left.

A chunk and its message indexes are built for a whole batch at once, by a compiled kernel
(`twin.bag._native`) or, for a batch out of time order, a bad one, or without a C compiler, with
numpy; both give the same bytes. The per-message Python work is one tuple appended to a list by
the recorder.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import logging
import os
import struct
import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag._native import load_chunk_kernel

__all__ = [
    "MAGIC",
    "ZSTD_MAGIC",
    "McapRecovery",
    "McapScan",
    "McapSummary",
    "McapWriter",
    "mcap_has_footer",
    "read_mcap_summary",
    "recover_mcap",
    "scan_mcap",
]

_log = logging.getLogger(__name__)

MAGIC = b"\x89MCAP0\r\n"
#: The first bytes of a zstd frame; a CDR message starts with a 0 byte (its encapsulation kind).
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_STATISTICS = 0x0B
OP_METADATA = 0x0C
OP_METADATA_INDEX = 0x0D
OP_SUMMARY_OFFSET = 0x0E
OP_DATA_END = 0x0F

_RECORD = struct.Struct("<BQ")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_INDEX_HEAD = struct.Struct("<BQHI")  # MessageIndex: opcode, record length, channel, entries' byte length
_CHUNK_HEAD = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed crc
_FOOTER = struct.Struct("<BQQQI")
_STATS_HEAD = struct.Struct("<QHIIII")  # messages, schemas, channels, attachments, metadata, chunks

# A Message record's fixed part: opcode, record length, channel, sequence, log and publish time.
_MESSAGE_HEAD = np.dtype(
    [("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"), ("log", "<u8"), ("publish", "<u8")]
)
_MESSAGE_HEAD_SIZE = _MESSAGE_HEAD.itemsize  # 31
_INDEX_ENTRY = np.dtype([("time", "<u8"), ("offset", "<u8")])


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _map(items: Mapping[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in items.items())
    return _U32.pack(len(body)) + body


def _record(op: int, content: bytes) -> bytes:
    return _RECORD.pack(op, len(content)) + content


@dataclass(frozen=True, kw_only=True, slots=True)
class SchemaRecord:
    """A Schema record's fields."""

    id: int
    name: str
    encoding: str
    data: bytes

    def encode(self) -> bytes:
        """The full record."""
        return _record(
            OP_SCHEMA,
            _U16.pack(self.id) + _string(self.name) + _string(self.encoding) + _U32.pack(len(self.data)) + self.data,
        )


@dataclass(frozen=True, kw_only=True, slots=True)
class ChannelRecord:
    """A Channel record's fields."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: Mapping[str, str]

    def encode(self) -> bytes:
        """The full record."""
        return _record(
            OP_CHANNEL,
            _U16.pack(self.id)
            + _U16.pack(self.schema_id)
            + _string(self.topic)
            + _string(self.message_encoding)
            + _map(self.metadata),
        )


@dataclass(kw_only=True, slots=True)
class _Stats:
    """Running totals for the Statistics record and rosbag2's metadata."""

    message_count: int = 0
    start_ns: int = 2**64 - 1
    end_ns: int = 0
    counts: NDArray[np.int64] = field(default_factory=lambda: np.zeros(1, dtype=np.int64))

    @property
    def channel_counts(self) -> dict[int, int]:
        """Messages per channel id (channels without messages left out)."""
        return {ch: int(n) for ch, n in enumerate(self.counts.tolist()) if n}

    def add(self, channels: NDArray[np.uint16], times: NDArray[np.uint64]) -> None:
        if channels.size == 0:
            return
        self.add_counts(np.bincount(channels), int(channels.size), int(times.min()), int(times.max()))

    def add_counts(self, per_channel: NDArray[np.int64], n: int, start_ns: int, end_ns: int) -> None:
        """Add `n` messages from `start_ns` to `end_ns`, `per_channel[ch]` of them on channel `ch`."""
        self.message_count += n
        self.start_ns = min(self.start_ns, start_ns)
        self.end_ns = max(self.end_ns, end_ns)
        if per_channel.size > self.counts.size:
            self.counts = np.concatenate((self.counts, np.zeros(per_channel.size - self.counts.size, dtype=np.int64)))
        self.counts[: per_channel.size] += per_channel


def _chunk_index(
    *,
    start_ns: int,
    end_ns: int,
    chunk_offset: int,
    chunk_length: int,
    index_offsets: Mapping[int, int] | bytes,
    index_length: int,
    size: int,
    compression: str = "",
    compressed_size: int | None = None,
) -> bytes:
    """A ChunkIndex record; `index_offsets` maps channels to MessageIndex offsets (or is that map's bytes)."""
    if isinstance(index_offsets, bytes):
        offsets = index_offsets
    else:
        offsets = b"".join(_U16.pack(ch) + _U64.pack(off) for ch, off in index_offsets.items())
    content = (
        struct.pack("<QQQQ", start_ns, end_ns, chunk_offset, chunk_length)
        + _U32.pack(len(offsets))
        + offsets
        + _U64.pack(index_length)
        + _string(compression)
        + _U64.pack(size if compressed_size is None else compressed_size)
        + _U64.pack(size)
    )
    return _record(OP_CHUNK_INDEX, content)


def _message_indexes(
    channels: NDArray[np.uint16], times: NDArray[np.uint64], offsets: NDArray[np.uint64], base: int
) -> tuple[bytes, dict[int, int]]:
    """MessageIndex records for one chunk (one per channel) and each record's file offset."""
    order = np.argsort(channels, kind="stable")  # per channel, in time order
    entries = np.empty(channels.size, dtype=_INDEX_ENTRY)
    entries["time"] = times[order]
    entries["offset"] = offsets[order]
    raw = memoryview(entries.tobytes())
    sorted_channels = channels[order]
    cuts = (np.flatnonzero(sorted_channels[1:] != sorted_channels[:-1]) + 1).tolist()
    starts = [0, *cuts]
    parts: list[bytes | memoryview] = []
    where: dict[int, int] = {}
    pos = base
    for ch, a, b in zip(sorted_channels[starts].tolist(), starts, [*cuts, channels.size], strict=True):
        size = 16 * (b - a)
        parts.append(_INDEX_HEAD.pack(OP_MESSAGE_INDEX, 6 + size, ch, size))
        parts.append(raw[16 * a : 16 * b])
        where[ch] = pos
        pos += _INDEX_HEAD.size + size
    return b"".join(parts), where


class McapWriter:
    """Writes an MCAP file in chunks, each chunk on disk as soon as it is written.

    Not thread-safe; one writer per file. Every method that touches the file may raise
    `OSError` (e.g. ENOSPC); `truncate_to_good_end()` then cuts the file back to its last complete
    record, which keeps it recoverable.
    """

    def __init__(
        self,
        path: Path,
        *,
        library: str,
        profile: str = "ros2",
        fsync: bool = False,
        chunk_crc: bool = False,
        native: bool = True,
    ) -> None:
        """Create `path` (it must not exist) and write the magic and the Header record.

        Args:
            path: The file to create.
            library: The Header's `library` field.
            profile: The Header's `profile` field (`ros2` for ROS 2 bags).
            fsync: Sync the file after every record batch.
            chunk_crc: Store a CRC32 of each chunk (rosbag2 does not: it costs ~0.2 µs per message).
            native: Build chunks with the compiled kernel (`twin.bag._native`) when it is available;
                the numpy path gives the same bytes.
        """
        self.path = path
        self._fsync = fsync
        self._chunk_crc = chunk_crc
        self._file = open(path, "xb", buffering=0)  # noqa: SIM115 - closed by finish()/close()
        self._pos = 0
        self.good_end = 0  #: file offset just after the last complete record
        self.schemas: dict[int, SchemaRecord] = {}
        self.channels: dict[int, ChannelRecord] = {}
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self.stats = _Stats()
        self._closed = False
        # The compiled chunk builder and its buffers, grown as needed. Loaded here, not at the first
        # batch: building it on a cold cache inside a flush would stall the recording, and the
        # recorder's wall-clock flushes would then cut chunks where a warm cache's run does not.
        self._native = native
        self._kernel: Any = (load_chunk_kernel() or False) if native else None
        self._inputs = np.zeros((3, 0), dtype=np.int64)  # channels, times, lengths
        self._out = np.zeros(0, dtype=np.uint8)
        self._work = np.zeros(0, dtype=np.int64)
        self._input_ptrs, self._out_ptr, self._work_ptr = (0, 0, 0), 0, 0
        self._write_data(MAGIC + _record(OP_HEADER, _string(profile) + _string(library)))

    # -- low level -------------------------------------------------------------------------

    def _write_raw(self, data: bytes | memoryview) -> None:
        view = memoryview(data)
        while view:
            written = self._file.write(view)
            if written is None or written <= 0:  # pragma: no cover - a regular file never returns 0
                raise OSError(f"short write to {self.path}")
            view = view[written:]
        self._pos += len(data)

    def _write_data(self, data: bytes | memoryview) -> None:
        """Append complete data-section records; the file is consistent after it returns.

        If the write is interrupted (an error, or Ctrl-C between two partial writes), the file is
        cut back to its last complete record before the exception propagates.
        """
        try:
            self._write_raw(data)
        except BaseException:
            with contextlib.suppress(OSError):
                self.truncate_to_good_end()
            raise
        self.good_end = self._pos
        if self._fsync:
            os.fsync(self._file.fileno())

    def truncate_to_good_end(self) -> None:
        """Drop a partially written record (after a failed write), keeping the file recoverable."""
        if self._closed:
            return
        self._file.truncate(self.good_end)
        self._file.seek(self.good_end)
        self._pos = self.good_end

    # -- records ---------------------------------------------------------------------------

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Write a Schema record; return its id."""
        schema = SchemaRecord(id=len(self.schemas) + 1, name=name, encoding=encoding, data=data)
        self._write_data(schema.encode())
        self.schemas[schema.id] = schema
        return schema.id

    def add_channel(self, topic: str, schema_id: int, message_encoding: str, metadata: Mapping[str, str]) -> int:
        """Write a Channel record; return its id."""
        channel = ChannelRecord(
            id=len(self.channels) + 1,
            schema_id=schema_id,
            topic=topic,
            message_encoding=message_encoding,
            metadata=dict(metadata),
        )
        self._write_data(channel.encode())
        self.channels[channel.id] = channel
        return channel.id

    def add_metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Write a Metadata record (and remember its index for the summary)."""
        offset = self._pos
        record = _record(OP_METADATA, _string(name) + _map(values))
        self._write_data(record)
        self._metadata_indexes.append(
            _record(OP_METADATA_INDEX, _U64.pack(offset) + _U64.pack(len(record)) + _string(name))
        )

    def write_batch(self, batch: Sequence[tuple[int, int, bytes]]) -> None:
        """Write `(channel_id, log_time_ns, data)` messages as one chunk and its message indexes.

        Raises:
            ValueError: If a channel id is unknown, a time is negative or data is not bytes (nothing
                is written).
            OSError: If the file cannot be written.
        """
        n = len(batch)
        if n == 0:
            return
        if self._kernel is None and self._native:
            self._kernel = load_chunk_kernel() or False
        try:
            handles, stamps, datas = zip(*batch, strict=True)
            channels = np.fromiter(handles, dtype=np.int64, count=n)
            times = np.fromiter(stamps, dtype=np.int64, count=n)
            lengths = np.fromiter(map(len, datas), dtype=np.int64, count=n)
            blob = b"".join(datas) if self._kernel else b""
        except (OverflowError, TypeError, ValueError) as err:
            msg = f"message handles and times must be integers and data bytes: {err}"
            raise ValueError(msg) from None
        if not (self._kernel and self._chunk_native(channels, times, lengths, blob)):
            self._chunk_numpy(channels, times, lengths, datas)

    def _chunk_native(
        self, channels: NDArray[np.int64], times: NDArray[np.int64], lengths: NDArray[np.int64], blob: bytes
    ) -> bool:
        """Write the chunk through the compiled kernel; False (nothing written) for a batch it does not take."""
        n, n_channels = channels.size, len(self.channels)
        if n > self._inputs.shape[1]:
            self._inputs = np.zeros((3, 2 * n), dtype=np.int64)
            at, row = self._inputs.ctypes.data, self._inputs.strides[0]
            self._input_ptrs = (at, at + row, at + 2 * row)
        work_size = 2 * (n_channels + 1) + 4 + (10 * n_channels) // 8 + 1
        if work_size > self._work.size:
            self._work = np.zeros(2 * work_size, dtype=np.int64)
            self._work_ptr = self._work.ctypes.data
        bound = 9 + 40 + len(blob) + 31 * n + 15 * n_channels + 16 * n
        if bound > self._out.size:
            self._out = np.zeros(2 * bound, dtype=np.uint8)
            self._out_ptr = self._out.ctypes.data
        inputs, out, work = self._inputs, self._out, self._work
        inputs[0, :n] = channels
        inputs[1, :n] = times
        inputs[2, :n] = lengths
        chunk_offset = self._pos
        status = self._kernel.twin_mcap_chunk(
            n, *self._input_ptrs, blob, n_channels, chunk_offset, self._out_ptr, self._work_ptr
        )
        if status:
            return False
        info = 2 * (n_channels + 1)
        total, chunk_length, records_size, present = work[info : info + 4].tolist()
        chunk = out.data
        if self._chunk_crc:
            _U32.pack_into(chunk, 9 + 24, zlib.crc32(chunk[9 + 40 : chunk_length]))
        self._write_data(chunk[:total])
        start_ns, end_ns = int(times[0]), int(times[-1])
        self.stats.add_counts(work[: n_channels + 1], n, start_ns, end_ns)
        map_at = 8 * (info + 4)
        self._chunk_indexes.append(
            _chunk_index(
                start_ns=start_ns,
                end_ns=end_ns,
                chunk_offset=chunk_offset,
                chunk_length=chunk_length,
                index_offsets=work.view(np.uint8)[map_at : map_at + 10 * present].tobytes(),
                index_length=total - chunk_length,
                size=records_size,
            )
        )
        return True

    def _chunk_numpy(
        self,
        channels: NDArray[np.int64],
        times: NDArray[np.int64],
        lengths: NDArray[np.int64],
        datas: tuple[bytes, ...],
    ) -> None:
        """Write the chunk with numpy: any batch, sorted by time here; names a bad channel or time."""
        n = channels.size
        if channels.min() < 1 or channels.max() > len(self.channels):
            bad = int(channels[(channels < 1) | (channels > len(self.channels))][0])
            msg = f"unknown topic handle {bad}"
            raise ValueError(msg)
        if times.min() < 0:
            msg = f"negative message time {int(times.min())} ns"
            raise ValueError(msg)
        if np.any(times[1:] < times[:-1]):  # keep chunks in time order, ties in write order
            order = np.argsort(times, kind="stable")
            channels, times, lengths = channels[order], times[order], lengths[order]
            datas = tuple(map(datas.__getitem__, order.tolist()))
        heads = np.zeros(n, dtype=_MESSAGE_HEAD)
        heads["op"] = OP_MESSAGE
        heads["length"] = lengths + (_MESSAGE_HEAD_SIZE - 9)
        heads["channel"] = channels
        heads["log"] = times
        heads["publish"] = times
        sizes = lengths + _MESSAGE_HEAD_SIZE
        records_size = int(sizes.sum())
        offsets = (np.cumsum(sizes) - sizes).astype(np.uint64)
        start_ns, end_ns = int(times[0]), int(times[-1])
        # One buffer for the chunk record and its message indexes: prefix, (head, data)*, indexes.
        head_size = _CHUNK_HEAD.size + 4 + 8  # + compression "" + records length
        chunk_length = 9 + head_size + records_size
        chunk_offset = self._pos
        ch16 = channels.astype(np.uint16)
        t64 = times.astype(np.uint64)
        indexes, index_offsets = _message_indexes(ch16, t64, offsets, chunk_offset + chunk_length)
        parts: list[bytes] = [b""] * (2 * n + 2)
        parts[1:-1:2] = heads.view(f"V{_MESSAGE_HEAD_SIZE}").tolist()
        parts[2:-1:2] = datas
        parts[-1] = indexes
        crc = zlib.crc32(b"".join(parts[1:-1])) if self._chunk_crc else 0
        parts[0] = (
            _RECORD.pack(OP_CHUNK, head_size + records_size)
            + _CHUNK_HEAD.pack(start_ns, end_ns, records_size, crc)
            + _string("")
            + _U64.pack(records_size)
        )
        try:
            buffer = b"".join(parts)
        except TypeError as err:
            msg = f"message handles and times must be integers and data bytes: {err}"
            raise ValueError(msg) from None
        self._write_data(buffer)
        self.stats.add(ch16, t64)
        self._chunk_indexes.append(
            _chunk_index(
                start_ns=start_ns,
                end_ns=end_ns,
                chunk_offset=chunk_offset,
                chunk_length=chunk_length,
                index_offsets=index_offsets,
                index_length=len(indexes),
                size=records_size,
            )
        )

    # -- closing ---------------------------------------------------------------------------

    def finish(self) -> None:
        """Write DataEnd, the summary section, the Footer and the closing magic; close the file."""
        if self._closed:
            return
        self._write_raw(_record(OP_DATA_END, _U32.pack(0)))  # 0: no data-section CRC, as rosbag2 writes
        summary = _summary_section(
            start=self._pos,
            schemas=list(self.schemas.values()),
            channels=list(self.channels.values()),
            stats=self.stats,
            chunk_indexes=self._chunk_indexes,
            metadata_indexes=self._metadata_indexes,
        )
        self._write_raw(summary)
        if self._fsync:
            os.fsync(self._file.fileno())
        self.close()

    def close(self) -> None:
        """Close the file as it is (without a summary if `finish()` was not called)."""
        if not self._closed:
            self._closed = True
            self._file.close()


def _summary_section(
    *,
    start: int,
    schemas: Sequence[SchemaRecord],
    channels: Sequence[ChannelRecord],
    stats: _Stats,
    chunk_indexes: Sequence[bytes],
    metadata_indexes: Sequence[bytes],
) -> bytes:
    """The summary section, summary offsets, Footer and closing magic, for a summary at `start`."""
    groups: list[tuple[int, bytes]] = [
        (OP_SCHEMA, b"".join(s.encode() for s in schemas)),
        (OP_CHANNEL, b"".join(c.encode() for c in channels)),
        (OP_STATISTICS, _statistics(stats, len(schemas), len(channels), len(chunk_indexes), len(metadata_indexes))),
        (OP_CHUNK_INDEX, b"".join(chunk_indexes)),
        (OP_METADATA_INDEX, b"".join(metadata_indexes)),
    ]
    body = bytearray()
    offsets = bytearray()
    for op, group in groups:
        if group:
            offsets += _record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, start + len(body), len(group)))
            body += group
    offset_start = start + len(body)
    summary = bytes(body + offsets)
    footer_head = _RECORD.pack(OP_FOOTER, 20) + struct.pack("<QQ", start, offset_start)
    crc = zlib.crc32(footer_head, zlib.crc32(summary))
    return summary + footer_head + _U32.pack(crc) + MAGIC


def _statistics(stats: _Stats, schemas: int, channels: int, chunks: int, metadata: int) -> bytes:
    counts = b"".join(_U16.pack(ch) + _U64.pack(n) for ch, n in sorted(stats.channel_counts.items()))
    start = stats.start_ns if stats.message_count else 0
    content = (
        _STATS_HEAD.pack(stats.message_count, schemas, channels, 0, metadata, chunks)
        + struct.pack("<QQ", start, stats.end_ns)
        + _U32.pack(len(counts))
        + counts
    )
    return _record(OP_STATISTICS, content)


# ---------------------------------------------------------------------------------------------
# Reading what a (possibly killed) writer left


class _Cursor:
    """Reads little-endian fields from a bytes object, raising ValueError past its end."""

    __slots__ = ("data", "pos")

    def __init__(self, data: bytes | memoryview, pos: int = 0) -> None:
        self.data = data
        self.pos = pos

    def take(self, n: int) -> bytes:
        end = self.pos + n
        if end > len(self.data):
            raise ValueError("record truncated")
        out = bytes(self.data[self.pos : end])
        self.pos = end
        return out

    def u16(self) -> int:
        return int(_U16.unpack(self.take(2))[0])

    def u32(self) -> int:
        return int(_U32.unpack(self.take(4))[0])

    def u64(self) -> int:
        return int(_U64.unpack(self.take(8))[0])

    def string(self) -> str:
        return self.take(self.u32()).decode()

    def mapping(self) -> dict[str, str]:
        length = self.u32()
        end = self.pos + length
        out: dict[str, str] = {}
        while self.pos < end:
            key = self.string()
            out[key] = self.string()
        if self.pos != end:
            raise ValueError("map entries run past the map's length")
        return out


@dataclass(kw_only=True, slots=True)
class _ChunkInfo:
    offset: int
    length: int
    start_ns: int
    end_ns: int
    size: int
    compression: str
    compressed_size: int
    channels: NDArray[np.uint16]
    times: NDArray[np.uint64]
    offsets: NDArray[np.uint64]
    index_offsets: dict[int, int] = field(default_factory=dict)
    index_length: int = 0
    #: Schema and Channel records written inside the chunk (other writers put them there).
    schemas: list[SchemaRecord] = field(default_factory=list)
    channel_records: list[ChannelRecord] = field(default_factory=list)
    first_data: bytes = b""  #: the data of the chunk's first message (tells a per-message compression)


@dataclass(kw_only=True, slots=True)
class McapScan:
    """What a pass over an MCAP file's data section found."""

    library: str = ""
    header: bytes = b""  #: the Header record as found (empty if it was damaged)
    schemas: dict[int, SchemaRecord] = field(default_factory=dict)
    channels: dict[int, ChannelRecord] = field(default_factory=dict)
    metadata: list[tuple[int, int, str, dict[str, str]]] = field(default_factory=list)  # offset, length, name, map
    chunks: list[_ChunkInfo] = field(default_factory=list)
    loose_messages: int = 0  #: Message records outside chunks (counted, not indexed)
    #: Data-section records a rebuilt file keeps, in file order: (opcode, offset, length).
    kept: list[tuple[int, int, int]] = field(default_factory=list)
    #: Byte ranges skipped as damaged (a record that did not parse, up to the next valid one).
    damaged: list[tuple[int, int]] = field(default_factory=list)
    data_end: int = 0  #: offset just after the last complete data record (at DataEnd: its offset)
    found_data_end: bool = False  #: the scan reached the DataEnd record
    complete: bool = False  #: undamaged, with DataEnd, a summary that agrees with the data and the Footer
    file_size: int = 0

    def stats(self) -> _Stats:
        """Message totals per channel over all complete chunks."""
        stats = _Stats()
        for chunk in self.chunks:
            stats.add(chunk.channels, chunk.times)
        return stats


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    # Other writers' chunks; zstd comes with the standard library (3.14) or with rosbags:
    # backports.zstd from its later 0.11 releases, zstandard before.
    if compression == "zstd":
        for name in ("compression.zstd", "backports.zstd"):
            try:
                return bytes(importlib.import_module(name).decompress(data))
            except ImportError:
                continue
        return bytes(importlib.import_module("zstandard").ZstdDecompressor().decompressobj().decompress(data))
    if compression == "lz4":
        return bytes(importlib.import_module("lz4.frame").decompress(data))
    msg = f"unsupported chunk compression {compression!r}"
    raise ValueError(msg)


_COMPRESSIONS = frozenset({"", "zstd", "lz4"})


def _parse_chunk(view: memoryview, offset: int, length: int) -> _ChunkInfo:
    """Parse the Chunk record at `offset`, checking that every field agrees with the others.

    Raises:
        ValueError: If the chunk is damaged: its length, sizes, CRC (when the writer stored one),
            inner records or message times disagree.
    """
    cur = _Cursor(view, offset + 9)
    start_ns, end_ns, size = cur.u64(), cur.u64(), cur.u64()
    crc = cur.u32()
    compression = cur.string()
    if compression not in _COMPRESSIONS:
        msg = f"unknown chunk compression {compression[:20]!r}"
        raise ValueError(msg)
    compressed_size = cur.u64()
    if cur.pos + compressed_size != offset + length or (not compression and compressed_size != size):
        msg = "chunk sizes disagree with its record length"
        raise ValueError(msg)
    try:
        records = _decompress(compression, cur.take(compressed_size), size)
    except ValueError:
        raise
    except Exception as err:  # each decompressor has its own error type for a damaged frame
        msg = f"chunk does not decompress: {err}"
        raise ValueError(msg) from None
    if len(records) != size or (crc and zlib.crc32(records) != crc):
        msg = "chunk CRC or size mismatch"
        raise ValueError(msg)
    channels: list[int] = []
    times: list[int] = []
    offsets: list[int] = []
    schemas: list[SchemaRecord] = []
    channel_records: list[ChannelRecord] = []
    first_data = b""
    inner = _Cursor(records)
    while inner.pos < len(records):
        rec_start = inner.pos
        op = inner.take(1)[0]
        rec_len = inner.u64()
        body = _Cursor(inner.take(rec_len))
        if op == OP_MESSAGE:
            if rec_len < 22:
                msg = "message record too short"
                raise ValueError(msg)
            channels.append(body.u16())
            body.u32()
            times.append(body.u64())
            offsets.append(rec_start)
            if not first_data:
                first_data = bytes(body.data[22:])  # after channel, sequence, log and publish time
        elif op == OP_SCHEMA:
            schemas.append(_schema_record(body, exact=True))
        elif op == OP_CHANNEL:
            channel_records.append(_channel_record(body, exact=True))
        else:
            msg = f"record with opcode {op:#x} inside a chunk"
            raise ValueError(msg)
    if times and (min(times) < start_ns or max(times) > end_ns):
        msg = "message times outside the chunk's time range"
        raise ValueError(msg)
    return _ChunkInfo(
        offset=offset,
        length=length,
        start_ns=start_ns,
        end_ns=end_ns,
        size=size,
        compression=compression,
        compressed_size=compressed_size,
        channels=np.array(channels, dtype=np.uint16),
        times=np.array(times, dtype=np.uint64),
        offsets=np.array(offsets, dtype=np.uint64),
        schemas=schemas,
        channel_records=channel_records,
        first_data=bytes(first_data),
    )


def _exact(cur: _Cursor, exact: bool) -> None:
    if exact and cur.pos != len(cur.data):
        msg = "record length disagrees with its fields"
        raise ValueError(msg)


def _schema_record(cur: _Cursor, *, exact: bool = False) -> SchemaRecord:
    sid = cur.u16()
    name, encoding = cur.string(), cur.string()
    record = SchemaRecord(id=sid, name=name, encoding=encoding, data=cur.take(cur.u32()))
    _exact(cur, exact)
    return record


def _channel_record(cur: _Cursor, *, exact: bool = False) -> ChannelRecord:
    cid, sid = cur.u16(), cur.u16()
    topic, encoding = cur.string(), cur.string()
    record = ChannelRecord(id=cid, schema_id=sid, topic=topic, message_encoding=encoding, metadata=cur.mapping())
    _exact(cur, exact)
    return record


def _records(view: memoryview, pos: int) -> Iterator[tuple[int, int, int]]:
    """Yield `(opcode, offset, length)` of complete records from `pos` until the first incomplete one."""
    size = len(view)
    while pos + 9 <= size:
        op, length = _RECORD.unpack_from(view, pos)
        if pos + 9 + length > size:
            return
        yield op, pos, length
        pos += 9 + length


#: Records a scan resynchronises on after damage: what writers put between chunks.
_RESYNC_OPS = (OP_SCHEMA, OP_CHANNEL, OP_CHUNK, OP_METADATA, OP_DATA_END)
#: Summary-section records, skipped by length if met in the data section.
_SUMMARY_OPS = frozenset({OP_CHUNK_INDEX, 0x0A, OP_STATISTICS, OP_METADATA_INDEX, OP_SUMMARY_OFFSET})
_OP_ATTACHMENT = 0x09


def _body(view: memoryview, offset: int, length: int) -> _Cursor:
    """A cursor over one record's content only (so a field cannot read into the next record)."""
    return _Cursor(view[offset + 9 : offset + 9 + length])


def _take_record(scan: McapScan, view: memoryview, op: int, offset: int, length: int) -> bool:
    """Parse one data-section record into `scan`; True at DataEnd.

    Raises:
        ValueError: If the record is damaged (it does not parse exactly as its opcode says).
    """
    cur = _body(view, offset, length)
    if op == OP_CHUNK:
        chunk = _parse_chunk(view, offset, 9 + length)
        scan.chunks.append(chunk)
        scan.schemas.update((schema.id, schema) for schema in chunk.schemas)
        scan.channels.update((channel.id, channel) for channel in chunk.channel_records)
    elif op == OP_MESSAGE_INDEX:
        cur.u16()
        if cur.u32() != length - 6 or (length - 6) % 16:
            msg = "message index length disagrees with its entries"
            raise ValueError(msg)
        return False  # rebuilt from its chunk, never copied
    elif op == OP_SCHEMA:
        schema = _schema_record(cur, exact=True)
        scan.schemas[schema.id] = schema
    elif op == OP_CHANNEL:
        channel = _channel_record(cur, exact=True)
        scan.channels[channel.id] = channel
    elif op == OP_METADATA:
        name = cur.string()
        values = cur.mapping()
        _exact(cur, True)
        scan.metadata.append((offset, 9 + length, name, values))
    elif op == OP_MESSAGE:
        if length < 22:
            msg = "message record too short"
            raise ValueError(msg)
        scan.loose_messages += 1
    elif op == OP_DATA_END:
        if length != 4:
            msg = "DataEnd record of the wrong length"
            raise ValueError(msg)
        return True
    elif op in _SUMMARY_OPS:
        return False  # an index out of place: rebuilt, never copied
    elif op != _OP_ATTACHMENT:
        msg = f"unknown record opcode {op:#x}"
        raise ValueError(msg)
    scan.kept.append((op, offset, 9 + length))
    return False


def _valid_at(view: memoryview, pos: int) -> bool:
    """Whether a data-section record that a resync can start from begins at `pos`.

    A chunk checks itself (lengths, sizes, inner records); any other record must parse exactly
    and be followed by the start of another record (DataEnd: by the Footer).
    """
    size = len(view)
    op, length = _RECORD.unpack_from(view, pos)
    end = pos + 9 + length
    if end > size:
        return False
    try:
        _take_record(McapScan(), view, op, pos, length)
    except (ValueError, UnicodeDecodeError, struct.error):
        return False
    if op == OP_CHUNK:
        return True
    if op == OP_DATA_END:
        return _has_footer(view)
    if end + 9 > size:
        return False
    next_op, next_length = _RECORD.unpack_from(view, end)
    return next_op in (*_RESYNC_OPS, OP_MESSAGE_INDEX) and end + 9 + next_length <= size


def _resync(view: memoryview, start: int) -> int | None:
    """The offset of the next valid record at or after `start`, or None if there is none.

    Candidates are found with numpy (an opcode a writer puts between chunks, then a length below
    4 GiB that fits in the file), and checked one by one, nearest first.
    """
    arr = np.frombuffer(view, dtype=np.uint8)
    size = arr.size
    lo, window = start, 1 << 20
    while lo + 9 <= size:
        hi = min(size - 8, lo + window)
        n = hi - lo
        seg = arr[lo : hi + 8]
        mask = np.isin(seg[:n], _RESYNC_OPS)
        for k in range(5, 9):  # the length's high four bytes
            mask &= seg[k : k + n] == 0
        for i in np.flatnonzero(mask).tolist():
            if _valid_at(view, lo + i):
                return int(lo + i)
        lo, window = hi, window * 4
    return None


def _header_at(view: memoryview, pos: int) -> bool:
    if pos + 9 > len(view):
        return False
    op, length = _RECORD.unpack_from(view, pos)
    if op != OP_HEADER or pos + 9 + length > len(view):
        return False
    cur = _body(view, pos, length)
    try:
        cur.string()
        cur.string()
    except (ValueError, UnicodeDecodeError):
        return False
    return bool(cur.pos == length)


def scan_mcap(path: Path) -> McapScan:
    """Scan an MCAP file that may end anywhere (a killed writer) or hold damaged records.

    A record that does not parse as its opcode says (a chunk whose sizes, CRC, inner records or
    times disagree; a schema, channel or metadata record whose fields do not fill its length) is
    skipped up to the next valid record, which chunks' own lengths and checks make findable: one
    damaged chunk costs that chunk, not what follows it. A file that ends inside a record (a
    killed writer) keeps every complete record before it.

    Raises:
        ValueError: If the file is not MCAP (bad magic and no Header record after it).
        OSError: If it cannot be read.
    """
    data = path.read_bytes()
    view = memoryview(data)
    scan = McapScan(file_size=len(data))
    if data[:8] != MAGIC:
        if not _header_at(view, 8):
            msg = "not an MCAP file (bad magic)"
            raise ValueError(msg)
        scan.damaged.append((0, 8))
    size = len(data)
    pos = 8
    if _header_at(view, pos):
        _op, length = _RECORD.unpack_from(view, pos)
        cur = _body(view, pos, length)
        cur.string()
        scan.library = cur.string()
        scan.header = bytes(view[pos : pos + 9 + length])
        pos += 9 + length
    scan.data_end = pos
    while pos + 9 <= size:
        op, length = _RECORD.unpack_from(view, pos)
        try:
            if pos + 9 + length > size:
                msg = "record runs past the end of the file"
                raise ValueError(msg)
            at_end = _take_record(scan, view, op, pos, length)
        except (ValueError, UnicodeDecodeError, struct.error) as err:
            resumed = _resync(view, pos + 1)
            if resumed is None:
                if pos + 9 + length <= size:  # not a cut-off tail: a damaged record
                    scan.damaged.append((pos, size))
                    _log.warning("%s: record at byte %d is damaged (%s); nothing valid follows it", path, pos, err)
                break
            _log.warning(
                "%s: bytes %d to %d are damaged (%s); skipped to the next valid record",
                path,
                pos,
                resumed,
                err,
            )
            scan.damaged.append((pos, resumed))
            pos = resumed
            continue
        if at_end:
            scan.data_end = pos
            scan.found_data_end = True
            _add_summary_definitions(scan, view)
            _check_channels(scan, path)
            scan.complete = not scan.damaged and _summary_agrees(scan, view)
            return scan
        pos += 9 + length
        scan.data_end = pos
    _add_summary_definitions(scan, view)
    _check_channels(scan, path)
    return scan


def _check_channels(scan: McapScan, path: Path) -> None:
    """Count a chunk with messages on a channel defined nowhere as damaged (a flipped channel id, a lost channel)."""
    for chunk in scan.chunks:
        unknown = set(np.unique(chunk.channels).tolist()) - scan.channels.keys()
        if unknown:
            _log.warning(
                "%s: the chunk at byte %d has messages on undefined channel %d; it is damaged",
                path,
                chunk.offset,
                min(unknown),
            )
            scan.damaged.append((chunk.offset, chunk.offset + chunk.length))
    scan.damaged.sort()


def _summary_span(view: memoryview) -> tuple[int, int, int] | None:
    """(summary start, footer offset, footer CRC) of a file that ends with its Footer, else None."""
    if not _has_footer(view):
        return None
    footer = len(view) - 8 - _FOOTER.size
    _op, _length, summary_start, _offsets_start, crc = _FOOTER.unpack_from(view, footer)
    if not 8 < summary_start <= footer:
        return None
    return summary_start, footer, crc


def _add_summary_definitions(scan: McapScan, view: memoryview) -> None:
    """Add the summary's schemas and channels that the data section lost to damage.

    The summary is found from the Footer; with the Footer or the closing magic damaged, from the
    DataEnd record, which the summary section follows. Only records that parse exactly are taken.
    """
    span = _summary_span(view)
    if span is not None:
        start, end = span[0], span[1]
    elif scan.found_data_end:  # after the DataEnd record, up to the first broken record
        start, end = scan.data_end + 9 + _RECORD.unpack_from(view, scan.data_end)[1], len(view)
    else:
        return
    for op, offset, length in _records(view[:end], start):
        try:
            if op == OP_SCHEMA:
                schema = _schema_record(_body(view, offset, length), exact=True)
                scan.schemas.setdefault(schema.id, schema)
            elif op == OP_CHANNEL:
                channel = _channel_record(_body(view, offset, length), exact=True)
                scan.channels.setdefault(channel.id, channel)
        except (ValueError, UnicodeDecodeError, struct.error):
            continue


def _summary_agrees(scan: McapScan, view: memoryview) -> bool:
    """Whether the summary section is intact and describes the data section the scan found."""
    if not _has_footer(view):
        return False
    footer = len(view) - 8 - _FOOTER.size
    summary_start = _FOOTER.unpack_from(view, footer)[2]
    if summary_start == 0:
        return not scan.chunks  # no summary: fine for a file without chunks to index
    span = _summary_span(view)
    if span is None or span[0] < scan.data_end + 13:  # after the 13-byte DataEnd
        return False
    start, footer, crc = span
    if crc and zlib.crc32(view[start : footer + 9 + 16]) != crc:
        return False
    chunk_offsets: set[int] = set()
    count = None
    pos = start
    try:
        for op, offset, length in _records(view[:footer], start):
            cur = _body(view, offset, length)
            if op == OP_STATISTICS:
                count = _STATS_HEAD.unpack(cur.take(_STATS_HEAD.size))[0]
            elif op == OP_CHUNK_INDEX:
                cur.u64()
                cur.u64()
                chunk_offsets.add(cur.u64())
            pos = offset + 9 + length
    except ValueError:
        return False
    if pos != footer:
        return False
    if chunk_offsets != {c.offset for c in scan.chunks}:
        return False
    return count is None or count == scan.stats().message_count + scan.loose_messages


@dataclass(frozen=True, kw_only=True, slots=True)
class McapSummary:
    """What a complete MCAP file holds, as its summary section says."""

    schemas: dict[int, SchemaRecord]
    channels: dict[int, ChannelRecord]
    channel_counts: dict[int, int]  #: messages per channel id
    message_count: int
    start_ns: int  #: log time of the first message (0 without messages)
    end_ns: int  #: log time of the last message
    metadata: list[tuple[str, dict[str, str]]]  #: Metadata records: name, values


def read_mcap_summary(path: Path) -> McapSummary:
    """Describe a complete MCAP file from its summary section, found through the footer, without reading its data.

    A file whose summary lacks the statistics (optional in MCAP) is scanned whole instead.

    Raises:
        ValueError: If the file is not MCAP, or has no footer (a killed writer's file: run
            `recover_mcap` first).
        OSError: If the file cannot be read.
    """
    with path.open("rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(8) != MAGIC:
            msg = "not an MCAP file (bad magic)"
            raise ValueError(msg)
        head = f.read(9)
        if len(head) < 9 or head[0] != OP_HEADER or 17 + _RECORD.unpack_from(head)[1] > size:
            # (`twin bag recover` cannot help either: there is nothing to keep)
            msg = "the MCAP file ends before its header: nothing was recorded"
            raise ValueError(msg)
        tail = _FOOTER.size + len(MAGIC)
        f.seek(max(size - tail, 0))
        end = f.read(tail)
        if size < 8 + tail or end[-8:] != MAGIC or end[0] != OP_FOOTER:
            msg = "the MCAP file ends without its footer (a recording that was killed)"
            raise ValueError(msg)
        _op, _length, summary_start, _offsets_start, _crc = _FOOTER.unpack_from(end, 0)
        if not 8 <= summary_start <= size - tail:
            return _summary_by_scan(path)
        f.seek(summary_start)
        view = memoryview(f.read(size - tail - summary_start))
        schemas: dict[int, SchemaRecord] = {}
        channels: dict[int, ChannelRecord] = {}
        stats: tuple[int, int, int, dict[int, int]] | None = None
        metadata_at: list[tuple[int, int]] = []
        for op, offset, _len in _records(view, 0):
            cur = _Cursor(view, offset + 9)
            if op == OP_SCHEMA:
                schema = _schema_record(cur)
                schemas[schema.id] = schema
            elif op == OP_CHANNEL:
                channel = _channel_record(cur)
                channels[channel.id] = channel
            elif op == OP_STATISTICS:
                count, *_record_counts = _STATS_HEAD.unpack(cur.take(_STATS_HEAD.size))
                start_ns, end_ns = cur.u64(), cur.u64()
                entries = cur.take(cur.u32())
                counts = {ch: n for ch, n in struct.iter_unpack("<HQ", entries)}
                stats = (count, start_ns, end_ns, counts)
            elif op == OP_METADATA_INDEX:
                metadata_at.append((cur.u64(), cur.u64()))
        if stats is None:
            return _summary_by_scan(path)
        metadata = []
        for offset, length in metadata_at:
            f.seek(offset)
            cur = _Cursor(f.read(length), 9)
            name = cur.string()
            metadata.append((name, cur.mapping()))
    count, start_ns, end_ns, counts = stats
    return McapSummary(
        schemas=schemas,
        channels=channels,
        channel_counts=counts,
        message_count=count,
        start_ns=start_ns if count else 0,
        end_ns=end_ns if count else 0,
        metadata=metadata,
    )


def _summary_by_scan(path: Path) -> McapSummary:
    scan = scan_mcap(path)
    stats = scan.stats()
    return McapSummary(
        schemas=scan.schemas,
        channels=scan.channels,
        channel_counts=stats.channel_counts,
        message_count=stats.message_count,
        start_ns=stats.start_ns if stats.message_count else 0,
        end_ns=stats.end_ns,
        metadata=[(name, values) for _, _, name, values in scan.metadata],
    )


def mcap_has_footer(path: Path) -> bool:
    """Whether the MCAP file at `path` ends with its footer and magic (a killed writer's file does not)."""
    tail = _FOOTER.size + len(MAGIC)
    with path.open("rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size < len(MAGIC) + tail:
            return False
        f.seek(size - tail)
        end = f.read(tail)
    op, length, *_ = _FOOTER.unpack_from(end, 0)
    return bool(end[-8:] == MAGIC and op == OP_FOOTER and length == 20)


def _has_footer(view: memoryview) -> bool:
    if len(view) < 8 + _FOOTER.size + 8 or bytes(view[-8:]) != MAGIC:
        return False
    op, length, *_ = _FOOTER.unpack_from(view, len(view) - 8 - _FOOTER.size)
    return bool(op == OP_FOOTER and length == 20)


@dataclass(frozen=True, kw_only=True, slots=True)
class McapRecovery:
    """The outcome of `recover_mcap`."""

    scan: McapScan  #: the repaired file's scan (complete), or the source's if it was complete
    was_complete: bool  #: it already had its summary and footer, and nothing was damaged: nothing written
    dropped_bytes: int  #: bytes of the source not carried over (a partial record at its end, damaged records)
    damaged: tuple[tuple[int, int], ...]  #: byte ranges of the source skipped as damaged
    lost_messages: int  #: messages of undamaged chunks left out (their channel is defined nowhere)
    #: The source only lacked its end, as a killed writer leaves it: undamaged, no DataEnd. Anything
    #: else (damaged records, a summary or footer that does not check out) is damage.
    killed_writer: bool


_TEXT_SCHEMAS = ("ros2msg", "ros2idl", "jsonschema")


def _mend_schemas(schemas: Mapping[int, SchemaRecord]) -> dict[int, SchemaRecord]:
    """The schemas whose definition text is not UTF-8 (a flipped byte), mended; empty when none is.

    A type the twin knows gets its definition back whole (its text, byte for byte, as the twin
    writes it); another gets its bad bytes replaced by U+FFFD, so readers open the bag and fail, if
    at all, on that one type's messages.
    """
    from twin.bag.typesys import TypeRegistry
    from twin.core.errors import BagError

    out: dict[int, SchemaRecord] = {}
    registry: TypeRegistry | None = None
    for sid, schema in schemas.items():
        if schema.encoding not in _TEXT_SCHEMAS:
            continue
        try:
            schema.data.decode("utf-8")
            continue
        except UnicodeDecodeError:
            pass
        text = schema.data.decode("utf-8", "replace").encode("utf-8")
        if schema.encoding == "ros2msg":
            registry = registry or TypeRegistry()
            try:
                if registry.knows(schema.name):
                    text = registry.definition(schema.name).text.encode("utf-8")
            except BagError:
                pass
        out[sid] = dataclasses.replace(schema, data=text)
    if out:
        names = ", ".join(s.name for s in out.values())
        _log.warning("mended the definitions of %d damaged schema(s): %s", len(out), names)
    return out


def _loose_chunk(messages: Sequence[memoryview]) -> bytes:
    """An uncompressed Chunk record holding these Message records (time-sorted, as a writer's chunk)."""
    times = [_U64.unpack_from(m, 15)[0] for m in messages]  # op, length, channel, sequence, then log time
    order = sorted(range(len(messages)), key=times.__getitem__)
    records = b"".join(messages[i] for i in order)
    head = _CHUNK_HEAD.pack(times[order[0]], times[order[-1]], len(records), zlib.crc32(records))
    body = head + _string("") + _U64.pack(len(records)) + records
    return _RECORD.pack(OP_CHUNK, len(body)) + body


def recover_mcap(source: Path, target: Path) -> McapRecovery:
    """Write a complete MCAP file at `target` from what `source` holds; `source` is only read.

    Keeps every valid record of the data section (a damaged record is skipped up to the next
    valid one; a partial record at the end is dropped), writes fresh message indexes after each
    chunk, then DataEnd, a rebuilt summary (schemas, channels, statistics, chunk and metadata
    indexes) and the Footer. A complete, undamaged source is left alone and nothing is written.

    Raises:
        ValueError: If the source is not MCAP or holds no record at all.
        OSError: If the source cannot be read or the target written (it must not exist).
    """
    scan = scan_mcap(source)
    mended = _mend_schemas(scan.schemas)  # definitions whose text damage made them unreadable (no CRC covers them)
    if scan.complete and not mended:
        return McapRecovery(
            scan=scan, was_complete=True, dropped_bytes=0, damaged=(), lost_messages=0, killed_writer=False
        )
    scan.schemas.update(mended)
    if scan.data_end <= 8 and not scan.chunks:
        msg = "the file ends before its header: nothing was recorded"
        raise ValueError(msg)
    view = memoryview(source.read_bytes())
    kept_chunks = {c.offset: c for c in scan.chunks if set(np.unique(c.channels).tolist()) <= scan.channels.keys()}
    lost = sum(len(c.channels) for c in scan.chunks if c.offset not in kept_chunks)
    if lost:
        _log.warning("%s: %d messages of intact chunks left out: their channels are defined nowhere", source, lost)
    header = scan.header or _record(OP_HEADER, _string("ros2") + _string(scan.library or "twin bag recover"))
    parts: list[bytes | memoryview] = [MAGIC, header]
    parts += [s.encode() for s in scan.schemas.values()]
    parts += [c.encode() for c in scan.channels.values()]
    pos = sum(map(len, parts))
    chunks: list[_ChunkInfo] = []
    chunk_indexes: list[bytes] = []
    metadata_indexes: list[bytes] = []

    def add_chunk(record: bytes | memoryview, chunk: _ChunkInfo) -> None:
        """Append a chunk record and its fresh message indexes at `pos`."""
        nonlocal pos
        length = len(record)
        indexes, index_offsets = _message_indexes(chunk.channels, chunk.times, chunk.offsets, pos + length)
        parts.extend((record, indexes))
        chunks.append(chunk)
        chunk_indexes.append(
            _chunk_index(
                start_ns=chunk.start_ns,
                end_ns=chunk.end_ns,
                chunk_offset=pos,
                chunk_length=length,
                index_offsets=index_offsets,
                index_length=len(indexes),
                size=chunk.size,
                compression=chunk.compression,
                compressed_size=chunk.compressed_size,
            )
        )
        pos += length + len(indexes)

    # Message records outside any chunk (the records of a cut chunk, found again past its damage, or
    # an unchunked writer's) go into chunks of their own: indexed readers read chunked messages only.
    loose: list[memoryview] = []
    for op, offset, length in [*scan.kept, (-1, 0, 0)]:  # (-1: the end, which closes a run of loose messages)
        if op == OP_MESSAGE:
            if _U16.unpack_from(view, offset + 9)[0] in scan.channels:
                loose.append(view[offset : offset + length])
            else:
                lost += 1
            continue
        if loose:
            record = _loose_chunk(loose)
            add_chunk(record, _parse_chunk(memoryview(record), 0, len(record)))
            loose = []
        if op < 0 or op in (OP_SCHEMA, OP_CHANNEL) or (op == OP_CHUNK and offset not in kept_chunks):
            continue
        if op == OP_CHUNK:
            add_chunk(view[offset : offset + length], kept_chunks[offset])
            continue
        parts.append(view[offset : offset + length])
        if op == OP_METADATA:
            name = next(m[2] for m in scan.metadata if m[0] == offset)
            metadata_indexes.append(_record(OP_METADATA_INDEX, _U64.pack(pos) + _U64.pack(length) + _string(name)))
        pos += length
    data_end = _record(OP_DATA_END, _U32.pack(0))
    parts.append(data_end)
    stats = _Stats()
    for chunk in chunks:
        stats.add(chunk.channels, chunk.times)
    parts.append(
        _summary_section(
            start=pos + len(data_end),
            schemas=list(scan.schemas.values()),
            channels=list(scan.channels.values()),
            stats=stats,
            chunk_indexes=chunk_indexes,
            metadata_indexes=metadata_indexes,
        )
    )
    with open(target, "xb") as out:
        for part in parts:
            out.write(part)
        out.flush()
        os.fsync(out.fileno())
    repaired = scan_mcap(target)
    damaged_to_end = bool(scan.damaged) and scan.damaged[-1][1] == scan.file_size
    tail = 0 if scan.found_data_end or damaged_to_end else scan.file_size - scan.data_end
    if not repaired.complete or repaired.stats().message_count != stats.message_count:
        msg = "the repaired file does not read back as written"  # a bug, never the input's fault
        raise RuntimeError(msg)
    return McapRecovery(
        scan=repaired,
        was_complete=False,
        dropped_bytes=sum(b - a for a, b in scan.damaged) + tail,
        damaged=tuple(scan.damaged),
        lost_messages=lost,
        killed_writer=not scan.damaged and not scan.found_data_end,
    )
