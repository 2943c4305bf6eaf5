"""The ROS 2 bridge's configuration: what it hands to DDS, ROS 2's names, the scenario section, bad input.

Nothing here starts DDS (tests/integration/test_ros2_bridge.py does, inside a network namespace).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.conftest import REPO, run_twin
from twin.core.errors import ConfigError
from twin.ros2 import Ros2Bridge, cyclone_config, dds_topic_name, dds_type_name
from twin.ros2.dds_types import struct_type
from twin.sim.scenario import (
    BehaviorTreeMission,
    NoMission,
    Ros2Section,
    default_scenario_path,
    for_ros2_role,
)
from twin.sim.scenario_file import load_scenario


def test_by_default_dds_is_told_loopback_alone_multicast_off_and_unicast_peers_on_127_0_0_1() -> None:
    root = ET.fromstring(cyclone_config(7))
    domain = root.find("Domain")
    assert domain is not None and domain.get("Id") == "7"
    interfaces = root.findall("./Domain/General/Interfaces/NetworkInterface")
    assert [i.get("name") for i in interfaces] == ["lo"]
    assert root.findtext("./Domain/General/AllowMulticast") == "false"
    assert [p.get("address") for p in root.findall("./Domain/Discovery/Peers/Peer")] == ["127.0.0.1"]
    # Without multicast a node started later is found by the twin's unicast announcements: every second.
    assert root.findtext("./Domain/Discovery/SPDPInterval") == "1s"


def test_another_interface_is_used_only_when_named() -> None:
    root = ET.fromstring(cyclone_config(0, "eth0"))
    assert [i.get("name") for i in root.findall("./Domain/General/Interfaces/NetworkInterface")] == ["eth0"]
    assert root.find("./Domain/Discovery/Peers") is None


def test_topics_and_types_carry_ros2_names_on_dds() -> None:
    assert dds_topic_name("/scan") == "rt/scan"
    assert dds_topic_name("/robot1/cmd_vel") == "rt/robot1/cmd_vel"
    assert dds_type_name("sensor_msgs/msg/LaserScan") == "sensor_msgs::msg::dds_::LaserScan_"


def test_a_dds_type_is_the_ros_message_laid_out_as_rosidl_generates_it() -> None:
    from twin.bag.typesys import TypeRegistry

    laser = struct_type("sensor_msgs/msg/LaserScan", TypeRegistry().store)
    assert laser.__idl_typename__ == "sensor_msgs::msg::dds_::LaserScan_"
    fields = list(laser.__annotations__)
    assert fields[0] == "header" and fields[-2:] == ["ranges", "intensities"]
    header = laser.__annotations__["header"]
    assert header.__idl_typename__ == "std_msgs::msg::dds_::Header_"


def test_the_scenario_section_is_off_by_default_and_full_role_runs_the_scenario_as_it_is() -> None:
    scenario = load_scenario(default_scenario_path())
    assert scenario.ros2 == Ros2Section()
    assert not scenario.ros2.enabled and scenario.ros2.subscribe == ("/cmd_vel", "/initialpose")
    on = dataclasses.replace(scenario, ros2=Ros2Section(enabled=True))
    assert for_ros2_role(on) is on


def test_the_simulator_role_runs_no_mission_and_no_localization_of_its_own() -> None:
    scenario = load_scenario(default_scenario_path())
    assert isinstance(scenario.mission, BehaviorTreeMission)
    sim = for_ros2_role(dataclasses.replace(scenario, ros2=Ros2Section(enabled=True, role="simulator")))
    assert isinstance(sim.mission, NoMission)
    assert sim.localization.type == "none" and sim.localization.initial_pose is None
    assert sim.world == scenario.world and sim.robot == scenario.robot and sim.drive == scenario.drive


def test_the_simulator_role_applies_to_every_robot_of_a_fleet_and_takes_each_robots_topics() -> None:
    # An external multi-robot Nav2 drives each robot on /<ns>/cmd_vel: none of the twin's own stacks may run.
    fleet = load_scenario(REPO / "scenarios" / "house_two_waffles.yaml")
    assert all(isinstance(e.mission, BehaviorTreeMission) for e in fleet.robots)
    sim = for_ros2_role(dataclasses.replace(fleet, ros2=Ros2Section(enabled=True, role="simulator")))
    assert [e.ns for e in sim.robots] == ["robot1", "robot2"]
    for entry, before in zip(sim.robots, fleet.robots, strict=True):
        assert isinstance(entry.mission, NoMission), entry.ns
        assert entry.localization.type == "none" and entry.localization.initial_pose is None
        assert entry.robot == before.robot and entry.drive == before.drive and entry.sensors == before.sensors
    each = ("/robot1/cmd_vel", "/robot1/initialpose", "/robot2/cmd_vel", "/robot2/initialpose")
    assert sim.ros2.subscribe == each
    full = for_ros2_role(dataclasses.replace(fleet, ros2=Ros2Section(enabled=True)))
    assert full.ros2.subscribe == each and full.robots == fleet.robots  # full: the fleet's own stacks run
    chosen = Ros2Section(enabled=True, subscribe=("/robot2/cmd_vel",))
    assert for_ros2_role(dataclasses.replace(fleet, ros2=chosen)).ros2.subscribe == ("/robot2/cmd_vel",)


@pytest.mark.parametrize(
    ("section", "expected"),
    [
        ("{role: gazebo}", "ros2.role: 'gazebo' is not allowed"),
        ("{domain_id: 233}", "domain_id must be a whole number from 0 to 232, got 233"),
        ("{domain_id: -1}", "domain_id must be a whole number from 0 to 232, got -1"),
        ("{subscribe: [cmd_vel]}", "subscribe: 'cmd_vel' is not an absolute ROS 2 topic name"),
        ("{publish: [/scan/]}", "publish: '/scan/' is not an absolute ROS 2 topic name"),
        ("{publish: [/9scan]}", "publish: '/9scan' is not an absolute ROS 2 topic name"),
        ("{domian_id: 3}", "ros2.domian_id: unknown key; did you mean 'domain_id'?"),
    ],
)
def test_a_bad_ros2_section_is_one_line_naming_file_and_key_exit_2(tmp_path: Path, section: str, expected: str) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"ros2: {section}\n")
    result = run_twin("scenario", "check", str(path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and expected in lines[0], result.stderr


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--ros2", "--domain-id", "233"], "--domain-id: domain_id must be a whole number from 0 to 232, got 233"),
        (["--domain-id", "3"], "--domain-id: configures the ROS 2 bridge; add --ros2"),
        (["--ros2", "--ros2-role", "gazebo"], "invalid choice: 'gazebo'"),
    ],
)
def test_bad_ros2_options_are_one_line_exit_2_and_leave_no_bag(tmp_path: Path, args: list[str], expected: str) -> None:
    out = tmp_path / "bag"
    result = run_twin("simulate", "--duration", "1", "--out", str(out), *args)
    assert result.returncode == 2
    assert expected in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert not out.exists()


def test_without_the_binding_ros2_is_one_line_naming_the_package_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # `import cyclonedds...` raises ImportError, for the package and every module of it already imported.
    for name in [m for m in sys.modules if m == "cyclonedds" or m.startswith("cyclonedds.")] + ["cyclonedds"]:
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(ConfigError, match=r"pip install cyclonedds"):
        Ros2Bridge(Ros2Section(enabled=True))
    from twin.cli import main

    out = tmp_path / "bag"
    capsys.readouterr()
    assert main(["simulate", "--ros2", "--duration", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install cyclonedds" in err[0], err
    assert not out.exists()


def test_a_run_without_ros2_never_loads_dds() -> None:
    code = (
        "import sys, twin.ros2, twin.cli.simulate, twin.sim.simulation\n"
        "assert not [m for m in sys.modules if m.startswith('cyclonedds')], sorted(sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False, cwd=REPO)
    assert result.returncode == 0, result.stderr
