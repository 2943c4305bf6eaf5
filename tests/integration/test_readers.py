"""Issue 6's must-hold on the real product: the default scenario's bag decodes completely in every reader.

`twin simulate` records the default scenario (the thesis's mission: tree log, plan, IMU, EKF odometry,
scans, TF, ...) in both storages, and a wall-contact run with the FMU drive adds the twin's own
message types; rosbags' AnyReader, the mcap reader with mcap-ros2-support, and Foxglove's JavaScript
readers must each decode every message of every topic, with the same values.
"""

from __future__ import annotations

import json
import subprocess
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from tests.conftest import run_twin
from tests.unit.bag.test_reader_checks import JS_DIR, _node_modules_or_fail, foxglove_time, plain, rosbags_decoded
from twin.bag import open_bag

CONTACT_FMU = """\
name: wall_fmu
robot: {initial_pose: {x_m: 0.0, y_m: 0.0, yaw_rad: -1.5708}}
drive: {type: fmu}
mission:
  type: cmd_vel_script
  segments: [{duration_s: 8.0, linear_mps: 0.2}, {duration_s: 2.0, linear_mps: -0.1}]
"""


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("readers")
    out = {}
    for storage in ("mcap", "sqlite3"):
        bag = root / f"default_{storage}"
        result = run_twin("simulate", "--duration", "12", "--storage", storage, "--out", str(bag))
        assert result.returncode == 0, result.stderr
        out[storage] = bag
    scenario = root / "wall.yaml"
    scenario.write_text(CONTACT_FMU)
    result = run_twin("simulate", str(scenario), "--out", str(root / "wall"))
    assert result.returncode == 0, result.stderr
    out["contact"] = root / "wall"
    return out


def counts(bag: Path) -> dict[str, int]:
    return {t.name: t.message_count for t in open_bag(bag).topics if t.message_count}


@pytest.mark.parametrize("name", ["mcap", "sqlite3", "contact"])
def test_rosbags_anyreader_decodes_every_message_of_every_topic(bags: dict[str, Path], name: str) -> None:
    decoded = rosbags_decoded(bags[name])
    assert {topic: len(m) for topic, m in decoded.items()} == counts(bags[name])
    expected = {"/clock", "/tf", "/tf_static", "/robot_description", "/scan", "/imu", "/joint_states", "/odom",
                "/ground_truth/odom", "/cmd_vel", "/rosout"}  # fmt: skip
    assert expected <= set(decoded)
    if name == "contact":
        assert {"/motor_state", "/contacts"} <= set(decoded)
    else:
        assert {"/behavior_tree_log", "/plan"} <= set(decoded)


@pytest.mark.parametrize("name", ["mcap", "contact"])
def test_mcap_reader_with_ros2_support_decodes_every_message(bags: dict[str, Path], name: str) -> None:
    (file,) = bags[name].glob("*.mcap")
    got: Counter[str] = Counter()
    with file.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages():
            assert decoded is not None
            got[channel.topic] += 1
    assert dict(got) == counts(bags[name])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["mcap", "sqlite3", "contact"])
def test_foxglove_js_readers_decode_every_message_with_rosbags_values(bags: dict[str, Path], name: str) -> None:
    _node_modules_or_fail()
    run = subprocess.run(
        ["node", str(JS_DIR / "read_bag.mjs"), str(bags[name])],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    js_topics = json.loads(run.stdout)["topics"]
    expected = rosbags_decoded(bags[name])
    js_counts = {topic: len(v["messages"]) for topic, v in js_topics.items() if v["messages"]}
    assert js_counts == {t: len(m) for t, m in expected.items()}
    for topic, entry in js_topics.items():
        for got, (t_ns, msg) in zip(entry["messages"], expected.get(topic, []), strict=True):
            assert int(got["t_ns"]) == t_ns
            assert foxglove_time(got["msg"]) == plain(msg), f"{topic} at {t_ns} ns decodes differently in JS"
