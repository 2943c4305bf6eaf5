"""`twin bag recover`: turn what a killed recording left into a complete, indexed bag.

A killed recorder leaves the storage file without its end (MCAP: no summary or footer, maybe a
partial chunk; sqlite3: maybe a hot journal) and no `metadata.yaml`. Recovery completes the
storage file in place, keeping every complete record, and rebuilds `metadata.yaml` from it, in
the distro form the recording used. A complete bag (complete storage files and a `metadata.yaml`
that counts the same messages) is reported as complete and left untouched, whatever its metadata
version or distro. When `metadata.yaml` must be rewritten, the original is kept beside it as
`metadata.yaml.orig` (`.orig.2`, ... if that exists).
"""

from __future__ import annotations

import logging
import os
import sqlite3
from dataclasses import dataclass
from pathlib import Path

from twin.bag.mcap_file import ZSTD_MAGIC, recover_mcap, scan_mcap
from twin.bag.metadata import (
    METADATA_FILE,
    BagMetadata,
    FileInformation,
    TopicMetadata,
    parse_metadata,
    render_metadata,
    write_metadata,
)
from twin.bag.profiles import DISTROS, distro_profile
from twin.bag.qos import parse_qos_profiles
from twin.bag.single_file import STORAGE_SUFFIXES, rosbag2_record, storage_file_metadata
from twin.bag.sqlite_file import recover_sqlite
from twin.core.errors import BagError

__all__ = ["RecoveryReport", "recover_bag"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True, slots=True)
class RecoveryReport:
    """What `recover_bag` found and did."""

    path: Path
    storage: str
    files: tuple[str, ...]
    message_count: int
    topic_counts: tuple[tuple[str, int], ...]
    was_complete: bool  #: storage files complete and metadata.yaml present: nothing was missing
    dropped_bytes: int  #: bytes of partial records cut off the end
    metadata: BagMetadata


def _previous_metadata(bag: Path) -> BagMetadata | None:
    path = bag / METADATA_FILE
    if not path.exists():
        return None
    try:
        return parse_metadata(path.read_text(encoding="utf-8"), path)
    except (BagError, OSError, UnicodeDecodeError) as err:
        _log.warning("%s: ignoring unreadable metadata (%s)", path, err)
        return None


def _distro(name: str) -> str:
    return name if name in DISTROS else "humble"


def recover_bag(path: str | os.PathLike[str]) -> RecoveryReport:
    """Complete the bag in folder `path` and rewrite its `metadata.yaml`.

    A single storage file (`.mcap` or `.db3` outside a bag folder) is completed in place; it
    needs no `metadata.yaml`, so none is written.

    Raises:
        BagError: If the folder holds no storage file, mixes storages, or a file is not a bag.
    """
    bag = Path(path)
    if bag.is_file() and (bag.parent / METADATA_FILE).exists():
        bag = bag.parent  # a storage file inside a bag folder
    elif bag.is_file() and bag.suffix in STORAGE_SUFFIXES:
        return _recover_file(bag)
    if not bag.is_dir():
        msg = f"{bag}: no such bag folder (or .mcap or .db3 file)"
        raise BagError(msg)
    packed = sorted(p.name for p in bag.glob("*.zstd") if Path(p.stem).suffix in STORAGE_SUFFIXES)
    if packed:
        # rosbag2's `--compression-mode file`: recovery reads and rewrites records in place, which a
        # compressed file does not allow. Unpacked, the files are ordinary storage files.
        names = ", ".join(packed)
        msg = (
            f"{bag}: {names}: storage compressed as whole files, which recover cannot check or mend; "
            f"unpack them (`zstd -d --rm` on each) and run `twin bag recover {bag}` again"
        )
        raise BagError(msg)
    mcaps = sorted(bag.glob("*.mcap"))
    dbs = sorted(bag.glob("*.db3"))
    if mcaps and dbs:
        msg = f"{bag}: holds both .mcap and .db3 files; recover one storage per folder"
        raise BagError(msg)
    previous = _previous_metadata(bag)
    if not mcaps and not dbs:
        listed = ", ".join(Path(rel).name for rel in previous.relative_file_paths) if previous else ""
        if listed:  # a metadata.yaml copied without its bag
            msg = f"{bag}: {listed} (listed in {METADATA_FILE}) is not there, so nothing to recover; copy it into {bag}"
        else:
            msg = f"{bag}: no .mcap or .db3 storage file to recover"
        raise BagError(msg)
    if previous is not None:
        untouched = _complete_report(bag, mcaps, dbs, previous)
        if untouched is not None:
            return untouched
        _backup_metadata(bag)
    if mcaps:
        return _recover_mcap_bag(bag, mcaps, previous)
    return _recover_sqlite_bag(bag, dbs, previous)


def _recover_file(file: Path) -> RecoveryReport:
    """Complete a single storage file in place; it describes itself, so no metadata.yaml is written."""
    dropped = 0
    try:
        if file.suffix == ".mcap":
            outcome = recover_mcap(file)
            was_complete, dropped = outcome.was_complete, outcome.dropped_bytes
        else:
            was_complete = not any(file.with_name(file.name + end).exists() for end in ("-journal", "-wal"))
            recover_sqlite(file)
    except (ValueError, sqlite3.Error) as err:
        msg = f"{file}: cannot recover: {err}"
        raise BagError(msg) from None
    except OSError as err:
        msg = f"{file}: cannot rewrite: {err.strerror}; free space or fix permissions and run again"
        raise BagError(msg) from None
    meta = storage_file_metadata(file)
    return RecoveryReport(
        path=file,
        storage=meta.storage_identifier,
        files=(file.name,),
        message_count=meta.message_count,
        topic_counts=tuple((t.name, t.message_count) for t in meta.topics),
        was_complete=was_complete,
        dropped_bytes=dropped,
        metadata=meta,
    )


def _backup_metadata(bag: Path) -> Path | None:
    """Copy `metadata.yaml` to `metadata.yaml.orig` (or the next free `.orig.N`) before it is rewritten."""
    source = bag / METADATA_FILE
    if not source.exists():
        return None
    target, n = bag / f"{METADATA_FILE}.orig", 1
    while target.exists():
        n += 1
        target = bag / f"{METADATA_FILE}.orig.{n}"
    try:
        target.write_bytes(source.read_bytes())
    except OSError as err:
        msg = f"{bag}: cannot keep the original {METADATA_FILE} as {target.name}: {err.strerror}; nothing was changed"
        raise BagError(msg) from None
    _log.info("%s: original metadata kept as %s", bag, target.name)
    return target


def _complete_report(bag: Path, mcaps: list[Path], dbs: list[Path], previous: BagMetadata) -> RecoveryReport | None:
    """A report for a bag that needs nothing (read-only checks), or None if it must be recovered."""
    names = {f.name for f in (*mcaps, *dbs)}
    if set(previous.relative_file_paths) != names:
        return None
    total = 0
    firsts: list[bytes] = []
    try:
        for file in mcaps:
            scan = scan_mcap(file)
            if not scan.complete:
                return None
            total += scan.stats().message_count
            firsts += [c.first_data for c in scan.chunks[:1]]
        for file in dbs:
            if file.with_name(file.name + "-journal").exists() or file.with_name(file.name + "-wal").exists():
                return None
            db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro", uri=True)
            try:
                total += int(db.execute("SELECT count(*) FROM messages").fetchone()[0])
                firsts += _first_sqlite_data(db)
            finally:
                db.close()
    except (ValueError, OSError, sqlite3.Error):
        return None  # the recovery proper names the problem
    if total != previous.message_count:
        return None
    if _compressed_messages(firsts) and previous.compression_mode.lower() != "message":
        return None  # zstd frames the metadata does not announce: readers would take them for CDR
    return RecoveryReport(
        path=bag,
        storage="mcap" if mcaps else "sqlite3",
        files=tuple(sorted(names)),
        message_count=total,
        topic_counts=tuple((t.name, t.message_count) for t in previous.topics),
        was_complete=True,
        dropped_bytes=0,
        metadata=previous,
    )


def _first_sqlite_data(db: sqlite3.Connection) -> list[bytes]:
    row = db.execute("SELECT data FROM messages ORDER BY rowid LIMIT 1").fetchone()
    return [] if row is None else [bytes(row[0])]


def _compressed_messages(firsts: list[bytes]) -> bool:
    """Whether the storage's messages are zstd frames (`--compression-mode message`), judged by the first of each file.

    A CDR message starts with a 0 byte (its encapsulation kind), a zstd frame with its magic number,
    so the two cannot be confused.
    """
    return any(data[:4] == ZSTD_MAGIC for data in firsts)


def _file_info(name: str, start: int, end: int, count: int) -> FileInformation:
    return FileInformation(path=name, starting_time_ns=start, duration_ns=end - start, message_count=count)


def _recover_mcap_bag(bag: Path, files: list[Path], previous: BagMetadata | None) -> RecoveryReport:
    topics: dict[str, TopicMetadata] = {}
    counts: dict[str, int] = {}
    infos: list[FileInformation] = []
    distro = previous.ros_distro if previous else ""
    dropped = 0
    starts: list[int] = []
    ends: list[int] = []
    firsts: list[bytes] = []
    for file in files:
        try:
            outcome = recover_mcap(file)
        except ValueError as err:
            msg = f"{file}: cannot recover: {err}"
            raise BagError(msg) from None
        except OSError as err:
            msg = f"{file}: cannot rewrite: {err.strerror}; free space or fix permissions and run again"
            raise BagError(msg) from None
        scan = outcome.scan
        firsts += [c.first_data for c in scan.chunks[:1]]
        dropped += outcome.dropped_bytes
        for _, _, name, values in scan.metadata:
            if name == "twin" and values.get("ros_distro") and not distro:
                distro = values["ros_distro"]
        # rosbag2's own record: `ROS_DISTRO` on Humble, the whole metadata (with `ros_distro`) from Iron on
        distro = distro or str(
            rosbag2_record([(name, values) for _, _, name, values in scan.metadata]).get("ros_distro", "")
        )
        stats = scan.stats()
        for cid, channel in scan.channels.items():
            schema = scan.schemas.get(channel.schema_id)
            n = stats.channel_counts.get(cid, 0)
            counts[channel.topic] = counts.get(channel.topic, 0) + n
            if channel.topic not in topics:
                try:
                    qos = parse_qos_profiles(channel.metadata.get("offered_qos_profiles", ""))
                except ValueError:
                    qos = ()
                topics[channel.topic] = TopicMetadata(
                    name=channel.topic,
                    msgtype=schema.name if schema else "",
                    serialization_format=channel.message_encoding,
                    offered_qos_profiles=qos,
                    type_description_hash=channel.metadata.get("topic_type_hash", ""),
                )
        if stats.message_count:
            starts.append(stats.start_ns)
            ends.append(stats.end_ns)
            infos.append(_file_info(file.name, stats.start_ns, stats.end_ns, stats.message_count))
        else:
            infos.append(_file_info(file.name, 0, 0, 0))
    return _finish(
        bag=bag,
        storage="mcap",
        files=files,
        topics=topics,
        counts=counts,
        infos=infos,
        starts=starts,
        ends=ends,
        distro=distro,
        previous=previous,
        dropped=dropped,
        compressed=_compressed_messages(firsts),
    )


def _recover_sqlite_bag(bag: Path, files: list[Path], previous: BagMetadata | None) -> RecoveryReport:
    topics: dict[str, TopicMetadata] = {}
    counts: dict[str, int] = {}
    infos: list[FileInformation] = []
    distro = previous.ros_distro if previous else ""
    starts: list[int] = []
    ends: list[int] = []
    firsts: list[bytes] = []
    for file in files:
        try:
            rows, file_distro = recover_sqlite(file)
        except sqlite3.Error as err:
            msg = f"{file}: cannot recover: {err}"
            raise BagError(msg) from None
        distro = distro or file_distro
        db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro", uri=True)
        try:
            firsts += _first_sqlite_data(db)
        finally:
            db.close()
        live = [r for r in rows if r.count]
        for r in rows:
            counts[r.name] = counts.get(r.name, 0) + r.count
            if r.name not in topics:
                try:
                    qos = parse_qos_profiles(r.qos)
                except ValueError:
                    qos = ()
                topics[r.name] = TopicMetadata(
                    name=r.name,
                    msgtype=r.msgtype,
                    serialization_format=r.serialization_format,
                    offered_qos_profiles=qos,
                    type_description_hash=r.type_hash,
                )
        if live:
            start, end = min(r.start_ns for r in live), max(r.end_ns for r in live)
            starts.append(start)
            ends.append(end)
            infos.append(_file_info(file.name, start, end, sum(r.count for r in live)))
        else:
            infos.append(_file_info(file.name, 0, 0, 0))
    report = _finish(
        bag=bag,
        storage="sqlite3",
        files=files,
        topics=topics,
        counts=counts,
        infos=infos,
        starts=starts,
        ends=ends,
        distro=distro,
        previous=previous,
        dropped=0,
        compressed=_compressed_messages(firsts),
    )
    for file in files:  # keep the metadata table in step with metadata.yaml, as rosbag2 does on close
        try:
            db = sqlite3.connect(file, isolation_level=None)
            try:
                db.execute(
                    "INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)",
                    (report.metadata.version, render_metadata(report.metadata, root=False)),
                )
            finally:
                db.close()
        except sqlite3.Error as err:
            _log.info("%s: metadata table not updated: %s", file, err)
    return report


def _finish(
    *,
    bag: Path,
    storage: str,
    files: list[Path],
    topics: dict[str, TopicMetadata],
    counts: dict[str, int],
    infos: list[FileInformation],
    starts: list[int],
    ends: list[int],
    distro: str,
    previous: BagMetadata | None,
    dropped: int,
    compressed: bool,
) -> RecoveryReport:
    profile = distro_profile(_distro(distro))
    version = previous.version if previous and previous.version >= 8 else profile.metadata_version
    start = min(starts) if starts else 0
    end = max(ends) if ends else 0
    total = sum(counts.values())
    full_topics = tuple(
        TopicMetadata(
            name=t.name,
            msgtype=t.msgtype,
            serialization_format=t.serialization_format,
            offered_qos_profiles=t.offered_qos_profiles,
            type_description_hash=t.type_description_hash,
            message_count=counts.get(t.name, 0),
        )
        for t in topics.values()
    )
    meta = BagMetadata(
        version=version,
        storage_identifier=storage,
        relative_file_paths=tuple(f.name for f in files),
        starting_time_ns=start,
        duration_ns=end - start,
        message_count=total,
        topics=full_topics,
        files=tuple(infos),
        # rosbag2 writes the mode in capitals; every reader takes either case
        compression_format="zstd" if compressed else "",
        compression_mode="MESSAGE" if compressed else "",
        custom_data=previous.custom_data if previous else (),
        ros_distro=profile.name,
    )
    try:
        write_metadata(bag, meta)
    except OSError as err:
        msg = f"{bag}: cannot write {METADATA_FILE}: {err.strerror}"
        raise BagError(msg) from None
    return RecoveryReport(
        path=bag,
        storage=storage,
        files=tuple(f.name for f in files),
        message_count=total,
        topic_counts=tuple((t.name, t.message_count) for t in full_topics),
        was_complete=False,  # complete means nothing had to change; metadata.yaml was just rewritten
        dropped_bytes=dropped,
        metadata=meta,
    )
