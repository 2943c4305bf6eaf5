"""The compiled EKF step against filterpy's `SolvedEkf` (the reference): the same filter on every kind of drive.

Tolerances: the slip release puts 1e4 rad² on the wheels' differential travel beside ~1e-7 rad² along
their common travel, so the update's Cholesky factor loses about eleven digits there in either
implementation, and two correct implementations that round differently (BLAS against plain loops)
agree to about 1e-11 in the covariances and 1e-9 in the state over a 120 s drive, not to the last bit.
(With the release set to 1 rad² they agree to 1e-14: the arithmetic is the same.)
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.unit.estimation.drive import (
    STEP_NS,
    WHEEL_RADIUS_M,
    WHEEL_SEPARATION_M,
    DriveRun,
    feed_perfect_wheels,
    make_filter,
    run_drive,
)
from twin.core.errors import EstimationError
from twin.core.native import find_compiler
from twin.estimation import EstimationSection, OdometryEstimate, OdometryFilter
from twin.robot.disturbances import Disturbances, SlipRegion, WheelSlip
from twin.robot.trajectory import Trajectory, default_test_drive, generate_trajectory

STATE_ATOL = 2e-9  # m, rad, m/s, rad/s
COVARIANCE_ATOL = 1e-10


def assert_same_estimate(native: OdometryEstimate, reference: OdometryEstimate) -> None:
    assert native.t_ns == reference.t_ns
    values = ("x_m", "y_m", "yaw_rad", "v_mps", "yaw_rate_radps", "gyro_bias_radps")
    assert [getattr(native, v) for v in values] == pytest.approx(
        [getattr(reference, v) for v in values], rel=0, abs=STATE_ATOL
    )
    np.testing.assert_allclose(native.pose_covariance, reference.pose_covariance, rtol=0, atol=COVARIANCE_ATOL)
    np.testing.assert_allclose(native.twist_covariance, reference.twist_covariance, rtol=0, atol=COVARIANCE_ATOL)


def assert_same_filter(native: OdometryFilter, reference: OdometryFilter) -> None:
    assert native.native and not reference.native
    np.testing.assert_allclose(native.state, reference.state, rtol=0, atol=STATE_ATOL)
    np.testing.assert_allclose(native.covariance, reference.covariance, rtol=0, atol=COVARIANCE_ATOL)
    assert native.slip_detections == reference.slip_detections
    assert_same_estimate(native.estimate, reference.estimate)


def assert_same_run(native: DriveRun, reference: DriveRun) -> None:
    assert native.native and not reference.native
    np.testing.assert_allclose(native.state, reference.state, rtol=0, atol=STATE_ATOL)
    np.testing.assert_allclose(native.covariance, reference.covariance, rtol=0, atol=COVARIANCE_ATOL)
    assert native.slip_detections == reference.slip_detections
    for a, b in zip(native.estimates, reference.estimates, strict=True):
        assert_same_estimate(a, b)


def both_runs(traj: Trajectory, **kwargs: object) -> tuple[DriveRun, DriveRun]:
    return run_drive(traj, native=True, **kwargs), run_drive(traj, native=False, **kwargs)  # type: ignore[arg-type]


def test_the_kernel_builds_wherever_a_c_compiler_is_found() -> None:
    assert make_filter().native == (find_compiler() is not None)
    assert not make_filter(native=False).native


def test_twin_no_native_selects_the_filterpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_NO_NATIVE", "1")
    assert not make_filter().native


@pytest.mark.slow
def test_default_noise_drive_gives_the_same_estimates_at_every_step(default_drive: Trajectory) -> None:
    native, reference = both_runs(default_drive, seed=4)
    assert_same_run(native, reference)


@pytest.mark.slow
@pytest.mark.parametrize(
    "slip",
    [
        WheelSlip(left_fraction=0.05),
        WheelSlip(
            regions=(
                SlipRegion.rectangle(
                    x_min_m=1.0, y_min_m=-4.5, x_max_m=3.0, y_max_m=-2.0, left_fraction=0.3, right_fraction=0.1
                ),
            )
        ),
    ],
    ids=["left_wheel_5pct", "slippery_patch"],
)
@pytest.mark.parametrize("fuse_gyro", [True, False], ids=["encoders_and_gyro", "encoders_only"])
def test_slip_drives_give_the_same_estimates(slip: WheelSlip, fuse_gyro: bool) -> None:
    traj = generate_trajectory(default_test_drive(), slip=slip)
    config = dataclasses.replace(EstimationSection(), fuse_gyro=fuse_gyro)
    native, reference = both_runs(traj, config=config, disturbances=Disturbances(wheel_slip=slip))
    assert_same_run(native, reference)


def test_standstill_bias_learning_and_a_push_through_the_gate_match() -> None:
    native, reference = make_filter(native=True), make_filter(native=False)
    for odom in (native, reference):
        k = feed_perfect_wheels(odom, 3.0, 0.0, 0.0, gyro=3e-4)  # zero-velocity updates learn the bias
        k = feed_perfect_wheels(odom, 1.0, 0.0, 0.0, gyro=0.5, start=k)  # pushed round: the gate fires
        k = feed_perfect_wheels(odom, 4.0, 0.2, 0.1, gyro=0.0, start=k)  # one wheel slips: the gyro owns the yaw
        feed_perfect_wheels(odom, 2.0, 0.1, -0.3, start=k)
    assert reference.slip_detections > 0
    assert_same_filter(native, reference)


@pytest.mark.parametrize("gate", [0.999, None], ids=["gated", "no_gate"])
def test_wheel_speed_readings_match_through_release_and_gate(gate: float | None) -> None:
    config = dataclasses.replace(EstimationSection(), slip_gate_probability=gate)
    native, reference = make_filter(config, native=True), make_filter(config, native=False)
    r, b = WHEEL_RADIUS_M, WHEEL_SEPARATION_M
    for odom in (native, reference):
        rng = np.random.default_rng(7)
        odom.add_wheel_speeds(0, 0.0, 0.0)
        for k in range(1, 600):
            t = k * STEP_NS
            v, w = (0.0, 0.0) if k < 90 else (0.15, 0.3 if k < 400 else 0.0)
            gyro = 0.4 if 60 <= k < 75 else w  # pushed round at standstill, then driving
            for j in range(6, 0, -1):
                odom.add_gyro(t - j * 5_000_000 + 1, gyro + float(rng.normal(0.0, 2e-4)))
            slip = 0.02 if k >= 400 else 0.0  # a slipping left wheel on the straight
            odom.add_wheel_speeds(t, (v - w * b / 2) / r * (1.0 + slip), (v + w * b / 2) / r)
    assert (reference.slip_detections > 0) == (gate is not None)
    assert_same_filter(native, reference)


def test_a_native_estimate_owns_its_covariances() -> None:
    odom = make_filter(native=True)
    feed_perfect_wheels(odom, 1.0, 0.2, 0.1)
    first = odom.estimate
    held = first.pose_covariance.copy(), first.twist_covariance.copy()
    feed_perfect_wheels(odom, 1.0, 0.2, 0.1, start=30)
    assert odom.estimate.pose_covariance is not first.pose_covariance
    assert np.array_equal(first.pose_covariance, held[0]) and np.array_equal(first.twist_covariance, held[1])
    assert not np.array_equal(odom.estimate.pose_covariance, held[0])


@pytest.mark.parametrize("native", [True, False], ids=["native", "filterpy"])
def test_a_reading_that_is_not_a_number_is_refused_and_a_bad_gyro_sample_dropped(native: bool) -> None:
    odom = make_filter(native=native)
    k = feed_perfect_wheels(odom, 1.0, 0.1, 0.0)
    before = odom.state
    with pytest.raises(EstimationError, match=r"wheel reading at t=\d+ ns is not a finite number: left nan"):
        odom.add_wheel_positions((k + 1) * STEP_NS, math.nan, 0.1)
    assert np.array_equal(odom.state, before)
    odom.add_gyro((k + 1) * STEP_NS - 1000, math.inf)
    feed_perfect_wheels(odom, 1.0, 0.1, 0.0, start=k)
    assert np.isfinite(odom.state).all()
    assert odom.estimate.x_m == pytest.approx(0.2, abs=1e-3)
