from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from twin.robot.imu import GRAVITY_MPS2, GaussianNoise, ImuModel, ImuSpec, three_axes

EXACT = three_axes(GaussianNoise(type="none"))


def make(spec: ImuSpec, seed: int = 0) -> ImuModel:
    gyro_ss, accel_ss = np.random.SeedSequence(seed).spawn(2)
    return ImuModel(spec, gyro_rng=np.random.default_rng(gyro_ss), accel_rng=np.random.default_rng(accel_ss))


def exact(**kwargs: object) -> ImuModel:
    spec = ImuSpec(angular_velocity_noise=EXACT, linear_acceleration_noise=EXACT)
    return make(dataclasses.replace(spec, **kwargs))  # type: ignore[arg-type]


def test_level_imu_at_rest_reads_gravity_up_and_no_rotation() -> None:
    r = exact().sample(0.0, 0.0, 0.0, 0.0, 0.0)
    assert (r.linear_acceleration_x, r.linear_acceleration_y, r.linear_acceleration_z) == (0.0, 0.0, GRAVITY_MPS2)
    assert (r.angular_velocity_x, r.angular_velocity_y, r.angular_velocity_z) == (0.0, 0.0, 0.0)
    assert (r.orientation_x, r.orientation_y, r.orientation_z, r.orientation_w) == (0.0, 0.0, 0.0, 1.0)


def test_orientation_is_world_referenced_not_relative_to_the_start() -> None:
    # gazebo_ros leaves initial_orientation_as_reference false (REP-145): a robot spawned at yaw 1 rad
    # reports yaw 1 rad on its first sample, not identity.
    r = exact().sample(1.0, 0.0, 0.0, 0.0, 0.0)
    assert r.orientation_z == pytest.approx(math.sin(0.5))
    assert r.orientation_w == pytest.approx(math.cos(0.5))


def test_spinning_imu_off_axis_feels_centripetal_and_tangential_acceleration() -> None:
    # TB3 Waffle: IMU 0.032 m behind the wheel axis. Spinning at w: centripetal w²·0.032 towards the
    # axis (+x); spinning up at alpha: tangential alpha·(-0.032) along y.
    imu = exact(mount_xyz_m=(-0.032, 0.0, 0.068))
    r = imu.sample(0.0, 2.0, 0.0, 0.0, 0.0)
    assert r.linear_acceleration_x == pytest.approx(4.0 * 0.032)
    assert r.linear_acceleration_y == pytest.approx(0.0)
    assert r.angular_velocity_z == 2.0
    r = imu.sample(0.0, 0.0, 5.0, 0.0, 0.0)
    assert r.linear_acceleration_y == pytest.approx(-5.0 * 0.032)


def test_chassis_accelerations_pass_through_at_the_rotation_centre() -> None:
    r = exact(mount_xyz_m=(0.0, 0.0, 0.1)).sample(0.3, 0.5, 0.0, 0.7, 0.2 * 0.5)
    assert r.linear_acceleration_x == pytest.approx(0.7)
    assert r.linear_acceleration_y == pytest.approx(0.1)


def test_mounting_rotation_expresses_readings_in_the_imu_frame() -> None:
    # IMU turned +90° about z: its x axis is the chassis y, its y axis the chassis -x.
    r = exact(mount_xyz_m=(0.0, 0.0, 0.0), mount_rpy_rad=(0.0, 0.0, math.pi / 2)).sample(0.0, 0.0, 0.0, 1.0, 0.0)
    assert r.linear_acceleration_x == pytest.approx(0.0, abs=1e-12)
    assert r.linear_acceleration_y == pytest.approx(-1.0)
    # Upside down (roll pi): gravity reads -g on z and the yaw rate flips sign.
    r = exact(mount_xyz_m=(0.0, 0.0, 0.0), mount_rpy_rad=(math.pi, 0.0, 0.0)).sample(0.0, 0.4, 0.0, 0.0, 0.0)
    assert r.linear_acceleration_z == pytest.approx(-GRAVITY_MPS2)
    assert r.angular_velocity_z == pytest.approx(-0.4)


def test_covariances_are_the_noise_variances_and_orientation_is_left_zero() -> None:
    imu = make(ImuSpec())
    assert imu.angular_velocity_covariance == pytest.approx((4e-8, 0, 0, 0, 4e-8, 0, 0, 0, 4e-8))
    assert imu.linear_acceleration_covariance == pytest.approx((2.89e-4, 0, 0, 0, 2.89e-4, 0, 0, 0, 2.89e-4))
    assert imu.orientation_covariance == (0.0,) * 9
    silent = make(ImuSpec(angular_velocity_noise=EXACT))
    assert silent.angular_velocity_covariance == (0.0,) * 9


def test_white_noise_has_the_configured_mean_and_deviation() -> None:
    spec = ImuSpec(angular_velocity_noise=three_axes(GaussianNoise(mean=1e-3, stddev=2e-4)))
    imu = make(spec)
    z = np.array([imu.sample(0.0, 0.1, 0.0, 0.0, 0.0).angular_velocity_z for _ in range(20000)])
    assert z.mean() == pytest.approx(0.1 + 1e-3, abs=5e-6)
    assert z.std() == pytest.approx(2e-4, rel=0.03)


def test_turn_on_bias_has_a_random_sign_and_the_configured_size() -> None:
    spec = ImuSpec(angular_velocity_noise=three_axes(GaussianNoise(bias_mean=1e-3)))
    biases = [make(spec, seed).gyro_bias_radps for seed in range(40)]
    values = np.array(biases).ravel()
    assert np.allclose(np.abs(values), 1e-3)
    assert 0.2 < (values > 0).mean() < 0.8
    imu = make(spec, 3)
    first = imu.sample(0.0, 0.0, 0.0, 0.0, 0.0).angular_velocity_z
    assert first == pytest.approx(imu.gyro_bias_radps[2])


def test_dynamic_bias_is_a_gauss_markov_process_as_gz_sensors_drives_it() -> None:
    # Driving density sigma, correlation time tau: stationary deviation sigma * sqrt(tau / 2) and
    # correlation exp(-lag / tau).
    sigma, tau = 2e-3, 0.5
    spec = ImuSpec(
        angular_velocity_noise=three_axes(GaussianNoise(dynamic_bias_stddev=sigma, dynamic_bias_correlation_time_s=tau))
    )
    imu = make(spec)
    b = []
    for _ in range(200 * 200):
        imu.sample(0.0, 0.0, 0.0, 0.0, 0.0)
        b.append(imu.gyro_bias_radps[2])
    bias = np.array(b)
    assert bias.std() == pytest.approx(sigma * math.sqrt(tau / 2), rel=0.15)
    lag = int(tau * 200)
    corr = np.corrcoef(bias[:-lag], bias[lag:])[0, 1]
    assert corr == pytest.approx(math.exp(-1.0), abs=0.1)


def test_each_axis_drifts_with_its_own_correlation_time_and_density() -> None:
    # Axes that drift alike are filtered together; each must still follow b' = phi b + sigma_d w with
    # its own phi and sigma_d (w standard normal), and an axis without drift must keep its bias.
    def drift(sigma: float, tau: float) -> GaussianNoise:
        return GaussianNoise(
            stddev=1e-4, bias_stddev=1e-3, dynamic_bias_stddev=sigma, dynamic_bias_correlation_time_s=tau
        )

    gyro = (drift(1e-3, 2.0), GaussianNoise(stddev=1e-4, bias_stddev=1e-3), drift(4e-3, 0.25))
    accel = (drift(1e-2, 0.5), drift(1e-2, 0.5), drift(3e-2, 0.5))
    imu = make(ImuSpec(angular_velocity_noise=gyro, linear_acceleration_noise=accel))
    rows = []
    for _ in range(4000):
        imu.sample(0.0, 0.0, 0.0, 0.0, 0.0)
        rows.append((*imu.gyro_bias_radps, *imu.accel_bias_mps2))
    biases = np.array(rows)
    dt = 1.0 / 200.0
    for axis, noise in enumerate((*gyro, *accel)):
        b = biases[:, axis]
        if not noise.drifts:
            assert np.all(b == b[0]) and b[0] != 0.0
            continue
        tau, sigma = noise.dynamic_bias_correlation_time_s, noise.dynamic_bias_stddev
        phi = math.exp(-dt / tau)
        sigma_d = sigma * math.sqrt(-0.5 * tau * math.expm1(-2.0 * dt / tau))
        w = (b[1:] - phi * b[:-1]) / sigma_d
        assert w.std() == pytest.approx(1.0, abs=0.05), axis
        assert abs(w.mean()) < 0.1, axis


def test_drift_recursion_is_bit_for_bit_scipys_first_order_filter() -> None:
    # The drift used to be `scipy.signal.lfilter`; the recursion written out must give the same
    # floats to the last bit (the same bags for a seed), over the magnitudes IMU settings reach.
    from scipy.signal import lfilter

    from twin.robot.imu import _gauss_markov

    rng = np.random.default_rng(16)
    for _ in range(300):
        columns = int(rng.integers(1, 4))
        steps = rng.standard_normal((256, columns)) * 10.0 ** rng.uniform(-3, 3)
        start = rng.standard_normal(columns) * 10.0 ** rng.uniform(-6, 1)
        dt, tau, sigma = 1.0 / 200.0, 10.0 ** rng.uniform(-2, 4), 10.0 ** rng.uniform(-8, 0)
        phi, sigma_d = math.exp(-dt / tau), sigma * math.sqrt(-0.5 * tau * math.expm1(-2.0 * dt / tau))
        expected = lfilter([sigma_d], [1.0, -phi], steps, axis=0, zi=(phi * start)[None, :])[0]
        assert _gauss_markov(steps, phi, sigma_d, start).tobytes() == expected.tobytes()


def test_quantised_noise_rounds_to_the_precision() -> None:
    spec = ImuSpec(
        linear_acceleration_noise=three_axes(GaussianNoise(type="gaussian_quantized", stddev=0.05, precision=0.01))
    )
    imu = make(spec)
    values = np.array([imu.sample(0.0, 0.0, 0.0, 0.0, 0.0).linear_acceleration_x for _ in range(200)])
    assert np.allclose(values / 0.01, np.round(values / 0.01), atol=1e-9)
    assert len(set(values.round(6))) > 3


def test_same_seeds_give_the_same_readings_and_streams_are_independent() -> None:
    a, b = make(ImuSpec(), 7), make(ImuSpec(), 7)
    ra = [a.sample(0.1 * k, 0.2, 0.0, 0.0, 0.0) for k in range(600)]
    rb = [b.sample(0.1 * k, 0.2, 0.0, 0.0, 0.0) for k in range(600)]
    assert ra == rb
    # A different gyro stream leaves the accelerometer's readings untouched.
    accel_ss = np.random.SeedSequence(7).spawn(2)[1]
    c = ImuModel(ImuSpec(), gyro_rng=np.random.default_rng(99), accel_rng=np.random.default_rng(accel_ss))
    rc = [c.sample(0.1 * k, 0.2, 0.0, 0.0, 0.0) for k in range(600)]
    assert [r.linear_acceleration_x for r in rc] == [r.linear_acceleration_x for r in ra]
    assert [r.angular_velocity_z for r in rc] != [r.angular_velocity_z for r in ra]


@pytest.mark.parametrize("field", ["stddev", "bias_stddev", "dynamic_bias_stddev", "dynamic_bias_correlation_time_s"])
def test_negative_or_infinite_noise_settings_are_rejected(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        GaussianNoise(**{field: -1.0})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=field):
        GaussianNoise(**{field: math.inf})  # type: ignore[arg-type]


def test_rate_must_be_positive() -> None:
    with pytest.raises(ValueError, match="rate_hz"):
        ImuSpec(rate_hz=0.0)
    assert make(ImuSpec()).period_ns == 5_000_000
