"""The error hierarchy of twin: one base class, one subclass per concern, each with its exit code.

Every error the user can cause is a `TwinError`. Its message is one line that names what failed,
where (file, line, key, sim time) and the fix. `twin.cli` prints that line and exits with
`exit_code`; a traceback is shown only with `--debug`.

Subclasses also inherit the builtin they refine, so callers may catch either.
"""

from __future__ import annotations

from typing import ClassVar

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


class TwinError(Exception):
    """Base of every error twin reports to the user as one line."""

    exit_code: ClassVar[int] = 1


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
