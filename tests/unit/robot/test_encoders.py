from __future__ import annotations

import math

import numpy as np
import pytest

from twin.robot.encoders import EncoderModel, EncoderNoise, EncoderSpec

TICK = 2 * math.pi / 4096
EXACT = EncoderNoise(travel_std_per_sqrt_rad=0.0)
PERIOD_NS = 33_333_333


def test_positions_are_whole_ticks_within_half_a_tick_of_the_truth() -> None:
    enc = EncoderModel(EncoderSpec(), EXACT, np.random.default_rng(0))
    for k, angle in enumerate(np.linspace(-7.0, 11.0, 97)):
        js = enc.read(k * PERIOD_NS, float(angle), float(-angle))
        assert js.position_left_rad / TICK == pytest.approx(round(js.position_left_rad / TICK), abs=1e-9)
        assert abs(js.position_left_rad - angle) <= TICK / 2 + 1e-12
        assert abs(js.position_right_rad + angle) <= TICK / 2 + 1e-12


def test_velocity_is_the_tick_change_over_the_interval() -> None:
    enc = EncoderModel(EncoderSpec(), EXACT, np.random.default_rng(0))
    first = enc.read(0, 0.0, 0.0)
    assert (first.velocity_left, first.velocity_right) == (0.0, 0.0)
    js = enc.read(PERIOD_NS, 6.0 * PERIOD_NS * 1e-9, -3.0 * PERIOD_NS * 1e-9)
    ticks_left = round(6.0 * PERIOD_NS * 1e-9 / TICK)
    assert js.velocity_left == pytest.approx(ticks_left * TICK / (PERIOD_NS * 1e-9))
    assert js.velocity_left == pytest.approx(6.0, abs=TICK / (PERIOD_NS * 1e-9))
    assert js.velocity_right == pytest.approx(-3.0, abs=TICK / (PERIOD_NS * 1e-9))


def test_rim_speed_units_scale_by_the_wheel_radius() -> None:
    rad = EncoderModel(EncoderSpec(), EXACT, np.random.default_rng(0))
    rim = EncoderModel(EncoderSpec(velocity_units="m/s", wheel_radius_m=0.033), EXACT, np.random.default_rng(0))
    for enc in (rad, rim):
        enc.read(0, 0.0, 0.0)
    a = rad.read(PERIOD_NS, 0.2, 0.1)
    b = rim.read(PERIOD_NS, 0.2, 0.1)
    assert b.velocity_left == pytest.approx(a.velocity_left * 0.033)
    assert b.position_left_rad == a.position_left_rad  # positions stay radians


def test_odometry_noise_grows_with_travel_and_is_zero_at_standstill() -> None:
    sigma = 0.01
    drifts = []
    for seed in range(200):
        enc = EncoderModel(EncoderSpec(), EncoderNoise(travel_std_per_sqrt_rad=sigma), np.random.default_rng(seed))
        for k in range(101):  # 100 rad of travel on the left wheel, the right one held still
            enc.read(k * PERIOD_NS, k * 1.0, 0.0)
        drifts.append(enc.drift_rad)
    d = np.array(drifts)
    assert d[:, 0].std() == pytest.approx(sigma * math.sqrt(100.0), rel=0.15)
    assert np.all(d[:, 1] == 0.0)


def test_a_still_wheel_reads_the_same_tick_every_time() -> None:
    enc = EncoderModel(EncoderSpec(), EncoderNoise(travel_std_per_sqrt_rad=0.05), np.random.default_rng(1))
    readings = {enc.read(k * PERIOD_NS, 1.2345, -0.5).position_left_rad for k in range(50)}
    assert len(readings) == 1


def test_tick_jitter_spreads_readings_by_the_configured_ticks() -> None:
    enc = EncoderModel(
        EncoderSpec(), EncoderNoise(travel_std_per_sqrt_rad=0.0, tick_noise_std=2.0), np.random.default_rng(2)
    )
    ticks = np.array([enc.ticks(100.5 * TICK, 0.0)[0] for _ in range(4000)])
    assert ticks.std() == pytest.approx(math.sqrt(4.0 + 1.0 / 12.0), rel=0.08)
    assert ticks.mean() == pytest.approx(100.5, abs=0.15)


def test_same_seed_same_readings() -> None:
    def run(seed: int) -> list[tuple[float, ...]]:
        enc = EncoderModel(EncoderSpec(), EncoderNoise(tick_noise_std=0.5), np.random.default_rng(seed))
        return [tuple(enc.read(k * PERIOD_NS, 0.2 * k, 0.21 * k)) for k in range(300)]

    assert run(4) == run(4)
    assert run(4) != run(5)


def test_invalid_settings_are_rejected() -> None:
    with pytest.raises(ValueError, match="ticks_per_rev"):
        EncoderSpec(ticks_per_rev=0)
    with pytest.raises(ValueError, match="rate_hz"):
        EncoderSpec(rate_hz=-30.0)
    with pytest.raises(ValueError, match="travel_std_per_sqrt_rad"):
        EncoderNoise(travel_std_per_sqrt_rad=-0.1)
