"""The error hierarchy of twin: one base class, one subclass per concern, each with its exit code.

Every error the user can cause is a `TwinError`. Its message is one line that names what failed,
where (file, line, key, sim time) and the fix. `twin.cli` prints that line and exits with
`exit_code`; a traceback is shown only with `--debug`.

Subclasses also inherit the builtin they refine, so callers may catch either.
"""

from __future__ import annotations

from typing import Any, ClassVar, Self

__all__ = [
    "BagError",
    "ConfigError",
    "EstimationError",
    "FmuError",
    "Interrupted",
    "SimulationError",
    "TreeError",
    "TwinError",
    "WorldError",
]


def _rebuild(cls: type[TwinError], args: tuple[Any, ...], state: dict[str, Any]) -> TwinError:
    """Unpickle a `TwinError` without calling its `__init__` (subclasses take other arguments)."""
    err = cls.__new__(cls)
    err.args = args
    err.__dict__.update(state)
    return err


class TwinError(Exception):
    """Base of every error twin reports to the user as one line.

    Subclasses may take any `__init__` arguments: `with_context` and pickling (Dask workers,
    multiprocessing) never call `__init__` again, so every subclass keeps its message and attributes.
    """

    exit_code: ClassVar[int] = 1

    def __str__(self) -> str:
        text = super().__str__()
        # One line, always: a message built from file contents may carry newlines.
        return " ".join(text.split("\n")) if "\n" in text else text

    def with_context(self, *, before: str = "", after: str = "") -> Self:
        """Return a copy of this error, same class and attributes, with text added around its message.

        Use it to re-raise with context: `raise err.with_context(after=" (at t=3.2 s)") from err`.

        Args:
            before: Text put before the message (e.g. `"scenario.yaml: "`).
            after: Text put after the message.
        """
        copy = type(self).__new__(type(self))
        copy.__dict__.update(self.__dict__)
        copy.args = (f"{before}{self}{after}",)
        return copy

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (type(self), self.args, dict(self.__dict__)))


class ConfigError(TwinError, ValueError):
    """A scenario, mapping or other configuration file is wrong."""

    exit_code: ClassVar[int] = 2


class WorldError(TwinError, ValueError):
    """An SDF world or model cannot be loaded."""

    exit_code: ClassVar[int] = 3


class FmuError(TwinError, RuntimeError):
    """An FMU cannot be built, loaded, mapped or stepped."""

    exit_code: ClassVar[int] = 4


class BagError(TwinError, RuntimeError):
    """A bag cannot be written, read or recovered."""

    exit_code: ClassVar[int] = 5


class BagFolderTaken(BagError):
    """The bag folder to write holds a bag already (maybe one another run is writing): never to be removed."""


class TreeError(TwinError, ValueError):
    """A behaviour-tree file is invalid, or a node failed while ticking."""

    exit_code: ClassVar[int] = 6


class EstimationError(TwinError, RuntimeError):
    """The state estimator cannot run on its inputs."""

    exit_code: ClassVar[int] = 7


class SimulationError(TwinError, RuntimeError):
    """The simulation loop cannot continue."""

    exit_code: ClassVar[int] = 8


class Interrupted(TwinError):
    """The run was stopped by SIGINT or SIGTERM; what was recorded is kept."""

    exit_code: ClassVar[int] = 130
