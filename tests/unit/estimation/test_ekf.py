from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from tests.unit.estimation.drive import WHEEL_RADIUS_M, WHEEL_SEPARATION_M
from tests.unit.estimation.drive import feed_perfect_wheels as drive
from tests.unit.estimation.drive import make_filter as make
from twin.core.config import load_config
from twin.core.errors import ConfigError, EstimationError
from twin.estimation import EstimationSection, OdometryFilter
from twin.estimation.config import MeasurementNoise, ProcessNoise
from twin.estimation.ekf import UNOBSERVED_VARIANCE, SolvedEkf, chi2_3_quantile

R, B = WHEEL_RADIUS_M, WHEEL_SEPARATION_M
DT_NS = 33_333_333

pytestmark = pytest.mark.usefixtures("ekf_backend")


def test_the_solved_joseph_update_equals_the_textbook_kalman_update() -> None:
    rng = np.random.default_rng(1)
    a = rng.standard_normal((8, 8))
    p = a @ a.T + 8 * np.eye(8)
    x = rng.standard_normal(8)
    h = rng.standard_normal((3, 8))
    r = np.diag([0.1, 0.2, 0.3])
    z = rng.standard_normal(3)
    ekf = SolvedEkf(x, p, wheel_radius_m=R, wheel_separation_m=B)
    assert ekf.update_linear(z, h, r)
    k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
    assert np.allclose(ekf.x, x + k @ (z - h @ x))
    assert np.allclose(ekf.P, (np.eye(8) - k @ h) @ p)
    # filterpy's own interface reaches the same update.
    other = SolvedEkf(x, p, wheel_radius_m=R, wheel_separation_m=B)
    other.update(z, lambda _s: h, lambda s: h @ s, R=r)
    assert np.allclose(other.x, ekf.x) and np.allclose(other.P, ekf.P)


def test_the_covariance_stays_symmetric_positive_definite_over_a_long_noisy_run() -> None:
    odom = make()
    rng = np.random.default_rng(3)
    left = right = 0.0
    for k in range(1, 3000):
        t = k * DT_NS
        odom.add_gyro(t - 1000, float(rng.normal(0.3, 0.05)))
        left += float(rng.uniform(0.0, 0.3))
        right += float(rng.uniform(0.0, 0.3))
        odom.add_wheel_positions(t, left, right)
        p = odom.covariance
        assert np.array_equal(p, p.T)
    assert np.linalg.eigvalsh(odom.covariance).min() > 0.0


def test_a_straight_drive_is_followed_and_published_with_ros_covariances() -> None:
    odom = make(pose=(1.0, 2.0, math.pi / 2))
    drive(odom, 10.0, 0.2, 0.0)
    est = odom.estimate
    assert est.x_m == pytest.approx(1.0, abs=1e-3)
    assert est.y_m == pytest.approx(2.0 + 0.2 * 10.0, abs=2e-3)
    assert est.yaw_rad == pytest.approx(math.pi / 2, abs=1e-4)
    assert est.v_mps == pytest.approx(0.2, abs=1e-3)
    pose = est.pose_covariance.reshape(6, 6)
    twist = est.twist_covariance.reshape(6, 6)
    p = odom.covariance
    assert pose[0, 0] == p[0, 0] and pose[1, 1] == p[1, 1] and pose[5, 5] == p[2, 2] and pose[0, 5] == p[0, 2]
    assert twist[0, 0] == p[3, 3] and twist[5, 5] == p[4, 4] and twist[0, 5] == p[3, 4]
    assert [pose[i, i] for i in (2, 3, 4)] == [UNOBSERVED_VARIANCE] * 3
    assert [twist[i, i] for i in (1, 2, 3, 4)] == [UNOBSERVED_VARIANCE] * 4
    assert np.array_equal(pose, pose.T) and np.array_equal(twist, twist.T)
    # Along-track (y here) uncertainty is the wheels' odometry noise: each wheel's travel of
    # 2 m / R rad wanders by sigma² per rad, and the chassis takes the mean of the two.
    sigma = EstimationSection().process_noise.wheel_travel_std_per_sqrt_rad
    assert pose[1, 1] == pytest.approx(R**2 * sigma**2 * (2.0 / R) / 2, rel=0.1)


def test_the_gyro_bias_is_learned_at_standstill() -> None:
    odom = make()
    k = drive(odom, 5.0, 0.0, 0.0, gyro=3e-4)
    assert odom.estimate.gyro_bias_radps == pytest.approx(3e-4, abs=1e-5)
    # ...and does not turn a later straight drive.
    drive(odom, 10.0, 0.2, 0.0, gyro=3e-4, start=k)
    assert odom.estimate.yaw_rad == pytest.approx(0.0, abs=2e-4)


def test_the_gyro_owns_the_yaw_while_the_wheels_turn() -> None:
    # The wheels say the robot turns at 0.1 rad/s (one wheel slips); the gyro says it goes straight.
    fused, wheels_only = make(), make(dataclasses.replace(EstimationSection(), fuse_gyro=False))
    for odom in (fused, wheels_only):
        drive(odom, 10.0, 0.2, 0.1, gyro=0.0)
    assert fused.estimate.yaw_rad == pytest.approx(0.0, abs=1e-3)
    assert wheels_only.estimate.yaw_rad == pytest.approx(1.0, abs=1e-3)
    assert abs(fused.estimate.gyro_bias_radps) < 1e-4  # the slip did not leak into the bias


@pytest.mark.parametrize("p", [0.9, 0.95, 0.99, 0.995, 0.999, 0.9999, 0.97, 0.5])
def test_the_slip_gate_is_scipys_chi_square_quantile_to_the_bit(p: float) -> None:
    # Usual gate probabilities are answered without importing scipy; every answer must be what
    # scipy.stats.chi2(3).ppf gives, or runs would change with the gate setting's spelling.
    from scipy.stats import chi2

    assert chi2_3_quantile(p) == float(chi2(3).ppf(p))


def test_a_robot_turned_at_standstill_trips_the_slip_gate() -> None:
    odom = make()
    k = drive(odom, 2.0, 0.0, 0.0, gyro=0.0)
    assert odom.slip_detections == 0
    drive(odom, 1.0, 0.0, 0.0, gyro=0.5, start=k)  # wheels still, robot rotated by a push
    assert odom.slip_detections > 0
    assert odom.estimate.yaw_rad == pytest.approx(0.5, abs=0.05)


def test_wheel_speeds_give_the_same_odometry_as_wheel_positions() -> None:
    by_pos, by_speed = make(), make()
    left = right = 0.0
    v, w = 0.15, 0.3
    for k in range(0, 300):
        t = k * DT_NS
        by_pos.add_gyro(t, w)
        by_speed.add_gyro(t, w)
        if k:
            left += (v - w * B / 2) / R * DT_NS * 1e-9
            right += (v + w * B / 2) / R * DT_NS * 1e-9
        by_pos.add_wheel_positions(t, left, right)
        by_speed.add_wheel_speeds(t, (v - w * B / 2) / R, (v + w * B / 2) / R)
    a, b = by_pos.estimate, by_speed.estimate
    assert (b.x_m, b.y_m, b.yaw_rad) == pytest.approx((a.x_m, a.y_m, a.yaw_rad), abs=2e-3)


def test_readings_must_move_forward_in_time() -> None:
    odom = make()
    odom.add_wheel_positions(DT_NS, 0.0, 0.0)
    with pytest.raises(EstimationError, match="not after the previous one"):
        odom.add_wheel_positions(DT_NS, 0.1, 0.1)


def test_wheel_geometry_must_be_positive() -> None:
    with pytest.raises(EstimationError, match="positive"):
        OdometryFilter(EstimationSection(), wheel_radius_m=0.0, wheel_separation_m=B)


def test_the_estimation_section_loads_from_yaml_and_rejects_bad_values(tmp_path: Path) -> None:
    good = tmp_path / "e.yaml"
    good.write_text("fuse_gyro: false\nprocess_noise: {wheel_travel_std_per_sqrt_rad: 0.02}\n", encoding="utf-8")
    config = load_config(EstimationSection, good)
    assert config.fuse_gyro is False
    assert config.process_noise == ProcessNoise(wheel_travel_std_per_sqrt_rad=0.02)
    assert config.measurement_noise == MeasurementNoise()
    bad = tmp_path / "bad.yaml"
    bad.write_text("measurement_noise:\n  gyro_std_radps: 0.0\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad.yaml:2: measurement_noise: gyro_std_radps must be positive"):
        load_config(EstimationSection, bad)
    typo = tmp_path / "typo.yaml"
    typo.write_text("slip_gate_probabilty: 0.99\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="did you mean 'slip_gate_probability'"):
        load_config(EstimationSection, typo)


def test_interval_mean_gyro_samples_integrate_to_the_exact_heading() -> None:
    # A yaw rate that steps every 7 ms, sampled by a gyro that reports its mean rate over each 5 ms
    # period: the rectangle rule recovers the heading exactly; the trapezoid rule does not.
    def rate(t_ms: int) -> float:
        return 0.8 if (t_ms // 7) % 2 else -0.3

    results = {}
    for mode in ("interval_mean", "instantaneous"):
        odom = OdometryFilter(
            EstimationSection(),
            wheel_radius_m=0.033,
            wheel_separation_m=0.287,
            gyro_samples=mode,  # type: ignore[arg-type]
        )
        odom.add_wheel_positions(0, 0.0, 0.0)
        heading = 0.0
        for t_ms in range(1, 3001):
            heading += rate(t_ms - 1) * 1e-3
            if t_ms % 5 == 0:
                mean = sum(rate(k) for k in range(t_ms - 5, t_ms)) / 5.0
                odom.add_gyro(t_ms * 1_000_000, mean)
            if t_ms % 100 == 0:
                # The wheels turn too (spin in place), so the gyro owns the yaw.
                wheel = heading * 0.287 / 2 / 0.033
                odom.add_wheel_positions(t_ms * 1_000_000, -wheel, wheel)
        results[mode] = abs(odom.estimate.yaw_rad - math.remainder(heading, math.tau))
    assert results["interval_mean"] < 1e-5
    assert results["instantaneous"] > 10 * results["interval_mean"]
