"""CDR building blocks: a struct-format builder for fixed layouts and a writer for variable ones.

ROS 2 serialises messages as plain (XCDR1) CDR, little endian: a 4-byte encapsulation header
`00 01 00 00`, then the fields in order, each primitive aligned to its own size counted from the
end of that header; strings are a uint32 length (including the NUL), the bytes and a NUL;
sequences are a uint32 count followed by the elements.

Most of the twin's messages have a layout that is fixed once their frame names and array sizes
are known. `Layout` turns such a layout into one `struct.Struct` whose arguments are the
precomputed constant byte runs (encapsulation, frame ids, counts, padding, constant covariances)
interleaved with the values that change per message, so encoding a message is one `pack` call.
`CdrWriter` handles the rest (strings and arrays whose length changes per message).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

__all__ = ["ENCAPSULATION", "CdrWriter", "Layout", "string_bytes"]

#: CDR, little endian, no options.
ENCAPSULATION = b"\x00\x01\x00\x00"

_ZEROS = bytes(8)
_TIME = struct.Struct("<iI")


def string_bytes(text: str) -> bytes:
    """A CDR string without its alignment: uint32 length including the NUL, UTF-8 bytes, NUL."""
    raw = text.encode()
    return struct.pack("<I", len(raw) + 1) + raw + b"\x00"


class Layout:
    """Builds a `struct.Struct` for a CDR message whose layout is fixed.

    Fields are added in message order. Constant fields accumulate into byte runs; each run
    becomes one `{n}s` argument. Variable fields become struct codes. Call `build()` to get
    the struct and the constant runs in the order the struct expects them.
    """

    def __init__(self, *, offset: int | None = None) -> None:
        """Start a message, or with `offset` a fragment of one: its bytes from that offset from the CDR origin on.

        A fragment has no encapsulation header; its alignment counts from the CDR origin, so a
        fragment built for one offset fits only where the message reaches that offset (modulo 8).
        """
        self._fmt: list[str] = ["<"]
        self._pos = 0 if offset is None else offset  # offset from the CDR origin (just after the header)
        self._run = bytearray(ENCAPSULATION) if offset is None else bytearray()
        self._runs: list[bytes] = []
        self.slots: list[str] = []  #: argument kinds in pack order: "const" or the variable's name

    @property
    def size(self) -> int:
        """Bytes of the message so far, header included."""
        return 4 + self._pos

    @property
    def offset(self) -> int:
        """Where the next field would start, from the CDR origin."""
        return self._pos

    def _align(self, size: int) -> None:
        pad = (-self._pos) % size
        if not pad:
            return
        if self._run:
            self._run += _ZEROS[:pad]
        else:
            self._fmt.append(f"{pad}x")
        self._pos += pad

    def _end_run(self) -> None:
        if self._run:
            self._fmt.append(f"{len(self._run)}s")
            self._runs.append(bytes(self._run))
            self.slots.append("const")
            self._run = bytearray()

    def const(self, code: str, *values: float | int | bool) -> None:
        """A constant field or fixed array of one primitive struct code (e.g. `d`, `I`, `B`)."""
        if not values:
            return
        size = struct.calcsize(code)
        self._align(size)
        self._run += struct.pack(f"<{len(values)}{code}", *values)
        self._pos += size * len(values)

    def const_string(self, text: str) -> None:
        """A constant string."""
        self._align(4)
        raw = string_bytes(text)
        self._run += raw
        self._pos += len(raw)

    def const_count(self, count: int) -> None:
        """A constant sequence length."""
        self.const("I", count)

    def var(self, name: str, code: str, count: int = 1) -> None:
        """`count` variable values of one struct code (e.g. `d`), passed as separate arguments."""
        if count == 0:
            # Nothing to align or pack, but keep the constant runs split here so the argument
            # order stays the same as for a non-empty array.
            self._end_run()
            return
        size = struct.calcsize(code)
        self._align(size)
        self._end_run()
        self._fmt.append(f"{count}{code}" if count != 1 else code)
        self.slots.extend([name] * count)
        self._pos += size * count

    def var_time(self, name: str = "stamp") -> None:
        """A `builtin_interfaces/Time`: int32 sec, uint32 nanosec."""
        self.var(f"{name}.sec", "i")
        self.var(f"{name}.nanosec", "I")

    def var_bytes(self, name: str, size: int, align: int) -> None:
        """A variable run of `size` raw bytes (e.g. an array's `tobytes()`), aligned to `align`."""
        self._align(align)
        self._end_run()
        self._fmt.append(f"{size}s")
        self.slots.append(name)
        self._pos += size

    def build(self) -> tuple[struct.Struct, tuple[bytes, ...]]:
        """Return the struct and the constant runs, in the order `pack` takes them."""
        self._end_run()
        return struct.Struct("".join(self._fmt)), tuple(self._runs)


class CdrWriter:
    """Appends CDR fields to a growing buffer (for messages whose layout changes per message)."""

    __slots__ = ("_buf",)

    def __init__(self) -> None:
        self._buf = bytearray(ENCAPSULATION)

    def _align(self, size: int) -> None:
        pad = (4 - len(self._buf)) % size
        if pad:
            self._buf += _ZEROS[:pad]

    def pack(self, code: str, *values: float | int | bool) -> None:
        """Values of one primitive struct code (a single character, e.g. `d`), aligned to its size."""
        if not values:
            return
        self._align(struct.calcsize(code))
        self._buf += struct.pack(f"<{len(values)}{code}", *values)

    def time(self, t_ns: int) -> None:
        """A `builtin_interfaces/Time` from integer nanoseconds."""
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        self._align(4)
        self._buf += _TIME.pack(sec, nanosec)

    def string(self, text: str) -> None:
        """A string."""
        self._align(4)
        self._buf += string_bytes(text)

    def header(self, t_ns: int, frame_id: str) -> None:
        """A `std_msgs/Header`."""
        self.time(t_ns)
        self.string(frame_id)

    def count(self, n: int) -> None:
        """A sequence length."""
        self.pack("I", n)

    def strings(self, texts: Iterable[str]) -> None:
        """A `string[]` sequence."""
        items = list(texts)
        self.count(len(items))
        for text in items:
            self.string(text)

    def array(self, values: NDArray[np.generic], *, sequence: bool) -> None:
        """A numeric array (its dtype decides the element type), with a count if `sequence`."""
        flat = np.ascontiguousarray(values).reshape(-1)
        if sequence:
            self.count(flat.size)
        if flat.size:
            self._align(flat.dtype.itemsize)
            self._buf += flat.astype(flat.dtype.newbyteorder("<"), copy=False).tobytes()

    def raw(self, data: bytes, *, align: int) -> None:
        """Raw bytes (already in CDR form), aligned to `align` first."""
        self._align(align)
        self._buf += data

    def getvalue(self) -> bytes:
        """The message so far."""
        return bytes(self._buf)
