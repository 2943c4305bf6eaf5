"""`twin bag recover`: what a killed recording leaves becomes a complete, indexed bag."""

from __future__ import annotations

import random
import re
import shutil
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from twin.bag import ClockEncoder, Recorder, open_bag, read_messages, recover_bag
from twin.bag.mcap_file import scan_mcap
from twin.bag.mission_mix import MissionMix
from twin.core.errors import BagError


def _record_in_chunks(bag: Path, *, storage: str = "mcap", distro: str = "humble") -> None:
    with Recorder(bag, storage=storage, distro=distro, chunk_messages=300) as rec:
        MissionMix(rec, particles=20, path_poses=10).run(3_000_000_000)


def _chunk_ends(file: Path) -> list[tuple[int, int]]:
    """(end offset of each chunk record, messages up to and including it)."""
    scan = scan_mcap(file)
    out, total = [], 0
    for chunk in scan.chunks:
        total += len(chunk.channels)
        out.append((chunk.offset + chunk.length, total))
    return out


def _valid_everywhere(bag: Path, expected: int) -> None:
    """Indexed readers find exactly `expected` messages, and every one decodes."""
    (file,) = bag.glob("*.mcap")
    with file.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == expected
        assert sum(1 for _ in reader.iter_messages()) == expected
    with AnyReader([bag]) as reader:
        assert sum(1 for c, _, raw in reader.messages() if reader.deserialize(raw, c.msgtype) is not None) == expected
    assert open_bag(bag).message_count == expected


def test_a_truncated_mcap_keeps_every_complete_chunk(tmp_path: Path) -> None:
    """Cut the file at random bytes (as a kill would); recovery keeps exactly the whole chunks before the cut."""
    complete = tmp_path / "complete"
    _record_in_chunks(complete)
    (src,) = complete.glob("*.mcap")
    complete_info = open_bag(complete)
    ends = _chunk_ends(src)
    assert len(ends) >= 5
    data = src.read_bytes()
    rng = random.Random(7)
    # random cuts, plus right at the end of a chunk, one byte short of it, and inside its indexes
    cuts = [rng.randrange(200, ends[-1][0]) for _ in range(8)] + [ends[2][0], ends[2][0] - 1, ends[2][0] + 20]
    for i, cut in enumerate(cuts):
        bag = tmp_path / f"cut{i}"
        bag.mkdir()
        (bag / src.name).write_bytes(data[:cut])
        report = recover_bag(bag)
        # a whole chunk is kept even if its message indexes were cut off: they are rebuilt
        expected = max((n for end, n in ends if end <= cut), default=0)
        assert not report.was_complete
        assert report.message_count == expected, f"cut at byte {cut}"
        _valid_everywhere(bag, expected)
        meta = (bag / "metadata.yaml").read_text()
        assert "version: 8" in meta and "ros_distro: humble" in meta
        if expected:  # each topic's type hash, which Humble's MCAP channels do not carry, back from its type
            hashes = {t.name: t.type_hash for t in open_bag(bag).topics}
            assert hashes == {t.name: t.type_hash for t in complete_info.topics if t.name in hashes}
            assert all(h.startswith("RIHS01_") for h in hashes.values()), hashes


def test_recovering_a_complete_bag_only_rewrites_metadata(tmp_path: Path) -> None:
    bag = tmp_path / "ok"
    _record_in_chunks(bag, distro="jazzy")
    (file,) = bag.glob("*.mcap")
    before = file.read_bytes()
    original = (bag / "metadata.yaml").read_text()
    assert recover_bag(bag).was_complete
    (bag / "metadata.yaml").unlink()
    report = recover_bag(bag)
    assert not report.was_complete and report.dropped_bytes == 0
    assert file.read_bytes() == before
    assert (bag / "metadata.yaml").read_text() == original  # same distro form (version 9) and counts


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_sqlite3_without_metadata_is_rebuilt_in_its_distro_form(tmp_path: Path, distro: str) -> None:
    bag = tmp_path / "db"
    _record_in_chunks(bag, storage="sqlite3", distro=distro)
    original = open_bag(bag)
    (bag / "metadata.yaml").unlink()
    with pytest.raises(BagError, match="twin bag recover"):
        open_bag(bag)
    report = recover_bag(bag)
    info = open_bag(bag)
    assert report.metadata.version == (8 if distro == "humble" else 9)
    assert info.message_count == original.message_count
    assert {t.name: (t.message_count, t.qos) for t in info.topics} == {
        t.name: (t.message_count, t.qos) for t in original.topics
    }
    assert sum(1 for _ in read_messages(bag)) == original.message_count


def test_a_sqlite3_file_missing_its_last_page_keeps_every_row_that_is_there(tmp_path: Path) -> None:
    # A file cut short (a disk that filled, a copy that stopped): SQLite refused to attach it at all,
    # so the salvage copied nothing; with its schema taken as written, every row still there reads.
    bag = tmp_path / "db"
    _record_in_chunks(bag, storage="sqlite3")
    recorded = open_bag(bag).message_count
    (db_file,) = bag.glob("*.db3")
    page = 4096
    assert db_file.stat().st_size % page == 0
    with db_file.open("r+b") as f:
        f.truncate(db_file.stat().st_size - page)
    cut = db_file.read_bytes()
    report = recover_bag(bag)
    assert (bag / (db_file.name + ".orig")).read_bytes() == cut  # the damaged original, kept as it was
    info = open_bag(bag)
    assert 0.9 * recorded <= info.message_count <= recorded, (info.message_count, recorded)
    assert report.metadata.message_count == info.message_count
    with AnyReader([bag]) as reader:
        assert sum(1 for c, _, raw in reader.messages() if reader.deserialize(raw, c.msgtype) is not None) == (
            info.message_count
        )


def test_sqlite3_interrupted_mid_transaction_rolls_back_to_the_last_commit(tmp_path: Path) -> None:
    """A hot journal (the process died inside a commit) is rolled back; committed batches stay."""
    bag = tmp_path / "hot"
    clock = ClockEncoder()
    with Recorder(bag, storage="sqlite3") as rec:
        h = rec.add_topic("/clock", ClockEncoder.msgtype)
        for k in range(100):
            rec.write(h, k, clock.encode(k))
    (db_file,) = bag.glob("*.db3")
    (bag / "metadata.yaml").unlink()
    # Simulate the kill: a second connection starts a big transaction, spills it to the file and
    # leaves its journal behind (we copy both files mid-transaction).
    crashed = tmp_path / "crashed"
    crashed.mkdir()
    conn = sqlite3.connect(db_file, isolation_level=None)
    conn.execute("PRAGMA cache_size=1")
    conn.execute("BEGIN")
    conn.executemany(
        "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
        [(1, 1000 + k, bytes(4000)) for k in range(500)],
    )
    shutil.copy(db_file, crashed / db_file.name)
    journal = db_file.with_name(db_file.name + "-journal")
    assert journal.exists()
    shutil.copy(journal, crashed / journal.name)
    conn.execute("ROLLBACK")
    conn.close()
    report = recover_bag(crashed)
    assert not report.was_complete
    assert report.message_count == 100
    assert not (crashed / journal.name).exists()
    assert [m.msg.clock.nanosec for m in read_messages(crashed)][:3] == [0, 1, 2]


def test_recover_refuses_what_it_cannot_recover(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="no such bag folder"):
        recover_bag(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match=r"no \.mcap or \.db3"):
        recover_bag(tmp_path / "empty")
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "junk_0.mcap").write_bytes(b"not an mcap file at all")
    with pytest.raises(BagError, match="not an MCAP file"):
        recover_bag(tmp_path / "junk")
    (tmp_path / "junkdb").mkdir()
    (tmp_path / "junkdb" / "junkdb_0.db3").write_bytes(b"not a database" * 100)
    with pytest.raises(BagError, match="cannot recover"):
        recover_bag(tmp_path / "junkdb")


def test_an_mcap_file_of_its_magic_alone_is_said_to_hold_nothing_not_sent_to_recover(tmp_path: Path) -> None:
    # `bag info` said "a recording that was killed; `twin bag recover` completes it", and recover then refused it.
    from tests.conftest import run_twin

    file = tmp_path / "x.mcap"
    file.write_bytes(b"\x89MCAP0\r\n")
    info = run_twin("bag", "info", str(file))
    assert info.returncode == 5
    assert info.stderr.strip().splitlines() == [
        f"twin: error: {file}: the MCAP file ends before its header: nothing was recorded"
    ]
    assert "cannot recover: the file ends before its header" in run_twin("bag", "recover", str(file)).stderr


def _another_writers_bag(tmp_path: Path, *, crcs: bool) -> tuple[Path, Path, list[Any]]:
    """500 `/chatter` strings (log times 1, 2, ...) as the mcap library writes them: zstd chunks of ~2 kB,
    the schema and channel inside the first chunk (and in the summary); the bag, its file, its chunk indexes."""
    import struct

    from mcap.writer import CompressionType, Writer

    bag = tmp_path / "other"
    bag.mkdir()
    file = bag / "other_0.mcap"
    with file.open("wb") as stream:
        writer = Writer(stream, chunk_size=2000, compression=CompressionType.ZSTD, enable_crcs=crcs)
        writer.start(profile="ros2", library="another writer")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = writer.register_channel("/chatter", "cdr", schema)
        for i in range(1, 501):
            text = f"hello {i}".encode() + b"\0"
            writer.add_message(
                channel, log_time=i, publish_time=i, data=b"\0\1\0\0" + struct.pack("<I", len(text)) + text
            )
        writer.finish()
    with file.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return bag, file, sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def test_another_writers_zstd_chunks_holding_their_schemas_recover(tmp_path: Path) -> None:
    """Writers such as rosbag2's and the mcap libraries put Schema and Channel records inside
    (compressed) chunks; a killed file of theirs must recover with its topics, not as an empty bag."""
    bag, file, chunks = _another_writers_bag(tmp_path, crcs=False)
    assert len(chunks) >= 4 and {c.compression for c in chunks} == {"zstd"}
    kept = chunks[len(chunks) // 2]
    cut = kept.chunk_start_offset + kept.chunk_length + 5  # inside its message indexes, as a kill leaves it
    file.write_bytes(file.read_bytes()[:cut])
    report = recover_bag(bag)
    expected = kept.message_end_time  # log times run 1, 2, 3, ...
    assert report.message_count == expected
    _valid_everywhere(bag, expected)
    meta = (bag / "metadata.yaml").read_text()
    assert "name: /chatter" in meta and "type: std_msgs/msg/String" in meta


def test_channels_defined_in_a_damaged_chunk_come_from_the_summary_when_the_closing_magic_is_damaged_too(
    tmp_path: Path,
) -> None:
    """The mcap library defines a channel inside the chunk of its first message and again in the summary.

    With that first chunk damaged and the file's last bytes flipped (the closing magic), the summary
    is still there after DataEnd: the later, intact chunks keep their messages.
    """
    bag, file, (first, *rest) = _another_writers_bag(tmp_path, crcs=True)
    data = bytearray(file.read_bytes())
    data[first.chunk_start_offset + first.chunk_length // 2] ^= 0x10  # inside the chunk that defines /chatter
    data[-3] ^= 0x01  # the closing magic
    file.write_bytes(bytes(data))
    report = recover_bag(bag)
    expected = sum(c.message_end_time - c.message_start_time + 1 for c in rest)  # log times run 1, 2, 3, ...
    assert report.message_count == expected
    _valid_everywhere(bag, expected)
    assert "name: /chatter" in (bag / "metadata.yaml").read_text()


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_complete_bag_is_reported_complete_and_left_untouched(tmp_path: Path, storage: str) -> None:
    bag = tmp_path / "ok"
    _record_in_chunks(bag, storage=storage, distro="jazzy")
    before = {f.name: f.read_bytes() for f in bag.iterdir()}
    report = recover_bag(bag)
    assert report.was_complete
    assert {f.name: f.read_bytes() for f in bag.iterdir()} == before  # no file changed, none added


def test_a_real_humble_bag_is_left_untouched(tmp_path: Path, fixtures: Path) -> None:
    import shutil

    bag = tmp_path / "real"
    shutil.copytree(fixtures / "bags" / "tb3_waffle_gazebo_humble", bag)
    before = {f.name: f.read_bytes() for f in bag.iterdir()}
    assert recover_bag(bag).was_complete
    assert {f.name: f.read_bytes() for f in bag.iterdir()} == before
    from tests.conftest import run_twin

    result = run_twin("bag", "recover", str(bag))  # its metadata (version 5) names no distro: none printed
    assert result.stdout.strip() == (
        f"{bag}: sqlite3 bag complete (nothing changed): 9432 messages on 13 topics (metadata version 5)"
    )


def test_a_rewrite_keeps_the_original_metadata_as_a_backup(tmp_path: Path) -> None:
    bag = tmp_path / "stale"
    _record_in_chunks(bag)
    text = (bag / "metadata.yaml").read_text()
    count = re.search(r"^  message_count: (\d+)$", text, re.MULTILINE)
    assert count is not None
    stale = text.replace(count.group(0), f"  message_count: {int(count.group(1)) + 1}")
    (bag / "metadata.yaml").write_text(stale)  # a count that does not match the storage
    report = recover_bag(bag)
    assert not report.was_complete
    assert (bag / "metadata.yaml.orig").read_text() == stale
    recover_bag(bag)  # now complete: no second backup
    assert not (bag / "metadata.yaml.orig.2").exists()


def test_a_schema_definition_with_a_flipped_byte_is_mended(tmp_path: Path) -> None:
    # No CRC covers a schema's text: a flipped byte made it non-UTF-8, every reader refused the bag,
    # and `recover` (seeing a complete file) changed nothing, sending the user round in a loop.
    bag = tmp_path / "flipped"
    _record_in_chunks(bag)
    recorded = open_bag(bag).message_count
    (file,) = bag.glob("*.mcap")
    data = bytearray(file.read_bytes())
    marker = (
        b"================================================================================\nMSG: geometry_msgs/Point"
    )
    at = data.find(marker)
    assert at > 0
    while at >= 0:  # the schema's record and its copy in the summary: a flipped byte inside each
        data[at + 3] = 0x8D
        at = data.find(marker, at + 1)
    file.write_bytes(bytes(data))
    with pytest.raises(UnicodeDecodeError), AnyReader([bag]) as reader:  # (rosbags, as Foxglove's readers do)
        sum(1 for _ in reader.messages())
    report = recover_bag(bag)
    assert not report.was_complete
    _valid_everywhere(bag, recorded)  # every message back, decoding with the definitions mended


def test_a_foxy_database_without_metadata_is_rebuilt_naming_no_distro(tmp_path: Path) -> None:
    # rosbag2 on Foxy wrote no schema table and no distro anywhere: the rebuilt metadata called it Humble.
    from tests.conftest import run_twin

    bag = tmp_path / "foxy"
    bag.mkdir()
    with sqlite3.connect(bag / "foxy_0.db3") as db:
        db.execute(
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
            "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)"
        )
        db.execute(
            "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, "
            "data BLOB NOT NULL)"
        )
        db.execute("INSERT INTO topics VALUES (1, '/chatter', 'std_msgs/msg/String', 'cdr', '')")
        for i in range(3):
            data = b"\x00\x01\x00\x00" + (5).to_bytes(4, "little") + b"hi %d\x00" % i
            db.execute("INSERT INTO messages VALUES (?, 1, ?, ?)", (i + 1, (i + 1) * 10**8, data))
    result = run_twin("bag", "recover", str(bag))
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("3 messages on 1 topics (metadata version 8)")  # no distro named
    assert open_bag(bag).ros_distro == ""
    assert [m.msg.data for m in read_messages(bag, ["/chatter"])] == ["hi 0", "hi 1", "hi 2"]


def test_a_database_cut_before_its_messages_is_refused_unchanged_and_reading_it_says_recover(
    tmp_path: Path, fixtures: Path
) -> None:
    from tests.conftest import run_twin

    bag = tmp_path / "cut"
    shutil.copytree(fixtures / "bags" / "tb3_waffle_gazebo_humble", bag)
    for file in bag.iterdir():
        file.chmod(0o644)
    (file,) = bag.glob("*.db3")
    with file.open("r+b") as f:
        f.truncate(1_000_000)  # of 4 MB: SQLite finds none of the messages' rows
    before = {f.name: f.read_bytes() for f in bag.iterdir()}
    read = run_twin("analyze", str(bag), "--out", str(tmp_path / "report"))
    assert read.returncode == 5
    assert "database disk image is malformed" in read.stderr and f"`twin bag recover {bag}`" in read.stderr
    result = run_twin("bag", "recover", str(bag))
    assert result.returncode == 5
    (line,) = result.stderr.strip().splitlines()[-1:]
    assert "cannot recover: not one of the 9432 messages its metadata.yaml lists still reads" in line
    assert {f.name: f.read_bytes() for f in bag.iterdir()} == before
