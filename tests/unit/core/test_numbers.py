"""The one finite-and-bounded check every user number goes through, and the bounded input reader."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from twin.core.files import read_input
from twin.core.numbers import number_problem


@pytest.mark.parametrize(
    ("value", "key", "unit", "problem"),
    [
        (float("nan"), "x_m", None, "is NaN; give a number"),
        (float("-inf"), "yaw_rad", None, "is -inf; give a finite number"),
        (1e300, "max_duration_s", None, "1e+300 s is out of range: give at most 1e+09 s"),
        (1e300, "--duration", "s", "1e+300 s is out of range"),
        (2e9, "rate_hz", None, "2e+09 Hz is out of range"),
        (-2e7, "obstacles[0].path_xy_m[1][0]", None, "-2e+07 m is out of range"),
        (1e16, "drive.speed_loop.voltage_limit_v", None, "1e+16 is out of range: give at most 1e+15"),
        (2**63, "seed", None, "does not fit a 64-bit whole number"),
    ],
)
def test_out_of_range_numbers_say_why(value: float, key: str, unit: str | None, problem: str) -> None:
    found = number_problem(value, key, unit=unit)
    assert found is not None and problem in found


@pytest.mark.parametrize(
    ("value", "key"),
    [
        (600.0, "max_duration_s"),
        (-3.0, "yaw_rad"),
        (1e7, "x_m"),
        (2**63 - 1, "seed"),
        (True, "enabled"),
        (0.25, "xy_variance_m2"),
    ],
)
def test_numbers_within_range_pass(value: float, key: str) -> None:
    assert number_problem(value, key) is None


def test_read_input_refuses_devices_fifos_and_large_files(tmp_path: Path) -> None:
    with pytest.raises(OSError, match="not a regular file"):
        read_input(Path("/dev/zero"), max_bytes=1024)
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(OSError, match="not a regular file"):
        read_input(tmp_path / "fifo", max_bytes=1024)  # refused without opening it (an open would block)
    big = tmp_path / "big.yaml"
    big.write_bytes(b"x" * 4096)
    with pytest.raises(OSError, match="larger than"):
        read_input(big, max_bytes=1024)
    with pytest.raises(IsADirectoryError):
        read_input(tmp_path, max_bytes=1024)
    assert read_input(big, max_bytes=4096) == b"x" * 4096
