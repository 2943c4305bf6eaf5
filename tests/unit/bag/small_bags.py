"""Small bags built in the tests, then altered the way other recorders and tools leave bags.

Each builder records a few messages with the twin's own recorder; the edits reproduce what was
found in public bags (Foxy's QoS spelling, message compression, a storage file without its
folder, ...) without committing anyone's bag files.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from twin.bag import OdometryEncoder, Recorder, StringEncoder, read_messages
from twin.bag.metadata import BagMetadata, TopicMetadata, read_metadata, write_metadata

#: Messages per topic in `small_bag`.
COUNT = 10
STEP_NS = 100_000_000
START_NS = 1_700_000_000 * 1_000_000_000


def small_bag(path: Path, *, storage: str = "mcap", distro: str = "humble") -> Path:
    """A bag with `/chatter` (String) and `/odom` (Odometry), `COUNT` messages each, 10 Hz."""
    with Recorder(path, storage=storage, distro=distro) as rec:
        chatter = rec.add_topic("/chatter", StringEncoder.msgtype)
        odom = rec.add_topic("/odom", OdometryEncoder.msgtype)
        text, pose = StringEncoder(), OdometryEncoder("odom", "base_footprint")
        for k in range(COUNT):
            t_ns = START_NS + k * STEP_NS
            rec.write(chatter, t_ns, text.encode(f"hello {k}"))
            rec.write(odom, t_ns, pose.encode(t_ns, 0.1 * k, 0.0, 0.0, 1.0, 0.0))
    return path


def storage_file(bag: Path) -> Path:
    """The bag's one storage file."""
    (file,) = (p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    return file


def edit_metadata(bag: Path, change: Callable[[BagMetadata], BagMetadata]) -> None:
    """Rewrite the bag's metadata.yaml with `change` applied."""
    write_metadata(bag, change(read_metadata(bag)), fsync=False)


def edit_topics(bag: Path, change: Callable[[TopicMetadata], TopicMetadata]) -> None:
    """Rewrite every topic of the bag's metadata.yaml with `change` applied."""
    edit_metadata(bag, lambda meta: dataclasses.replace(meta, topics=tuple(change(t) for t in meta.topics)))


def zstd() -> Any:
    """The zstd module rosbags uses (the standard library's from Python 3.14, else backports.zstd)."""
    try:
        return importlib.import_module("compression.zstd")
    except ImportError:
        return importlib.import_module("backports.zstd")


def compress_files(bag: Path) -> Path:
    """Turn the bag into what `ros2 bag record --compression-mode file` leaves: its storage file zstd-compressed whole."""
    file = storage_file(bag)
    packed = file.with_name(file.name + ".zstd")
    packed.write_bytes(zstd().compress(file.read_bytes()))
    file.unlink()
    edit_metadata(
        bag,
        lambda meta: dataclasses.replace(
            meta,
            compression_format="zstd",
            compression_mode="FILE",
            relative_file_paths=(packed.name,),
            files=tuple(dataclasses.replace(f, path=packed.name) for f in meta.files),
        ),
    )
    return packed


def message_compressed_bag(path: Path, *, storage: str = "mcap") -> Path:
    """`small_bag`'s messages as `ros2 bag record --compression-mode message` writes them (each a zstd frame).

    Written with rosbags' writer, which compresses per message the way rosbag2 does.
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from twin.bag.typesys import TypeRegistry

    source = small_bag(path.with_name(path.name + "_plain"), storage=storage)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(path, version=8, storage_plugin=plugin)
    writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    store = TypeRegistry().store
    with writer:
        connections: dict[str, Any] = {}
        for m in read_messages(source, decode=False):
            if m.topic not in connections:
                connections[m.topic] = writer.add_connection(m.topic, m.msgtype, typestore=store)
            writer.write(connections[m.topic], m.t_ns, m.msg)
    return path


#: A type named the way early rosbag2 bags name types (no `/msg/`), with its definition.
LEGACY_TYPE = "legacy_msgs/Reading"
LEGACY_DEFINITION = "float64 value\nstring label"


def legacy_type_bag(path: Path, *, storage: str = "mcap") -> Path:
    """A bag whose one topic, `/reading`, has a legacy type name and its definition embedded (rosbags' writer)."""
    import struct

    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        conn = writer.add_connection("/reading", LEGACY_TYPE, msgdef=LEGACY_DEFINITION, rihs01="RIHS01_" + "0" * 64)
        for k in range(COUNT):
            label = f"r{k}".encode() + b"\0"
            data = b"\0\x01\0\0" + struct.pack("<d", 1.5 * k) + struct.pack("<I", len(label)) + label
            writer.write(conn, START_NS + k * STEP_NS, data)
    return path
