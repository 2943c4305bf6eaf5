"""What identifies the code a run ran: a digest of the twin package's sources and the FMUs' sources.

`twin.__version__` stays the same while the code under it changes (a checkout, an editable
install), so a result kept for re-use (a sweep's finished runs) is keyed by this digest too: a run
whose code changed is run again rather than read back.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parents[1]
_FMUS = _PACKAGE.parent / "fmus"  # the FMUs' C sources, beside the package in a checkout
_SUFFIXES = frozenset({".py", ".c", ".h", ".xml", ".yaml", ".msg"})


@functools.cache
def code_digest() -> str:
    """A SHA-256 (16 hex digits) over the relative path and bytes of every source file of twin and its FMUs."""
    h = hashlib.sha256()
    for root in (_PACKAGE, _FMUS):
        if not root.is_dir():
            continue
        for path in sorted(p for p in root.rglob("*") if p.suffix in _SUFFIXES and p.is_file()):
            if "__pycache__" in path.parts:
                continue
            h.update(str(path.relative_to(root.parent)).encode() + b"\0")
            h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]
