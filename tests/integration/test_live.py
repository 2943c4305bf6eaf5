"""`twin simulate --live` and `twin play` end to end: a WebSocket client sees what the bag records."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from tests.conftest import REPO, run_twin
from tests.foxglove_client import Watch, watch

pytestmark = pytest.mark.slow

TOPICS = ["/scan", "/tf", "/robot_description"]


def start_twin(*args: str) -> tuple[subprocess.Popen[str], str]:
    """Start `python -m twin ARGS` serving on a free port; return the process and the URL its banner names."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin", *args, "--port", "0"],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    for line in proc.stderr:
        found = re.search(r"live on (ws://\S+) ", line)
        if found:
            return proc, found.group(1)
    proc.wait(timeout=60)
    pytest.fail(f"no live banner; exit {proc.returncode}: {proc.stderr.read()}")


def finish(proc: subprocess.Popen[str], timeout: float = 120) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def bag_messages(bag: Path) -> dict[str, list[tuple[int, bytes, Any]]]:
    """The bag's messages as rosbags reads them (Humble's types for a bag without embedded definitions)."""
    found: dict[str, list[tuple[int, bytes, Any]]] = defaultdict(list)
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        wanted = [c for c in reader.connections if c.msgtype in reader.typestore.fielddefs]
        for con, t_ns, raw in reader.messages(wanted):
            found[con.topic].append((t_ns, bytes(raw), reader.deserialize(raw, con.msgtype)))
    return found


def assert_same_as_bag(seen: Watch, bag: Path, *, min_scans: int) -> None:
    """Every received /scan, /tf and /robot_description decodes to a message the bag holds at the same time."""
    recorded = bag_messages(bag)
    by_time: dict[str, dict[int, list[Any]]] = {}
    for topic in TOPICS:
        by_time[topic] = defaultdict(list)
        for t_ns, _, msg in recorded[topic]:
            by_time[topic][t_ns].append(msg)
    assert len(seen.messages["/scan"]) >= min_scans
    for t_ns, payload in seen.messages["/scan"]:
        scan = seen.decode("/scan", payload)
        (expected,) = by_time["/scan"][t_ns]
        assert (scan.header.stamp.sec, scan.header.stamp.nanosec) == (
            expected.header.stamp.sec,
            expected.header.stamp.nanosec,
        )
        assert scan.header.frame_id == expected.header.frame_id
        np.testing.assert_array_equal(scan.ranges, expected.ranges)
        assert scan.angle_increment == expected.angle_increment
    assert seen.messages["/tf"]
    for t_ns, payload in seen.messages["/tf"]:
        tf = seen.decode("/tf", payload)
        got = [
            (t.header.frame_id, t.child_frame_id, t.transform.translation.x, t.transform.rotation.w)
            for t in tf.transforms
        ]
        candidates = [
            [
                (t.header.frame_id, t.child_frame_id, t.transform.translation.x, t.transform.rotation.w)
                for t in m.transforms
            ]
            for m in by_time["/tf"][t_ns]
        ]
        assert got in candidates
    (_, _, description), *_ = recorded["/robot_description"]
    received = [seen.decode("/robot_description", p).data for _, p in seen.messages["/robot_description"]]
    assert received and set(received) == {description.data}
    assert "<robot" in description.data


async def watch_with_late_client(url: str) -> tuple[Watch, Watch]:
    """One client from the start; a second that connects once the first has three scans."""
    ready = asyncio.Event()

    def first_stop(w: Watch) -> bool:
        if len(w.messages["/scan"]) >= 3:
            ready.set()
        return False

    async def late() -> Watch:
        await ready.wait()
        return await watch(
            url, ["/robot_description", "/tf_static"], stop=lambda w: all(w.messages.values()), timeout_s=30
        )

    return await asyncio.gather(watch(url, TOPICS, stop=first_stop, timeout_s=120), late())


@pytest.fixture(scope="module")
def live_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Watch, Watch, str]:
    bag = tmp_path_factory.mktemp("live") / "run"
    proc, url = start_twin("simulate", "--live", "--speed", "4", "--duration", "8", "--out", str(bag))
    first, late = asyncio.run(watch_with_late_client(url))
    code, out, err = finish(proc)
    assert code == 0, err
    assert "simulated 8.0 s" in out
    return bag, first, late, url


def test_a_client_of_a_live_run_receives_scan_tf_and_robot_description_equal_to_the_recorded_bag(
    live_run: tuple[Path, Watch, Watch, str],
) -> None:
    bag, first, _, url = live_run
    assert url.startswith("ws://127.0.0.1:")
    assert first.closed_by_server  # the run ended: the server closed the connection
    assert_same_as_bag(first, bag, min_scans=38)  # 5 Hz for 8 s: all but the first may be seen


def test_a_client_that_connects_late_to_a_live_run_still_gets_the_robot_description_and_static_frames(
    live_run: tuple[Path, Watch, Watch, str],
) -> None:
    bag, _, late, _ = live_run
    recorded = bag_messages(bag)
    ((t_description, _),) = late.messages["/robot_description"]
    assert t_description == 0  # published once at t = 0, long before this client connected
    assert late.decode("/robot_description", late.messages["/robot_description"][0][1]).data == (
        recorded["/robot_description"][0][2].data
    )
    frames = {t.child_frame_id for t in late.decode("/tf_static", late.messages["/tf_static"][0][1]).transforms}
    assert frames == {t.child_frame_id for t in recorded["/tf_static"][0][2].transforms}


def test_the_server_broadcasts_sim_time(live_run: tuple[Path, Watch, Watch, str]) -> None:
    _, first, _, _ = live_run
    assert first.times_ns == sorted(first.times_ns)
    assert first.times_ns[-1] >= 7_900_000_000


def test_twin_play_serves_the_recorded_bag_with_the_same_values(live_run: tuple[Path, Watch, Watch, str]) -> None:
    bag = live_run[0]
    proc, _url = start_twin("play", str(bag), "--speed", "4")
    seen = asyncio.run(watch(_url, TOPICS, timeout_s=120))
    code, out, err = finish(proc)
    assert code == 0, err
    assert "played" in out
    assert_same_as_bag(seen, bag, min_scans=38)


def test_twin_play_serves_a_real_sqlite3_bag_and_names_the_topics_it_cannot_describe(fixtures: Path) -> None:
    bag = fixtures / "bags" / "tb3_waffle_gazebo_humble"
    proc, url = start_twin("play", str(bag), "--speed", "10")
    seen = asyncio.run(watch(url, ["/scan", "/robot_description", "/performance_metrics"], timeout_s=120))
    code, out, err = finish(proc)
    assert code == 0, err
    assert "not served (no definition): /performance_metrics" in out
    assert "/performance_metrics" not in seen.channels
    recorded = bag_messages(bag)
    scans = {t: msg for t, _, msg in recorded["/scan"]}
    assert len(seen.messages["/scan"]) >= len(scans) - 2
    for t_ns, payload in seen.messages["/scan"]:
        np.testing.assert_array_equal(seen.decode("/scan", payload).ranges, scans[t_ns].ranges)
    assert seen.decode("/robot_description", seen.messages["/robot_description"][0][1]).data == (
        recorded["/robot_description"][0][2].data
    )


@pytest.mark.parametrize(
    "command", [["simulate", "--live"], ["play", "../shared/fixtures/bags/tb3_waffle_gazebo_humble"]]
)
def test_a_port_in_use_gives_one_line_and_exit_2(command: list[str], tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_twin(
            *command, "--port", str(port), *(["--out", str(tmp_path / "bag")] if command[0] == "simulate" else [])
        )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("twin: error: ") and f"127.0.0.1:{port}" in lines[0] and "in use" in lines[0]
    assert not (tmp_path / "bag").exists()  # refused before a bag was started


def test_ctrl_c_ends_a_live_run_with_a_complete_bag(tmp_path: Path) -> None:
    bag = tmp_path / "run"
    proc, url = start_twin("simulate", "--live", "--duration", "120", "--out", str(bag))
    seen = asyncio.run(watch(url, ["/scan"], stop=lambda w: len(w.messages["/scan"]) >= 5, timeout_s=60))
    assert len(seen.messages["/scan"]) >= 5
    proc.send_signal(signal.SIGINT)
    code, out, err = finish(proc, timeout=60)
    assert code == 130, err
    assert "stopped by SIGINT; the bag is complete" in err
    assert "interrupted" in out
    recorded = bag_messages(bag)  # metadata.yaml and a finished MCAP: rosbags opens it
    assert len(recorded["/scan"]) >= 5
    assert json.loads(json.dumps(sorted(recorded)))  # topics listed
    assert (bag / "metadata.yaml").exists()


def test_speed_1_holds_real_time_within_2_percent_over_30_s(tmp_path: Path) -> None:
    """The one long test: a 30 s run at the default live speed (1), watched by a client on /clock."""
    proc, url = start_twin("simulate", "--live", "--duration", "30", "--json", "--out", str(tmp_path / "run"))
    arrivals: list[tuple[float, int]] = []

    def on_clock(w: Watch) -> bool:
        clock = w.messages["/clock"]
        if clock and (not arrivals or arrivals[-1][1] != clock[-1][0]):
            arrivals.append((time.perf_counter(), clock[-1][0]))
        return False

    asyncio.run(watch(url, ["/clock"], stop=on_clock, timeout_s=120))
    code, out, err = finish(proc)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["sim_s"] == pytest.approx(30.0)
    assert summary["wall_s"] == pytest.approx(30.0, rel=0.02)
    (wall0, t0), (wall1, t1) = arrivals[0], arrivals[-1]
    assert (t1 - t0) / 1e9 >= 29.0  # the client saw the whole run
    assert (wall1 - wall0) == pytest.approx((t1 - t0) / 1e9, rel=0.02)


# Topics the layout shows that arrive with later parts (map_server, costmaps, AMCL).
LATER = {"/map", "/global_costmap/costmap", "/local_costmap/costmap", "/particle_cloud"}


def test_the_shipped_layout_shows_topics_and_fields_a_live_run_serves(live_run: tuple[Path, Watch, Watch, str]) -> None:
    bag, first, _, _ = live_run
    layout = json.loads((REPO / "docs" / "foxglove_layout.json").read_text())
    panels = layout["configById"]
    assert {key.split("!")[0] for key in panels} >= {"3D", "Plot", "RawMessages"}
    three_d = next(v for k, v in panels.items() if k.startswith("3D!"))
    assert three_d["followTf"] == "base_footprint"
    paths = [p["value"] for k, v in panels.items() if k.startswith("Plot!") for p in v["paths"]]
    paths += [v["topicPath"] for k, v in panels.items() if k.startswith("RawMessages!")]
    topics = set(three_d["topics"]) | {p.split(".", 1)[0] for p in paths}
    assert {"/scan", "/robot_description", "/plan", "/map", "/cmd_vel", "/odom", "/behavior_tree_log"} <= topics
    assert topics - LATER <= set(first.channels)
    recorded = bag_messages(bag)
    for path in paths:
        topic, *fields = path.split(".")
        value = recorded[topic][-1][2]
        for name in fields:
            value = getattr(value, name)
        assert value is not None, path


def test_a_live_paced_run_records_the_same_messages_as_a_plain_one(tmp_path: Path) -> None:
    plain, live = tmp_path / "plain", tmp_path / "live"
    result = run_twin("simulate", "--duration", "3", "--seed", "5", "--out", str(plain))
    assert result.returncode == 0, result.stderr
    result = run_twin(
        "simulate", "--live", "--port", "0", "--speed", "10", "--duration", "3", "--seed", "5", "--out", str(live)
    )
    assert result.returncode == 0, result.stderr
    assert "simulated 3.0 s" in result.stdout
    bags = []
    for bag in (plain, live):
        with AnyReader([bag]) as reader:
            bags.append([(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()])
    assert len(bags[0]) > 1000
    assert bags[0] == bags[1]


def test_a_live_search_run_shows_the_cameras_frames_as_the_bag_records_them(tmp_path: Path) -> None:
    # Foxglove's Image panel on a live run: the camera's JPEG frames and camera_info reach the client
    # with the bytes the bag records at the same times.
    bag = tmp_path / "search"
    scenario = str(REPO / "scenarios" / "house_search_queue.yaml")
    proc, url = start_twin("simulate", scenario, "--live", "--speed", "4", "--duration", "3", "--out", str(bag))
    topics = ["/camera/image_raw/compressed", "/camera/camera_info"]
    seen = asyncio.run(watch(url, topics, timeout_s=120))
    code, _, err = finish(proc)
    assert code in (0, 1), err  # a 3 s run of the search ends by its duration
    assert seen.channels["/camera/image_raw/compressed"]["schemaName"] == "sensor_msgs/msg/CompressedImage"
    recorded = bag_messages(bag)
    for topic in topics:
        assert len(seen.messages[topic]) >= 10, topic  # 10 Hz for 3 s: all but the first moments
        by_time = {t_ns: raw for t_ns, raw, _ in recorded[topic]}
        for t_ns, payload in seen.messages[topic]:
            assert by_time[t_ns] == payload, (topic, t_ns)
    frame = seen.decode("/camera/image_raw/compressed", seen.messages["/camera/image_raw/compressed"][0][1])
    assert frame.format.startswith("rgb8") or "jpeg" in frame.format
    assert bytes(frame.data[:2]) == b"\xff\xd8"  # a JPEG's start-of-image marker


def test_looping_a_bag_with_no_messages_ends_instead_of_spinning(tmp_path: Path) -> None:
    # rosbag2's own empty_bag resource: `play --loop` spun at full CPU for ever and did not hear Ctrl-C.
    from rosbags.rosbag2 import Writer

    bag = tmp_path / "empty"
    with Writer(bag, version=8) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=get_typestore(Stores.ROS2_HUMBLE))
    result = run_twin("play", str(bag), "--loop", "--port", "0", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "played 0 messages on 1 topics" in result.stdout and "nothing to loop over" in result.stdout
