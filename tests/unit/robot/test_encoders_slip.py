"""Wheel slip and the `disturbances:` section (twin.robot.disturbances): what makes the encoders lie."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.core.config import load_config
from twin.core.errors import ConfigError
from twin.robot.disturbances import DEFAULT_GYRO_NOISE, Disturbances, ImuDisturbances, SlipRegion, WheelSlip
from twin.robot.imu import GaussianNoise, ImuSpec


def test_slip_regions_override_the_global_fractions_inside_their_polygon() -> None:
    triangle = SlipRegion(polygon_xy_m=((0.0, 0.0), (2.0, 0.0), (0.0, 2.0)), left_fraction=0.3, right_fraction=0.1)
    slip = WheelSlip(left_fraction=0.05, regions=(triangle,))
    assert slip.fractions_at(0.5, 0.5) == (0.3, 0.1)
    assert slip.fractions_at(1.5, 1.5) == (0.05, 0.0)  # beyond the hypotenuse
    assert slip.fractions_at(-0.1, 0.5) == (0.05, 0.0)
    assert not slip.is_uniform and WheelSlip().is_uniform


def test_the_first_matching_region_wins_and_rectangles_are_polygons() -> None:
    a = SlipRegion.rectangle(x_min_m=0, y_min_m=0, x_max_m=2, y_max_m=2, left_fraction=0.2, right_fraction=0.2)
    b = SlipRegion.rectangle(x_min_m=1, y_min_m=1, x_max_m=3, y_max_m=3, left_fraction=0.5, right_fraction=0.5)
    slip = WheelSlip(regions=(a, b))
    assert slip.fractions_at(1.5, 1.5) == (0.2, 0.2)
    assert slip.fractions_at(2.5, 2.5) == (0.5, 0.5)


@pytest.mark.parametrize("value", [-0.1, 1.0, 1.5])
def test_slip_fractions_must_be_in_zero_to_one(value: float) -> None:
    with pytest.raises(ValueError, match="left_fraction"):
        WheelSlip(left_fraction=value)


def test_a_region_needs_three_vertices() -> None:
    with pytest.raises(ValueError, match="3 vertices"):
        SlipRegion(polygon_xy_m=((0.0, 0.0), (1.0, 1.0)))


def test_imu_disturbances_replace_the_sdf_noise_on_all_axes_or_keep_it() -> None:
    spec = Disturbances().imu.apply(ImuSpec())
    assert spec.angular_velocity_noise == (DEFAULT_GYRO_NOISE,) * 3
    assert spec.linear_acceleration_noise == ImuSpec().linear_acceleration_noise
    kept = ImuDisturbances(gyro=None).apply(ImuSpec())
    assert kept.angular_velocity_noise == ImuSpec().angular_velocity_noise


def test_disturbances_load_from_yaml_with_regions(tmp_path: Path) -> None:
    path = tmp_path / "d.yaml"
    path.write_text(
        "wheel_slip:\n"
        "  regions:\n"
        "    - polygon_xy_m: [[1.0, -4.5], [3.0, -4.5], [3.0, -2.0], [1.0, -2.0]]\n"
        "      left_fraction: 0.3\n"
        "encoders: {travel_std_per_sqrt_rad: 0.01}\n"
        "imu:\n"
        "  gyro: {stddev: 1.0e-3, bias_stddev: 0.0}\n",
        encoding="utf-8",
    )
    d = load_config(Disturbances, path)
    assert d.wheel_slip.fractions_at(2.0, -3.0) == (0.3, 0.0)
    assert d.encoders.travel_std_per_sqrt_rad == 0.01
    assert d.imu.gyro == GaussianNoise(stddev=1.0e-3)


def test_a_misspelt_key_names_file_line_and_the_fix(tmp_path: Path) -> None:
    path = tmp_path / "d.yaml"
    path.write_text("encoders:\n  travel_std_per_sqrt_rads: 0.01\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"d.yaml:2: encoders.travel_std_per_sqrt_rads: unknown key; did you mean"):
        load_config(Disturbances, path)
