"""twin.bag.read_raw: the same messages as read_messages(decode=False), per topic in the same order."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest

from twin.bag import read_messages, read_raw
from twin.core.errors import BagError


def _per_topic(rows: list[tuple[str, int, bytes]]) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
    for topic, t_ns, data in rows:
        out[topic].append((t_ns, data))
    return dict(out)


@pytest.mark.parametrize("which", ["mcap", "sqlite3", "gazebo"])
def test_read_raw_matches_rosbags(which: str, twin_bag: Path, twin_bag_sqlite: Path, gazebo_bag: Path) -> None:
    bag = {"mcap": twin_bag, "sqlite3": twin_bag_sqlite, "gazebo": gazebo_bag}[which]
    fast = [(topic, t_ns, bytes(data)) for topic, t_ns, data in read_raw(bag)]
    ref = [(m.topic, m.t_ns, m.msg) for m in read_messages(bag, None, decode=False)]
    assert _per_topic(fast) == _per_topic(ref)
    times = [t for _, t, _ in fast]
    assert times == sorted(times)


def test_read_raw_filters_topics_and_names_a_missing_one(twin_bag: Path) -> None:
    rows = list(read_raw(twin_bag, ["/odom", "/scan"]))
    assert {t for t, _, _ in rows} == {"/odom", "/scan"}
    with pytest.raises(BagError, match="no topic '/nope'"):
        list(read_raw(twin_bag, ["/nope"]))
