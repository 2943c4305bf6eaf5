"""Bags shared by the bag tests: the mission's full topic mix, in each storage and distro form."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from twin.bag import Recorder
from twin.bag.mission_mix import MissionMix

MIX_SECONDS = 3


class MixBag:
    """A recorded mission-mix bag and what was written into it."""

    def __init__(self, path: Path, counts: dict[str, int]) -> None:
        self.path = path
        self.counts = counts


def record_mix(path: Path, *, storage: str, distro: str, seconds: float = MIX_SECONDS) -> MixBag:
    with Recorder(path, storage=storage, distro=distro) as rec:
        mix = MissionMix(rec, particles=50, path_poses=20)
        mix.run(round(seconds * 1e9))
    return MixBag(path, dict(mix.counts))


@pytest.fixture(scope="session")
def mix_bag(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, str], MixBag]:
    """`mix_bag(storage, distro)`: a 3 s mission-mix bag, recorded once per session."""
    cache: dict[tuple[str, str], MixBag] = {}

    def get(storage: str, distro: str) -> MixBag:
        key = (storage, distro)
        if key not in cache:
            cache[key] = record_mix(
                tmp_path_factory.mktemp("mix") / f"{storage}_{distro}", storage=storage, distro=distro
            )
        return cache[key]

    return get
