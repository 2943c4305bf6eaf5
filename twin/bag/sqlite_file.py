"""sqlite3 storage: rosbag2's `.db3` schema, written in committed batches, and its recovery.

The tables are those of rosbag2's sqlite3 plugin at schema version 4 (Iron and later):
`schema`, `metadata`, `topics` (with `type_description_hash`), `message_definitions` and
`messages`, plus the `timestamp_idx` index (built on close). Humble's reader selects only the columns it knows
and ignores the rest, so the same file serves every distro; `message_definitions` is what lets
readers decode types they have never seen.

Crash safety: the database uses a rollback journal (not WAL), and every batch is one
transaction, so between commits the `.db3` file alone holds every committed message. A process
killed mid-commit leaves a hot journal that the next read-write open rolls back, which
`recover_sqlite()` does.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path

__all__ = ["Sqlite3Writer", "SqliteTopicStats", "recover_sqlite", "sqlite_topic_stats"]

_INSERT = "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)"
_TIME_INDEX = "CREATE INDEX IF NOT EXISTS timestamp_idx ON messages (timestamp ASC)"


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


def recover_sqlite(path: Path) -> tuple[list[SqliteTopicStats], str]:
    """Bring a killed writer's database back to its last commit and index it.

    Returns:
        The topics with their statistics, and the `ros_distro` the schema table names ("" if none).

    Raises:
        sqlite3.Error: If the file is not a database or is damaged beyond its journal.
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
        db.execute(_TIME_INDEX)
        distro = ""
        if "schema" in tables:
            row = db.execute("SELECT ros_distro FROM schema").fetchone()
            distro = str(row[0]) if row else ""
        db.execute("PRAGMA journal_mode=DELETE")
        return sqlite_topic_stats(db), distro
    finally:
        db.close()
