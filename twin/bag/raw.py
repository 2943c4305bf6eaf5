"""Raw messages in time order at a few hundred nanoseconds each: `read_raw` for passes over whole long bags.

`read_messages(..., decode=False)` goes through rosbags (a heap merge over connections and a
record parser per message, about 4 µs a message). Analysis reads every message of bags with
millions of them, so for MCAP files whose chunks follow each other in time (every writer that
flushes in order: the twin's recorder, rosbag2's) this walks the chunks directly: one read and
decompression per chunk, its message records located with `struct`, sorted by log time within
the chunk, and yielded as views into the chunk. Anything else (sqlite3, overlapping chunks,
several files) falls back to rosbags, with the same output.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from twin.bag.mcap_file import MAGIC, OP_CHANNEL, OP_CHUNK, OP_DATA_END, OP_FOOTER, OP_MESSAGE, _decompress
from twin.bag.reader import _bag_dir, bag_metadata, read_messages, storage_paths
from twin.core.errors import BagError
from twin.core.numbers import INT64_MAX

__all__ = ["raw_readable", "read_raw", "require_readable"]

_RECORD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MSG_HEAD = struct.Struct("<HIQQ")
_CHANNEL_HEAD = struct.Struct("<HH")


def _fast(bag: Path, topics: Sequence[str] | None) -> _McapChunks | None:
    meta = bag_metadata(bag)
    files = storage_paths(bag, meta)
    cdr = all(t.serialization_format == "cdr" for t in meta.topics)  # other formats: rosbags says what it reads
    if meta.storage_identifier == "mcap" and len(files) == 1 and not meta.compression_format and cdr:
        fast = _McapChunks(files[0], topics)
        if fast.in_order():
            return fast
    return None


def raw_readable(path: str | os.PathLike[str]) -> bool:
    """Whether `read_raw` reads this bag's file directly (a complete, in-order MCAP file).

    Raises:
        BagError: If `path` is not a bag (no such folder or file, no metadata.yaml).
    """
    return _fast(_bag_dir(path), None) is not None


def require_readable(path: str | os.PathLike[str]) -> None:
    """Raise the bag's one-line error now if its storage cannot be read (a truncated file: `twin bag recover`).

    `open_bag` reads such a bag from its metadata.yaml alone, with a warning, so that `twin bag info`
    still shows it; a command that goes on to read its messages calls this first, so that it says
    one error line, not a warning per `open_bag` and then the error.

    Raises:
        BagError: If it is not a bag, or its storage cannot be read.
    """
    if not raw_readable(path):
        for _ in read_messages(path, []):
            pass


def read_raw(
    path: str | os.PathLike[str], topics: Sequence[str] | None = None
) -> Iterator[tuple[str, int, bytes | memoryview]]:
    """Yield `(topic, record time ns, CDR bytes)` of the bag's messages in time order.

    The bytes may be a memoryview into a chunk: use them before the next message, or copy them.

    Raises:
        BagError: If the bag is unreadable (or a requested topic is missing, listing the bag's topics).
    """
    bag = _bag_dir(path)
    fast = _fast(bag, topics)
    if fast is not None:
        names = {t.name for t in bag_metadata(bag).topics}
        for name in topics or ():
            if name not in names:
                msg = f"{bag}: no topic {name!r}; it has {', '.join(sorted(names)) or 'no topics'}"
                raise BagError(msg)
        try:
            yield from fast.messages()
        except BagError:
            raise
        except Exception as err:  # a damaged chunk: a flipped length, compression name or channel record
            what = f"{type(err).__name__}: {err}".splitlines()[0]
            msg = f"{bag}: cannot read the bag ({what}); its storage is damaged: run `twin bag recover {bag}`"
            raise BagError(msg) from None
        return
    for m in read_messages(bag, topics, decode=False):
        yield m.topic, m.t_ns, m.msg


class _McapChunks:
    """The chunks of one MCAP file, walked in file order."""

    def __init__(self, path: Path, topics: Sequence[str] | None) -> None:
        self.path = path
        self._wanted = None if topics is None else set(topics)
        self._chunks: list[tuple[int, int, int, int]] = []  # offset, length, start ns, end ns
        self._channels: dict[int, str] = {}
        self._ok = self._index()

    def _index(self) -> bool:
        try:
            with self.path.open("rb") as f:
                if f.read(8) != MAGIC:
                    return False
                pos = 8
                size = os.fstat(f.fileno()).st_size
                while pos + 9 <= size:
                    f.seek(pos)
                    op, length = _RECORD.unpack(f.read(9))
                    if pos + 9 + length > size:
                        return False  # truncated: let the full reader say so
                    if op == OP_CHUNK:
                        start, end, _usize, _crc = _CHUNK_HEAD.unpack(f.read(_CHUNK_HEAD.size))
                        self._chunks.append((pos + 9, length, start, end))
                    elif op == OP_CHANNEL:
                        self._channel(f.read(length))
                    elif op == OP_MESSAGE:
                        return False  # messages outside chunks: the general reader handles them
                    elif op in (OP_DATA_END, OP_FOOTER):
                        return True
                    pos += 9 + length
        except (OSError, UnicodeDecodeError, struct.error):
            return False  # unreadable or damaged: the general reader, which skips damaged records, takes it
        return False  # no DataEnd: an unfinished file

    def _channel(self, body: bytes | memoryview) -> None:
        cid, _sid = _CHANNEL_HEAD.unpack_from(body, 0)
        (n,) = _U32.unpack_from(body, 4)
        self._channels[cid] = bytes(body[8 : 8 + n]).decode()

    def in_order(self) -> bool:
        """Whether the chunks can be walked as they are: complete, and each after the one before in time."""
        if not self._ok:
            return False
        last_end = -1
        for _off, _len, start, end in self._chunks:
            if start < last_end:
                return False
            last_end = end
        return True

    def messages(self) -> Iterator[tuple[str, int, memoryview]]:
        wanted, channels = self._wanted, self._channels
        with self.path.open("rb") as f:
            for offset, length, _start, _end in self._chunks:
                f.seek(offset)
                content = f.read(length)
                # start, end, uncompressed size, crc, compression string, records length, records
                (n,) = _U32.unpack_from(content, _CHUNK_HEAD.size)
                compression = content[_CHUNK_HEAD.size + 4 : _CHUNK_HEAD.size + 4 + n].decode()
                pos = _CHUNK_HEAD.size + 4 + n
                (csize,) = _U64.unpack_from(content, pos)
                (usize,) = _U64.unpack_from(content, _CHUNK_HEAD.size - 12)
                data = content[pos + 8 : pos + 8 + csize]
                records = memoryview(_decompress(compression, data, usize) if compression else data)
                yield from self._chunk_messages(records, wanted, channels)

    def _chunk_messages(
        self, records: memoryview, wanted: set[str] | None, channels: dict[int, str]
    ) -> Iterator[tuple[str, int, memoryview]]:
        unpack_rec, unpack_msg = _RECORD.unpack_from, _MSG_HEAD.unpack_from
        found: list[tuple[int, str, int, int]] = []
        pos, size = 0, len(records)
        while pos + 9 <= size:
            op, length = unpack_rec(records, pos)
            body = pos + 9
            if op == OP_MESSAGE:
                cid, _seq, log_time, _pub = unpack_msg(records, body)
                topic = channels.get(cid)
                if topic is not None and (wanted is None or topic in wanted):
                    found.append((log_time, topic, body + 22, body + length))
            elif op == OP_CHANNEL:
                self._channel(records[body : body + length])
                channels = self._channels
            pos = body + length
        times = np.fromiter((m[0] for m in found), dtype=np.uint64, count=len(found))
        if len(times) and int(times.max()) > INT64_MAX:  # MCAP stores uint64; a ROS time is int64
            msg = f"a message time past int64 ({int(times.max())} ns): a damaged record"
            raise ValueError(msg)
        if len(times) > 1 and bool(np.any(times[1:] < times[:-1])):
            found = [found[i] for i in np.argsort(times, kind="stable").tolist()]
        for log_time, topic, start, end in found:
            yield topic, log_time, records[start:end]
