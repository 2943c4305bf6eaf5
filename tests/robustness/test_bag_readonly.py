"""Reading a bag never writes into it, and `recover` judges a sqlite3 bag by its content.

rosbag2 writes sqlite3 bags in WAL mode. Opening such a database read-only but not immutable
leaves `-wal` and `-shm` files beside it, which a later `recover` took for a killed recording
(and rewrote a Galactic bag's metadata.yaml as Humble's). Every reading command runs here on an
MCAP bag, a WAL-mode sqlite3 bag and the real Gazebo bag in WAL mode with Galactic's metadata
version, and the folder must be byte for byte as it was, for `recover` too.
"""

from __future__ import annotations

import dataclasses
import shutil
import sqlite3
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.bag.small_bags import edit_metadata
from twin.bag import open_bag, read_messages
from twin.cli import main

REPO = Path(__file__).resolve().parents[2]


def _wal(db3: Path) -> None:
    """Switch a database to WAL mode, as rosbag2 writes them (the mode is kept in the file's header)."""
    db = sqlite3.connect(db3)
    try:
        assert db.execute("PRAGMA journal_mode=WAL").fetchone() == ("wal",)
    finally:
        db.close()


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory, fixtures: Path) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("readonly")
    out = {}
    for storage in ("mcap", "sqlite3"):
        bag = root / storage
        proc = run_twin("simulate", "--duration", "5", "--storage", storage, "--out", str(bag), "-q")
        assert proc.returncode == 0, proc.stderr
        out[storage] = bag
    (db3,) = out["sqlite3"].glob("*.db3")
    _wal(db3)
    galactic = root / "gazebo_galactic"
    shutil.copytree(fixtures / "bags" / "tb3_waffle_gazebo_humble", galactic)
    _wal(galactic / "rosbag_0.db3")
    # Galactic writes metadata version 5, without a ros_distro
    edit_metadata(galactic, lambda meta: dataclasses.replace(meta, version=5, ros_distro=""))
    out["gazebo_galactic"] = galactic
    return out


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _commands(bag: Path, out: Path, fixtures: Path) -> dict[str, list[str]]:
    gazebo = "gazebo" in bag.name
    world = (
        [
            "--world",
            str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
            "--model-path",
            str(fixtures / "gazebo_classic" / "models"),
        ]
        if gazebo
        else ["--world", str(REPO / "sdf" / "worlds" / "house.sdf")]
    )
    return {
        "bag info": ["bag", "info", str(bag)],
        "bag info --json": ["bag", "info", str(bag), "--json"],
        "analyze": ["analyze", str(bag), "--out", str(out / "analyze"), "--no-plots"],
        "bag export": ["bag", "export", str(bag), "--topics", "/odom", "--out", str(out / "export")],
        "ekf replay": ["ekf", "replay", str(bag), "--out", str(out / "ekf")],
        "replay": ["replay", str(bag), *world, "--out", str(out / "replay")],
        "play": ["play", str(bag), "--speed", "max", "--port", "0"],
    }


@pytest.mark.parametrize("which", ["mcap", "sqlite3", "gazebo_galactic"])
def test_reading_commands_leave_the_bag_byte_for_byte_as_it_was(
    which: str,
    bags: dict[str, Path],
    tmp_path: Path,
    fixtures: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bag = tmp_path / which
    shutil.copytree(bags[which], bag)
    monkeypatch.chdir(tmp_path)  # defaults (bags/...) land here, never in the bag
    before = _snapshot(bag)
    for name, argv in _commands(bag, tmp_path / "out", fixtures).items():
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 0, f"{name}: {err}"
        assert _snapshot(bag) == before, f"{name} changed the bag folder: {sorted(_snapshot(bag))}"
    code = main(["bag", "recover", str(bag)])
    out = capsys.readouterr().out
    assert code == 0 and "complete (nothing changed)" in out, out
    assert _snapshot(bag) == before


def test_empty_side_files_are_no_sign_of_a_killed_run(bags: dict[str, Path], tmp_path: Path) -> None:
    """What a non-immutable reader leaves (an empty `-wal`, a `-shm`) is not a killed recording."""
    bag = tmp_path / "galactic"
    shutil.copytree(bags["gazebo_galactic"], bag)
    (bag / "rosbag_0.db3-wal").write_bytes(b"")
    (bag / "rosbag_0.db3-shm").write_bytes(bytes(32768))
    before = _snapshot(bag)
    assert main(["bag", "recover", str(bag)]) == 0
    assert _snapshot(bag) == before  # metadata version 5, no distro: as it was


def test_a_wal_with_frames_is_recovered_with_its_messages(
    bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A WAL holding committed frames (a recording killed before its checkpoint) is content: recover keeps it."""
    source = tmp_path / "source"
    shutil.copytree(bags["sqlite3"], source)
    (db3,) = source.glob("*.db3")
    count = open_bag(source).message_count
    killed = tmp_path / "killed"
    killed.mkdir()
    db = sqlite3.connect(db3, isolation_level=None)
    try:
        db.execute("PRAGMA wal_autocheckpoint=0")
        topic, stamp, data = db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id DESC").fetchone()
        db.executemany(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
            [(topic, stamp + k, data) for k in range(1, 51)],
        )
        wal = db3.with_name(db3.name + "-wal")
        assert wal.stat().st_size > 32  # the frames are in the WAL, not yet in the file
        for file in (db3, wal):
            shutil.copyfile(file, killed / file.name)
    finally:
        db.close()
    (killed / db3.name).with_name(db3.name + "-journal").unlink(missing_ok=True)
    # the immutable readers see the file alone: the 50 messages are only in the WAL
    assert main(["bag", "recover", str(killed)]) == 0
    assert "recovered" in capsys.readouterr().out
    assert sorted(p.name for p in killed.iterdir()) == sorted([db3.name, "metadata.yaml"])
    assert open_bag(killed).message_count == count + 50
    assert sum(1 for _ in read_messages(killed, decode=False)) == count + 50


def test_a_rewritten_metadata_keeps_the_bags_version_and_distro(bags: dict[str, Path], tmp_path: Path) -> None:
    """A Galactic bag whose metadata.yaml miscounts is rewritten as Galactic wrote it: version 5, no distro."""
    bag = tmp_path / "galactic"
    shutil.copytree(bags["gazebo_galactic"], bag)
    edit_metadata(bag, lambda meta: dataclasses.replace(meta, message_count=meta.message_count + 1))
    assert main(["bag", "recover", str(bag)]) == 0
    text = (bag / "metadata.yaml").read_text()
    assert "  version: 5\n" in text and "ros_distro" not in text
    assert open_bag(bag).message_count == sum(1 for _ in read_messages(bag, decode=False))
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "metadata.yaml.orig", "rosbag_0.db3"]
