"""Hypothesis-generated scenario values: `scenario check` and `simulate` agree, and neither ever fails badly.

For a value drawn for one numeric key (any float: NaN, infinities, negatives, huge, tiny), either
both commands accept the scenario and the run's bag reads back, or both refuse it with the same
exit code and one line, and `simulate` leaves no bag folder.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from tests.robustness.test_inputs import overlay
from twin.cli import main

KEYS = (
    "physics.step_s",
    "max_duration_s",
    "seed",
    "robot.initial_pose.x_m",
    "robot.initial_pose.yaw_rad",
    "sensors.clock.rate_hz",
    "sensors.ground_truth.rate_hz",
    "sensors.lidar.rate_hz",
    "sensors.lidar.samples",
    "sensors.lidar.range_min_m",
    "sensors.lidar.range_max_m",
    "sensors.lidar.noise_std_m",
    "mission.tick_rate_hz",
    "mission.controller_rate_hz",
    "mission.follower.max_linear_mps",
    "mission.planner.resolution_m",
    "drive.max_wheel_acceleration_mps2",
)

values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, 1e-9, 1e12, 0.001, 5.0, 30.0, 1000.0]),
    st.integers(min_value=-(2**40), max_value=2**40),
)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(KEYS), value=values)
def test_check_and_simulate_agree_on_any_value(
    key: str, value: float | int, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = Path(tempfile.mkdtemp(prefix="twin-gen-"))
    try:
        scenario = folder / "scenario.yaml"
        scenario.write_text(yaml.safe_dump({"name": "generated", **overlay({key: value})}))  # NaN as .nan
        check_code = main(["scenario", "check", str(scenario)])
        check_err = capsys.readouterr().err
        assert check_code in (0, 2, 3, 6), check_err
        bag = folder / "bag"
        sim_code = main(["simulate", str(scenario), "--duration", "0.3", "--watchdog-s", "60", "--out", str(bag)])
        sim_err = capsys.readouterr().err
        assert "Traceback" not in check_err + sim_err and "internal error" not in check_err + sim_err
        if check_code == 0:
            assert sim_code == 0, sim_err
            assert_bag_reads_back(bag)
        else:
            assert_one_line_error(check_err)
            assert sim_code == check_code, sim_err
            assert_one_line_error(sim_err)
            assert not bag.exists()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
