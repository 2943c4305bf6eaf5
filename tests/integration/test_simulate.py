"""`twin simulate` end to end: the default scenario records a bag every reader opens, on time and deterministic."""

from __future__ import annotations

import itertools
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from tests.conftest import REPO, run_twin
from twin.bag import open_bag

RATES_HZ = {"/clock": 10.0, "/odom": 30.0, "/joint_states": 30.0, "/scan": 5.0}
# Nav2's velocity_smoother publishes /cmd_vel at its smoothing_frequency (TB3's Humble file: 20 Hz) from the
# first command the controller sends on, which waits for AMCL's initial pose and the first plan.
CMD_VEL_HZ = 20.0


def read_all(bag: Path) -> tuple[Counter[str], dict[str, list[tuple[int, object]]]]:
    counts: Counter[str] = Counter()
    messages: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([bag]) as reader:
        for con, t_ns, raw in reader.messages():
            counts[con.topic] += 1
            messages.setdefault(con.topic, []).append((t_ns, reader.deserialize(raw, con.msgtype)))
    return counts, messages


@pytest.fixture(scope="module")
def default_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("sim") / "default"
    result = run_twin("simulate", "--duration", "20", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert "simulated 20.0 s" in result.stdout and str(bag) in result.stdout
    return bag


def test_default_scenario_bag_opens_in_rosbags_with_counts_equal_to_rate_times_duration(default_bag: Path) -> None:
    counts, messages = read_all(default_bag)
    for topic, rate in RATES_HZ.items():
        assert abs(counts[topic] - rate * 20.0) <= 1, (topic, counts[topic])
    cmd_stamps = [t for t, _ in messages["/cmd_vel"]]
    assert cmd_stamps[0] < 2_000_000_000, "the robot was still idle 2 s into the mission"
    periods = {b - a for a, b in itertools.pairwise(cmd_stamps)}
    assert periods == {round(1e9 / CMD_VEL_HZ)}, sorted(periods)[:5]
    assert counts["/tf_static"] == 1
    assert counts["/robot_description"] == 1
    stamps = [t for t, _ in messages["/clock"]]
    assert stamps == sorted(stamps)
    # The scan carries the LDS-01 geometry and sees the house's walls (finite ranges within limits).
    _, scan = messages["/scan"][-1]
    assert len(scan.ranges) == 360
    finite = [r for r in scan.ranges if math.isfinite(r)]
    assert finite and all(0.12 <= r <= 3.5 for r in finite)
    # The robot drove: ground-truth odometry moved away from the spawn point.
    _, odom = messages["/odom"][-1]
    assert math.hypot(odom.pose.pose.position.x, odom.pose.pose.position.y) > 0.5


def test_default_scenario_bag_opens_in_the_mcap_reader(default_bag: Path) -> None:
    files = list(default_bag.glob("*.mcap"))
    assert [f.name for f in files] == ["default_0.mcap"]
    with files[0].open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        topics = {channel.topic for channel in summary.channels.values()}
        total = sum(1 for _ in reader.iter_messages())
    assert set(RATES_HZ) <= topics
    assert total == summary.statistics.message_count


def test_same_seed_gives_identical_messages_and_another_seed_other_noise(tmp_path: Path) -> None:
    bags = []
    for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        bag = tmp_path / name
        result = run_twin("simulate", "--duration", "3", "--seed", seed, "--out", str(bag))
        assert result.returncode == 0, result.stderr
        with AnyReader([bag]) as reader:
            bags.append([(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()])
    assert bags[0] == bags[1]
    scans = [[raw for topic, _, raw in bag if topic == "/scan"] for bag in bags]
    assert scans[0] != scans[2]


def _bag_files(bag: Path) -> dict[str, bytes]:
    return {f.name: f.read_bytes() for f in sorted(bag.iterdir())}


def test_a_cold_cache_and_a_warm_cache_give_byte_identical_bags(tmp_path: Path) -> None:
    """A run on an empty cache folder builds its kernels and FMUs there; its bag must not show it."""
    cache = tmp_path / "cache"
    env = {**os.environ, "PYTHONPATH": str(REPO), "TWIN_CACHE_DIR": str(cache)}
    bags = []
    for name in ("cold", "warm"):
        bag = tmp_path / name / "run"  # the same folder name: metadata.yaml names the file after it
        result = subprocess.run(
            [sys.executable, "-m", "twin", "simulate", "--duration", "10", "--out", str(bag)],
            cwd=REPO,
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
            check=False,
        )
        assert result.returncode == 0, result.stderr
        bags.append(bag)
    assert any((cache / "kernels").iterdir()), "the cold run built nothing into the cache folder"
    cold, warm = (_bag_files(b) for b in bags)
    assert cold.keys() == warm.keys()
    for name in cold:
        assert cold[name] == warm[name], f"{name} differs between the cold-cache and the warm-cache run"
        assert str(cache).encode() not in cold[name], f"{name} names the cache folder"  # messages and metadata
    with AnyReader([bags[0]]) as reader:
        for con, _, raw in reader.messages():
            assert str(cache).encode() not in bytes(raw), f"{con.topic} names the cache folder"
            assert str(REPO).encode() not in bytes(raw), f"{con.topic} names the checkout's folder"


def test_sqlite3_storage_records_the_same_topics(tmp_path: Path) -> None:
    bag = tmp_path / "sq"
    result = run_twin("simulate", "--duration", "2", "--storage", "sqlite3", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert (bag / "sq_0.db3").is_file()
    counts, _ = read_all(bag)
    assert abs(counts["/clock"] - 20) <= 1  # 10 Hz for 2 s


def test_sigint_ends_the_run_gracefully_with_a_complete_bag(tmp_path: Path) -> None:
    bag = tmp_path / "interrupted"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin", "simulate", "--duration", "100000", "--out", str(bag)],
        cwd=REPO,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while not (bag / "metadata.yaml").exists() and not list(bag.glob("*.mcap")) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "interrupted" in out
    counts, _ = read_all(bag)
    assert counts["/clock"] > 100


def test_scenario_typo_is_one_line_exit_2(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: t\nrecording:\n  storag: mcap\n")
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    assert result.stderr.strip() == f"twin: error: {scenario}:3: recording.storag: unknown key; did you mean 'storage'?"
    assert not (tmp_path / "bag").exists()


def test_world_that_is_not_sdf_is_one_line_exit_3(tmp_path: Path) -> None:
    world = tmp_path / "w.world"
    world.write_text("<html><body>not a world</body></html>\n")
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"name: t\nworld: {{sdf: {world}}}\n")
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"))
    assert result.returncode == 3, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(world) in lines[0] and "Traceback" not in result.stderr


def test_a_scenario_asking_for_the_retired_grid_navigator_is_one_line_exit_2(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: t\nnavigation:\n  type: grid\n")
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert (
        f"{scenario}:3: navigation: type 'grid': the grid stand-in is gone, Nav2's stack is the navigator" in lines[0]
    )
    assert not (tmp_path / "bag").exists()


def test_spawning_inside_a_wall_is_refused_before_the_run(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: t\nrobot: {initial_pose: {x_m: -0.536, y_m: -1.356}}\n")
    result = run_twin("simulate", str(scenario), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    assert "robot.initial_pose" in result.stderr and "choose a free spawn pose" in result.stderr
    assert not (tmp_path / "bag").exists()
    # `twin scenario check` says the same before anything runs.
    checked = run_twin("scenario", "check", str(scenario))
    assert checked.returncode == 2
    assert checked.stderr.strip().splitlines() == [result.stderr.strip()]


def test_a_spawn_far_outside_the_world_is_refused_not_mapped(tmp_path: Path) -> None:
    # A map made from the world covers the spawn point: 3,760 km away it would span 3,760 km (300 m at most).
    # (37,600 km, this test's first value, is now out of any coordinate's range: refused as that, in one line.)
    scenario = tmp_path / "s.yaml"
    for x_m, hint in (("3760349.0", "map file"), ("37603494.0", "is out of range")):
        scenario.write_text(f"name: t\nrobot: {{initial_pose: {{x_m: {x_m}}}}}\n")
        commands = (("scenario", "check", str(scenario)), ("simulate", str(scenario), "--out", str(tmp_path / "bag")))
        for command in commands:
            result = run_twin(*command)
            assert result.returncode == 2, result.stderr
            lines = result.stderr.strip().splitlines()
            assert len(lines) == 1 and "robot.initial_pose" in lines[0] and hint in lines[0], lines
        assert not (tmp_path / "bag").exists()


def test_driving_into_a_wall_stops_the_robot_and_records_the_contact(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        "name: wall\nmission:\n  type: cmd_vel_script\n  segments:\n    - {duration_s: 12.0, linear_mps: 0.2}\n"
        "robot: {initial_pose: {x_m: 0.0, y_m: 0.0, yaw_rad: -1.5708}}\n"
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert "1 contacts" in result.stdout
    counts, messages = read_all(bag)
    assert counts["/contacts"] == 1
    _, contact = messages["/contacts"][0]
    assert "Wall" in contact.world_collision
    # The wall's face is at y = -1.356 + 0.075; the robot stopped short of it and stayed there.
    _, odom = messages["/odom"][-1]
    y_end = odom.pose.pose.position.y
    assert -1.281 < y_end - 0.0 < -0.9
    assert odom.twist.twist.linear.x == 0.0


def test_the_summary_counts_the_messages_the_bag_holds(tmp_path: Path) -> None:
    # A recording that leaves topics out (the camera scenarios' raw images): the summary said 2440
    # messages of a bag holding 2390; it counts what the bag holds.
    scenario = tmp_path / "few.yaml"
    scenario.write_text("name: few\nrecording:\n  topics: {exclude: [/imu, /joint_states]}\n")
    proc = run_twin("simulate", str(scenario), "--duration", "3", "--out", str(tmp_path / "bag"), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    info = open_bag(tmp_path / "bag")
    assert summary["messages"] == info.message_count
    assert summary["topics"]["/imu"] > 0 and "/imu" not in {t.name for t in info.topics}


def test_a_missing_include_is_refused_unless_the_scenario_skips_it_and_check_says_what_the_run_says(
    tmp_path: Path,
) -> None:
    world = tmp_path / "tb3.sdf"
    text = (REPO / "sdf" / "worlds" / "turtlebot3_world.sdf").read_text()
    world.write_text(text.replace("</world>", "<include><uri>model://VendingMachine</uri></include>\n</world>", 1))
    line = text[: text.index("</world>")].count("\n") + 1
    scenario = tmp_path / "s.yaml"
    base = f"name: t\nrobot: {{initial_pose: {{x_m: -2.0, y_m: -0.5}}}}\nmission: {{type: none}}\nworld: {{sdf: {world}"
    scenario.write_text(base + "}\n")
    for command in (("scenario", "check", str(scenario)), ("simulate", str(scenario), "--out", str(tmp_path / "b0"))):
        refused = run_twin(*command)
        assert refused.returncode == 3, refused.stderr
        (error,) = refused.stderr.strip().splitlines()
        assert f"{world}:{line}: <include> 'model://VendingMachine' not found" in error
        assert "world.missing_includes: warn" in error
    scenario.write_text(base + ", missing_includes: warn}\n")
    for command in (("scenario", "check", str(scenario)), ("simulate", str(scenario), "--out", str(tmp_path / "b1"))):
        done = run_twin(*command, "--duration", "1") if command[0] == "simulate" else run_twin(*command)
        assert done.returncode == 0, done.stderr
        (warning,) = [ln for ln in done.stderr.splitlines() if "VendingMachine" in ln]
        assert f"{world}:{line}:" in warning and "skipped" in warning
