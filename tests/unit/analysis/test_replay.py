"""`twin replay` and the `type: replay` mission on the real Gazebo bag; compare's one-line refusals."""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.conftest import run_twin
from tests.unit.analysis.test_analyze_cli import _copy_topics, _one_line_error
from twin.analysis.compare import compare_bags
from twin.bag import Recorder, open_bag, read_messages
from twin.core.errors import BagError, ConfigError
from twin.sim.bag_robot import robot_from_bag, robot_from_urdf
from twin.sim.replay import load_commands
from twin.sim.scenario import ReplayMission


def _replay(fixtures: Path, gazebo_bag: Path, out: Path, drive: str) -> dict:
    proc = run_twin(
        "replay",
        str(gazebo_bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
        "--model-path",
        str(fixtures / "gazebo_classic" / "models"),
        "--drive",
        drive,
        "--out",
        str(out),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _odom(bag: Path, topic: str) -> list[tuple[float, float, float]]:
    rows = []
    for m in read_messages(bag, [topic]):
        s = m.msg.header.stamp
        rows.append((s.sec + s.nanosec * 1e-9, m.msg.pose.pose.position.x, m.msg.pose.pose.position.y))
    return rows


def _error_at(src: list, twin: list, t_rel: float) -> float:
    """Position error at t_rel s after each bag's first pose, by linear interpolation in each."""

    def at(rows: list, t: float) -> tuple[float, float]:
        t0 = rows[0][0]
        for (ta, xa, ya), (tb, xb, yb) in itertools.pairwise(rows):
            if ta - t0 <= t <= tb - t0:
                f = (t - (ta - t0)) / (tb - ta)
                return xa + f * (xb - xa), ya + f * (yb - ya)
        return rows[-1][1], rows[-1][2]

    return math.dist(at(src, t_rel), at(twin, t_rel))


@pytest.fixture(scope="module")
def kinematic_replay(fixtures: Path, gazebo_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("replay_kinematic")
    return _replay(fixtures, gazebo_bag, out, "kinematic"), out


def test_kinematic_replay_of_the_gazebo_bag_stays_within_10_mm_at_25_s(
    kinematic_replay: tuple[dict, Path], gazebo_bag: Path
) -> None:
    result, out = kinematic_replay
    assert result["robot"] == "turtlebot3_waffle_pi"  # from the bag's /robot_description
    assert "/robot_description names turtlebot3_waffle_pi" in result["robot_reason"]
    src = _odom(gazebo_bag, "/odom")
    twin = _odom(out / "bag", "/ground_truth/odom")
    end = src[-1][0] - src[0][0]
    assert end > 25.0
    assert _error_at(src, twin, 25.0) <= 0.010  # measured 2.9 mm
    assert _error_at(src, twin, end) <= 0.05
    # The reported comparison says the same.
    assert result["position_error_final_m"] == pytest.approx(_error_at(src, twin, result["matched_span_s"]), abs=1e-6)
    assert result["position_error_max_m"] <= 0.05
    assert (out / "overlay.png").exists() and (out / "scenario.yaml").exists()


def test_replay_starts_at_the_bags_first_pose(kinematic_replay: tuple[dict, Path], gazebo_bag: Path) -> None:
    _, out = kinematic_replay
    first_src = _odom(gazebo_bag, "/odom")[0]
    first_twin = _odom(out / "bag", "/ground_truth/odom")[0]
    assert math.dist(first_src[1:], first_twin[1:]) < 1e-9


def test_fmu_replay_figure(fixtures: Path, gazebo_bag: Path, tmp_path: Path) -> None:
    result = _replay(fixtures, gazebo_bag, tmp_path / "fmu", "fmu")
    src = _odom(gazebo_bag, "/odom")
    twin = _odom(tmp_path / "fmu" / "bag", "/ground_truth/odom")
    at_25, at_end = _error_at(src, twin, 25.0), _error_at(src, twin, src[-1][0] - src[0][0])
    # Measured: 2.8 mm at 25 s and 4.9 mm at the end with the robot's own XM430 servos (fmu: auto,
    # velocity-servo, as `simulate` runs them); the voltage-profile motor gave 20 mm and 109 mm.
    assert at_25 <= 0.010
    assert at_end <= 0.015
    assert result["drive"] == "fmu"
    assert "fmu: auto" in (tmp_path / "fmu" / "scenario.yaml").read_text()


def test_scenario_file_replay_mission_runs_under_simulate(fixtures: Path, gazebo_bag: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "replay.yaml"
    scenario.write_text(
        "name: replay_test\n"
        f"world: {{sdf: {fixtures}/gazebo_classic/worlds/turtlebot3_world.world, "
        f"model_path: [{fixtures}/gazebo_classic/models]}}\n"
        "robot: {model: turtlebot3_waffle_pi}\n"
        f"mission: {{type: replay, bag: {gazebo_bag}, topic: /cmd_vel}}\n"
    )
    proc = run_twin("simulate", str(scenario), "--out", str(tmp_path / "run"), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["ended_by"] == "mission complete"
    result = compare_bags(gazebo_bag, tmp_path / "run", topics=("/odom", "/ground_truth/odom"))
    assert result.final_position_error_m <= 0.05


def test_replay_bag_without_cmd_vel_is_one_line(fixtures: Path, twin_bag: Path, tmp_path: Path) -> None:
    bag = _copy_topics(twin_bag, tmp_path / "no_cmd", ["/odom", "/clock"])
    proc = run_twin(
        "replay",
        str(bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
        "--model-path",
        str(fixtures / "gazebo_classic" / "models"),
        "--out",
        str(tmp_path / "out"),
    )
    line = _one_line_error(proc)
    assert "/cmd_vel" in line and str(bag) in line


def test_compare_without_common_pose_topic_is_one_line(twin_bag: Path, tmp_path: Path) -> None:
    a = _copy_topics(twin_bag, tmp_path / "a", ["/odom"])
    b = _copy_topics(twin_bag, tmp_path / "b", ["/ground_truth/odom"])
    line = _one_line_error(run_twin("analyze", "compare", str(a), str(b)))
    assert "--topic" in line and "no pose topic" in line


def test_compare_exit_code_follows_the_threshold(twin_bag: Path, tmp_path: Path) -> None:
    other = tmp_path / "seed3"
    assert run_twin("simulate", "--duration", "20", "--seed", "3", "--out", str(other)).returncode == 0
    result = compare_bags(twin_bag, other)
    loose = run_twin("analyze", "compare", str(twin_bag), str(other), "--max-position-error", "1.0")
    tight = run_twin("analyze", "compare", str(twin_bag), str(other), "--max-position-error", "1e-9")
    assert loose.returncode == 0, loose.stderr
    assert tight.returncode == 1, tight.stderr
    assert result.max_position_error_m > 1e-9


def test_replayed_commands_match_the_bags_at_their_sim_times(
    kinematic_replay: tuple[dict, Path], gazebo_bag: Path
) -> None:
    _, out = kinematic_replay
    result = compare_bags(gazebo_bag, out / "bag", topics=("/odom", "/ground_truth/odom"))
    cmd = {f["field"]: f for f in result.fields if f["topic"] == "/cmd_vel"}
    # Held commands on one sim clock: equal but within the 5 ms the loop may apply them late.
    assert cmd["linear.x"]["rms_diff"] < 1e-3
    assert cmd["angular.z"]["rms_diff"] < 1e-3


def test_replay_bag_holds_the_commands_as_sent(kinematic_replay: tuple[dict, Path], gazebo_bag: Path) -> None:
    _, out = kinematic_replay
    sent = [(m.msg.linear.x, m.msg.angular.z) for m in read_messages(gazebo_bag, ["/cmd_vel"])]
    replayed = [(m.msg.linear.x, m.msg.angular.z) for m in read_messages(out / "bag", ["/cmd_vel"])]
    assert replayed == sent  # each once, in order: not a resample at the loop's rate


def test_a_waffle_pi_bag_without_its_model_runs_on_the_waffles_wheels(gazebo_bag: Path) -> None:
    chosen = robot_from_bag(gazebo_bag, [])  # the project has no Waffle Pi; the Waffle has its wheels
    assert chosen.model == "turtlebot3_waffle"
    assert "turtlebot3_waffle_pi" in chosen.reason and "wheel_left_joint" in chosen.reason


def test_a_robot_no_model_matches_is_refused_naming_the_urdf_and_robot_option() -> None:
    urdf = (
        '<robot name="rover4"><link name="base"/>'
        '<link name="l"><collision><geometry><cylinder radius="0.1" length="0.05"/></geometry></collision></link>'
        '<link name="r"><collision><geometry><cylinder radius="0.1" length="0.05"/></geometry></collision></link>'
        '<joint name="left_wheel" type="continuous"><parent link="base"/><child link="l"/>'
        '<origin xyz="0 0.3 0"/></joint>'
        '<joint name="right_wheel" type="continuous"><parent link="base"/><child link="r"/>'
        '<origin xyz="0 -0.3 0"/></joint></robot>'
    )
    with pytest.raises(ConfigError) as err:
        robot_from_urdf(urdf, [], where="some_bag")
    line = str(err.value)
    assert "\n" not in line and "some_bag" in line and "'rover4'" in line and "0.6 m" in line
    assert "--robot" in line and "--model-path" in line


def test_replay_of_a_bag_without_robot_description_asks_for_robot(
    fixtures: Path, twin_bag: Path, tmp_path: Path
) -> None:
    bag = _copy_topics(twin_bag, tmp_path / "no_urdf", ["/odom", "/clock", "/cmd_vel"])
    proc = run_twin(
        "replay",
        str(bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "turtlebot3_world.world"),
        "--model-path",
        str(fixtures / "gazebo_classic" / "models"),
        "--out",
        str(tmp_path / "out"),
    )
    line = _one_line_error(proc, code=2)
    assert "/robot_description" in line and "--robot" in line and str(bag) in line


def test_commands_recorded_before_the_first_pose_are_not_replayed(gazebo_bag: Path, tmp_path: Path) -> None:
    # As the ros2_walker bag: a command sent before Gazebo's diff drive ran (no pose yet) reached no one.
    topics = ["/odom", "/clock", "/cmd_vel"]
    info = open_bag(gazebo_bag)
    first_odom = next(iter(read_messages(gazebo_bag, ["/odom"], decode=False))).t_ns
    moving = next(m for m in read_messages(gazebo_bag, ["/cmd_vel"]) if m.msg.linear.x > 0.1)
    raw = next(m.msg for m in read_messages(gazebo_bag, ["/cmd_vel"], decode=False) if m.t_ns == moving.t_ns)
    bag = tmp_path / "early_command"
    with Recorder(bag) as rec:
        handles = {t: rec.add_topic(t, info.topic(t).msgtype) for t in topics}
        rec.write(handles["/cmd_vel"], first_odom - 300_000_000, raw)
        for m in read_messages(gazebo_bag, topics, decode=False):
            rec.write(handles[m.topic], m.t_ns, m.msg)
    spec = ReplayMission(bag=bag, pose_topic="/odom")
    plain = load_commands(ReplayMission(bag=gazebo_bag, pose_topic="/odom"))
    early = load_commands(spec)
    assert (early.t_ns >= 0).all()
    assert early.t_ns.tolist() == plain.t_ns.tolist()
    assert early.v_mps.tolist() == plain.v_mps.tolist()


@pytest.fixture(scope="module")
def burger_bag(fixtures: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Burger driven by a short cmd_vel script in Gazebo's empty world (no public Burger bag here)."""
    tmp = tmp_path_factory.mktemp("burger")
    scenario = tmp / "burger.yaml"
    scenario.write_text(
        "name: burger_script\n"
        f"world: {{sdf: {fixtures}/gazebo_classic/worlds/empty_world.world, "
        f"model_path: [{fixtures}/gazebo_classic/models]}}\n"
        "robot: {model: turtlebot3_burger}\n"
        "drive: {type: kinematic}\n"
        "localization: {type: none}\n"
        "mission:\n"
        "  type: cmd_vel_script\n"
        "  segments:\n"
        "    - {duration_s: 6, linear_mps: 0.1}\n"
        "    - {duration_s: 4, angular_radps: 0.5}\n"
        "    - {duration_s: 8, linear_mps: 0.06, angular_radps: -0.3}\n"
        "    - {duration_s: 6, linear_mps: 0.08, angular_radps: 0.4}\n"
        "    - {duration_s: 4}\n"
    )
    proc = run_twin("simulate", str(scenario), "--out", str(tmp / "bag"))
    assert proc.returncode == 0, proc.stderr
    return tmp / "bag"


@pytest.mark.parametrize("drive", ["kinematic", "fmu"])
def test_a_burger_bag_replays_as_a_burger_with_its_own_motors(
    fixtures: Path, burger_bag: Path, tmp_path: Path, drive: str
) -> None:
    proc = run_twin(
        "replay",
        str(burger_bag),
        "--world",
        str(fixtures / "gazebo_classic" / "worlds" / "empty_world.world"),
        "--drive",
        drive,
        "--out",
        str(tmp_path / "out"),
        "--json",
        "-v",
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["robot"] == "turtlebot3_burger"  # no --robot, no --model-path: the bag's URDF says so
    src = _odom(burger_bag, "/ground_truth/odom")
    twin = _odom(tmp_path / "out" / "bag", "/ground_truth/odom")
    assert _error_at(src, twin, 25.0) <= 0.010
    if drive == "fmu":  # the Burger's XL430 servos, as `simulate` runs them (fmu: auto), not the Waffle's XM430
        assert "xl430_w250_servo" in proc.stderr and "xm430" not in proc.stderr


def _stamped_copy(gazebo_bag: Path, bag: Path, stamp: Callable[[int], int], topics: list[str]) -> Path:
    """The bag's /odom (and `topics`) with its /cmd_vel as TwistStamped stamped `stamp(record time)`."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    Header, Stamped, Time = (
        store.types[n] for n in ("std_msgs/msg/Header", "geometry_msgs/msg/TwistStamped", "builtin_interfaces/msg/Time")
    )
    info = open_bag(gazebo_bag)
    with Recorder(bag) as rec:
        handles = {t: rec.add_topic(t, info.topic(t).msgtype) for t in topics}
        cmd = rec.add_topic("/cmd_vel", "geometry_msgs/msg/TwistStamped")
        for m in read_messages(gazebo_bag, topics, decode=False):
            rec.write(handles[m.topic], m.t_ns, m.msg)
        for m in read_messages(gazebo_bag, ["/cmd_vel"]):
            ns = stamp(m.t_ns)
            header = Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="base_link")
            rec.write(cmd, m.t_ns, store.serialize_cdr(Stamped(header=header, twist=m.msg), Stamped.__msgtype__))
    return bag


@pytest.mark.parametrize(
    ("name", "stamp"),
    [("zero", lambda t: 0), ("wall_clock", lambda t: t)],  # the bag's record times: the wall clock
)
def test_stamped_commands_off_the_poses_clock_replay_at_their_record_times_and_say_so(
    gazebo_bag: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, name: str, stamp: Callable[[int], int]
) -> None:
    # A TwistStamped /cmd_vel stamped 0 (never set) or on the wall clock in a sim-time bag: every
    # command fell before the first pose or after the last, and the replay drove nothing, silently.
    bag = _stamped_copy(gazebo_bag, tmp_path / name, stamp, ["/odom", "/clock"])
    plain = load_commands(ReplayMission(bag=gazebo_bag, pose_topic="/odom"))
    with caplog.at_level("WARNING", logger="twin.sim.replay"):
        stamped = load_commands(ReplayMission(bag=bag, pose_topic="/odom"))
    assert stamped.time_source == "record times mapped through /clock"
    assert stamped.t_ns.tolist() == plain.t_ns.tolist() and stamped.v_mps.tolist() == plain.v_mps.tolist()
    (line,) = [r.getMessage() for r in caplog.records]
    assert "the header stamps of /cmd_vel are not on the clock of the poses on /odom" in line


def test_commands_no_clock_puts_among_the_poses_are_one_line(gazebo_bag: Path, tmp_path: Path) -> None:
    # stamps never set and no /clock to map the record (wall) times onto the poses' sim time
    bag = _stamped_copy(gazebo_bag, tmp_path / "lost", lambda t: 0, ["/odom"])
    with pytest.raises(BagError, match=r"no command on /cmd_vel falls within the poses on /odom .* clocks disagree"):
        load_commands(ReplayMission(bag=bag, pose_topic="/odom"))


def test_a_twin_bag_replays_with_the_drive_its_provenance_records(twin_bag: Path, tmp_path: Path) -> None:
    # The default mission's bag records its FMU drive: replayed with it, the run is the same run.
    house = Path(__file__).resolve().parents[3] / "sdf" / "worlds" / "house.sdf"
    proc = run_twin("replay", str(twin_bag), "--world", str(house), "--out", str(tmp_path / "out"), "--json")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["drive"] == "fmu" and result["drive_from"] == "the bag's provenance"
    assert result["position_error_max_m"] < 1e-6
    ideal = run_twin(
        "replay", str(twin_bag), "--world", str(house), "--out", str(tmp_path / "k"), "--drive", "kinematic"
    )
    assert ideal.returncode == 0 and "(kinematic drive)" in ideal.stdout, ideal.stderr
