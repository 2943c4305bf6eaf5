"""The bag files look like what rosbag2 writes: metadata forms per distro, QoS, storage details."""

from __future__ import annotations

import shutil
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader

from twin.bag import open_bag
from twin.bag.metadata import parse_metadata, render_metadata
from twin.bag.qos import Durability, Reliability

MixBagFactory = Callable[[str, str], Any]  # conftest.mix_bag

INFINITE = {"sec": 9223372036, "nsec": 854775807}
LATCHED = {"/tf_static", "/map", "/robot_description", "/amcl_pose"}


def humble_parse(text: str) -> dict[str, Any]:
    """Read metadata.yaml the way Humble's rosbag2 does (metadata_io.cpp, rosbag2_transport/qos.cpp).

    yaml-cpp's `as<std::string>()` throws on a sequence and `as<int>()` on a name; the checks
    below raise where Humble's parser would.
    """
    node = yaml.safe_load(text)["rosbag2_bagfile_information"]
    version = node["version"]
    assert isinstance(version, int)
    assert isinstance(node["storage_identifier"], str)
    assert isinstance(node["duration"]["nanoseconds"], int)
    assert isinstance(node["starting_time"]["nanoseconds_since_epoch"], int)
    assert isinstance(node["message_count"], int)
    topics = {}
    for item in node["topics_with_message_count"]:
        meta = item["topic_metadata"]
        for key in ("name", "type", "serialization_format"):
            assert isinstance(meta[key], str)
        qos_text = meta["offered_qos_profiles"]
        if not isinstance(qos_text, str):
            raise TypeError(f"{meta['name']}: offered_qos_profiles is not a string (yaml-cpp bad conversion)")
        profiles = yaml.safe_load(qos_text)
        for p in profiles:
            for key in ("history", "reliability", "durability", "liveliness", "depth"):
                if not isinstance(p[key], int) or isinstance(p[key], bool):
                    raise TypeError(f"{meta['name']}: QoS {key}={p[key]!r} is not an integer")
            for key in ("deadline", "lifespan", "liveliness_lease_duration"):
                assert isinstance(p[key]["sec"], int) and isinstance(p[key]["nsec"], int)
            assert isinstance(p["avoid_ros_namespace_conventions"], bool)
        assert isinstance(item["message_count"], int)
        topics[meta["name"]] = profiles
    assert all(isinstance(p, str) for p in node["relative_file_paths"])
    if version >= 3:
        assert isinstance(node["compression_format"], str)
        assert isinstance(node["compression_mode"], str)
    if version >= 5:
        for f in node["files"]:
            assert isinstance(f["path"], str)
            assert isinstance(f["starting_time"]["nanoseconds_since_epoch"], int)
            assert isinstance(f["duration"]["nanoseconds"], int)
            assert isinstance(f["message_count"], int)
    return topics


JAZZY_NAMES = {
    "history": {"system_default", "keep_last", "keep_all", "unknown"},
    "reliability": {"system_default", "reliable", "best_effort", "unknown", "best_available"},
    "durability": {"system_default", "transient_local", "volatile", "unknown", "best_available"},
    "liveliness": {"system_default", "automatic", "manual_by_topic", "unknown", "best_available"},
}


def jazzy_parse(text: str) -> dict[str, Any]:
    """Read metadata.yaml the way Jazzy's rosbag2_storage/yaml.hpp does for version 9."""
    node = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert node["version"] == 9
    topics = {}
    for item in node["topics_with_message_count"]:
        meta = item["topic_metadata"]
        assert isinstance(meta["offered_qos_profiles"], list), "version 9 keeps QoS as a YAML sequence"
        for p in meta["offered_qos_profiles"]:
            for key, names in JAZZY_NAMES.items():
                assert p[key] in names, f"{meta['name']}: {key}={p[key]!r}"
        assert meta["type_description_hash"].startswith("RIHS01_")
        topics[meta["name"]] = meta["offered_qos_profiles"]
    assert node["custom_data"] is None or isinstance(node["custom_data"], dict)
    assert isinstance(node["ros_distro"], str)
    return topics


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_default_metadata_is_version_8_that_humble_parses(mix_bag: MixBagFactory, storage: str) -> None:
    bag = mix_bag(storage, "humble")
    text = (bag.path / "metadata.yaml").read_text()
    topics = humble_parse(text)
    node = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert node["version"] == 8
    assert node["ros_distro"] == "humble"
    assert node["relative_file_paths"] == [f"{bag.path.name}_0.{'mcap' if storage == 'mcap' else 'db3'}"]
    assert set(topics) == set(bag.counts)
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in node["topics_with_message_count"]} == bag.counts
    assert node["message_count"] == sum(bag.counts.values()) == node["files"][0]["message_count"]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_jazzy_metadata_is_version_9_in_jazzys_form(mix_bag: MixBagFactory, storage: str) -> None:
    bag = mix_bag(storage, "jazzy")
    text = (bag.path / "metadata.yaml").read_text()
    topics = jazzy_parse(text)
    assert set(topics) == set(bag.counts)
    assert yaml.safe_load(text)["rosbag2_bagfile_information"]["ros_distro"] == "jazzy"
    with pytest.raises(TypeError, match="not a string"):
        humble_parse(text)  # why the default is version 8


def test_qos_is_what_a_tb3_nav2_system_offers(mix_bag: MixBagFactory) -> None:
    topics = humble_parse((mix_bag("mcap", "humble").path / "metadata.yaml").read_text())
    for name, profiles in topics.items():
        (p,) = profiles
        assert p["history"] == 3 and p["depth"] == 0  # as DDS reports an offered profile
        assert p["deadline"] == INFINITE and p["liveliness"] == 1
        expected_durability = Durability.TRANSIENT_LOCAL if name in LATCHED | {"/rosout"} else Durability.VOLATILE
        assert p["durability"] == expected_durability, name
        expected_reliability = (
            Reliability.BEST_EFFORT if name in {"/clock", "/particle_cloud"} else Reliability.RELIABLE
        )
        assert p["reliability"] == expected_reliability, name
    assert topics["/rosout"][0]["lifespan"] == {"sec": 10, "nsec": 0}


def test_fixture_metadata_round_trips_through_our_writer(fixtures: Path) -> None:
    """Humble's own metadata (version 5) parses, and our version 8 rendering of it parses back equal."""
    path = fixtures / "bags" / "tb3_waffle_gazebo_humble" / "metadata.yaml"
    meta = parse_metadata(path.read_text(), path)
    assert meta.version == 5 and meta.message_count == 9432
    assert {t.name for t in meta.topics if t.offered_qos_profiles[0].durability == Durability.TRANSIENT_LOCAL} == {
        "/robot_description",
        "/tf_static",
        "/rosout",
    }
    for version in (8, 9):
        again = parse_metadata(render_metadata(_with_version(meta, version)), path)
        assert again.topics == meta.topics
        assert again.files == meta.files


def _with_version(meta: Any, version: int) -> Any:
    from dataclasses import replace

    return replace(meta, version=version)


def test_mcap_file_is_a_ros2_profile_file_with_ros2msg_schemas(mix_bag: MixBagFactory) -> None:
    for distro in ("humble", "jazzy"):
        bag = mix_bag("mcap", distro)
        (file,) = bag.path.glob("*.mcap")
        assert file.name == f"{bag.path.name}_0.mcap"  # the name `ros2 bag reindex` expects
        with file.open("rb") as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            assert summary is not None
            assert reader.get_header().profile == "ros2"
            assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
            assert all(s.name.count("/msg/") == 1 and s.data for s in summary.schemas.values())
            records = {m.name: m.metadata for m in reader.iter_metadata()}
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
            if distro == "humble":
                assert isinstance(qos[0]["reliability"], int)
                assert "topic_type_hash" not in channel.metadata
            else:
                assert qos[0]["reliability"] in {"reliable", "best_effort"}
                assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        if distro == "humble":
            assert records["rosbag2"] == {"ROS_DISTRO": "humble"}
        else:
            embedded = yaml.safe_load(records["rosbag2"]["serialized_metadata"])
            assert embedded["version"] == 9 and embedded["message_count"] == sum(bag.counts.values())


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_sqlite3_has_rosbag2s_schema_with_message_definitions(mix_bag: MixBagFactory, distro: str) -> None:
    bag = mix_bag("sqlite3", distro)
    (file,) = bag.path.glob("*.db3")
    db = sqlite3.connect(f"file:{file}?mode=ro", uri=True)
    try:
        assert db.execute("SELECT schema_version, ros_distro FROM schema").fetchall() == [(4, distro)]
        types = {row[0] for row in db.execute("SELECT type FROM topics")}
        definitions = dict(db.execute("SELECT topic_type, encoding FROM message_definitions"))
        assert set(definitions) == types and set(definitions.values()) == {"ros2msg"}
        qos = yaml.safe_load(
            db.execute("SELECT offered_qos_profiles FROM topics WHERE name='/tf_static'").fetchone()[0]
        )
        assert qos[0]["durability"] == (1 if distro == "humble" else "transient_local")
        (version, text) = db.execute("SELECT metadata_version, metadata FROM metadata").fetchone()
        assert version == (8 if distro == "humble" else 9)
        assert yaml.safe_load(text)["message_count"] == sum(bag.counts.values())
        index = db.execute("SELECT sql FROM sqlite_master WHERE name='timestamp_idx'").fetchone()[0]
        assert "timestamp ASC" in index
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    finally:
        db.close()
    assert not list(bag.path.glob("*-journal")) and not list(bag.path.glob("*-wal"))


@pytest.mark.parametrize("version", [4, 5, 6, 7])
def test_info_reads_older_metadata_versions(fixtures: Path, tmp_path: Path, version: int) -> None:
    """Versions 4 to 7 (Foxy to Iron) as their writers laid them out, derived from the Humble fixture."""
    src = fixtures / "bags" / "tb3_waffle_gazebo_humble"
    bag = tmp_path / f"v{version}"
    shutil.copytree(src, bag)
    doc = yaml.safe_load((src / "metadata.yaml").read_text())
    node = doc["rosbag2_bagfile_information"]
    node["version"] = version
    if version < 5:
        del node["files"]
    if version >= 6:
        node["custom_data"] = {"operator": "fixture"}
    if version >= 7:
        for t in node["topics_with_message_count"]:
            t["topic_metadata"]["type_description_hash"] = ""
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    info = open_bag(bag)
    assert info.version == version
    assert info.message_count == 9432
    assert info.topic("/imu").message_count == 5636
    assert info.topic("/performance_metrics").definition == "none"
    assert info.topic("/imu").definition == "type store"
    assert dict(info.custom_data) == ({"operator": "fixture"} if version >= 6 else {})
