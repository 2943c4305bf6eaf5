"""A resource that is its own context manager: `with Thing(...) as thing:` closes it on leaving.

Subclasses define `close()` (idempotent by convention); leaving the `with` block calls it on success,
on an exception and on Ctrl-C alike, so files, processes and servers are released however a run ends.
"""

from __future__ import annotations

from types import TracebackType
from typing import Self

__all__ = ["Closing"]


class Closing:
    """Base for classes whose `close()` ends them: `__enter__` returns the object, `__exit__` closes it."""

    __slots__ = ()

    def close(self) -> None:
        """Release what the object holds; subclasses override this."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
