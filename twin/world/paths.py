"""Where `model://NAME` and other resource URIs point: the model path, model.config, file URIs.

The search list is the explicit one given by the caller (a scenario's `world.model_path`, the
CLI's `--model-path`) after `TWIN_MODEL_PATH`, then Gazebo's own variables, so a shell already
set up for Gazebo Classic (`GAZEBO_MODEL_PATH`) or gz-sim (`GZ_SIM_RESOURCE_PATH`) works as is.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from twin.core.errors import WorldError
from twin.world._xml import parse_file

__all__ = ["MAX_SDF_VERSION", "find_model_dir", "model_file", "resolve_resource", "sdf_version", "search_path"]

#: The newest SDFormat version this loader knows.
MAX_SDF_VERSION = (1, 11)

_ENV_BEFORE = ("TWIN_MODEL_PATH",)
_ENV_AFTER = ("GAZEBO_MODEL_PATH", "GZ_SIM_RESOURCE_PATH", "IGN_GAZEBO_RESOURCE_PATH")


def search_path(explicit: Sequence[Path | str] = (), env: Mapping[str, str] | None = None) -> tuple[Path, ...]:
    """Return the model search path: `TWIN_MODEL_PATH`, then `explicit`, then Gazebo's variables.

    Args:
        explicit: Folders that hold model folders (each with a model.config).
        env: Environment to read (defaults to `os.environ`).
    """
    env = os.environ if env is None else env
    out: list[Path] = []

    def add(entry: Path) -> None:
        if entry not in out:
            out.append(entry)

    for name in _ENV_BEFORE:
        for part in env.get(name, "").split(os.pathsep):
            if part:
                add(Path(part).expanduser())
    for item in explicit:
        add(Path(item).expanduser())
    for name in _ENV_AFTER:
        for part in env.get(name, "").split(os.pathsep):
            if part:
                add(Path(part).expanduser())
    return tuple(out)


def sdf_version(text: str | None) -> tuple[int, int] | None:
    """Parse an SDF version string like `1.6` into (1, 6); None if it is not one."""
    if not text:
        return None
    parts = text.strip().split(".")
    try:
        return int(parts[0]), int(parts[1]) if len(parts) > 1 else 0
    except ValueError:
        return None


def find_model_dir(name: str, search: Sequence[Path]) -> Path | None:
    """Return the first folder `<dir>/<name>` on the search path, or None.

    `name` may have several parts (`turtlebot3_dqn_world/inner_walls`).
    """
    name = name.strip("/")
    if not name:
        return None
    for base in search:
        candidate = base / name
        if candidate.is_dir():
            return candidate
    return None


def model_file(model_dir: Path) -> Path:
    """Return the SDF file of a model folder, choosing from model.config as Gazebo does.

    model.config lists `<sdf version="...">file</sdf>` entries; the newest version this loader
    supports wins. Without a model.config, `model.sdf` is used.

    Raises:
        WorldError: If no SDF file can be found.
    """
    config = model_dir / "model.config"
    if config.is_file():
        root = parse_file(config)
        best: tuple[tuple[int, int], str] | None = None
        fallback: str | None = None
        for entry in root.findall("sdf"):
            if not entry.text:
                continue
            fallback = fallback or entry.text
            version = sdf_version(entry.get("version")) or (0, 0)
            if version <= MAX_SDF_VERSION and (best is None or version > best[0]):
                best = (version, entry.text)
        chosen = best[1] if best is not None else fallback
        if chosen is not None:
            path = model_dir / chosen
            if path.is_file():
                return path
            msg = f"{config}:{root.line}: model.config names {chosen!r}, which does not exist in {model_dir}"
            raise WorldError(msg)
    default = model_dir / "model.sdf"
    if default.is_file():
        return default
    msg = f"{model_dir}: no model.config and no model.sdf; a model folder needs one of them"
    raise WorldError(msg)


def resolve_resource(uri: str, *, base_dir: Path, search: Sequence[Path]) -> Path | None:
    """Resolve a mesh or include URI to an existing path, or None.

    Understands `model://NAME/rest` and `package://NAME/rest` (both against the search path),
    `file://` URIs, absolute paths and paths relative to the SDF file that names them (`base_dir`).
    Web URIs (`http://`, `https://`) are never fetched: they resolve to None.
    """
    uri = uri.strip()
    for scheme in ("model://", "package://"):
        if uri.startswith(scheme):
            rest = uri[len(scheme) :].lstrip("/")
            for base in search:
                candidate = base / rest
                if candidate.exists():
                    return candidate
            return None
    if uri.startswith(("http://", "https://")):
        return None
    if uri.startswith("file://"):
        uri = uri[len("file://") :]
    path = Path(uri).expanduser()
    if path.is_absolute():
        return path if path.exists() else None
    for base in (base_dir, *search):
        candidate = base / path
        if candidate.exists():
            return candidate
    return None
