"""Bags as other recorders and tools leave them: each case was found in a public bag, rebuilt here small."""

from __future__ import annotations

import dataclasses
import json
import shutil
from collections import Counter
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.bag.small_bags import (
    COUNT,
    START_NS,
    compress_files,
    edit_metadata,
    edit_topics,
    message_compressed_bag,
    small_bag,
    storage_file,
    zstd,
)
from twin.bag import OdometryEncoder, Recorder, StringEncoder, open_bag, read_messages, read_raw, recover_bag
from twin.bag.mcap_file import McapWriter, scan_mcap
from twin.bag.metadata import read_metadata
from twin.bag.qos import QosDuration, QosProfile, qos_summary

STORAGES = ["mcap", "sqlite3"]

#: How Foxy's metadata.yaml writes a profile its storage file writes with 2147483647 s durations.
FOXY_YAML_QOS = QosProfile(
    deadline=QosDuration(0, 0), lifespan=QosDuration(0, 0), liveliness_lease_duration=QosDuration(0, 0)
)


@pytest.mark.parametrize("storage", STORAGES)
def test_messages_are_read_whatever_qos_metadata_yaml_states(tmp_path: Path, storage: str) -> None:
    bag = small_bag(tmp_path / "bag", storage=storage)
    edit_topics(bag, lambda t: dataclasses.replace(t, offered_qos_profiles=(FOXY_YAML_QOS,)))
    decoded = Counter(m.topic for m in read_messages(bag))
    raw = Counter(topic for topic, _, _ in read_raw(bag))
    chosen = Counter(m.topic for m in read_messages(bag, ["/odom"]))
    assert decoded == raw == {"/chatter": COUNT, "/odom": COUNT}
    assert chosen == {"/odom": COUNT}


def loose_copy(bag: Path, where: Path) -> Path:
    """The bag's storage file copied alone into `where`, as projects publish them."""
    where.mkdir()
    file = storage_file(bag)
    return Path(shutil.copy(file, where / file.name))


@pytest.mark.parametrize("storage", STORAGES)
def test_a_single_storage_file_reads_like_its_bag_folder(tmp_path: Path, storage: str) -> None:
    bag = small_bag(tmp_path / "bag", storage=storage)
    file = loose_copy(bag, tmp_path / "loose")
    folder, alone = open_bag(bag), open_bag(file)
    assert alone.path == file and [f.path for f in alone.files] == [file.name]
    assert alone.storage == storage and alone.ros_distro == "humble"
    assert (alone.start_ns, alone.end_ns, alone.message_count) == (folder.start_ns, folder.end_ns, 2 * COUNT)
    assert {(t.name, t.msgtype, t.message_count, t.qos) for t in alone.topics} == {
        (t.name, t.msgtype, t.message_count, t.qos) for t in folder.topics
    }
    assert Counter(m.topic for m in read_messages(file)) == {"/chatter": COUNT, "/odom": COUNT}
    assert Counter(topic for topic, _, _ in read_raw(file)) == {"/chatter": COUNT, "/odom": COUNT}


def test_the_cli_takes_a_single_mcap_file_wherever_it_takes_a_bag(tmp_path: Path) -> None:
    file = loose_copy(small_bag(tmp_path / "bag"), tmp_path / "loose")
    info = run_twin("bag", "info", str(file), "--json")
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["message_count"] == 2 * COUNT
    export = run_twin("bag", "export", str(file), "--topics", "/odom", "--out", str(tmp_path / "csv"))
    assert export.returncode == 0, export.stderr
    assert len((tmp_path / "csv" / "odom.csv").read_text().splitlines()) == 1 + COUNT
    report = run_twin("analyze", str(file), "--no-plots", "--json", "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    assert {h["topic"]: h["count"] for h in json.loads(report.stdout)["topic_health"]} == {
        "/chatter": COUNT,
        "/odom": COUNT,
    }


def test_a_killed_single_mcap_file_says_to_recover_it_and_recover_completes_it(tmp_path: Path) -> None:
    file = loose_copy(small_bag(tmp_path / "bag"), tmp_path / "loose")
    with file.open("r+b") as f:
        f.truncate(scan_mcap(file).data_end)  # the summary and footer are never written
    refused = run_twin("bag", "info", str(file))
    assert refused.returncode == 5 and refused.stderr.count("\n") == 1, refused.stderr
    assert f"`twin bag recover {file}`" in refused.stderr
    recovered = run_twin("bag", "recover", str(file))
    assert recovered.returncode == 0, recovered.stderr
    assert not (file.parent / "metadata.yaml").exists()
    assert open_bag(file).message_count == 2 * COUNT


@pytest.mark.parametrize("storage", STORAGES)
def test_a_missing_storage_file_is_one_line_naming_it(tmp_path: Path, storage: str) -> None:
    bag = small_bag(tmp_path / "bag", storage=storage)
    name = storage_file(bag).name
    storage_file(bag).unlink()
    run = run_twin("bag", "info", str(bag))
    assert run.returncode == 5
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("twin: error: "), run.stderr
    assert f"its storage file {name}" in run.stderr and "not there" in run.stderr
    assert "recover" not in run.stderr
    recover = run_twin("bag", "recover", str(bag))
    assert recover.returncode == 5 and recover.stderr.count("\n") == 1, recover.stderr
    assert f"{name} (listed in metadata.yaml) is not there, so nothing to recover" in recover.stderr


@pytest.mark.parametrize("storage", STORAGES)
def test_info_describes_a_file_compressed_bag(tmp_path: Path, storage: str) -> None:
    bag = small_bag(tmp_path / "bag", storage=storage)
    packed = compress_files(bag)
    run = run_twin("bag", "info", str(bag), "--json")
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout)
    assert [f["path"] for f in info["files"]] == [packed.name]
    assert (info["compression_format"], info["compression_mode"], info["message_count"]) == ("zstd", "FILE", 2 * COUNT)
    assert Counter(m.topic for m in read_messages(bag)) == {"/chatter": COUNT, "/odom": COUNT}


def test_recover_refuses_a_file_compressed_bag_in_one_line_that_says_how(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    packed = compress_files(bag)
    before = {f.name: f.read_bytes() for f in bag.iterdir()}
    run = run_twin("bag", "recover", str(bag))
    assert run.returncode == 5 and run.stderr.count("\n") == 1, run.stderr
    assert packed.name in run.stderr and "compressed as whole files" in run.stderr and "zstd -d" in run.stderr
    assert {f.name: f.read_bytes() for f in bag.iterdir()} == before


def test_recover_after_unpacking_says_it_rewrote_the_metadata(tmp_path: Path) -> None:
    bag = small_bag(tmp_path / "bag")
    packed = compress_files(bag)
    packed.with_suffix("").write_bytes(zstd().decompress(packed.read_bytes()))
    packed.unlink()
    report = recover_bag(bag)
    assert not report.was_complete  # metadata.yaml was rewritten: not "complete (nothing changed)"
    meta = read_metadata(bag)
    assert meta.relative_file_paths == (packed.with_suffix("").name,) and meta.compression_mode == ""
    assert Counter(m.topic for m in read_messages(bag)) == {"/chatter": COUNT, "/odom": COUNT}


def _without_compression(bag: Path) -> None:
    """metadata.yaml rebuilt by a tool that did not know the messages are compressed."""
    edit_metadata(bag, lambda meta: dataclasses.replace(meta, compression_format="", compression_mode=""))


@pytest.mark.parametrize("command", ["analyze", "export"])
def test_compressed_messages_read_as_cdr_are_one_bag_error_naming_topic_and_bag(tmp_path: Path, command: str) -> None:
    bag = message_compressed_bag(tmp_path / "bag")
    _without_compression(bag)
    out = str(tmp_path / "out")
    args = (
        ["analyze", str(bag), "--out", out]
        if command == "analyze"
        else ["bag", "export", str(bag), "--topics", "/odom", "--out", out]
    )
    run = run_twin(*args)
    assert run.returncode == 5, run.stderr
    assert run.stderr.count("\n") == 1 and run.stderr.startswith(f"twin: error: {bag}: a message on /"), run.stderr
    assert "zstd frame" in run.stderr and f"`twin bag recover {bag}`" in run.stderr


def test_a_message_too_short_for_its_type_is_one_bag_error(tmp_path: Path) -> None:
    with Recorder(tmp_path / "bag") as rec:
        odom = rec.add_topic("/odom", OdometryEncoder.msgtype)
        rec.write(odom, START_NS, StringEncoder().encode("not an odometry"))  # CDR, but far too short
    run = run_twin("analyze", str(tmp_path / "bag"), "--out", str(tmp_path / "out"))
    assert run.returncode == 5, run.stderr
    assert run.stderr.count("\n") == 1 and "a message on /odom" in run.stderr and "nav_msgs/msg/Odometry" in run.stderr


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("metadata", ["stale", "missing"])
def test_recover_records_per_message_compression(tmp_path: Path, storage: str, metadata: str) -> None:
    bag = message_compressed_bag(tmp_path / "bag", storage=storage)
    if metadata == "stale":
        _without_compression(bag)
    else:
        (bag / "metadata.yaml").unlink()
    report = recover_bag(bag)
    assert not report.was_complete
    meta = read_metadata(bag)
    assert (meta.compression_format, meta.compression_mode) == ("zstd", "MESSAGE")
    assert Counter(m.topic for m in read_messages(bag)) == {"/chatter": COUNT, "/odom": COUNT}


def _bag_with_unusable_definitions(path: Path) -> Path:
    """A service-event type whose definition is not .msg text, and a String defined unlike the type store's."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    rihs = "RIHS01_" + "0" * 64
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        event = writer.add_connection(
            "/events", "demo_msgs/srv/Ping_Event", msgdef="bool a\n---\nbool b\n", rihs01=rihs
        )
        text = writer.add_connection(
            "/chatter", "std_msgs/msg/String", msgdef="string data\nint32 extra\n", rihs01=rihs
        )
        for k in range(COUNT):
            writer.write(event, START_NS + k, b"\0\x01\0\0\x01")
            writer.write(text, START_NS + k, b"\0\x01\0\0\x02\0\0\0x\0\0\0\x05\0\0\0")
    return path


def test_an_unusable_embedded_definition_is_one_warning_line_once_per_type(tmp_path: Path) -> None:
    bag = _bag_with_unusable_definitions(tmp_path / "bag")
    run = run_twin("analyze", str(bag), "--no-plots", "--out", str(tmp_path / "report"))
    assert run.returncode == 0, run.stderr
    warnings = [line for line in run.stderr.splitlines() if line.startswith("twin: WARNING:")]
    assert len(warnings) == len(run.stderr.splitlines()) == 2, run.stderr
    (event,) = [w for w in warnings if "demo_msgs/srv/Ping_Event" in w]
    (text,) = [w for w in warnings if "std_msgs/msg/String" in w]
    assert "not .msg text" in event and "cannot be decoded" in event
    assert "differs from the type store's" in text and "decoding with the type store's" in text


def test_info_on_an_empty_bag_shows_no_start_or_end(tmp_path: Path) -> None:
    with Recorder(tmp_path / "bag") as rec:
        rec.add_topic("/odom", OdometryEncoder.msgtype)
    # as rosbag2 writes an empty bag: the start is INT64_MAX (Apr 11 2262)
    edit_metadata(tmp_path / "bag", lambda meta: dataclasses.replace(meta, starting_time_ns=2**63 - 1, duration_ns=0))
    run = run_twin("bag", "info", str(tmp_path / "bag"))
    assert run.returncode == 0, run.stderr
    assert "Start:             -\n" in run.stdout and "End:               -\n" in run.stdout
    assert "2262" not in run.stdout


def test_foxy_and_unspecified_qos_durations_read_as_infinite() -> None:
    foxy = QosDuration(2147483647, 4294967295)
    storage_form = QosProfile(deadline=foxy, lifespan=foxy, liveliness_lease_duration=foxy)
    assert qos_summary((storage_form,)) == qos_summary((FOXY_YAML_QOS,)) == qos_summary((QosProfile(),))
    assert qos_summary((QosProfile(lifespan=QosDuration(10, 0)),)) == "reliable, volatile, lifespan 10s"


def test_recover_takes_the_distro_from_rosbag2s_serialized_metadata(tmp_path: Path) -> None:
    bag = tmp_path / "jazzy"
    bag.mkdir()
    writer = McapWriter(bag / "jazzy_0.mcap", library="rosbag2")  # a file from rosbag2 itself: no twin record
    schema = writer.add_schema("std_msgs/msg/String", "ros2msg", b"string data")
    channel = writer.add_channel("/chatter", schema, "cdr", {"offered_qos_profiles": ""})
    writer.write_batch([(channel, START_NS + k, StringEncoder().encode(f"hi {k}")) for k in range(COUNT)])
    record = "version: 9\nstorage_identifier: mcap\nmessage_count: 0\nros_distro: jazzy"
    writer.add_metadata("rosbag2", {"serialized_metadata": record})
    writer.finish()
    report = recover_bag(bag)
    assert (report.metadata.ros_distro, report.metadata.version) == ("jazzy", 9)
    assert read_metadata(bag).ros_distro == "jazzy"
