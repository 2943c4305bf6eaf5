"""sqlite3 storage: rosbag2's `.db3` schema, written in committed batches, and its recovery.

The tables are those of rosbag2's sqlite3 plugin at schema version 4 (Iron and later):
`schema`, `metadata`, `topics` (with `type_description_hash`), `message_definitions` and
`messages`, plus the `timestamp_idx` index (built on close). Humble's reader selects only the columns it knows
and ignores the rest, so the same file serves every distro; `message_definitions` is what lets
readers decode types they have never seen.

Crash safety: the database uses a rollback journal (not WAL), and every batch is one
transaction, so between commits the `.db3` file alone holds every committed message. A process
killed mid-commit leaves a hot journal that the next read-write open rolls back, which
`recover_sqlite()` does, on a copy: the original file is only ever read.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path

__all__ = [
    "Sqlite3Writer",
    "SqliteRecovery",
    "SqliteTopicStats",
    "connect_readonly",
    "pending_side_files",
    "recover_sqlite",
    "sqlite_needs_repair",
    "sqlite_topic_stats",
]

_INSERT = "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)"
_TIME_INDEX = "CREATE INDEX IF NOT EXISTS timestamp_idx ON messages (timestamp ASC)"


def connect_readonly(path: Path) -> sqlite3.Connection:
    """Open a bag database for reading only, writing nothing beside it.

    `mode=ro` alone still creates `-wal` and `-shm` files beside a WAL-mode database (as rosbag2
    writes them); `immutable=1` tells SQLite the file cannot change, so it takes no locks and
    creates no files. A WAL file's frames are not read that way: a complete bag has none (rosbag2
    checkpoints on close), and a killed recording's are `twin bag recover`'s to judge.
    """
    db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
    db.text_factory = _lenient_text
    return db


def _lenient_text(raw: bytes) -> str:
    """Text as UTF-8, a damaged byte shown as U+FFFD (never an exception in the middle of a query)."""
    return raw.decode("utf-8", "replace")


class Sqlite3Writer:
    """Writes a rosbag2 sqlite3 database; messages arrive in batches, one transaction each."""

    def __init__(self, path: Path, *, ros_distro: str, schema_version: int = 4, fsync: bool = False) -> None:
        """Create the database at `path` (which must not exist) with rosbag2's tables."""
        self.path = path
        with open(path, "xb"):  # refuse to overwrite, like rosbag2
            pass
        self._db = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=DELETE")
        self._db.execute(f"PRAGMA synchronous={'FULL' if fsync else 'OFF'}")
        self._schema_version = schema_version
        self._topic_ids: set[int] = set()
        self._definitions: set[str] = set()
        self._closed = False
        with self._transaction():
            self._db.execute("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL)")
            self._db.execute(
                "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,metadata TEXT NOT NULL)"
            )
            hash_column = ",type_description_hash TEXT NOT NULL" if schema_version >= 4 else ""
            self._db.execute(
                "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
                f"serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL{hash_column})"
            )
            if schema_version >= 4:
                self._db.execute(
                    "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY,topic_type TEXT NOT NULL,"
                    "encoding TEXT NOT NULL,encoded_message_definition TEXT NOT NULL,"
                    "type_description_hash TEXT NOT NULL)"
                )
            self._db.execute(
                "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
                "timestamp INTEGER NOT NULL, data BLOB NOT NULL)"
            )
            self._db.execute("CREATE INDEX timestamp_idx ON messages (timestamp ASC)")
            self._db.execute(
                "INSERT INTO schema (schema_version, ros_distro) VALUES (?, ?)", (schema_version, ros_distro)
            )

    def _transaction(self) -> _Transaction:
        return _Transaction(self._db)

    def add_topic(
        self,
        *,
        name: str,
        msgtype: str,
        serialization_format: str,
        qos: str,
        type_hash: str,
        encoding: str,
        definition: str,
    ) -> int:
        """Insert a topic (and its type's definition, once per type); return the topic id."""
        with self._transaction():
            if self._schema_version >= 4:
                cursor = self._db.execute(
                    "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles, type_description_hash)"
                    " VALUES (?, ?, ?, ?, ?)",
                    (name, msgtype, serialization_format, qos, type_hash),
                )
                if msgtype not in self._definitions:
                    self._db.execute(
                        "INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition,"
                        " type_description_hash) VALUES (?, ?, ?, ?)",
                        (msgtype, encoding, definition, type_hash),
                    )
                    self._definitions.add(msgtype)
            else:
                cursor = self._db.execute(
                    "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles) VALUES (?, ?, ?, ?)",
                    (name, msgtype, serialization_format, qos),
                )
        topic_id = int(cursor.lastrowid or 0)
        self._topic_ids.add(topic_id)
        return topic_id

    def write_batch(self, batch: Sequence[tuple[int, int, bytes]]) -> None:
        """Insert `(topic_id, timestamp_ns, data)` rows in one transaction.

        Raises:
            ValueError: If a topic id is unknown or a time negative (nothing is written).
            sqlite3.Error: If the insert fails (e.g. disk full); the transaction is rolled back.
        """
        if not batch:
            return
        unknown = set(map(itemgetter(0), batch)) - self._topic_ids
        if unknown:
            msg = f"unknown topic handle {sorted(unknown, key=repr)[0]!r}"
            raise ValueError(msg)
        if min(map(itemgetter(1), batch)) < 0:
            msg = "negative message time"
            raise ValueError(msg)
        with self._transaction():
            self._db.executemany(_INSERT, batch)

    def set_metadata(self, version: int, text: str) -> None:
        """Store the serialized bag metadata, as Iron and later do on close."""
        with self._transaction():
            self._db.execute("INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)", (version, text))

    def close(self) -> None:
        """Index the messages by time, as rosbag2 does, and close the database.

        The index is built here rather than kept up while recording: that saves about a
        microsecond per message, and a killed recording gets it from `recover_sqlite()`.
        """
        if not self._closed:
            self._closed = True
            try:
                self._db.execute(_TIME_INDEX)
            finally:
                self._db.close()


class _Transaction:
    """`BEGIN` … `COMMIT`, or `ROLLBACK` if the block raises."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self._db = db

    def __enter__(self) -> None:
        self._db.execute("BEGIN")

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self._db.execute("COMMIT")
        elif self._db.in_transaction:
            self._db.execute("ROLLBACK")


@dataclass(frozen=True, kw_only=True, slots=True)
class SqliteTopicStats:
    """A topic row of a sqlite3 bag with its message statistics."""

    topic_id: int
    name: str
    msgtype: str
    serialization_format: str
    qos: str
    type_hash: str
    count: int
    start_ns: int
    end_ns: int


def sqlite_topic_stats(db: sqlite3.Connection) -> list[SqliteTopicStats]:
    """Every topic of an open bag database with its message count and time range."""
    columns = {row[1] for row in db.execute("PRAGMA table_info(topics)")}
    qos_col = "offered_qos_profiles" if "offered_qos_profiles" in columns else "''"
    hash_col = "type_description_hash" if "type_description_hash" in columns else "''"
    counts = {
        int(row[0]): (int(row[1]), int(row[2]), int(row[3]))
        for row in db.execute(
            "SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages GROUP BY topic_id"
        )
    }
    out = []
    for topic_id, name, msgtype, fmt, qos, type_hash in db.execute(
        f"SELECT id, name, type, serialization_format, {qos_col}, {hash_col} FROM topics ORDER BY id"
    ):
        count, start, end = counts.get(int(topic_id), (0, 0, 0))
        out.append(
            SqliteTopicStats(
                topic_id=int(topic_id),
                name=str(name),
                msgtype=str(msgtype),
                serialization_format=str(fmt),
                qos=str(qos or ""),
                type_hash=str(type_hash or ""),
                count=count,
                start_ns=start,
                end_ns=end,
            )
        )
    return out


_JOURNAL_MAGIC = bytes.fromhex("d9d505f920a163d7")
_WAL_MAGICS = frozenset({0x377F0682, 0x377F0683})
_WAL_HEADER = 32
_BLOCK_ROWS = 4096


def pending_side_files(path: Path) -> list[Path]:
    """The side files that hold content the database file alone lacks: a hot journal, a WAL with frames.

    Judged by content: an empty WAL (what a reader opening a WAL-mode database without
    `immutable` leaves), a WAL with only its header, or a zeroed journal say nothing about a
    killed recording.
    """
    pending = []
    journal = path.with_name(path.name + "-journal")
    wal = path.with_name(path.name + "-wal")
    try:
        with journal.open("rb") as f:
            if f.read(8) == _JOURNAL_MAGIC:
                pending.append(journal)
    except FileNotFoundError:
        pass
    try:
        with wal.open("rb") as f:
            head = f.read(_WAL_HEADER + 1)
        if len(head) > _WAL_HEADER and int.from_bytes(head[:4], "big") in _WAL_MAGICS:
            pending.append(wal)
    except FileNotFoundError:
        pass
    return pending


def sqlite_needs_repair(path: Path) -> bool:
    """Whether the bag database at `path` needs `recover_sqlite` (read only; nothing written).

    It does when a side file holds content the file lacks, when it fails SQLite's integrity
    check, or when it lacks the time index a killed recording never built.

    Raises:
        sqlite3.Error: If the file is not a database at all.
    """
    if pending_side_files(path):
        return True
    db = connect_readonly(path)
    try:
        try:
            result = db.execute("PRAGMA quick_check").fetchone()
        except sqlite3.DatabaseError:
            return True
        if result is None or result[0] != "ok" or _bad_text(db):
            return True
        names = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
        return "messages" in names and "timestamp_idx" not in names
    finally:
        db.close()


@dataclass(frozen=True, kw_only=True, slots=True)
class SqliteRecovery:
    """The outcome of `recover_sqlite`."""

    rows: list[SqliteTopicStats]  #: the repaired file's topics with their statistics
    distro: str  #: the `ros_distro` its schema table names ("" if none)
    #: It was damaged: it failed the integrity check (its readable rows were copied into a new
    #: database), or text in its small tables was not UTF-8 (replaced by U+FFFD).
    salvaged: bool


def recover_sqlite(source: Path, target: Path, *, max_rowid: int | None = None) -> SqliteRecovery:
    """Write a complete, indexed copy of a bag database at `target`; `source` and its side files are only read.

    The copy takes the source's hot journal (rolled back: the interrupted transaction is undone)
    or WAL (its committed frames kept) with it. A copy that fails SQLite's integrity check is
    salvaged: every row that still reads is copied, block by block, into a fresh database with
    the same tables, a damaged page costing only the rows on it.

    Args:
        source: The database.
        target: Where the repaired database goes (it must not exist).
        max_rowid: The highest row id worth trying when the table's own maximum does not read
            (e.g. the message count metadata.yaml names); default: one per 16 bytes of the file.

    Raises:
        sqlite3.Error: If the file is not a rosbag2 database, or is damaged beyond any row.
        OSError: If the copy cannot be written.
    """
    side = pending_side_files(source)
    with source.open("rb") as src, target.open("xb") as out:
        shutil.copyfileobj(src, out)
    for file in side:
        shutil.copyfile(file, target.with_name(target.name + file.name[len(source.name) :]))
    try:
        rows, distro, mended = _repair(target)
        salvaged = mended > 0
    except sqlite3.DatabaseError as err:
        if "not a rosbag2 database" in str(err):
            _remove_with_side_files(target)
            raise
        salvage = target.with_name(target.name + ".salvage")
        _remove_with_side_files(salvage)
        try:
            _salvage(target, salvage, max_rowid or source.stat().st_size // 16)
            rows, distro, _ = _repair(salvage)
        except BaseException:
            _remove_with_side_files(salvage)
            _remove_with_side_files(target)
            raise
        _remove_with_side_files(target)
        os.replace(salvage, target)
        salvaged = True
    except BaseException:
        _remove_with_side_files(target)
        raise
    return SqliteRecovery(rows=rows, distro=distro, salvaged=salvaged)


def _remove_with_side_files(path: Path) -> None:
    for end in ("", "-journal", "-wal", "-shm"):
        path.with_name(path.name + end).unlink(missing_ok=True)


def _repair(path: Path) -> tuple[list[SqliteTopicStats], str, int]:
    """Roll back or replay what the side files hold, check integrity, mend text, index by time; the file is a copy.

    Returns:
        The topics with their statistics, the distro the schema table names, and how many text
        values were not UTF-8 (and now hold U+FFFD instead).
    """
    db = sqlite3.connect(path, isolation_level=None)
    try:
        # Any read of a database with a hot journal rolls the interrupted transaction back.
        result = db.execute("PRAGMA quick_check").fetchone()
        if result is None or result[0] != "ok":
            msg = f"database integrity check failed: {result[0] if result else 'no result'}"
            raise sqlite3.DatabaseError(msg)
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {"topics", "messages"} <= tables:
            msg = "not a rosbag2 database (no topics and messages tables)"
            raise sqlite3.DatabaseError(msg)
        mended = _mend_text(db)
        db.execute(_TIME_INDEX)
        distro = ""
        if "schema" in tables:
            row = db.execute("SELECT ros_distro FROM schema").fetchone()
            distro = str(row[0]) if row else ""
        db.execute("PRAGMA journal_mode=DELETE")  # readers open it immutable: everything in the one file
        return sqlite_topic_stats(db), distro, mended
    finally:
        db.close()


#: The tables whose text readers decode (topic names and types, definitions, the distro).
_TEXT_TABLES = ("schema", "metadata", "topics", "message_definitions")


def _bad_text(db: sqlite3.Connection) -> list[tuple[str, str, int, bytes]]:
    """Text values of the bag's small tables that are not UTF-8 (damage the integrity check does not see)."""
    names = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    bad = []
    for table in (t for t in _TEXT_TABLES if t in names):
        for column in [row[1] for row in db.execute(f"PRAGMA table_info({table})")]:
            quoted = '"' + str(column).replace('"', '""') + '"'
            query = f"SELECT rowid, CAST({quoted} AS BLOB) FROM {table} WHERE typeof({quoted}) = 'text'"
            for rowid, raw in db.execute(query):
                try:
                    bytes(raw).decode("utf-8")
                except UnicodeDecodeError:
                    bad.append((table, quoted, int(rowid), bytes(raw)))
    return bad


def _mend_text(db: sqlite3.Connection) -> int:
    """Replace the bytes of non-UTF-8 text in the small tables by U+FFFD, so readers open the bag; return how many."""
    bad = _bad_text(db)
    for table, column, rowid, raw in bad:
        db.execute(f"UPDATE {table} SET {column} = ? WHERE rowid = ?", (raw.decode("utf-8", "replace"), rowid))
    return len(bad)


def _salvage(damaged: Path, target: Path, max_rowid: int) -> None:
    """Copy every row of `damaged` that still reads into a new database `target` with the same tables.

    Rows are copied by row id in blocks; a block that fails is halved until the rows that do
    not read are found, so a damaged page loses only its own rows.

    Raises:
        sqlite3.DatabaseError: If not even the table definitions read.
    """
    db = sqlite3.connect(target, isolation_level=None)
    try:
        db.execute("PRAGMA journal_mode=DELETE")
        db.execute("PRAGMA synchronous=OFF")
        # SQLite checks an attached file's schema against the file when it reads it, and a file cut
        # short (a disk that filled, a copy that stopped) fails that as a whole, every row with it;
        # with the schema taken as written the rows that are there still read, one by one.
        db.execute("PRAGMA writable_schema=ON")
        db.execute("ATTACH DATABASE ? AS old", (str(damaged),))
        try:
            entries = db.execute("SELECT type, name, sql FROM old.sqlite_master WHERE sql IS NOT NULL").fetchall()
        except sqlite3.DatabaseError as err:
            msg = f"damaged beyond repair: its table definitions do not read ({err})"
            raise sqlite3.DatabaseError(msg) from None
        tables = [(name, sql) for kind, name, sql in entries if kind == "table" and not name.startswith("sqlite_")]
        if not {"topics", "messages"} <= {name for name, _ in tables}:
            msg = "not a rosbag2 database (no topics and messages tables)"
            raise sqlite3.DatabaseError(msg)
        for _, sql in tables:
            db.execute(sql)
        for name, _ in tables:
            _copy_rows(db, name, max_rowid)
        for kind, _, sql in entries:
            if kind == "index":
                try:
                    db.execute(sql)
                except sqlite3.DatabaseError:
                    continue
        db.execute("DETACH DATABASE old")
    finally:
        db.close()


def _copy_rows(db: sqlite3.Connection, table: str, max_rowid: int) -> None:
    """Copy the rows of `old.table` that read into `main.table`, by row id ranges.

    A range's row ids are listed in both directions: a damaged page with a row id out of order
    ends SQLite's range scan silently (ascending at an id above the range, descending below it),
    so what one direction misses beyond such a page, the other finds. What lies between the two,
    and any range whose listing fails, is tried again in smaller ranges. Rows are copied one by
    one inside SQLite (their text is never decoded), so a row that does not read costs only itself.
    """
    quoted = '"' + table.replace('"', '""') + '"'
    listing = f"SELECT rowid FROM old.{quoted} WHERE rowid BETWEEN ? AND ? ORDER BY rowid "
    copy = f"INSERT OR IGNORE INTO main.{quoted} SELECT * FROM old.{quoted} WHERE rowid = ?"
    try:
        row = db.execute(f"SELECT max(rowid) FROM old.{quoted}").fetchone()
        top = min(max(int(row[0] or 0), max_rowid), 16 * max_rowid)
    except sqlite3.DatabaseError:
        top = max_rowid
    ranges = [(lo, min(lo + _BLOCK_ROWS - 1, top)) for lo in range(top - (top - 1) % _BLOCK_ROWS, 0, -_BLOCK_ROWS)]
    while ranges:
        lo, hi = ranges.pop()
        ids: set[int] = set()
        failed = False
        ends: list[int | None] = []
        for order in ("ASC", "DESC"):
            last = None
            try:
                for (rowid,) in db.execute(listing + order, (lo, hi)):
                    ids.add(rowid)
                    if lo <= rowid <= hi:
                        last = rowid
            except sqlite3.DatabaseError:
                failed = True
            ends.append(last)
        _copy_each(db, copy, sorted(ids))
        up, down = ends
        gap_lo = lo if up is None else up + 1
        gap_hi = hi if down is None else down - 1
        if gap_lo > gap_hi:
            continue
        if (gap_lo, gap_hi) != (lo, hi):
            ranges.append((gap_lo, gap_hi))
        elif failed and lo < hi:
            mid = (lo + hi) // 2
            ranges += [(mid + 1, hi), (lo, mid)]


def _copy_each(db: sqlite3.Connection, copy: str, rowids: list[int]) -> None:
    """Copy rows one by one: in one transaction, or, if that does not commit, each in its own."""
    try:
        db.execute("BEGIN")
        for rowid in rowids:
            with contextlib.suppress(sqlite3.DatabaseError):
                db.execute(copy, (rowid,))
        db.execute("COMMIT")
        return
    except sqlite3.DatabaseError:
        if db.in_transaction:
            db.execute("ROLLBACK")
    for rowid in rowids:
        with contextlib.suppress(sqlite3.DatabaseError):
            db.execute(copy, (rowid,))
