"""The derived-artefact cache: an entry is reused for the same inputs, never for changed ones, and rebuilt when broken."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.core.cache import cache_key, cached_arrays, entry_path


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "cache"))


class _Builder:
    def __init__(self, value: float) -> None:
        self.value = value
        self.calls = 0

    def __call__(self) -> dict[str, np.ndarray]:
        self.calls += 1
        return {"grid": np.full((3, 4), self.value, dtype=np.int8), "origin": np.array([0.5, -1.0])}


def test_the_second_call_with_the_same_inputs_reads_the_entry_instead_of_building() -> None:
    build = _Builder(7)
    first = cached_arrays("grid", 1, (b"world", np.arange(5.0), 0.05), build)
    second = cached_arrays("grid", 1, (b"world", np.arange(5.0), 0.05), build)
    assert build.calls == 1
    assert second["grid"].dtype == np.int8 and np.array_equal(first["grid"], second["grid"])
    assert np.array_equal(second["origin"], [0.5, -1.0])


@pytest.mark.parametrize(
    "changed",
    [
        (b"world!", np.arange(5.0), 0.05),  # other file bytes
        (b"world", np.arange(5.0) + 1e-9, 0.05),  # other array values
        (b"world", np.arange(5.0).astype(np.float32), 0.05),  # same values, another dtype
        (b"world", np.arange(5.0).reshape(5, 1), 0.05),  # same bytes, another shape
        (b"world", np.arange(5.0), 0.1),  # another parameter
        (b"worl", b"d" + np.arange(5.0).tobytes(), 0.05),  # the same bytes split elsewhere
    ],
)
def test_any_changed_input_builds_a_new_entry(changed: tuple[object, ...]) -> None:
    old = _Builder(1)
    cached_arrays("grid", 1, (b"world", np.arange(5.0), 0.05), old)
    new = _Builder(2)
    out = cached_arrays("grid", 1, changed, new)  # type: ignore[arg-type]
    assert new.calls == 1 and int(out["grid"][0, 0]) == 2


def test_a_new_format_version_or_kind_never_reads_an_old_entry() -> None:
    parts = (b"same",)
    assert cache_key("grid", 1, parts) != cache_key("grid", 2, parts)
    assert cache_key("grid", 1, parts) != cache_key("field", 1, parts)


@pytest.mark.parametrize("garbage", [b"", b"PK\x03\x04 cut short", b"not a zip at all"])
def test_a_corrupt_entry_is_built_again_and_replaced(garbage: bytes) -> None:
    parts = (b"world",)
    cached_arrays("grid", 1, parts, _Builder(3))
    path = entry_path("grid", cache_key("grid", 1, parts))
    path.write_bytes(garbage)
    again = _Builder(3)
    out = cached_arrays("grid", 1, parts, again)
    assert again.calls == 1 and int(out["grid"][0, 0]) == 3
    assert path.stat().st_size > len(garbage)  # replaced by a good entry
    reread = _Builder(9)
    assert int(cached_arrays("grid", 1, parts, reread)["grid"][0, 0]) == 3 and reread.calls == 0


def test_an_unwritable_cache_folder_only_costs_building_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setenv("TWIN_CACHE_DIR", str(blocker))
    build = _Builder(4)
    for _ in range(2):
        assert int(cached_arrays("grid", 1, (b"x",), build)["grid"][0, 0]) == 4
    assert build.calls == 2


def test_a_failing_build_stores_nothing() -> None:
    def fail() -> dict[str, np.ndarray]:
        raise ValueError("free point on a wall")

    with pytest.raises(ValueError, match="free point"):
        cached_arrays("grid", 1, (b"x",), fail)
    assert not entry_path("grid", cache_key("grid", 1, (b"x",))).exists()
