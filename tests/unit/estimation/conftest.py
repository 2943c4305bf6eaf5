"""Fixtures for the estimation tests: the filter's two implementations, the Gazebo fixture bag (read with rosbags,
test-only), and a bag API."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from twin.estimation.replay import ReplayInputs, collect_inputs
from twin.robot.trajectory import Trajectory, default_test_drive, generate_trajectory


@pytest.fixture(params=["native", "filterpy"])
def ekf_backend(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run the test once with the compiled kernel (when it builds) and once with filterpy alone (`TWIN_NO_NATIVE`)."""
    if request.param == "filterpy":
        monkeypatch.setenv("TWIN_NO_NATIVE", "1")
    else:
        monkeypatch.delenv("TWIN_NO_NATIVE", raising=False)
    return str(request.param)


@pytest.fixture(scope="session")
def gazebo_bag(fixtures: Path) -> Path:
    return fixtures / "bags" / "tb3_waffle_gazebo_humble"


def read_with_rosbags(bag: Path, topics: tuple[str, ...]) -> Iterator[tuple[str, str, int, Any]]:
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        for conn, t_ns, raw in reader.messages(connections=conns):
            yield conn.topic, conn.msgtype, t_ns, reader.deserialize(raw, conn.msgtype)


@pytest.fixture(scope="session")
def gazebo_inputs(gazebo_bag: Path) -> ReplayInputs:
    return collect_inputs(read_with_rosbags(gazebo_bag, ("/imu", "/joint_states", "/odom")))


@pytest.fixture(scope="session")
def default_drive() -> Trajectory:
    return generate_trajectory(default_test_drive())


@pytest.fixture
def bag_module() -> ModuleType:
    """The bag package the replay reads and writes through."""
    import twin.bag

    return twin.bag
