"""Reading a user's input file whole, safely: only a regular file, and only up to a size.

`/dev/zero` given as a world once read for 13 s and ended in a MemoryError; a FIFO would block for
ever. `read_input` refuses both at once, with an `OSError` whose `strerror` says why, so callers'
one-line messages (`{path}: cannot read: {strerror}`) stay as they are.
"""

from __future__ import annotations

import errno
import stat
from pathlib import Path

__all__ = ["read_input"]


def read_input(path: Path, *, max_bytes: int) -> bytes:
    """Return the bytes of a regular file of at most `max_bytes`.

    Raises:
        FileNotFoundError: If it does not exist.
        IsADirectoryError: If it is a folder.
        OSError: If it is not a regular file (a device, pipe or socket), is larger than `max_bytes`,
            or cannot be read; `strerror` says which.
    """
    info = path.stat()
    if stat.S_ISDIR(info.st_mode):
        raise IsADirectoryError(errno.EISDIR, "is a folder", str(path))
    if not stat.S_ISREG(info.st_mode):
        raise OSError(errno.EINVAL, "not a regular file (a device, pipe or socket); give a file", str(path))
    if info.st_size > max_bytes:
        why = f"{info.st_size / 2**20:.0f} MiB is larger than the {max_bytes / 2**20:.0f} MiB an input file may be"
        raise OSError(errno.EFBIG, why, str(path))
    with path.open("rb") as stream:
        data = stream.read(max_bytes + 1)
    if len(data) > max_bytes:  # it grew while being read
        raise OSError(errno.EFBIG, f"larger than the {max_bytes / 2**20:.0f} MiB an input file may be", str(path))
    return data
