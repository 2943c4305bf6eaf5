"""The replay core over the Gazebo fixture bag (read with rosbags inside the test) and synthetic recordings."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from twin.core.errors import EstimationError
from twin.estimation import EstimationSection
from twin.estimation.replay import (
    PoseSeries,
    ReplayInputs,
    collect_inputs,
    compare,
    infer_velocity_units,
    replay,
)

R, B = 0.033, 0.287

pytestmark = pytest.mark.usefixtures("ekf_backend")


def run(inputs: ReplayInputs, **kwargs: object) -> tuple[float, float]:
    result = replay(inputs, EstimationSection(), wheel_radius_m=R, wheel_separation_m=B, **kwargs)  # type: ignore[arg-type]
    assert inputs.reference is not None
    c = compare(result, inputs.reference)
    return c.position_error_final_m, math.degrees(abs(c.yaw_error_final_rad))


def test_the_gazebo_bag_has_what_a_replay_needs(gazebo_inputs: ReplayInputs) -> None:
    assert len(gazebo_inputs.joint_t_ns) == 826
    assert len(gazebo_inputs.gyro_t_ns) == 5636
    assert gazebo_inputs.reference is not None and len(gazebo_inputs.reference.t_ns) == 826
    assert np.all(np.diff(gazebo_inputs.joint_t_ns) > 0)
    # Header stamps (simulation time), not the recorder's wall-clock times.
    assert gazebo_inputs.joint_t_ns[0] == 270_000_000


def test_gazebo_joint_velocities_are_recognised_as_rad_per_s(gazebo_inputs: ReplayInputs) -> None:
    decision = infer_velocity_units(gazebo_inputs, R)
    assert decision.units == "rad/s" and decision.how == "inferred"
    assert decision.ratio == pytest.approx(1.0, abs=1e-3)


def test_rim_speed_velocities_are_recognised_as_m_per_s(gazebo_inputs: ReplayInputs) -> None:
    assert gazebo_inputs.velocity_left is not None and gazebo_inputs.velocity_right is not None
    real_robot = dataclasses.replace(
        gazebo_inputs, velocity_left=gazebo_inputs.velocity_left * R, velocity_right=gazebo_inputs.velocity_right * R
    )
    decision = infer_velocity_units(real_robot, R)
    assert decision.units == "m/s" and decision.how == "inferred"
    assert "inferred" in decision.describe(R)
    no_positions = dataclasses.replace(real_robot, position_left_rad=None, position_right_rad=None)
    assert infer_velocity_units(no_positions, R).how == "assumed"


def test_fused_odometry_tracks_gazebo_ground_truth(gazebo_inputs: ReplayInputs) -> None:
    # Gazebo's /odom is ground truth (diff drive odometry_source WORLD): what the wheels and gyro give
    # must stay within millimetres and hundredths of a degree of it over the 4.8 m drive.
    pos, yaw = run(gazebo_inputs)
    assert pos < 0.01
    assert yaw < 0.1
    no_gyro = dataclasses.replace(EstimationSection(), fuse_gyro=False)
    result = replay(gazebo_inputs, no_gyro, wheel_radius_m=R, wheel_separation_m=B)
    assert gazebo_inputs.reference is not None
    wheels_yaw = math.degrees(abs(compare(result, gazebo_inputs.reference).yaw_error_final_rad))
    assert yaw < wheels_yaw / 5  # the gyro holds the heading better than the wheels


def test_velocities_in_either_unit_give_the_positions_answer(gazebo_inputs: ReplayInputs) -> None:
    from_positions = run(gazebo_inputs)
    from_rad_s = run(gazebo_inputs, wheel_source="velocities", velocity_units="rad/s")
    assert gazebo_inputs.velocity_left is not None and gazebo_inputs.velocity_right is not None
    as_rim = dataclasses.replace(
        gazebo_inputs, velocity_left=gazebo_inputs.velocity_left * R, velocity_right=gazebo_inputs.velocity_right * R
    )
    from_m_s = run(as_rim, wheel_source="velocities", velocity_units="m/s")
    assert from_rad_s == pytest.approx(from_m_s, abs=1e-9)
    assert from_rad_s[0] == pytest.approx(from_positions[0], abs=0.01)
    wrong_unit = run(as_rim, wheel_source="velocities", velocity_units="rad/s")
    assert wrong_unit[0] > 1.0  # taking m/s for rad/s stops the robot 30 times short


def test_starting_at_the_origin_gives_a_fresh_odom_frame(gazebo_inputs: ReplayInputs) -> None:
    result = replay(
        gazebo_inputs, EstimationSection(), wheel_radius_m=R, wheel_separation_m=B, start_at_reference=False
    )
    assert (result.x_m[0], result.y_m[0], result.yaw_rad[0]) == (0.0, 0.0, 0.0)
    assert result.pose_covariance.shape == (826, 36)


def test_joint_states_of_other_joints_are_named_in_the_error() -> None:
    class Msg:
        def __init__(self, names: list[str]) -> None:
            self.name, self.position, self.velocity = names, [0.0] * len(names), []
            self.header = None

    with pytest.raises(EstimationError, match=r"names joints arm_joint, left_wheel, not both .*; pass the wheel joint"):
        collect_inputs([("/joint_states", "sensor_msgs/msg/JointState", 1, Msg(["left_wheel", "arm_joint"]))])


def test_a_replay_needs_two_joint_states() -> None:
    empty = collect_inputs([])
    with pytest.raises(EstimationError, match="at least 2 joint states"):
        replay(empty, EstimationSection(), wheel_radius_m=R, wheel_separation_m=B)


def test_compare_reports_offsets_against_the_interpolated_reference() -> None:
    t = np.arange(0, 11, dtype=np.int64) * 100_000_000
    x = np.linspace(0.0, 1.0, 11)
    reference = PoseSeries(t_ns=t, x_m=x, y_m=np.zeros(11), yaw_rad=np.zeros(11))
    inputs = ReplayInputs(
        joint_t_ns=t[::2] + 50_000_000,
        position_left_rad=np.zeros(6),
        position_right_rad=np.zeros(6),
        velocity_left=None,
        velocity_right=None,
        gyro_t_ns=np.zeros(0, dtype=np.int64),
        gyro_z_radps=np.zeros(0),
        reference=reference,
    )
    result = replay(inputs, EstimationSection(), wheel_radius_m=R, wheel_separation_m=B, start_at_reference=False)
    c = compare(result, reference)
    assert c.samples == 5  # the last joint state is after the reference ends
    assert c.position_error_final_m == pytest.approx(0.85, abs=1e-6)  # the wheels did not move; the reference did
    assert c.distance_m == pytest.approx(0.8)
    assert c.final_error_percent_of_distance == pytest.approx(100 * 0.85 / 0.8)
