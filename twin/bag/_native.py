"""An MCAP chunk in C: the Chunk record and its MessageIndex records for one batch, in one call.

`McapWriter.write_batch` builds a chunk from a batch of `(channel, time, data)` messages. With numpy
that is some forty array operations per batch, whatever its size (a few hundred messages every
0.4 s of simulated time); this kernel does the same work in one pass over the batch, so a flush
costs little more than copying its bytes. It only takes the common case: channels known, times not
negative and already in order. Anything else (and a machine without a C compiler, or
`TWIN_NO_NATIVE`) goes through the numpy path, which sorts, and names a bad write; both give the
same bytes (the tests compare them).

`twin_mcap_chunk(n, channels, times, lengths, data, n_channels, chunk_offset, out, work)`:

    channels, times, lengths   n int64 each; `data` holds the n messages back to back
    out                        the Chunk record (no compression, CRC 0), then the MessageIndex
                               records by ascending channel, each listing its messages in order
    work                       int64, 2 (n_channels + 1) + 4 + 10 n_channels / 8 + 1 at least:
                               per channel its message count, then scratch; then the number of
                               bytes written, the chunk record's length, the records' size and
                               the number of channels present; then, as bytes, the ChunkIndex's
                               map of (uint16 channel, uint64 MessageIndex file offset) pairs

It returns 0, or 1 when the batch is not the common case (nothing written).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library, native_disabled

__all__ = ["load_chunk_kernel"]

_SOURCE = r"""
#include <stdint.h>
#include <string.h>

static unsigned char *put(unsigned char *p, uint64_t v, int bytes) {
    for (int i = 0; i < bytes; i++) p[i] = (unsigned char)(v >> (8 * i));
    return p + bytes;
}

int twin_mcap_chunk(long n, const int64_t *channels, const int64_t *times, const int64_t *lengths,
                    const unsigned char *data, long n_channels, int64_t chunk_offset,
                    unsigned char *out, int64_t *work) {
    int64_t *counts = work, *cursor = work + (n_channels + 1), *info = work + 2 * (n_channels + 1);
    unsigned char *map = (unsigned char *)(info + 4);
    int64_t records = 0;
    memset(counts, 0, sizeof(int64_t) * (size_t)(n_channels + 1));
    for (long i = 0; i < n; i++) {
        if (channels[i] < 1 || channels[i] > n_channels || times[i] < 0 || (i && times[i] < times[i - 1])) return 1;
        counts[channels[i]]++;
        records += 31 + lengths[i];
    }
    /* Chunk: opcode, length, start, end, uncompressed size, CRC, compression "", records' length. */
    const int64_t head = 8 + 8 + 8 + 4 + 4 + 8;
    const int64_t chunk = 9 + head + records;
    unsigned char *p = out;
    *p++ = 0x06;
    p = put(p, (uint64_t)(head + records), 8);
    p = put(p, (uint64_t)(n ? times[0] : 0), 8);
    p = put(p, (uint64_t)(n ? times[n - 1] : 0), 8);
    p = put(p, (uint64_t)records, 8);
    p = put(p, 0, 4);
    p = put(p, 0, 4);
    p = put(p, (uint64_t)records, 8);
    /* MessageIndex records after the chunk, by ascending channel: where each one's entries go. */
    int64_t at = chunk, present = 0;
    for (long ch = 1; ch <= n_channels; ch++) {
        if (!counts[ch]) continue;
        unsigned char *r = out + at;
        *r++ = 0x07;
        r = put(r, (uint64_t)(6 + 16 * counts[ch]), 8);
        r = put(r, (uint64_t)ch, 2);
        r = put(r, (uint64_t)(16 * counts[ch]), 4);
        cursor[ch] = at + 15;
        unsigned char *m = map + 10 * present++;
        m = put(m, (uint64_t)ch, 2);
        put(m, (uint64_t)(chunk_offset + at), 8);
        at += 15 + 16 * counts[ch];
    }
    /* Message records, and each one's index entry (time, offset in the records) in message order. */
    const unsigned char *src = data;
    int64_t offset = 0;
    for (long i = 0; i < n; i++) {
        int64_t ch = channels[i], t = times[i], len = lengths[i];
        *p++ = 0x05;
        p = put(p, (uint64_t)(len + 22), 8);
        p = put(p, (uint64_t)ch, 2);
        p = put(p, 0, 4);
        p = put(p, (uint64_t)t, 8);
        p = put(p, (uint64_t)t, 8);
        memcpy(p, src, (size_t)len);
        p += len;
        src += len;
        unsigned char *e = out + cursor[ch];
        e = put(e, (uint64_t)t, 8);
        put(e, (uint64_t)offset, 8);
        cursor[ch] += 16;
        offset += 31 + len;
    }
    info[0] = at;
    info[1] = chunk;
    info[2] = records;
    info[3] = present;
    return 0;
}
"""


def load_chunk_kernel() -> ctypes.CDLL | None:
    """Return the compiled chunk builder (built on first use); None without a C compiler or with `TWIN_NO_NATIVE`."""
    return None if native_disabled() else _load()


@functools.cache
def _load() -> ctypes.CDLL | None:
    lib = load_library(CLibrary(name="mcap_chunk", source=_SOURCE, flags=("-O2", "-shared", "-fPIC")), keep_gil=True)
    if lib is None:
        return None
    function = lib.twin_mcap_chunk
    function.restype = ctypes.c_int
    function.argtypes = [
        ctypes.c_long,
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_char_p,
        ctypes.c_long,
        ctypes.c_int64,
        ctypes.c_void_p,
        ctypes.c_void_p,
    ]
    return lib
