"""The twin's bags decode completely in the readers users have: rosbags, mcap (Python), Foxglove (JS).

Each check reads a bag holding every topic type the twin records (the mission mix), in both
storages and both metadata forms, and decodes every message of every topic. The Foxglove check
runs Foxglove's npm readers in node; install them with `npm ci --prefix tests/js`.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from collections import Counter
from collections.abc import Callable
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from twin.bag import read_messages

MixBagFactory = Callable[[str, str], Any]  # conftest.mix_bag

JS_DIR = Path(__file__).resolve().parents[2] / "js"
FORMS = [("mcap", "humble"), ("mcap", "jazzy"), ("sqlite3", "humble"), ("sqlite3", "jazzy")]


def plain(value: Any) -> Any:
    """A rosbags message as JSON-like data, the way the JS check prints decoded messages."""
    if is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: plain(getattr(value, f.name))
            for f in fields(value)
            if f.name != "__msgtype__" and not f.name.isupper()
        }
    if isinstance(value, np.ndarray):
        return [plain(v) for v in value.tolist()]
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


def foxglove_time(value: Any) -> Any:
    """Foxglove's built-in ROS 2 definitions name `Time.nanosec` `nsec`; map it back."""
    if isinstance(value, dict):
        if set(value) == {"sec", "nsec"}:
            return {"sec": value["sec"], "nanosec": value["nsec"]}
        return {k: foxglove_time(v) for k, v in value.items()}
    if isinstance(value, list):
        return [foxglove_time(v) for v in value]
    return value


def rosbags_decoded(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return out


@pytest.mark.parametrize(("storage", "distro"), FORMS)
def test_rosbags_anyreader_decodes_every_message(mix_bag: MixBagFactory, storage: str, distro: str) -> None:
    bag = mix_bag(storage, distro)
    decoded = rosbags_decoded(bag.path)
    assert {topic: len(msgs) for topic, msgs in decoded.items()} == bag.counts
    with AnyReader([bag.path]) as reader:
        # the definitions came from the bag itself, not from a type store
        assert all(c.msgdef.data for c in reader.connections)
        assert any(c.msgtype == "twin_msgs/msg/MotorState" for c in reader.connections)


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_mcap_python_reader_decodes_every_message(mix_bag: MixBagFactory, distro: str) -> None:
    bag = mix_bag("mcap", distro)
    (file,) = bag.path.glob("*.mcap")
    counts: Counter[str] = Counter()
    with file.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == sum(bag.counts.values())
        assert reader.get_header().profile == "ros2"
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            assert schema is not None and schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            assert decoded is not None
            counts[channel.topic] += 1
        last = decoded
    assert dict(counts) == bag.counts
    assert last is not None


def test_mcap_python_reader_matches_rosbags_values(mix_bag: MixBagFactory) -> None:
    bag = mix_bag("mcap", "humble")
    expected = rosbags_decoded(bag.path)
    (file,) = bag.path.glob("*.mcap")
    with file.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        got = [
            (c.topic, m.log_time, d) for _, c, m, d in reader.iter_decoded_messages(topics=["/motor_state", "/contact"])
        ]
    assert len(got) == bag.counts["/motor_state"] + bag.counts["/contact"]
    by_topic = {t: iter(expected[t]) for t in ("/motor_state", "/contact")}
    for topic, t_ns, decoded in got:
        want_t, want = next(by_topic[topic])
        assert t_ns == want_t
        if topic == "/motor_state":
            assert list(decoded.voltage_v) == want.voltage_v.tolist()
            assert list(decoded.name) == want.name
        else:
            assert decoded.world_collision == want.world_collision
            assert decoded.event == want.event == 1
            assert decoded.depth_m == want.depth_m


def _node_modules_or_fail() -> None:
    if shutil.which("node") is None:
        pytest.fail("node is not installed; the Foxglove reader check needs node >= 18")
    if not (JS_DIR / "node_modules" / "@mcap" / "core").is_dir():
        pytest.fail(
            f"Foxglove's JS readers are not installed: run `npm ci --prefix tests/js` (in {JS_DIR.parent.parent})"
        )


@pytest.mark.slow
@pytest.mark.parametrize(("storage", "distro"), FORMS)
def test_foxglove_js_readers_decode_every_message_like_rosbags(
    mix_bag: MixBagFactory, storage: str, distro: str
) -> None:
    _node_modules_or_fail()
    bag = mix_bag(storage, distro)
    run = subprocess.run(
        ["node", str(JS_DIR / "read_bag.mjs"), str(bag.path)], capture_output=True, text=True, timeout=300, check=False
    )
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    js_topics = result["topics"]
    assert {topic: len(v["messages"]) for topic, v in js_topics.items()} == bag.counts
    if storage == "sqlite3":
        # rosbag2-web decoded the standard types itself; only nav2_msgs/twin_msgs needed the bag's definitions
        assert "/imu" in result["builtin_topics"]
        assert set(result["embedded_topics"]) >= {"/motor_state", "/contact", "/particle_cloud", "/behavior_tree_log"}
    expected = rosbags_decoded(bag.path)
    for topic, entry in js_topics.items():
        want = expected[topic]
        for got_msg, (t_ns, msg) in zip(entry["messages"], want, strict=True):
            assert int(got_msg["t_ns"]) == t_ns
            assert foxglove_time(got_msg["msg"]) == plain(msg), f"{topic} at {t_ns} ns decodes differently in JS"


@pytest.mark.parametrize(("storage", "distro"), FORMS)
def test_twin_reader_decodes_every_message(mix_bag: MixBagFactory, storage: str, distro: str) -> None:
    bag = mix_bag(storage, distro)
    counts = Counter(m.topic for m in read_messages(bag.path))
    assert dict(counts) == bag.counts
    stamps = [m.msg.header.stamp for m in read_messages(bag.path, ["/imu"])]
    assert [s.sec * 10**9 + s.nanosec for s in stamps[:3]] == [0, 5_000_000, 10_000_000]
