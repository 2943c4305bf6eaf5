"""The recorder: streams to disk on time, always closes into a valid bag, fails with one clear error."""

from __future__ import annotations

import errno
import os
import re
import sqlite3
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from twin.bag import ClockEncoder, ImuEncoder, Recorder, StringEncoder, open_bag, read_messages
from twin.bag.mcap_file import scan_mcap
from twin.core.errors import BagError

REPO = Path(__file__).resolve().parents[3]
STORAGES = ["mcap", "sqlite3"]


def on_disk(bag: Path) -> int:
    """Messages a reader can find in the storage file right now (the recorder still open)."""
    if files := list(bag.glob("*.mcap")):
        return scan_mcap(files[0]).stats().message_count
    (db,) = bag.glob("*.db3")
    conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return int(conn.execute("SELECT COUNT(*) FROM messages").fetchone()[0])
    finally:
        conn.close()


@pytest.mark.parametrize("storage", STORAGES)
def test_messages_reach_disk_once_the_flush_interval_has_passed(tmp_path: Path, storage: str) -> None:
    bag = tmp_path / "run"
    clock = ClockEncoder()
    with Recorder(bag, storage=storage, flush_interval_s=0.1) as rec:
        h = rec.add_topic("/clock", ClockEncoder.msgtype)
        for k in range(200):
            rec.write(h, k, clock.encode(k))
        assert on_disk(bag) == 0  # batched: a fast loop pays no I/O per message
        time.sleep(0.12)
        # The recorder looks at the clock at least every 64 writes, so the batch goes out
        # within the next few writes.
        k = 200
        while on_disk(bag) == 0 and k < 264:
            rec.write(h, k, clock.encode(k))
            k += 1
        assert on_disk(bag) >= 200
        rec.write(h, k, clock.encode(k))
        time.sleep(0.12)
        rec.poll()  # a loop that stops writing flushes without writing
        assert on_disk(bag) == k + 1


@pytest.mark.parametrize("storage", STORAGES)
def test_a_slow_loop_is_still_flushed_on_time(tmp_path: Path, storage: str) -> None:
    """Few writes per interval: the recorder checks the clock on every write, not every few dozen."""
    bag = tmp_path / "slow"
    clock = ClockEncoder()
    with Recorder(bag, storage=storage, flush_interval_s=0.2) as rec:
        h = rec.add_topic("/clock", ClockEncoder.msgtype)
        start = time.monotonic()
        k = 0
        while time.monotonic() - start < 0.6:
            rec.write(h, k, clock.encode(k))
            k += 1
            time.sleep(0.02)
        handed = k
        written_before = handed - int(0.2 / 0.02) - 2  # everything older than one interval
        assert on_disk(bag) >= written_before


@pytest.mark.parametrize("storage", STORAGES)
def test_an_exception_in_the_block_still_closes_a_valid_bag(tmp_path: Path, storage: str) -> None:
    bag = tmp_path / "crashy"
    clock = ClockEncoder()
    with pytest.raises(RuntimeError, match="controller diverged"), Recorder(bag, storage=storage) as rec:
        h = rec.add_topic("/clock", ClockEncoder.msgtype)
        for k in range(5):
            rec.write(h, k * 10_000_000, clock.encode(k * 10_000_000))
        raise RuntimeError("controller diverged")
    info = open_bag(bag)
    assert info.message_count == 5
    assert [m.msg.clock.nanosec for m in read_messages(bag)] == [0, 10_000_000, 20_000_000, 30_000_000, 40_000_000]


@pytest.mark.parametrize("storage", STORAGES)
def test_close_is_idempotent_and_writing_after_close_fails(tmp_path: Path, storage: str) -> None:
    rec = Recorder(tmp_path / "b", storage=storage)
    h = rec.add_topic("/clock", ClockEncoder.msgtype)
    rec.write(h, 0, ClockEncoder().encode(0))
    rec.close()
    rec.close()
    assert rec.closed and rec.message_count == 1
    with pytest.raises(BagError, match="closed"):
        rec.write(h, 1, ClockEncoder().encode(1))
    with pytest.raises(BagError, match="closed"):
        rec.add_topic("/x", ClockEncoder.msgtype)
    assert open_bag(tmp_path / "b").message_count == 1


def test_an_empty_recording_is_a_valid_bag(tmp_path: Path) -> None:
    for storage in STORAGES:
        with Recorder(tmp_path / storage, storage=storage) as rec:
            rec.add_topic("/clock", ClockEncoder.msgtype)
        info = open_bag(tmp_path / storage)
        assert info.message_count == 0 and info.topic("/clock").message_count == 0
        assert list(read_messages(tmp_path / storage)) == []


def test_bad_arguments_raise_one_clear_bag_error(tmp_path: Path) -> None:
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(BagError, match="exists and is not empty"):
        Recorder(tmp_path / "full")
    with pytest.raises(BagError, match=r"full/x: is a file, where the bag's folder goes"):  # (it said "not empty")
        Recorder(tmp_path / "full" / "x")
    with pytest.raises(BagError, match="unknown bag storage 'rosbag'"):
        Recorder(tmp_path / "a", storage="rosbag")
    with pytest.raises(BagError, match="did you mean 'jazzy'"):
        Recorder(tmp_path / "b", distro="jazy")
    with Recorder(tmp_path / "c") as rec:
        with pytest.raises(BagError, match="did you mean 'sensor_msgs/msg/Imu'"):
            rec.add_topic("/imu", "sensor_msgs/msg/Imuu")
        rec.add_topic("/imu", ImuEncoder.msgtype)
        with pytest.raises(BagError, match="already recorded"):
            rec.add_topic("/imu", ImuEncoder.msgtype)


@pytest.mark.parametrize("storage", STORAGES)
def test_bad_writes_are_named_when_the_batch_is_written(tmp_path: Path, storage: str) -> None:
    with Recorder(tmp_path / "a", storage=storage) as rec:
        h = rec.add_topic("/clock", ClockEncoder.msgtype)
        rec.write(h + 7, 0, b"\x00\x01\x00\x00")  # type: ignore[arg-type]
        with pytest.raises(BagError, match="unknown topic handle 8"):
            rec.flush()
        rec.write(h, -5, ClockEncoder().encode(0))
        with pytest.raises(BagError, match=r"/clock got time -5"):
            rec.flush()


def test_custom_types_can_be_added_from_their_msg_text(tmp_path: Path) -> None:
    definition = "# battery\nfloat64 voltage_v\nfloat64 current_a\n"
    with Recorder(tmp_path / "b") as rec:
        h = rec.add_topic("/battery", "my_msgs/msg/Battery", msgdef=definition)
        rec.write(h, 0, b"\x00\x01\x00\x00" + struct.pack("<dd", 12.5, 1.5))
    (msg,) = read_messages(tmp_path / "b")
    assert msg.msgtype == "my_msgs/msg/Battery"
    assert (msg.msg.voltage_v, msg.msg.current_a) == (12.5, 1.5)
    assert open_bag(tmp_path / "b").topic("/battery").definition == "embedded"


@pytest.mark.parametrize("storage", STORAGES)
def test_disk_full_in_the_middle_of_a_recording(tmp_path: Path, storage: str) -> None:
    """A file-size limit makes the kernel refuse writes like a full disk: one BagError, a readable bag."""
    bag = tmp_path / "full"
    script = textwrap.dedent(
        f"""
        import resource, signal
        from twin.bag import Recorder, StringEncoder
        from twin.core.errors import BagError
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # get EFBIG instead of being killed
        resource.setrlimit(resource.RLIMIT_FSIZE, (400_000, 400_000))
        text = StringEncoder().encode("x" * 1000)
        rec = Recorder({str(bag)!r}, storage={storage!r}, chunk_messages=50)
        h = rec.add_topic("/chatter", StringEncoder.msgtype)
        try:
            for k in range(10_000):
                rec.write(h, k * 1_000_000, text)
            rec.close()
        except BagError as err:
            print("ERROR", err)
            print("CLOSED", rec.closed, rec.message_count)
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0].startswith("ERROR") and "cannot write" in lines[0], run.stdout
    # RLIMIT_FSIZE gives EFBIG: told apart from a full disk, and where the bag ends is stated
    assert "file-size limit" in lines[0] and "not a full disk" in lines[0], lines[0]  # sqlite3: from free space
    assert re.search(r"ends at t=\d+\.\d{3} s", lines[0]), lines[0]
    assert lines[1].startswith("CLOSED True")
    kept = int(lines[1].split()[-1])
    assert 100 < kept < 10_000
    if "closed with the" in lines[0]:
        info = open_bag(bag)  # readable as it is
    else:
        from twin.bag import recover_bag

        recover_bag(bag)  # the error told the user to do this
        info = open_bag(bag)
    assert info.message_count == kept
    assert sum(1 for _ in read_messages(bag)) == kept


def test_enospc_gives_one_disk_full_error_and_keeps_the_bag(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bag = tmp_path / "nospace"
    rec = Recorder(bag, chunk_messages=10)
    h = rec.add_topic("/chatter", StringEncoder.msgtype)
    enc = StringEncoder()
    for k in range(30):
        rec.write(h, k, enc.encode(f"hello {k}"))
    rec.flush()
    assert rec._mcap is not None
    file = rec._mcap._file
    real_write = file.write
    calls = {"n": 0}

    def failing_write(data: object) -> int:
        calls["n"] += 1
        if calls["n"] == 1:
            real_write(bytes(memoryview(data))[:100])  # type: ignore[arg-type]
            raise OSError(errno.ENOSPC, "No space left on device")
        return int(real_write(data))  # type: ignore[arg-type]

    monkeypatch.setattr(rec._mcap, "_file", _Wrapped(file, failing_write))
    with pytest.raises(BagError) as err:
        for k in range(30, 60):
            rec.write(h, k, enc.encode(f"hello {k}"))
    assert "the disk is full" in str(err.value) and "closed with the 30 messages" in str(err.value)
    rec.close()  # idempotent after the failure
    assert open_bag(bag).message_count == 30
    assert [m.msg.data for m in read_messages(bag)][-1] == "hello 29"


class _Wrapped:
    def __init__(self, inner: object, write: object) -> None:
        self._inner = inner
        self.write = write

    def __getattr__(self, name: str) -> object:
        return getattr(self._inner, name)


def test_ctrl_c_in_the_middle_of_a_disk_write_still_closes_a_complete_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = tmp_path / "interrupted"
    enc = StringEncoder()
    with pytest.raises(KeyboardInterrupt), Recorder(bag, chunk_messages=10) as rec:
        h = rec.add_topic("/chatter", StringEncoder.msgtype)
        for k in range(25):
            rec.write(h, k, enc.encode(f"hello {k}"))
        rec.flush()
        assert rec._mcap is not None
        file = rec._mcap._file
        real_write = file.write

        def interrupted_write(data: object) -> int:
            monkeypatch.setattr(rec._mcap, "_file", file)  # only the first write is interrupted
            real_write(bytes(memoryview(data))[:50])  # type: ignore[arg-type]
            raise KeyboardInterrupt

        monkeypatch.setattr(rec._mcap, "_file", _Wrapped(file, interrupted_write))
        for k in range(25, 40):
            rec.write(h, k, enc.encode(f"hello {k}"))
        rec.flush()
    # the interrupted batch was cut off the file, kept, and written on close
    assert [m.msg.data for m in read_messages(bag)] == [f"hello {k}" for k in range(40)]


@pytest.mark.parametrize("storage", STORAGES)
def test_topics_can_appear_in_the_middle_of_a_recording(tmp_path: Path, storage: str) -> None:
    bag = tmp_path / "late"
    clock, text = ClockEncoder(), StringEncoder()
    with Recorder(bag, storage=storage, chunk_messages=16) as rec:
        h_clock = rec.add_topic("/clock", ClockEncoder.msgtype)
        for k in range(40):
            rec.write(h_clock, k, clock.encode(k))
        h_late = rec.add_topic("/late", StringEncoder.msgtype)  # with messages still pending
        for k in range(40, 80):
            rec.write(h_clock, k, clock.encode(k))
            rec.write(h_late, k, text.encode(str(k)))
    got = [(m.topic, m.t_ns) for m in read_messages(bag)]
    assert len(got) == 120
    assert [t for topic, t in got if topic == "/late"] == list(range(40, 80))
    assert open_bag(bag).topic("/late").message_count == 40


def test_a_bag_folder_another_run_takes_meanwhile_is_refused_and_left_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # Two runs on one --out: the one refused deleted the folder the other was writing (it had looked
    # before the other made it). The folder appears between this run's look and its mkdir here.
    from twin.cli import main
    from twin.core.errors import BagFolderTaken

    target = tmp_path / "bag"
    real_mkdir = Path.mkdir

    def racing_mkdir(self: Path, *args: object, **kwargs: object) -> None:
        if self == target:
            real_mkdir(self)
            (self / "bag_0.mcap").write_bytes(b"the other run's")
        real_mkdir(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Path, "mkdir", racing_mkdir)
    with pytest.raises(BagFolderTaken):
        Recorder(target)
    assert (target / "bag_0.mcap").read_bytes() == b"the other run's"
    (target / "bag_0.mcap").unlink()
    target.rmdir()
    assert main(["simulate", "--duration", "1", "--out", str(target)]) == 5
    assert "the bag folder exists and is not empty" in capsys.readouterr().err
    assert (target / "bag_0.mcap").read_bytes() == b"the other run's"  # the other run's bag is still there
