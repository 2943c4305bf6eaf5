"""`twin bag recover`: turn what a killed recording or a damaged disk left into a complete, indexed bag.

A killed recorder leaves the storage file without its end (MCAP: no summary or footer, maybe a
partial chunk; sqlite3: maybe a hot journal or a WAL with frames) and no `metadata.yaml`. A
damaged file holds records that no longer parse (MCAP) or pages that fail SQLite's integrity
check. Recovery never changes a storage file: it writes a repaired copy beside it
(`<name>.recovering`), reads the copy back, and only then puts it in the original's place. The
original is kept as `<name>.orig` (`.orig.2`, ... if that exists) whenever the copy lacks any of
its data (damaged records skipped, rows that did not read); a killed recording's file, whose every
complete record the copy holds, is replaced. `metadata.yaml` is rebuilt from the storage in the
form the bag had (its version and distro), the original kept beside it as `metadata.yaml.orig`.

A complete bag (undamaged storage files, no side file with content, and a `metadata.yaml` that
counts the same messages) is reported as complete and left untouched, whatever its metadata
version or distro.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.bag.mcap_file import ZSTD_MAGIC, McapRecovery, recover_mcap, scan_mcap
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
from twin.bag.sqlite_file import (
    SqliteRecovery,
    SqliteTopicStats,
    connect_readonly,
    recover_sqlite,
    sqlite_needs_repair,
)
from twin.core.errors import BagError

__all__ = ["RecoveryReport", "recover_bag"]

_log = logging.getLogger(__name__)

#: The suffix of a repaired copy while it is written and checked.
WORK_SUFFIX = ".recovering"
_SIDE_ENDINGS = ("-journal", "-wal", "-shm")


@dataclass(frozen=True, kw_only=True, slots=True)
class RecoveryReport:
    """What `recover_bag` found and did."""

    path: Path
    storage: str
    files: tuple[str, ...]
    message_count: int
    topic_counts: tuple[tuple[str, int], ...]
    was_complete: bool  #: storage files complete and metadata.yaml present: nothing was changed
    dropped_bytes: int  #: bytes of the storage not carried over: partial records at the end, damaged records
    metadata: BagMetadata
    #: Storage files that were damaged, each with the name its original was kept under.
    kept_originals: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, kw_only=True, slots=True)
class _Repaired:
    """One storage file's repair: the checked copy, and whether the original must be kept."""

    file: Path
    copy: Path | None  #: None: the file needed nothing
    keep_original: bool


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


def _work_path(file: Path) -> Path:
    """Where the repaired copy of `file` is written; a copy an interrupted recover left there is removed."""
    work = file.with_name(file.name + WORK_SUFFIX)
    for end in ("", *_SIDE_ENDINGS, ".salvage", *(".salvage" + e for e in _SIDE_ENDINGS)):
        work.with_name(work.name + end).unlink(missing_ok=True)
    return work


def _free_name(path: Path) -> Path:
    target, n = path, 1
    while target.exists():
        n += 1
        target = path.with_name(f"{path.name}.{n}")
    return target


def _put_in_place(repaired: _Repaired) -> str | None:
    """Move the checked copy into the original's place; return the kept original's name, if kept.

    The original and its side files are renamed first (a journal must never sit beside a file it
    does not belong to), then the copy takes the original's name; a killed recording's original,
    which the copy holds whole, is then removed.
    """
    file, copy = repaired.file, repaired.copy
    if copy is None:
        return None
    backup = _free_name(file.with_name(file.name + ".orig"))
    sides = [file.with_name(file.name + end) for end in _SIDE_ENDINGS]
    os.rename(file, backup)
    for side in sides:
        if side.exists():
            os.rename(side, backup.with_name(backup.name + side.name[len(file.name) :]))
    os.replace(copy, file)
    if repaired.keep_original:
        _log.warning("%s: damaged; the original is kept as %s", file, backup.name)
        return backup.name
    for end in ("", *_SIDE_ENDINGS):
        backup.with_name(backup.name + end).unlink(missing_ok=True)
    return None


def _discard(repairs: list[_Repaired]) -> None:
    for repaired in repairs:
        if repaired.copy is not None:
            for end in ("", *_SIDE_ENDINGS):
                repaired.copy.with_name(repaired.copy.name + end).unlink(missing_ok=True)


def recover_bag(path: str | os.PathLike[str]) -> RecoveryReport:
    """Complete the bag in folder `path` and rewrite its `metadata.yaml`.

    A single storage file (`.mcap` or `.db3` outside a bag folder) is completed the same way; it
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
        # rosbag2's `--compression-mode file`: recovery reads and rewrites records, which a
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
    if mcaps:
        return _recover_mcap_bag(bag, mcaps, previous)
    return _recover_sqlite_bag(bag, dbs, previous)


def _cannot(file: Path, err: Exception) -> BagError:
    if isinstance(err, OSError) and not isinstance(err, FileNotFoundError):
        return BagError(
            f"{file}: cannot write its repaired copy beside it: {err.strerror or err}; "
            "free space or fix permissions and run again (the original is unchanged)"
        )
    return BagError(f"{file}: cannot recover: {err} (the original is unchanged)")


def _repair_mcap(file: Path) -> tuple[McapRecovery, _Repaired]:
    work = _work_path(file)
    try:
        outcome = recover_mcap(file, work)
    except (ValueError, OSError) as err:
        work.unlink(missing_ok=True)
        raise _cannot(file, err) from None
    if outcome.was_complete:
        return outcome, _Repaired(file=file, copy=None, keep_original=False)
    keep = not outcome.killed_writer or bool(outcome.lost_messages)
    return outcome, _Repaired(file=file, copy=work, keep_original=keep)


def _repair_sqlite(file: Path, max_rowid: int | None) -> tuple[SqliteRecovery | None, _Repaired]:
    """Repair a database into a copy if it needs it; (None, nothing to do) if it does not."""
    try:
        if not sqlite_needs_repair(file):
            return None, _Repaired(file=file, copy=None, keep_original=False)
    except sqlite3.Error:
        pass  # not even readable: the repair names the problem
    work = _work_path(file)
    try:
        outcome = recover_sqlite(file, work, max_rowid=max_rowid)
    except (sqlite3.Error, OSError) as err:
        raise _cannot(file, err) from None
    if outcome.salvaged:
        _log.warning("%s: failed SQLite's integrity check; the rows that still read were copied", file)
    return outcome, _Repaired(file=file, copy=work, keep_original=outcome.salvaged)


def _sqlite_rows(file: Path) -> tuple[list[SqliteTopicStats], str]:
    """Topic statistics and distro of a database that needs no repair, read without writing."""
    from twin.bag.sqlite_file import sqlite_topic_stats

    db = connect_readonly(file)
    try:
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        distro = ""
        if "schema" in tables:
            row = db.execute("SELECT ros_distro FROM schema").fetchone()
            distro = str(row[0]) if row else ""
        return sqlite_topic_stats(db), distro
    finally:
        db.close()


def _recover_file(file: Path) -> RecoveryReport:
    """Complete a single storage file; it describes itself, so no metadata.yaml is written."""
    dropped = 0
    if file.suffix == ".mcap":
        outcome, repaired = _repair_mcap(file)
        dropped = outcome.dropped_bytes
    else:
        _, repaired = _repair_sqlite(file, None)
    try:
        kept = _put_in_place(repaired)
    except OSError as err:
        _discard([repaired])
        raise _cannot(file, err) from None
    meta = storage_file_metadata(file)
    return RecoveryReport(
        path=file,
        storage=meta.storage_identifier,
        files=(file.name,),
        message_count=meta.message_count,
        topic_counts=tuple((t.name, t.message_count) for t in meta.topics),
        was_complete=repaired.copy is None,
        dropped_bytes=dropped,
        metadata=meta,
        kept_originals=((file.name, kept),) if kept else (),
    )


def _backup_metadata(bag: Path) -> Path | None:
    """Copy `metadata.yaml` to `metadata.yaml.orig` (or the next free `.orig.N`) before it is rewritten."""
    source = bag / METADATA_FILE
    if not source.exists():
        return None
    target = _free_name(bag / f"{METADATA_FILE}.orig")
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
    stored: dict[str, str] = {}  # each topic's type as the storage names it
    try:
        for file in mcaps:
            scan = scan_mcap(file)
            if not scan.complete:
                return None
            total += scan.stats().message_count
            firsts += [c.first_data for c in scan.chunks[:1]]
            for channel in scan.channels.values():
                schema = scan.schemas.get(channel.schema_id)
                stored.setdefault(channel.topic, schema.name if schema else "")
        for file in dbs:
            if sqlite_needs_repair(file):
                return None
            db = connect_readonly(file)
            try:
                total += int(db.execute("SELECT count(*) FROM messages").fetchone()[0])
                firsts += _first_sqlite_data(db)
                for name, msgtype in db.execute("SELECT name, type FROM topics"):
                    stored.setdefault(str(name), str(msgtype))
            finally:
                db.close()
    except (ValueError, OSError, sqlite3.Error):
        return None  # the recovery proper names the problem
    if total != previous.message_count:
        return None
    if any(stored.get(t.name, t.msgtype) != t.msgtype for t in previous.topics):
        return None  # metadata.yaml names a type the storage does not: rewrite it from the storage
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


def _known_hash(schema: Any) -> str:
    """A channel's RIHS01 type hash from its schema, when the schema is a type the twin knows, word for word.

    rosbag2 Humble's MCAP writer keeps no hash in the channel (metadata.yaml has it, written at the
    end): a killed recording's hashes come back from the type itself, as the recorder computed them.
    """
    if schema is None:
        return ""
    registry = _registry()
    try:
        if not registry.knows(schema.name):
            return ""
        definition = registry.definition(schema.name)
    except BagError:
        return ""
    return definition.type_hash if bytes(schema.data) == definition.text.encode() else ""


@functools.cache
def _registry() -> Any:
    """One type registry per process (its definitions are cached)."""
    from twin.bag.typesys import TypeRegistry

    return TypeRegistry()


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
    repairs: list[_Repaired] = []
    try:
        for file in files:
            outcome, repaired = _repair_mcap(file)
            repairs.append(repaired)
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
                        type_description_hash=channel.metadata.get("topic_type_hash", "") or _known_hash(schema),
                    )
            if stats.message_count:
                starts.append(stats.start_ns)
                ends.append(stats.end_ns)
                infos.append(_file_info(file.name, stats.start_ns, stats.end_ns, stats.message_count))
            else:
                infos.append(_file_info(file.name, 0, 0, 0))
        meta = _metadata(
            storage="mcap",
            files=files,
            topics=topics,
            counts=counts,
            infos=infos,
            starts=starts,
            ends=ends,
            distro=distro,
            previous=previous,
            compressed=_compressed_messages(firsts),
        )
    except BaseException:
        _discard(repairs)
        raise
    return _finish(bag, "mcap", files, repairs, meta=meta, dropped=dropped)


def _recover_sqlite_bag(bag: Path, files: list[Path], previous: BagMetadata | None) -> RecoveryReport:
    topics: dict[str, TopicMetadata] = {}
    counts: dict[str, int] = {}
    infos: list[FileInformation] = []
    distro = previous.ros_distro if previous else ""
    starts: list[int] = []
    ends: list[int] = []
    firsts: list[bytes] = []
    repairs: list[_Repaired] = []
    # rosbag2 numbers rows from 1 without gaps: the count metadata.yaml names bounds the row ids to try
    max_rowid = previous.message_count + 1 if previous and previous.message_count > 0 else None
    try:
        for file in files:
            outcome, repaired = _repair_sqlite(file, max_rowid)
            repairs.append(repaired)
            readable = repaired.copy or file
            try:
                rows, file_distro = (outcome.rows, outcome.distro) if outcome else _sqlite_rows(file)
                db = connect_readonly(readable)
                try:
                    firsts += _first_sqlite_data(db)
                finally:
                    db.close()
            except sqlite3.Error as err:
                raise _cannot(file, err) from None
            distro = distro or file_distro
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
        if previous is not None and previous.message_count and not any(counts.values()):
            msg = (
                f"{bag}: cannot recover: not one of the {previous.message_count} messages its {METADATA_FILE} "
                "lists still reads (SQLite finds no row of the messages table: the file is cut or overwritten "
                "where they are); nothing was changed"
            )
            raise BagError(msg)
        meta = _metadata(
            storage="sqlite3",
            files=files,
            topics=topics,
            counts=counts,
            infos=infos,
            starts=starts,
            ends=ends,
            distro=distro,
            previous=previous,
            compressed=_compressed_messages(firsts),
        )
        for repaired in repairs:  # keep a repaired copy's metadata table in step with metadata.yaml, as rosbag2 does
            if repaired.copy is not None:
                with (
                    contextlib.suppress(sqlite3.Error),
                    contextlib.closing(sqlite3.connect(repaired.copy)) as db,
                    db,
                ):
                    db.execute(
                        "INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)",
                        (meta.version, render_metadata(meta, root=False)),
                    )
    except BaseException:
        _discard(repairs)
        raise
    return _finish(bag, "sqlite3", files, repairs, meta=meta, dropped=0)


def _metadata(
    *,
    storage: str,
    files: list[Path],
    topics: dict[str, TopicMetadata],
    counts: dict[str, int],
    infos: list[FileInformation],
    starts: list[int],
    ends: list[int],
    distro: str,
    previous: BagMetadata | None,
    compressed: bool,
) -> BagMetadata:
    """The bag's metadata as the storage describes it, in the version and distro the bag had."""
    profile = distro_profile(_distro(distro))
    start = min(starts) if starts else 0
    end = max(ends) if ends else 0
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
    return BagMetadata(
        version=previous.version if previous else profile.metadata_version,
        storage_identifier=storage,
        relative_file_paths=tuple(f.name for f in files),
        starting_time_ns=start,
        duration_ns=end - start,
        message_count=sum(counts.values()),
        topics=full_topics,
        files=tuple(infos),
        # rosbag2 writes the mode in capitals; every reader takes either case
        compression_format="zstd" if compressed else "",
        compression_mode="MESSAGE" if compressed else "",
        custom_data=previous.custom_data if previous else (),
        # the distro the bag names (its metadata, its storage's records), never one made up: a Foxy
        # bag's version 4 metadata names none, and the report should not call it Humble
        ros_distro=previous.ros_distro if previous and previous.ros_distro else distro,
    )


def _finish(
    bag: Path, storage: str, files: list[Path], repairs: list[_Repaired], *, meta: BagMetadata, dropped: int
) -> RecoveryReport:
    """Put the checked copies in place and write metadata.yaml (the original kept beside it)."""
    try:
        _backup_metadata(bag)
    except BagError:
        _discard(repairs)
        raise
    kept: list[tuple[str, str]] = []
    for i, repaired in enumerate(repairs):
        try:
            name = _put_in_place(repaired)
        except OSError as err:
            _discard(repairs[i:])
            msg = f"{repaired.file}: cannot put its repaired copy in place: {err.strerror or err}"
            raise BagError(msg) from None
        if name:
            kept.append((repaired.file.name, name))
    try:
        write_metadata(bag, meta)
    except OSError as err:
        msg = f"{bag}: cannot write {METADATA_FILE}: {err.strerror}"
        raise BagError(msg) from None
    return RecoveryReport(
        path=bag,
        storage=storage,
        files=tuple(f.name for f in files),
        message_count=meta.message_count,
        topic_counts=tuple((t.name, t.message_count) for t in meta.topics),
        was_complete=False,  # complete means nothing had to change; metadata.yaml was just rewritten
        dropped_bytes=dropped,
        metadata=meta,
        kept_originals=tuple(kept),
    )
