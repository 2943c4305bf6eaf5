"""`twin bag recover` on bit-flipped bags: the original bytes survive, and every intact chunk's messages too.

Twenty seeded copies of a 20 s run per storage get random bit flips. What must survive is counted
here independently of the twin's reader: for MCAP, the chunks of the undamaged file (the `mcap`
library's summary) that no flip touched; for sqlite3, the rows whose b-tree page, its parent pages,
its overflow pages and the schema page (SQLite's `dbstat` table of the undamaged file) no flip
touched. The repaired bag is read back with the `mcap` library or plain sqlite3.
"""

from __future__ import annotations

import io
import random
import shutil
import sqlite3
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader

from tests.conftest import run_twin
from tests.robustness.helpers import assert_one_line_error
from twin.bag import open_bag
from twin.cli import main

COPIES = 20
#: The counts quoted in the hardening note (run with -s to see them).
_REPORT: list[str] = []


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 20 s default run in each storage."""
    root = tmp_path_factory.mktemp("runs")
    out = {}
    for storage in ("mcap", "sqlite3"):
        bag = root / storage
        proc = run_twin("simulate", "--duration", "20", "--storage", storage, "--out", str(bag), "-q")
        assert proc.returncode == 0, proc.stderr
        out[storage] = bag
    return out


def _flip(data: bytes, rng: random.Random, flips: int) -> tuple[bytes, list[int]]:
    buf = bytearray(data)
    where = sorted(rng.randrange(len(buf)) for _ in range(flips))
    for pos in where:
        buf[pos] ^= 1 << rng.randrange(8)
    return bytes(buf), where


def _recover(bag: Path, capsys: pytest.CaptureFixture[str]) -> int:
    code = main(["bag", "recover", str(bag)])
    err = capsys.readouterr().err
    assert code in (0, 5), err  # done, or refused with one line: never an internal error
    if code:
        print(assert_one_line_error(err, contains="cannot recover"))
    assert "Traceback" not in err
    return code


def _original_kept(file: Path, flipped: bytes) -> None:
    """The damaged bytes are still there: untouched in place, or kept beside as `<name>.orig`."""
    if file.exists() and file.read_bytes() == flipped:
        return
    assert (file.parent / (file.name + ".orig")).read_bytes() == flipped


# -- MCAP --------------------------------------------------------------------------------------------


def _mcap_chunks(data: bytes) -> list[tuple[int, int, Counter[tuple[str, int, bytes]]]]:
    """Each chunk of an undamaged file: its byte range and its messages (topic, log time, data)."""
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    assert summary is not None
    channels = summary.channels
    out = []
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        stream = io.BytesIO(data[index.chunk_start_offset : index.chunk_start_offset + index.chunk_length])
        chunk = next(iter(StreamReader(stream, skip_magic=True, emit_chunks=True).records))
        assert isinstance(chunk, Chunk)
        messages: Counter[tuple[str, int, bytes]] = Counter()
        for record in breakup_chunk(chunk):
            if isinstance(record, Message):
                messages[(channels[record.channel_id].topic, record.log_time, record.data)] += 1
        out.append((index.chunk_start_offset, index.chunk_start_offset + index.chunk_length, messages))
    return out


def _mcap_messages(file: Path) -> Counter[tuple[str, int, bytes]]:
    with file.open("rb") as stream:
        reader = make_reader(stream)
        return Counter((channel.topic, m.log_time, m.data) for _, channel, m in reader.iter_messages())


def _as_other_writer(
    source: Path, bag: Path, *, chunk_size: int = 100_000, compression: CompressionType = CompressionType.ZSTD
) -> Path:
    """The run as the mcap library writes it (as rosbag2's writer does): zstd chunks with CRCs, schemas inside."""
    bag.mkdir()
    shutil.copy(source.parent / "metadata.yaml", bag / "metadata.yaml")
    file = bag / source.name
    with source.open("rb") as stream, file.open("wb") as out:
        reader = make_reader(stream)
        writer = Writer(out, chunk_size=chunk_size, compression=compression, enable_crcs=True)
        writer.start(profile="ros2", library="mcap python")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            assert schema is not None
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], dict(channel.metadata)
                )
            writer.add_message(
                channels[channel.id],
                log_time=message.log_time,
                data=message.data,
                publish_time=message.publish_time,
                sequence=message.sequence,
            )
        writer.finish()
    return bag


@pytest.mark.parametrize("writer", ["twin", "mcap_zstd_crc"])
def test_recover_keeps_every_intact_mcap_chunk_and_the_original(
    writer: str, runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (source,) = runs["mcap"].glob("*.mcap")
    if writer != "twin":
        (source,) = _as_other_writer(source, tmp_path / "other").glob("*.mcap")
    data = source.read_bytes()
    chunks = _mcap_chunks(data)
    total = sum(sum(c.values()) for _, _, c in chunks)
    assert len(chunks) >= 20 and total > 5000
    rng = random.Random(f"mcap-flips-{writer}")
    must_total = got_total = 0
    for i in range(COPIES):
        bag = tmp_path / f"flipped{i}"
        shutil.copytree(source.parent, bag)
        flipped, where = _flip(data, rng, flips=1 + 3 * i)
        file = bag / source.name
        file.write_bytes(flipped)
        must: Counter[tuple[str, int, bytes]] = Counter()
        for start, end, messages in chunks:
            if not any(start <= p < end for p in where):
                must += messages
        assert _recover(bag, capsys) == 0
        _original_kept(file, flipped)
        got = _mcap_messages(file)
        missing = must - got
        assert not missing, f"copy {i} ({len(where)} flips): {sum(missing.values())} messages of intact chunks lost"
        must_total += sum(must.values())
        got_total += sum(got.values())
    _REPORT.append(
        f"mcap ({writer}, {len(chunks)} chunks): {COPIES} copies of {total} messages: "
        f"intact chunks hold {must_total}, recovered {got_total}"
    )
    print("\n" + _REPORT[-1])


def _whole_messages_before(data: bytes, chunk_start: int, cut: int) -> Counter[tuple[str, int, bytes]]:
    """The messages of an uncompressed chunk whose records end before byte `cut` (topic, log time, data)."""
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None
    out: Counter[tuple[str, int, bytes]] = Counter()
    pos = chunk_start + 1 + 8 + 8 + 8 + 8 + 4 + 4 + 8  # op, length, start, end, size, crc, "" compression, length
    while pos + 9 <= cut:
        op, length = data[pos], int.from_bytes(data[pos + 1 : pos + 9], "little")
        body = data[pos + 9 : pos + 9 + length]
        if pos + 9 + length > cut:
            break
        if op == 0x05:  # Message: channel, sequence, log time, publish time, data
            channel = summary.channels[int.from_bytes(body[:2], "little")].topic
            out[(channel, int.from_bytes(body[6:14], "little"), bytes(body[22:]))] += 1
        pos += 9 + length
    return out


@pytest.mark.parametrize("cut", [0.05, 0.3, 0.8])
def test_an_mcap_cut_inside_its_one_uncompressed_chunk_keeps_every_message_before_the_cut(
    cut: float, runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # As rosbags' MCAP writer leaves a bag: one large uncompressed chunk. Cut inside it, the chunk is
    # lost, but its records are whole up to the cut: `recover` stopped on an internal error (exit 70).
    (source,) = runs["mcap"].glob("*.mcap")
    bag = _as_other_writer(source, tmp_path / "one_chunk", chunk_size=1 << 30, compression=CompressionType.NONE)
    (file,) = bag.glob("*.mcap")
    data = file.read_bytes()
    ((start, end, _),) = _mcap_chunks(data)
    at = start + int(cut * (end - start))
    must = _whole_messages_before(data, start, at)
    file.write_bytes(data[:at])
    assert _recover(bag, capsys) == 0
    _original_kept(file, data[:at])
    got = _mcap_messages(file)
    assert sum(must.values()) > 100 and got == must  # every message the cut left whole, each once
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == sum(got.values())


# -- sqlite3 -----------------------------------------------------------------------------------------


def _sqlite_rows(file: Path) -> Counter[tuple[int, int, bytes]]:
    db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
    try:
        return Counter(
            (int(t), int(s), bytes(d)) for t, s, d in db.execute("SELECT topic_id, timestamp, data FROM messages")
        )
    finally:
        db.close()


def _sqlite_row_pages(file: Path) -> tuple[int, list[tuple[tuple[int, int, bytes], set[int]]]]:
    """The page size, and each message row with the pages it needs: schema page, parents, leaf, overflow."""
    db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
    try:
        page_size = int(db.execute("PRAGMA page_size").fetchone()[0])
        pages = db.execute("SELECT path, pageno, pagetype, ncell FROM dbstat WHERE name = 'messages'").fetchall()
        rows = db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY rowid").fetchall()
    finally:
        db.close()
    by_path = {path: pageno for path, pageno, _, _ in pages}
    leaves = sorted((path, pageno, ncell) for path, pageno, kind, ncell in pages if kind == "leaf")
    out = []
    k = 0
    for path, pageno, ncell in leaves:
        parents = {by_path[path[: i + 1]] for i, ch in enumerate(path[:-1]) if ch == "/"}
        for cell in range(ncell):
            overflow = {no for p, no in by_path.items() if p.startswith(f"{path}{cell:03x}+")}
            t, s, d = rows[k]
            out.append(((int(t), int(s), bytes(d)), {1, pageno, *parents, *overflow}))
            k += 1
    assert k == len(rows)
    return page_size, out


def test_recover_keeps_every_intact_sqlite3_row_and_the_original(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (source,) = runs["sqlite3"].glob("*.db3")
    data = source.read_bytes()
    page_size, rows = _sqlite_row_pages(source)
    assert len(rows) > 5000
    rng = random.Random("sqlite3-flips")
    must_total = got_total = refused = 0
    for i in range(COPIES):
        bag = tmp_path / f"flipped{i}"
        shutil.copytree(runs["sqlite3"], bag)
        flipped, where = _flip(data, rng, flips=1 + 3 * i)
        file = bag / source.name
        file.write_bytes(flipped)
        hit = {p // page_size + 1 for p in where}
        must = Counter(row for row, needs in rows if not needs & hit)
        code = _recover(bag, capsys)
        _original_kept(file, flipped)
        if code:  # refused: only when the schema page itself is gone
            assert 1 in hit
            refused += 1
            continue
        got = _sqlite_rows(file)
        missing = must - got
        assert not missing, f"copy {i} ({len(where)} flips): {sum(missing.values())} rows on intact pages lost"
        must_total += sum(must.values())
        got_total += sum(got.values())
        # and the twin reads the repaired bag (a message's damaged bytes may still fail to decode: one line, exit 5)
        code = main(["bag", "info", str(bag)])
        err = capsys.readouterr().err
        assert code == 0 or (code == 5 and assert_one_line_error(err)), err
    _REPORT.append(
        f"sqlite3: {COPIES} copies of {len(rows)} messages: intact pages hold {must_total}, recovered {got_total}"
        f" ({refused} refused: schema page hit)"
    )
    print("\n" + _REPORT[-1])


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_reading_a_damaged_bag_is_one_line_never_an_internal_error(
    storage: str, runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before any recover: what reads a damaged bag reads it, or says in one line that it is damaged."""
    (source,) = (p for p in runs[storage].iterdir() if p.suffix in (".mcap", ".db3"))
    data = source.read_bytes()
    rng = random.Random(f"read-{storage}")
    for i in range(8):
        bag = tmp_path / f"flipped{i}"
        shutil.copytree(runs[storage], bag)
        flipped, _ = _flip(data, rng, flips=1 + 8 * i)
        (bag / source.name).write_bytes(flipped)
        for argv in (
            ["bag", "info", str(bag)],
            ["analyze", str(bag), "--out", str(tmp_path / f"analysis{i}"), "--no-plots"],
            ["bag", "export", str(bag), "--topics", "/odom", "/scan", "--out", str(tmp_path / f"export{i}")],
        ):
            code = main(argv)
            err = capsys.readouterr().err
            assert code in (0, 5), f"{argv}: {err}"
            if code:
                assert_one_line_error(err)
        assert (bag / source.name).read_bytes() == flipped


def _copy(run: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of a run's bag folder to damage, and its storage file."""
    bag = tmp_path / "bag"
    shutil.copytree(run, bag)
    (path,) = (p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    return bag, path


def _read_with_commands(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], *, info: bool = False, topics: Sequence[str] = ()
) -> Iterator[tuple[list[str], int, str]]:
    """Each reading command on `bag` (`analyze`, `bag export` of `topics` or all, `bag info` if asked): argv, exit, stderr."""
    names = list(topics) or [t.name for t in open_bag(bag).topics]
    commands = [
        ["analyze", str(bag), "--out", str(tmp_path / "analysis"), "--no-plots"],
        ["bag", "export", str(bag), "--topics", *names, "--out", str(tmp_path / "export")],
    ]
    for argv in [["bag", "info", str(bag)]] * info + commands:
        code = main(argv)
        err = capsys.readouterr().err
        assert "Traceback" not in err and "internal error" not in err, f"{argv}: {err}"
        yield argv, code, err


def test_a_channel_whose_topic_name_is_not_text_is_read_around(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A flipped byte in a channel record's topic name (not UTF-8) is a damaged record, never exit 70."""
    bag, path = _copy(runs["mcap"], tmp_path)
    data = bytearray(path.read_bytes())
    pos = 8  # past the magic: records are op (1 byte) and length (8 bytes, little-endian)
    while data[pos] != 0x04:  # the first channel record: id (u16), schema id (u16), topic (u32 length + bytes)
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    data[pos + 9 + 8] = 0x9B  # the topic's first byte: not a UTF-8 start byte
    path.write_bytes(bytes(data))
    for argv, code, err in _read_with_commands(bag, tmp_path, capsys, topics=["/odom"]):
        assert code in (0, 5), f"{argv}: {err}"


def test_a_record_length_beyond_the_file_is_a_damaged_bag_never_an_internal_error(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A flip in a summary record's length (1 TiB stated): rosbags would read that many bytes at once (MemoryError)."""
    bag, path = _copy(runs["mcap"], tmp_path)
    data = bytearray(path.read_bytes())
    footer = len(data) - 8 - 29  # Footer: op (1), length (8), summary start (8), summary offset start (8), CRC (4)
    assert data[footer] == 0x02
    summary_start = int.from_bytes(data[footer + 9 : footer + 17], "little")
    data[summary_start + 1 : summary_start + 9] = (1 << 40).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    for argv, code, err in _read_with_commands(bag, tmp_path, capsys, info=True, topics=["/odom"]):
        assert code in (0, 5), f"{argv}: {err}"
        if code:
            assert "larger than the file" in assert_one_line_error(err, contains="twin bag recover")


def _mcap_first_message(data: bytes | bytearray) -> int:
    """The offset of the first Message record inside the first (uncompressed) Chunk of a twin MCAP file."""
    pos = 8
    while data[pos] != 0x06:  # Chunk
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    body = pos + 9 + 28  # start, end, uncompressed size (u64 each), CRC (u32)
    n = int.from_bytes(data[body : body + 4], "little")
    assert n == 0, "the twin writes uncompressed chunks"
    records = body + 4 + n + 8
    assert data[records] == 0x05  # Message: channel (u16), sequence (u32), log time (u64), publish time (u64)
    return records


def test_a_message_time_past_int64_is_a_damaged_bag(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """MCAP stores times as uint64, ROS as int64: a flipped top bit of a log time is damage, not exit 70."""
    bag, path = _copy(runs["mcap"], tmp_path)
    data = bytearray(path.read_bytes())
    data[_mcap_first_message(data) + 9 + 6 + 7] ^= 0x80  # the log time's most significant byte
    path.write_bytes(bytes(data))
    for argv, code, err in _read_with_commands(bag, tmp_path, capsys):
        # rosbags takes the times from the MessageIndex records, which the flip left alone: it may read the bag
        assert code == 5 or (code == 0 and argv[0] == "bag"), f"{argv}: {err}"
        if code:
            assert "past int64" in assert_one_line_error(err, contains="twin bag recover"), err


def test_a_sqlite3_timestamp_that_is_not_an_integer_is_a_damaged_bag(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """SQLite keeps what a damaged page holds, of any type: a text timestamp is damage, not exit 70."""
    bag, path = _copy(runs["sqlite3"], tmp_path)
    with sqlite3.connect(path) as db:
        db.execute("UPDATE messages SET timestamp = '' WHERE id = (SELECT min(id) FROM messages)")
    for argv, code, err in _read_with_commands(bag, tmp_path, capsys):
        assert code == 5, f"{argv}: {err}"
        assert "has time ''" in assert_one_line_error(err, contains="twin bag recover"), err


def test_a_truncated_mcap_is_one_error_line_for_every_reading_command(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `ekf replay` said the error three times (a warning from each open_bag first), and `play` read
    # the bag's metadata and got as far as serving before it failed.
    bag, path = _copy(runs["mcap"], tmp_path)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    for argv in (
        ["ekf", "replay", str(bag), "--out", str(tmp_path / "ekf")],
        ["play", str(bag), "--port", "0"],
        ["analyze", str(bag), "--out", str(tmp_path / "analysis"), "--no-plots"],
    ):
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 5, f"{argv}: {err}"
        assert_one_line_error(err, contains="run `twin bag recover")
        assert len(err.strip().splitlines()) == 1, err  # and no warning before it
