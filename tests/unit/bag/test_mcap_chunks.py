"""MCAP chunks from the compiled kernel and from numpy: the same bytes, and what readers read back."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.bag._native import load_chunk_kernel
from twin.bag.mcap_file import McapWriter, scan_mcap

CHANNELS = 6
message = st.tuples(
    st.integers(1, CHANNELS),
    st.integers(0, 3_000_000_000),
    st.binary(max_size=40).map(lambda b: b"\x00\x01\x00\x00" + b),
)
batches = st.lists(st.lists(message, min_size=1, max_size=60), min_size=1, max_size=4)


def _write(path: Path, batches: list[list[tuple[int, int, bytes]]], *, native: bool, crc: bool) -> bytes:
    writer = McapWriter(path, library="test", native=native, chunk_crc=crc)
    schema = writer.add_schema("std_msgs/msg/String", "ros2msg", b"string data")
    for k in range(CHANNELS):
        writer.add_channel(f"/t{k}", schema, "cdr", {})
    for batch in batches:
        writer.write_batch(batch)
    writer.finish()
    return path.read_bytes()


@pytest.fixture(scope="module")
def kernel() -> None:
    if load_chunk_kernel() is None:
        pytest.fail("the MCAP chunk kernel did not build (no C compiler?); these tests compare it with numpy")


@settings(max_examples=80, deadline=None)
@given(batches=batches, in_order=st.booleans(), crc=st.booleans())
def test_kernel_and_numpy_write_the_same_file(
    kernel: None,
    tmp_path_factory: pytest.TempPathFactory,
    batches: list[list[tuple[int, int, bytes]]],
    in_order: bool,
    crc: bool,
) -> None:
    if in_order:  # the recorder's batches are in time order; out of order they take the numpy path
        batches = [sorted(b, key=lambda m: m[1]) for b in batches]
    folder = tmp_path_factory.mktemp("chunks")
    native = _write(folder / "native.mcap", batches, native=True, crc=crc)
    numpy = _write(folder / "numpy.mcap", batches, native=False, crc=crc)
    assert native == numpy
    scan = scan_mcap(folder / "native.mcap")
    assert scan.complete
    assert [len(c.channels) for c in scan.chunks] == [len(b) for b in batches]
    for chunk, batch in zip(scan.chunks, batches, strict=True):
        in_time_order = sorted(batch, key=lambda m: m[1])
        assert chunk.channels.tolist() == [m[0] for m in in_time_order]
        assert chunk.times.tolist() == [m[1] for m in in_time_order]


@pytest.mark.parametrize("native", [True, False])
def test_a_bad_batch_is_refused_whole_by_both_paths(tmp_path: Path, native: bool) -> None:
    writer = McapWriter(tmp_path / "bad.mcap", library="test", native=native)
    writer.add_channel("/a", 0, "cdr", {})
    size = writer.good_end
    with pytest.raises(ValueError, match="unknown topic handle 2"):
        writer.write_batch([(1, 5, b"ok"), (2, 6, b"no such channel")])
    with pytest.raises(ValueError, match="negative message time -1"):
        writer.write_batch([(1, 5, b"ok"), (1, -1, b"before the epoch")])
    with pytest.raises(ValueError, match="data bytes"):
        writer.write_batch([(1, 5, "text")])  # type: ignore[list-item]
    assert writer.good_end == size and writer.stats.message_count == 0
    writer.close()
