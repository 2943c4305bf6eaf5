"""A content-keyed on-disk cache for what a run derives from its inputs (a map made from the world).

An entry's name is a hash of everything that shapes it: a kind, a format version and the input
parts the caller gives (bytes of arrays, file contents, parameters). A changed input is a new name,
so an entry is never stale; nothing is ever invalidated in place. Entries are numpy `.npz` files
(no pickles) in `<cache folder>/derived/<kind>/`, written beside their name and moved into place in
one step, so a concurrent or killed writer never leaves a partial entry under the final name. An
entry that cannot be read (cut short, corrupt, another format) is built again and replaced; a
cache folder that cannot be written only costs the time of building again.

    arrays = cached_arrays("world_map", 1, (segments, circles, repr(params)), build)

The cache folder is `twin.core.native.cache_dir()` (`$TWIN_CACHE_DIR`, `$XDG_CACHE_HOME/twin`,
`~/.cache/twin`). What the cache does is logged at DEBUG only: it describes the machine, not the
run, and must not reach a run's `/rosout`.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.core.native import cache_dir

__all__ = ["Arrays", "cache_key", "cached_arrays", "entry_path"]

_log = logging.getLogger(__name__)

Arrays = Mapping[str, NDArray[np.generic]]
"""An entry's content: named numpy arrays."""

KeyPart = bytes | str | int | float | tuple[float, ...] | NDArray[np.generic] | None


def cache_key(kind: str, version: int, parts: Iterable[KeyPart]) -> str:
    """Return the hex digest naming the entry of `kind` (format `version`) built from `parts`.

    Arrays count with their dtype and shape as well as their bytes; every part is framed by its
    length, so two different part lists never give the same byte stream.
    """
    h = hashlib.sha256()
    for head in (kind, str(version)):
        h.update(head.encode() + b"\0")
    for part in parts:
        if isinstance(part, np.ndarray):
            array = np.ascontiguousarray(part)
            data = f"{array.dtype.str}{array.shape}".encode() + b"\0" + array.tobytes()
        elif isinstance(part, bytes):
            data = part
        else:
            data = repr(part).encode()
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()[:32]


def entry_path(kind: str, key: str) -> Path:
    """Return where the entry `key` of `kind` is stored."""
    return cache_dir() / "derived" / kind / f"{key}.npz"


def _read(path: Path) -> dict[str, NDArray[np.generic]] | None:
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {name: npz[name] for name in npz.files}
    except FileNotFoundError:
        return None
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
        _log.debug("cache entry %s is unreadable (%s); building it again", path, err)
        return None


def _write(path: Path, arrays: Arrays) -> None:
    staged: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".tmp-", suffix=".npz", delete=False) as stream:
            staged = stream.name
            save: Any = np.savez  # numpy's stubs take **arrays for its allow_pickle flag
            save(stream, allow_pickle=False, **arrays)
        os.replace(staged, path)
        staged = None
    except OSError as err:
        _log.debug("cannot store cache entry %s (%s)", path, err)
    finally:
        if staged is not None:
            with contextlib.suppress(OSError):
                os.unlink(staged)


def cached_arrays(
    kind: str, version: int, parts: Iterable[KeyPart], build: Callable[[], Arrays]
) -> dict[str, NDArray[np.generic]]:
    """Return the arrays `build()` makes from the inputs `parts`, from the cache when an entry exists.

    Args:
        kind: What is cached (a folder name: letters, digits, `_`).
        version: The entry format's version; bump it when `build` changes what it returns.
        parts: Everything `build`'s result depends on (see `cache_key`).
        build: Makes the arrays on a miss (its exceptions propagate; nothing is stored then).
    """
    path = entry_path(kind, cache_key(kind, version, parts))
    found = _read(path)
    if found is not None:
        return found
    arrays = {name: np.asarray(value) for name, value in build().items()}
    _write(path, arrays)
    return arrays
