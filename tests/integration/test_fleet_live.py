"""`twin simulate --live` and `twin play` on a fleet: every namespace served, or one robot alone (`--namespace`)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import REPO, run_twin
from tests.foxglove_client import Watch, watch
from tests.integration.test_live import bag_messages, finish, start_twin
from twin.bag import open_bag
from twin.live import LiveServer, play_bag

pytestmark = pytest.mark.slow

EMPTY_WORLD = REPO.parent / "shared" / "fixtures" / "gazebo_classic" / "worlds" / "empty_world.world"

# Two robots driving apart in an empty world: sensors, TF and odometry, no Nav2 (a short run).
FLEET = f"""
name: two_apart
world: {{sdf: {EMPTY_WORLD}}}
localization: {{type: none}}
drive: {{type: kinematic}}
mission:
  type: cmd_vel_script
  rate_hz: 10
  segments: [{{duration_s: 3.0, linear_mps: 0.1}}]
robots:
  - {{name: robot1, robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 3.141592653589793}}}}}}
  - {{name: robot2, robot: {{initial_pose: {{x_m: 1.0, y_m: 0.0, yaw_rad: 0.0}}}}}}
"""

SINGLE_NAMES = ["/scan", "/tf", "/tf_static", "/robot_description", "/odom", "/clock"]


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fleet_live") / "two.yaml"
    path.write_text(FLEET)
    return path


@pytest.fixture(scope="module")
def robot2_live(scenario: Path) -> tuple[Path, Watch]:
    bag = scenario.parent / "run"
    proc, url = start_twin(
        "simulate",
        str(scenario),
        "--live",
        "--namespace",
        "robot2",
        "--speed",
        "4",
        "--duration",
        "20",
        "--out",
        str(bag),
    )

    # Paced at 4x, the run lasts 5 s of wall time: the client may connect late on a loaded machine,
    # and stops once it has ten of robot2's scans and its odometry and latched topics.
    def done(w: Watch) -> bool:
        wanted = ("/odom", "/tf_static", "/robot_description")
        return len(w.messages["/scan"]) >= 10 and all(w.messages[t] for t in wanted)

    seen = asyncio.run(watch(url, SINGLE_NAMES, stop=done, timeout_s=120))
    code, _, err = finish(proc)
    assert code == 0, err
    return bag, seen


def test_a_live_fleet_run_serves_one_robot_under_a_single_robots_names(robot2_live: tuple[Path, Watch]) -> None:
    bag, seen = robot2_live
    assert not [t for t in seen.channels if t.startswith(("/robot1/", "/robot2/"))], sorted(seen.channels)
    for topic in ("/scan", "/tf", "/tf_static", "/robot_description", "/odom", "/clock", "/rosout"):
        assert topic in seen.channels, topic
    recorded = bag_messages(bag)
    scans = {t: msg for t, _, msg in recorded["/robot2/scan"]}
    assert len(seen.messages["/scan"]) >= 10
    for t_ns, payload in seen.messages["/scan"]:  # robot2's scans, not robot1's
        np.testing.assert_array_equal(seen.decode("/scan", payload).ranges, scans[t_ns].ranges)
    odoms = {t: msg for t, _, msg in recorded["/robot2/odom"]}
    for t_ns, payload in seen.messages["/odom"]:
        assert seen.decode("/odom", payload).pose.pose.position.x == odoms[t_ns].pose.pose.position.x
    assert seen.messages["/tf_static"]  # robot2's, now on /tf_static: one robot's tree for the 3D panel
    description = seen.decode("/robot_description", seen.messages["/robot_description"][0][1]).data
    assert description == recorded["/robot2/robot_description"][0][2].data


def test_twin_play_serves_every_namespace_of_a_fleet_bag(robot2_live: tuple[Path, Watch]) -> None:
    bag, _ = robot2_live
    with LiveServer(port=0) as server:
        report = play_bag(bag, server, speed=None)
        seen: Any = asyncio.run(
            watch(
                server.url,
                ["/robot1/tf_static", "/robot2/tf_static"],
                stop=lambda w: all(w.messages.values()),
                timeout_s=10,
            )
        )
    assert set(report.topics) == {t.name for t in open_bag(bag).topics}  # nothing of any robot left out
    assert not report.skipped
    assert {"/robot1/tf", "/robot2/tf", "/robot1/scan", "/robot2/scan", "/clock"} <= set(seen.channels)
    for ns in ("robot1", "robot2"):  # each namespace's static frames reach a late client
        assert seen.messages[f"/{ns}/tf_static"], ns


def test_twin_play_namespace_serves_one_robot(robot2_live: tuple[Path, Watch]) -> None:
    bag, _ = robot2_live
    proc, url = start_twin("play", str(bag), "--namespace", "robot1", "--speed", "8")
    seen = asyncio.run(watch(url, ["/scan", "/odom"], timeout_s=120))
    code, out, err = finish(proc)
    assert code == 0, err
    assert "/robot1/ alone" in out
    assert not [t for t in seen.channels if t.startswith(("/robot1/", "/robot2/"))], sorted(seen.channels)
    scans = {t: msg for t, _, msg in bag_messages(bag)["/robot1/scan"]}
    assert len(seen.messages["/scan"]) >= len(scans) - 2
    for t_ns, payload in seen.messages["/scan"]:
        np.testing.assert_array_equal(seen.decode("/scan", payload).ranges, scans[t_ns].ranges)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--live", "--namespace", "robot3"], "--namespace 'robot3' is not a robot of the scenario; did you mean"),
        (["--namespace", "robot1"], "--namespace: configures the live view; add --live"),
    ],
)
def test_a_bad_live_namespace_is_one_line_and_exit_2(
    scenario: Path, tmp_path: Path, extra: list[str], message: str
) -> None:
    result = run_twin("simulate", str(scenario), *extra, "--port", "0", "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert not (tmp_path / "bag").exists()


def test_play_refuses_a_namespace_the_bag_lacks(robot2_live: tuple[Path, Watch]) -> None:
    bag, _ = robot2_live
    result = run_twin("play", str(bag), "--namespace", "robot3", "--port", "0")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "'robot3' is not a robot of this bag; it has robot1, robot2" in lines[0], lines
