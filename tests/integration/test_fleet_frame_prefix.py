"""Gazebo's `frame_prefix` on a fleet (`tf: {mode: frame_prefix}`), read back from the bag of a whole run.

Two Waffles in the house, each with its own one-goal mission: every robot's TF is on the one shared
`/tf` and `/tf_static` with its frames named `robotN/...` under one `map`, the transforms make one
tree, every frame a robot's message names is in it, and the robots do exactly what they do with
nav2_bringup's namespaced TF (only the names differ).
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import run_twin
from tests.integration.fleet_helpers import Messages, simulate_and_read, write_goals
from twin.core.errors import ConfigError
from twin.sim.scenario_file import load_scenario

SCENARIO = """
name: two_waffles_prefixed
max_duration_s: 120
{tf}
mission: {{tree: {tree}}}
robots:
  - name: robot1
    robot: {{initial_pose: {{x_m: 0.0, y_m: 0.0, yaw_rad: 0.0}}}}
    mission: {{locations: {goal1}}}
  - name: robot2
    robot: {{initial_pose: {{x_m: 1.5, y_m: -0.2, yaw_rad: 0.0}}}}
    mission: {{locations: {goal2}}}
"""

GOALS = {"robot1": (-1.0, -0.5, -2.25), "robot2": (4.0, 0.5, 1.571)}
ROBOTS = tuple(GOALS)


def _frames(msg: Any, out: set[str]) -> None:
    """Every `frame_id` / `child_frame_id` anywhere in a message (headers of nested messages too)."""
    fields = getattr(msg, "__dataclass_fields__", None)
    if fields is not None:
        for key in fields:
            value = getattr(msg, key)
            if key in ("frame_id", "child_frame_id") and isinstance(value, str):
                out.add(value)
            else:
                _frames(value, out)
    elif isinstance(msg, list):
        for item in msg:
            _frames(item, out)


def _run(tmp: Path, tf: str) -> tuple[dict[str, Any], Messages]:
    tree, files = write_goals(tmp, GOALS)
    scenario = tmp / "two.yaml"
    scenario.write_text(SCENARIO.format(tf=tf, tree=tree, goal1=files["robot1"], goal2=files["robot2"]))
    skipped = ("rcl_interfaces/msg/Log", "std_msgs/msg/String")
    return simulate_and_read(scenario, tmp / "bag", lambda con: con.msgtype not in skipped)


@pytest.fixture(scope="module")
def prefixed_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]]]:
    return _run(tmp_path_factory.mktemp("prefixed"), "tf: {mode: frame_prefix}")


def _tree(messages: dict[str, list[tuple[int, Any]]]) -> dict[str, set[str]]:
    parents: dict[str, set[str]] = {}
    for topic in ("/tf_static", "/tf"):
        for _, msg in messages[topic]:
            for tf in msg.transforms:
                parents.setdefault(tf.child_frame_id, set()).add(tf.header.frame_id)
    return parents


def test_both_robots_reach_their_goals(prefixed_run: tuple[dict[str, Any], Any]) -> None:
    summary, _ = prefixed_run
    assert summary["robots"] == {"robot1": "SUCCESS", "robot2": "SUCCESS"}, summary


def test_one_shared_tf_tree_holds_each_robots_chain(prefixed_run: tuple[dict[str, Any], Any]) -> None:
    _, messages = prefixed_run
    parents = _tree(messages)
    assert all(len(p) == 1 for p in parents.values()), parents  # each frame has one parent
    parent = {child: next(iter(p)) for child, p in parents.items()}
    for name in ROBOTS:
        chain = [f"{name}/base_scan", f"{name}/base_link", f"{name}/base_footprint", f"{name}/odom", "map"]
        for child, up in itertools.pairwise(chain):
            assert parent[child] == up, (child, parent.get(child))
    roots = set()
    for child in parent:
        top = child
        while top in parent:
            top = parent[top]
        roots.add(top)
    assert roots == {"map"}, parent  # one tree: the robots' frames all hang under the shared map
    for child in parent:  # every robot frame is one robot's, by its prefix
        assert child.split("/")[0] in ROBOTS, child


def test_nothing_is_on_a_namespaced_tf(prefixed_run: tuple[dict[str, Any], Any]) -> None:
    _, messages = prefixed_run
    assert not [t for t in messages if t.endswith(("/tf", "/tf_static")) and t not in ("/tf", "/tf_static")]
    outside = {t for t in messages if not t.startswith(tuple(f"/{n}/" for n in ROBOTS))}
    assert outside == {"/clock", "/rosout", "/tf", "/tf_static"}


def test_every_frame_a_robots_message_names_is_in_the_tree(prefixed_run: tuple[dict[str, Any], Any]) -> None:
    _, messages = prefixed_run
    tree = set(_tree(messages)) | {"map"}
    checked = set()
    for name in ROBOTS:
        for topic, entries in messages.items():
            if not topic.startswith(f"/{name}/"):
                continue
            frames: set[str] = set()
            for _, msg in entries:
                if msg is not None:
                    _frames(msg, frames)
            frames.discard("")  # joint_states and motor_state leave the header frame empty, as Gazebo does
            for frame in frames:
                assert frame in tree, (topic, frame)
                assert frame == "map" or frame.startswith(f"{name}/"), (topic, frame)  # its own, or the shared map
            if frames:
                checked.add(topic.removeprefix(f"/{name}/"))
    for topic in ("odom", "scan", "imu", "amcl_pose", "plan", "local_plan", "global_costmap/costmap"):
        assert topic in checked, topic
    assert "local_costmap/costmap" in checked  # in the robot's own odom frame


def test_frame_prefix_only_renames_the_robots_frames(prefixed_run: tuple[dict[str, Any], Any], tmp_path: Path) -> None:
    _, prefixed = prefixed_run
    _, namespaced = _run(tmp_path, "")
    for name in ROBOTS:
        topic = f"/{name}/ground_truth/odom"
        a = [(t, m.pose.pose.position.x, m.pose.pose.position.y) for t, m in prefixed[topic]]
        b = [(t, m.pose.pose.position.x, m.pose.pose.position.y) for t, m in namespaced[topic]]
        assert a == b  # the same motion, step for step
        assert namespaced[f"/{name}/odom"][0][1].header.frame_id == "odom"
        assert prefixed[f"/{name}/odom"][0][1].header.frame_id == f"{name}/odom"


def test_frame_prefix_without_robots_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ntf: {mode: frame_prefix}\n")
    result = run_twin("simulate", str(bad), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines == [
        f"twin: error: {bad}:2: tf.mode: frame_prefix names each robot's frames after its namespace and needs "
        "robots:; remove tf, or list the robots under robots:"
    ]
    assert not (tmp_path / "bag").exists()


def test_a_misspelt_tf_mode_is_refused_with_a_suggestion(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ntf: {mode: frame-prefix}\nrobots: [{name: a}]\n")
    with pytest.raises(ConfigError, match=r"bad.yaml:2: tf.mode: 'frame-prefix' is not allowed; did you mean"):
        load_scenario(bad)


def test_an_unknown_tf_key_is_refused_with_a_suggestion(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ntf: {mod: frame_prefix}\nrobots: [{name: a}]\n")
    result = run_twin("simulate", str(bad), "--out", str(tmp_path / "bag"))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [f"twin: error: {bad}:2: tf.mod: unknown key; did you mean 'mode'?"]
