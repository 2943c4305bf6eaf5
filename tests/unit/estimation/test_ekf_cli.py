"""`twin ekf replay`: the command, its outputs and its errors (run in-process with the bag API fixture)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader, Writer
from rosbags.typesys import Stores, get_typestore

from twin.cli import main
from twin.core.errors import ConfigError, EstimationError


def replay(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    code = main(["ekf", "replay", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.usefixtures("ekf_backend")
def test_replaying_the_gazebo_bag_writes_a_bag_and_a_csv_and_reports_the_error(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = replay(capsys, gazebo_bag, "--out", tmp_path / "fused")
    print(out)
    assert code == 0
    assert "rad/s (inferred: velocity / position rate = 1.0000" in out
    assert "speeds from joint positions" in out
    assert "against /odom over 28.1 s" in out
    assert "% of the distance travelled" in out
    rows = list(csv.DictReader((tmp_path / "fused" / "odometry.csv").open()))
    assert len(rows) == 826
    assert float(rows[0]["x_m"]) == pytest.approx(-2.0, abs=1e-4)  # starts at /odom's pose
    assert abs(float(rows[-1]["position_error_m"])) < 0.01
    with AnyReader([tmp_path / "fused" / "odometry"], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype) == ("/odometry/filtered", "nav_msgs/msg/Odometry")
        msgs = [reader.deserialize(raw, conn.msgtype) for _, _, raw in reader.messages()]
    assert len(msgs) == 826
    last = msgs[-1]
    assert (last.header.frame_id, last.child_frame_id) == ("odom", "base_footprint")
    assert last.pose.pose.position.x == pytest.approx(float(rows[-1]["x_m"]), abs=1e-6)
    assert last.pose.covariance[0] == pytest.approx(float(rows[-1]["var_x_m2"]), rel=1e-6)
    assert last.pose.covariance[14] == 1e12


@pytest.mark.usefixtures("ekf_backend")
def test_json_summary_for_scripts(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = replay(capsys, gazebo_bag, "--out", tmp_path, "--json", "--storage", "sqlite3")
    assert code == 0
    summary = json.loads(out)
    assert summary["joint_velocity_units"] == "rad/s" and summary["joint_velocity_units_how"] == "inferred"
    comparison = summary["comparison"]
    assert comparison["distance_m"] == pytest.approx(4.76, abs=0.01)
    assert comparison["position_error_final_m"] < 0.01
    assert abs(comparison["yaw_error_final_deg"]) < 0.1
    assert (tmp_path / "odometry" / "metadata.yaml").exists()


@pytest.mark.usefixtures("ekf_backend")
def test_the_unit_flag_is_reported_as_given(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = replay(capsys, gazebo_bag, "--out", tmp_path, "--joint-velocity-units", "m/s", "--json")
    assert code == 0
    assert json.loads(out)["joint_velocity_units_note"] == "m/s (given)"


def _copy_without(source: Path, target: Path, dropped: set[str], renamed: dict[str, str] | None = None) -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    names = renamed or {}
    with Reader(source) as reader, Writer(target, version=8) as writer:
        conns = {
            c.id: writer.add_connection(names.get(c.topic, c.topic), c.msgtype, typestore=store)
            for c in reader.connections
            if c.topic not in dropped and c.msgtype in store.types
        }
        for conn, t_ns, raw in reader.messages():
            if conn.id in conns:
                writer.write(conns[conn.id], t_ns, raw)


def test_a_bag_without_imu_gets_one_line_naming_the_flag_that_helps(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "no_imu"
    _copy_without(gazebo_bag, bag, {"/imu", "/scan", "/tf", "/tf_static", "/rosout", "/parameter_events"})
    code, out, err = replay(capsys, bag, "--out", tmp_path / "out")
    assert code == EstimationError.exit_code
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].endswith(f"{bag}: no /imu to replay; pass --no-gyro (the bag has no sensor_msgs/Imu topic)")
    # an IMU under another name (a real robot's /imu/data) is named with the flag that reads it
    renamed = tmp_path / "imu_data"
    _copy_without(gazebo_bag, renamed, {"/scan", "/tf", "/tf_static", "/rosout"}, {"/imu": "/imu/data"})
    code, _, err = replay(capsys, renamed, "--out", tmp_path / "out2")
    assert code == EstimationError.exit_code
    assert err.strip().endswith(f"{renamed}: no /imu to replay; pass --imu-topic /imu/data")
    code, _, _ = replay(capsys, renamed, "--out", tmp_path / "out3", "--imu-topic", "/imu/data")
    assert code == 0
    # Wheel odometry alone does not need it.
    code, out, _ = replay(capsys, bag, "--out", tmp_path / "wheels", "--no-gyro")
    assert code == 0
    assert "not fused (wheel odometry alone)" in out


@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        (
            ("--imu-topic", "/scan"),
            "--imu-topic /scan is sensor_msgs/msg/LaserScan, not sensor_msgs/msg/Imu; pass --imu-topic /imu",
        ),
        (
            ("--joint-topic", "/odom"),
            "--joint-topic /odom is nav_msgs/msg/Odometry, not sensor_msgs/msg/JointState; pass --joint-topic /joint_states",
        ),
        (
            ("--odom-topic", "/scan"),
            "--odom-topic /scan is sensor_msgs/msg/LaserScan, not nav_msgs/msg/Odometry; pass --odom-topic /odom",
        ),
    ],
)
def test_a_topic_of_another_type_is_named_with_the_one_to_pass(
    gazebo_bag: Path,
    tmp_path: Path,
    bag_module: ModuleType,
    capsys: pytest.CaptureFixture[str],
    flags: tuple[str, str],
    expected: str,
) -> None:
    # (these were AttributeErrors, exit 70)
    code, out, err = replay(capsys, gazebo_bag, "--out", tmp_path / "out", *flags)
    assert code == EstimationError.exit_code and out == ""
    assert err.strip().splitlines() == [f"twin: error: {gazebo_bag}: {expected}"]


def test_an_existing_output_bag_is_not_overwritten(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "odometry").mkdir()
    (tmp_path / "odometry" / "x").write_text("keep", encoding="utf-8")
    code, _, err = replay(capsys, gazebo_bag, "--out", tmp_path)
    assert code == EstimationError.exit_code
    assert "exists and is not empty; choose another --out" in err


@pytest.mark.usefixtures("ekf_backend")
def test_filter_settings_come_from_an_estimation_section(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "ekf.yaml"
    config.write_text("estimation:\n  fuse_gyro: false\n", encoding="utf-8")
    code, out, _ = replay(capsys, gazebo_bag, "--out", tmp_path / "a", "--config", config, "--json")
    assert code == 0
    summary = json.loads(out)
    assert not summary["gyro_fused"] and summary["gyro_samples_fused"] == 0
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimation:\n  fuse_gyro: false\n  process_noise: {velocity_random_walk: 1}\n", encoding="utf-8")
    code, _, err = replay(capsys, gazebo_bag, "--out", tmp_path / "b", "--config", bad)
    assert code == ConfigError.exit_code
    assert f"{bad}:3: estimation.process_noise.velocity_random_walk: unknown key; did you mean" in err


def test_wrong_geometry_is_refused_before_reading(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = replay(capsys, tmp_path, "--wheel-radius", "0")
    assert code == ConfigError.exit_code
    assert "--wheel-radius must be a length in metres above 0 and at most 100, got 0.0" in err


def test_the_command_is_registered_and_explains_itself(repo: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "twin", "ekf", "replay", "--help"], cwd=repo, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0
    assert "--joint-velocity-units" in done.stdout
    assert "examples:" in done.stdout


def test_a_bag_without_joint_states_gets_a_hint_that_works(
    gazebo_bag: Path, tmp_path: Path, bag_module: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "no_wheels"
    _copy_without(gazebo_bag, bag, {"/imu", "/joint_states", "/scan", "/tf", "/tf_static", "/rosout"})
    for extra in ((), ("--no-gyro",)):
        code, out, err = replay(capsys, bag, "--out", tmp_path / f"out{len(extra)}", *extra)
        assert code == EstimationError.exit_code
        lines = err.strip().splitlines()
        assert len(lines) == 1 and out == ""
        # --no-gyro would fail the same way: the line says what the EKF needs instead
        assert "--no-gyro" not in lines[0]
        assert "sensor_msgs/JointState" in lines[0] and "/joint_states" in lines[0] and str(bag) in lines[0]


def test_a_fleet_robot_is_replayed_with_its_own_topics_and_urdf(tmp_path: Path) -> None:
    # A Burger and a Waffle: replaying the Burger with the Waffle's track (the default) would be 45 % off.
    from tests.conftest import run_twin

    scenario = tmp_path / "pair.yaml"
    script = "{type: cmd_vel_script, segments: [{duration_s: 6.0, linear_mps: 0.15, angular_radps: 0.3}]}"
    scenario.write_text(
        f"name: pair\nmission: {script}\nrobots:\n  - {{name: waffle}}\n"
        "  - {name: burger, robot: {model: turtlebot3_burger, initial_pose: {x_m: 1.5, y_m: -0.2}}}\n"
    )
    bag = tmp_path / "bag"
    assert run_twin("simulate", str(scenario), "--out", str(bag), "-q").returncode == 0
    result = run_twin("ekf", "replay", str(bag), "--namespace", "burger", "--out", str(tmp_path / "b"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["geometry_sources"]["wheel_separation"] == "/burger/robot_description (URDF of turtlebot3_burger)"
    assert summary["wheel_separation_m"] == pytest.approx(0.160)
    assert summary["reference_topic"] == "/burger/odom"
    assert summary["comparison"]["final_error_percent_of_distance"] < 1.0
    flagged = ("--namespace", "burger", "--odom-topic", "/waffle/odom", "--json")
    other = run_twin("ekf", "replay", str(bag), *flagged, "--out", str(tmp_path / "w"))
    assert json.loads(other.stdout)["reference_topic"] == "/waffle/odom"  # a topic flag is read as given
    unchosen = run_twin("ekf", "replay", str(bag), "--out", str(tmp_path / "x"))
    assert unchosen.returncode == 2
    assert unchosen.stderr.strip().splitlines() == [
        f"twin: error: {bag}: a fleet's bag (robots burger, waffle) has no /joint_states; "
        "pick a robot with --namespace (e.g. --namespace burger)"
    ]
    wrong = run_twin("ekf", "replay", str(bag), "--namespace", "robot9", "--out", str(tmp_path / "y"))
    assert (
        wrong.returncode == 2
        and "--namespace 'robot9' is not a robot of this bag; it has burger, waffle" in wrong.stderr
    )


@pytest.mark.usefixtures("ekf_backend")
def test_another_robots_wheels_on_turtlebot3_geometry_are_warned_of(
    gazebo_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A Husky's bag without its URDF: the radius and separation fell back to the Waffle's, said only in the summary.
    store = get_typestore(Stores.ROS2_HUMBLE)
    bag = tmp_path / "husky"
    renames = {"wheel_left_joint": "front_left_wheel_joint", "wheel_right_joint": "front_right_wheel_joint"}
    with Reader(gazebo_bag) as reader, Writer(bag, version=8) as writer:
        keep = ("/imu", "/joint_states", "/odom")
        conns = {
            c.id: writer.add_connection(c.topic, c.msgtype, typestore=store)
            for c in reader.connections
            if c.topic in keep
        }
        for conn, t_ns, raw in reader.messages():
            if conn.id not in conns:
                continue
            data = raw
            if conn.topic == "/joint_states":
                msg = store.deserialize_cdr(raw, conn.msgtype)
                msg.name = [renames.get(n, n) for n in msg.name]
                data = store.serialize_cdr(msg, conn.msgtype)
            writer.write(conns[conn.id], t_ns, data)
    joints = ("--left-joint", "front_left_wheel_joint", "--right-joint", "front_right_wheel_joint")
    code, _, err = replay(capsys, bag, "--out", tmp_path / "out", *joints)
    assert code == 0, err
    (line,) = [ln for ln in err.splitlines() if "not a TurtleBot3's" in ln]
    assert "front_left_wheel_joint and front_right_wheel_joint" in line
    assert line.endswith("give --wheel-radius and --wheel-separation")
    code, _, err = replay(
        capsys, bag, "--out", tmp_path / "out2", *joints, "--wheel-radius", "0.165", "--wheel-separation", "0.555"
    )
    assert code == 0 and "not a TurtleBot3's" not in err


@pytest.mark.usefixtures("ekf_backend")
def test_a_bag_of_one_robot_under_a_namespace_needs_no_namespace_flag(
    gazebo_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # analyze, compare and replay read such a bag's one robot; ekf replay asked for --namespace tb3.
    bag = tmp_path / "tb3"
    topics = ("/imu", "/joint_states", "/odom", "/robot_description", "/clock")
    dropped = {t for t in ("/scan", "/tf", "/tf_static", "/rosout", "/parameter_events", "/cmd_vel")}
    _copy_without(gazebo_bag, bag, dropped, renamed={t: f"/tb3{t}" for t in topics if t != "/clock"})
    code, out, err = replay(capsys, bag, "--out", tmp_path / "out", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["reference_topic"] == "/tb3/odom"
    assert summary["comparison"]["final_error_percent_of_distance"] < 1.0
