"""Bags as other recorders and tools leave them: each case was found in a public bag, rebuilt here small."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path

import pytest

from tests.unit.bag.small_bags import COUNT, edit_topics, small_bag
from twin.bag import read_messages, read_raw
from twin.bag.qos import QosDuration, QosProfile

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
