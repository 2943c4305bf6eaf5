"""A Model Exchange FMU as the robot's drive: swapped in by the scenario alone, stepped by CVode."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from tests.conftest import run_twin
from tests.unit.cosim.helpers import model_exchange
from twin.cosim.build import FmiVersion


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_model_exchange_fmu_drives_a_short_simulation(tmp_path: Path, fmi_version: FmiVersion) -> None:
    scenario = tmp_path / "me.yaml"
    scenario.write_text(
        f"name: model_exchange\ndrive:\n  type: fmu\n  fmu_file: {model_exchange(fmi_version=fmi_version)}\n  profile: velocity-servo\n"
    )
    bag = tmp_path / "bag"
    result = run_twin("simulate", str(scenario), "--duration", "5", "--out", str(bag))
    assert result.returncode == 0, result.stderr
    assert "simulated 5.0 s" in result.stdout + result.stderr
    currents: list[float] = []
    last_odom = None
    with AnyReader([bag]) as reader:
        for con, _, raw in reader.messages():
            if con.topic == "/motor_state":
                currents.extend(reader.deserialize(raw, con.msgtype).current_a)
            elif con.topic == "/ground_truth/odom":
                last_odom = reader.deserialize(raw, con.msgtype)
    assert len(currents) >= 2 * 5 * 30 - 2  # two wheels at 30 Hz
    assert max(abs(c) for c in currents) > 0.05  # the ME motors draw current while driving
    assert last_odom is not None
    assert math.hypot(last_odom.pose.pose.position.x, last_odom.pose.pose.position.y) > 0.2
