"""Bags for the analysis tests: the real Gazebo bag, and short twin runs in both storages."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import run_twin


@pytest.fixture(scope="session")
def gazebo_bag(fixtures: Path) -> Path:
    return fixtures / "bags" / "tb3_waffle_gazebo_humble"


def _simulate(out: Path, *args: str) -> Path:
    proc = run_twin("simulate", "--duration", "20", "--out", str(out), *args)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="session")
def twin_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """20 s of the default mission (MCAP)."""
    return _simulate(tmp_path_factory.mktemp("twin") / "run")


@pytest.fixture(scope="session")
def twin_bag_sqlite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """20 s of the default mission (sqlite3)."""
    return _simulate(tmp_path_factory.mktemp("twin_sqlite") / "run", "--storage", "sqlite3")
