"""The recorder: a rosbag2 folder (`<name>_0.mcap` or `.db3` plus `metadata.yaml`) written as it streams.

```python
from twin.bag import Recorder, ClockEncoder, ImuEncoder

with Recorder("bags/run1") as rec:               # MCAP, Humble-readable metadata (version 8)
    clock = rec.add_topic("/clock", ClockEncoder.msgtype)
    imu = rec.add_topic("/imu", ImuEncoder.msgtype)
    clock_enc, imu_enc = ClockEncoder(), ImuEncoder("imu_link")
    for k in range(1000):
        t_ns = k * 5_000_000
        rec.write(imu, t_ns, imu_enc.encode(t_ns, 0, 0, 0, 1, 0, 0, 0, 0, 0, 9.81))
        if k % 2 == 0:
            rec.write(clock, t_ns, clock_enc.encode(t_ns))
```

`write()` only appends to a list. Every `flush_interval_s` of wall time (checked on writes, see
`poll()`), every `flush_interval_sim_s` of message time (a run at 100x real time loses no more
simulated time to a kill than one at real time), or every `chunk_messages` messages, the batch
goes to disk: one MCAP chunk with its indexes in a single write, or one committed sqlite3
transaction. A killed process therefore loses
at most the last interval; `twin bag recover` makes what it left a complete bag. Closing (also on
an exception inside the `with` block) writes the summary and `metadata.yaml`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import sqlite3
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, NewType, NoReturn, Protocol

from twin import __version__
from twin.bag.encoders import StringEncoder
from twin.bag.mcap_file import McapWriter
from twin.bag.metadata import BagMetadata, FileInformation, TopicMetadata, render_metadata, write_metadata
from twin.bag.profiles import DistroProfile, distro_profile
from twin.bag.provenance import PROVENANCE_NAME, PROVENANCE_TOPIC
from twin.bag.qos import QOS_LATCHED, QosProfile, default_qos, qos_profiles_to_yaml
from twin.bag.sqlite_file import Sqlite3Writer, sqlite_topic_stats
from twin.bag.typesys import MessageDefinition, TypeRegistry
from twin.core.errors import BagError, BagFolderTaken

__all__ = ["STORAGES", "Recorder", "TopicHandle"]

_log = logging.getLogger(__name__)

#: Handle of a recorded topic, returned by `Recorder.add_topic` and passed to `Recorder.write`.
TopicHandle = NewType("TopicHandle", int)

STORAGES = ("mcap", "sqlite3")
_EXTENSIONS = {"mcap": ".mcap", "sqlite3": ".db3"}
_MAX_STEP = 64  # most writes between two looks at the clock
_NEVER = 2**63  # beyond any int64 time
_DISK_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


@dataclass(frozen=True, kw_only=True, slots=True)
class _Topic:
    name: str
    definition: MessageDefinition
    qos: tuple[QosProfile, ...]


class _Storage(Protocol):
    """What the recorder needs from a storage backend."""

    def write_batch(self, batch: Sequence[tuple[int, int, bytes]]) -> None: ...


def _qos_text(profile: DistroProfile, qos: Sequence[QosProfile]) -> str:
    """The QoS string a storage keeps per topic (sqlite3 `topics` row, MCAP channel metadata)."""
    return qos_profiles_to_yaml(qos, named=profile.named_qos)


class Recorder:
    """Records messages into a new rosbag2 folder. Use as a context manager.

    Not thread-safe: call it from the simulation loop's thread.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        storage: str = "mcap",
        distro: str = "humble",
        flush_interval_s: float = 0.25,
        flush_interval_sim_s: float | None = 0.4,
        chunk_messages: int = 4096,
        fsync: bool = False,
        custom_data: dict[str, str] | None = None,
        write_log: str | os.PathLike[str] | None = None,
    ) -> None:
        """Create the bag folder and its storage file.

        Args:
            path: The bag folder to create; it must not exist or be empty. The storage file is
                `<folder name>_0.mcap` (or `.db3`) inside it, as `ros2 bag record` names it.
            storage: `mcap` (default) or `sqlite3`.
            distro: Whose rosbag2 the bag imitates: `humble` (default; metadata version 8, read by
                every distro from Humble on), `iron`, or `jazzy`/`kilted`/`rolling` (version 9).
            flush_interval_s: Longest wall time a written message waits before reaching the disk.
            flush_interval_sim_s: Longest message time (`t_ns`) a batch spans before it goes to disk,
                so a run far faster than real time loses at most this much simulated time to a
                kill (None: by wall time only).
            chunk_messages: Messages per MCAP chunk / sqlite3 transaction (a batch may run a few
                dozen over while the recorder is not looking).
            fsync: Also fsync each flush (survives power loss, not just a killed process).
            custom_data: `custom_data` entries for `metadata.yaml` (version >= 6).
            write_log: For crash tests: append `topic t_ns monotonic_ns` per `write()` to this
                file, each line one write(2) so it survives a kill. Slows writing down.

        Raises:
            BagError: If the folder exists and is not empty, the storage or distro is unknown, or
                the folder cannot be created.
        """
        if storage not in STORAGES:
            msg = f"unknown bag storage {storage!r}; use one of {', '.join(STORAGES)}"
            raise BagError(msg)
        if not flush_interval_s > 0:
            msg = f"flush_interval_s must be positive, got {flush_interval_s}"
            raise BagError(msg)
        if flush_interval_sim_s is not None and not flush_interval_sim_s > 0:
            msg = f"flush_interval_sim_s must be positive, got {flush_interval_sim_s}"
            raise BagError(msg)
        # Past this message time the pending batch is flushed (set from each flushed batch's last time).
        self._sim_interval_ns = round(flush_interval_sim_s * 1e9) if flush_interval_sim_s is not None else None
        self._sim_deadline_ns = self._sim_interval_ns if self._sim_interval_ns is not None else _NEVER
        self.profile = distro_profile(distro)
        self.path = Path(path)
        self.storage_id = storage
        self._interval_s = flush_interval_s
        self._chunk_messages = max(1, chunk_messages)
        self._custom_data = dict(custom_data or {})
        self._fsync = fsync
        self._registry = TypeRegistry()
        self._topics: dict[int, _Topic] = {}
        self._topic_names: dict[str, int] = {}
        self._pending: list[tuple[int, int, bytes]] = []
        self._step = 1  # writes between looks at the clock, adapted to the write rate
        self._next_check = 1
        self._closed = False
        self._failed = False
        self._written = 0
        self._end_ns: int | None = None  # the latest message time on disk
        taken = f"{self.path}: the bag folder exists and is not empty; choose a new output folder"
        if self.path.exists() and not self.path.is_dir():
            msg = f"{self.path}: is a file, where the bag's folder goes; choose a new output folder"
            raise BagFolderTaken(msg)
        if self.path.exists() and any(self.path.iterdir()):
            raise BagFolderTaken(taken)
        try:  # made here, or an empty one given: never one another run made in the meantime
            if not self.path.is_dir():
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.path.mkdir()
        except FileExistsError:
            raise BagFolderTaken(taken) from None
        except OSError as err:
            msg = f"{self.path}: cannot create the bag folder: {err.strerror}"
            raise BagError(msg) from None
        self.file_name = f"{self.path.name}_0{_EXTENSIONS[storage]}"
        self.file_path = self.path / self.file_name
        self._mcap: McapWriter | None = None
        self._sqlite: Sqlite3Writer | None = None
        try:
            if storage == "mcap":
                self._mcap = McapWriter(self.file_path, library=f"twin {__version__}", fsync=fsync)
                # Read back by `twin bag recover` to rebuild metadata of the same distro.
                self._mcap.add_metadata("twin", {"ros_distro": self.profile.name})
                self._storage: _Storage = self._mcap
            else:
                self._sqlite = Sqlite3Writer(
                    self.file_path,
                    ros_distro=self.profile.name,
                    schema_version=self.profile.sqlite_schema_version,
                    fsync=fsync,
                )
                self._storage = self._sqlite
        except FileExistsError:  # another run took the (empty) folder between the look and the file
            raise BagFolderTaken(taken) from None
        except (OSError, sqlite3.Error) as err:
            msg = f"{self.file_path}: cannot create the bag file: {_reason(err)}"
            raise BagError(msg) from None
        now = time.monotonic()
        self._deadline = now + self._interval_s
        self._last_check = now
        self._log_fd: int | None = None
        if write_log is not None:
            self._log_fd = os.open(write_log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
            self.write = self._write_and_log  # type: ignore[method-assign]

    # -- context manager ----------------------------------------------------------------------

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        # Close also on errors and Ctrl-C: what was recorded becomes a complete bag.
        if exc_type is None:
            self.close()
            return
        try:
            self.close()
        except BagError as err:
            _log.error("%s", err)

    # -- topics ---------------------------------------------------------------------------------

    def add_topic(
        self,
        topic: str,
        msgtype: str,
        *,
        qos: Sequence[QosProfile] | None = None,
        msgdef: str | None = None,
    ) -> TopicHandle:
        """Register a topic and return the handle to write its messages with.

        Args:
            topic: Topic name, e.g. `/scan`.
            msgtype: Message type, e.g. `sensor_msgs/msg/LaserScan` (or an encoder's `msgtype`).
            qos: Offered QoS profiles; by default what a TB3 + Nav2 system offers on `topic`
                (transient local for `/tf_static`, `/map`, `/robot_description`, …).
            msgdef: The `.msg` text of a type the registry does not know.

        Raises:
            BagError: If the topic exists, the type is unknown, or the bag is closed.
        """
        self._check_open()
        if topic in self._topic_names:
            msg = f"topic {topic} is already recorded in {self.path}"
            raise BagError(msg)
        if msgdef is not None:
            self._registry.register(msgtype, msgdef)
        definition = self._registry.definition(msgtype)
        profiles = tuple(qos) if qos is not None else default_qos(topic)
        qos_text = _qos_text(self.profile, profiles)
        try:
            if self._mcap is not None:
                schema_id = next(
                    (sid for sid, s in self._mcap.schemas.items() if s.name == msgtype),
                    0,
                ) or self._mcap.add_schema(msgtype, definition.encoding, definition.text.encode())
                metadata = {"offered_qos_profiles": qos_text}
                if self.profile.mcap_type_hash:
                    metadata["topic_type_hash"] = definition.type_hash
                handle = self._mcap.add_channel(topic, schema_id, "cdr", metadata)
            else:
                assert self._sqlite is not None
                handle = self._sqlite.add_topic(
                    name=topic,
                    msgtype=msgtype,
                    serialization_format="cdr",
                    qos=qos_text,
                    type_hash=definition.type_hash,
                    encoding=definition.encoding,
                    definition=definition.text,
                )
        except (OSError, sqlite3.Error) as err:
            self._fail(err)
        self._topics[handle] = _Topic(name=topic, definition=definition, qos=profiles)
        self._topic_names[topic] = handle
        return TopicHandle(handle)

    @property
    def topics(self) -> dict[str, TopicHandle]:
        """Recorded topic names and their handles."""
        return {name: TopicHandle(h) for name, h in self._topic_names.items()}

    def add_provenance(self, values: Mapping[str, str]) -> None:
        """Record how the bag was made (`twin.bag.provenance`).

        MCAP: a Metadata record; sqlite3: a latched `/twin/provenance` message at t = 0 holding the
        values as JSON.

        Raises:
            BagError: If the bag is closed or cannot be written.
        """
        self._check_open()
        if self._mcap is not None:
            try:
                self._mcap.add_metadata(PROVENANCE_NAME, {str(k): str(v) for k, v in values.items()})
            except OSError as err:
                self._fail(err)
            return
        handle = self.add_topic(PROVENANCE_TOPIC, StringEncoder.msgtype, qos=(QOS_LATCHED,))
        self.write(handle, 0, StringEncoder().encode(json.dumps(dict(values), sort_keys=True)))

    # -- writing --------------------------------------------------------------------------------

    def write(self, handle: TopicHandle, t_ns: int, data: bytes) -> None:
        """Record one serialized message (CDR bytes from an encoder) at integer time `t_ns`.

        Handles and types are checked when the batch is written (at the next flush), which
        raises `BagError` for an unknown handle or a negative time.
        """
        pending = self._pending
        pending.append((handle, t_ns, data))
        try:
            due = t_ns >= self._sim_deadline_ns
        except TypeError:  # not a time: flush now, which names the bad write
            due = True
        if due:
            self.flush()
        elif len(pending) >= self._next_check:
            self._check(len(pending))

    def _write_and_log(self, handle: TopicHandle, t_ns: int, data: bytes) -> None:
        Recorder.write(self, handle, t_ns, data)
        topic = self._topics.get(handle)
        line = f"{topic.name if topic else handle} {t_ns} {time.monotonic_ns()}\n"
        assert self._log_fd is not None
        os.write(self._log_fd, line.encode())

    def poll(self) -> None:
        """Flush if the flush interval has passed; call it when the loop goes long without writing."""
        if self._pending:
            self._check(len(self._pending), force_clock=True)

    def _check(self, n: int, *, force_clock: bool = False) -> None:
        now = time.monotonic()
        if n >= self._chunk_messages or now >= self._deadline:
            self.flush()
            return
        if force_clock:
            return
        # Look at the clock about every interval/16: every write in a slow loop, every few dozen
        # in a fast one. The step halves as soon as writes slow down.
        elapsed = now - self._last_check
        target = self._interval_s / 16
        if elapsed < target / 2:
            self._step = min(2 * self._step, _MAX_STEP)
        elif elapsed > target:
            self._step = max(self._step // 2, 1)
        self._last_check = now
        self._next_check = n + self._step

    def flush(self) -> None:
        """Write the pending messages to disk now.

        Raises:
            BagError: If a handle or time is invalid, or the disk is full (the bag is then closed
                with what fit, or left for `twin bag recover`).
        """
        self._check_open()
        batch, self._pending = self._pending, []
        now = time.monotonic()
        self._deadline = now + self._interval_s
        self._last_check = now
        self._next_check = self._step
        if not batch:
            return
        if self._sim_interval_ns is not None:
            last_t: object = batch[-1][1]  # checked by the storage below; may be bad input here
            self._sim_deadline_ns = (last_t if isinstance(last_t, int) else 0) + self._sim_interval_ns
        try:
            self._storage.write_batch(batch)
        except ValueError as err:
            msg = f"{self.file_path}: {self._describe_bad_batch(batch, err)}"
            raise BagError(msg) from None
        except (OSError, sqlite3.Error) as err:
            self._fail(err)
        except BaseException:
            # Interrupted mid-write (Ctrl-C, or the watchdog unwinding a stuck run): the storage is
            # back at its last complete batch; keep these messages so that closing still writes them.
            self._pending = batch + self._pending
            raise
        self._written += len(batch)
        batch_end: object = batch[-1][1]
        if isinstance(batch_end, int) and (self._end_ns is None or batch_end > self._end_ns):
            self._end_ns = batch_end

    def _describe_bad_batch(self, batch: Sequence[tuple[Any, Any, Any]], err: ValueError) -> str:
        """Name the first bad `write()` call of a batch the storage refused."""
        for handle, t_ns, data in batch:
            name = self._topics.get(handle) if isinstance(handle, int) else None
            if name is None:
                return f"write() got an unknown topic handle {handle!r}; use the handle add_topic() returned"
            if not isinstance(t_ns, int) or t_ns < 0:
                return f"write() on {name.name} got time {t_ns!r}; times are non-negative integer nanoseconds"
            if not isinstance(data, bytes | bytearray | memoryview):
                return f"write() on {name.name} got {type(data).__name__} data; pass the bytes an encoder returns"
        return str(err)

    # -- closing --------------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        """Whether the bag is closed (after `close()` or a storage failure)."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages handed to the storage so far (pending ones excluded)."""
        return self._written

    def close(self) -> None:
        """Flush, finish the storage file and write `metadata.yaml`. Safe to call more than once.

        Raises:
            BagError: If the disk is full or the bag cannot be finished.
        """
        if self._closed:
            return
        try:
            self.flush()
        finally:
            if not self._closed:
                self._finish()

    def _finish(self) -> None:
        self._closed = True
        self._pending = _ClosedBatch(self.path)
        if self._log_fd is not None:
            os.close(self._log_fd)
            self._log_fd = None
        try:
            meta = self.metadata()
            if self._mcap is not None:
                if self.profile.mcap_serialized_metadata:
                    self._mcap.add_metadata("rosbag2", {"serialized_metadata": render_metadata(meta, root=False)})
                else:
                    self._mcap.add_metadata("rosbag2", {"ROS_DISTRO": self.profile.name})
                self._mcap.finish()
            elif self._sqlite is not None:
                try:  # a copy of metadata.yaml, as Iron and later keep it; readers do not need it
                    self._sqlite.set_metadata(meta.version, render_metadata(meta, root=False))
                except sqlite3.Error as err:
                    _log.warning("%s: metadata table not updated: %s", self.file_path, err)
                self._sqlite.close()
            write_metadata(self.path, meta, fsync=self._fsync)
        except (OSError, sqlite3.Error) as err:
            self._close_quietly()
            msg = (
                f"{self.path}: cannot finish the bag: {_reason(err)}; "
                f"after fixing that, `twin bag recover {self.path}` completes it"
            )
            raise BagError(msg) from None

    def metadata(self) -> BagMetadata:
        """The bag's metadata as of the messages written to disk so far."""
        counts: dict[int, int] = {}
        start_ns, end_ns = 0, 0
        if self._mcap is not None:
            stats = self._mcap.stats
            counts = dict(stats.channel_counts)
            if stats.message_count:
                start_ns, end_ns = stats.start_ns, stats.end_ns
        elif self._sqlite is not None and not self._sqlite_closed():
            rows = sqlite_topic_stats(self._sqlite_db())
            counts = {r.topic_id: r.count for r in rows}
            live = [r for r in rows if r.count]
            if live:
                start_ns, end_ns = min(r.start_ns for r in live), max(r.end_ns for r in live)
        total = sum(counts.values())
        topics = tuple(
            TopicMetadata(
                name=topic.name,
                msgtype=topic.definition.msgtype,
                serialization_format="cdr",
                offered_qos_profiles=topic.qos,
                type_description_hash=topic.definition.type_hash,
                message_count=counts.get(handle, 0),
            )
            for handle, topic in self._topics.items()
        )
        return BagMetadata(
            version=self.profile.metadata_version,
            storage_identifier=self.storage_id,
            relative_file_paths=(self.file_name,),
            starting_time_ns=start_ns,
            duration_ns=end_ns - start_ns,
            message_count=total,
            topics=topics,
            files=(
                FileInformation(
                    path=self.file_name, starting_time_ns=start_ns, duration_ns=end_ns - start_ns, message_count=total
                ),
            ),
            custom_data=tuple(self._custom_data.items()),
            ros_distro=self.profile.name,
        )

    def _sqlite_db(self) -> sqlite3.Connection:
        assert self._sqlite is not None
        return self._sqlite._db

    def _sqlite_closed(self) -> bool:
        assert self._sqlite is not None
        return self._sqlite._closed

    def _check_open(self) -> None:
        if self._closed:
            state = "stopped after a storage error" if self._failed else "closed"
            msg = f"{self.path}: the recorder is {state}; no more messages can be written"
            raise BagError(msg)

    def _close_quietly(self) -> None:
        if self._mcap is not None:
            self._mcap.close()
        if self._sqlite is not None:
            self._sqlite.close()

    def _fail(self, err: OSError | sqlite3.Error) -> NoReturn:
        """Handle a storage write failure: keep what is on disk readable, then raise one BagError."""
        self._failed = True
        if self._mcap is not None:
            with contextlib.suppress(OSError):
                self._mcap.truncate_to_good_end()
        what = _reason(err, self.path)
        end = f"t={self._end_ns / 1e9:.3f} s" if self._end_ns is not None else "its start"
        try:
            self._finish()
            outcome = f"the bag was closed with the {self.message_count} messages that fit: it ends at {end}"
        except BagError:
            fix = "raise the limit" if _is_size_limit(err) else "free space"
            outcome = f"what was written ends at {end}; {fix}, then `twin bag recover {self.path}` completes it"
        self._closed = True
        self._pending = _ClosedBatch(self.path)
        msg = f"{self.file_path}: cannot write: {what}; {outcome}"
        raise BagError(msg) from None


class _ClosedBatch(list[tuple[int, int, bytes]]):
    """Stands in for the pending batch once the recorder is closed: writing raises at once."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self._path = path

    def append(self, item: tuple[int, int, bytes]) -> None:
        msg = f"{self._path}: the recorder is closed; no more messages can be written"
        raise BagError(msg)


def _is_size_limit(err: BaseException) -> bool:
    return isinstance(err, OSError) and err.errno == errno.EFBIG


def _reason(err: BaseException, folder: Path | None = None) -> str:
    if isinstance(err, OSError):
        if err.errno == errno.ENOSPC:
            return "the disk is full"
        if err.errno == errno.EDQUOT:
            return "the disk quota is exceeded"
        if err.errno == errno.EFBIG:
            return "the file-size limit was reached (ulimit -f, or the file system's largest file), not a full disk"
        return f"{err.strerror or err}"
    if "full" in str(err).lower():
        return f"the disk is full ({err})"
    if folder is not None:  # sqlite3 says "disk I/O error" for a size limit too: look at the disk
        with contextlib.suppress(OSError):
            free = shutil.disk_usage(folder).free
            if free > 16 * 2**20:
                return f"{err} with {free / 2**30:.1f} GiB free, so not a full disk (a file-size limit, ulimit -f?)"
    return str(err)
