"""Where `model://NAME` and other resource URIs point: the model path, model.config, file URIs.

The search list is the explicit one given by the caller (a scenario's `world.model_path`, the
CLI's `--model-path`) after `TWIN_MODEL_PATH`, then Gazebo's own variables, so a shell already
set up for Gazebo Classic (`GAZEBO_MODEL_PATH`) or gz-sim (`GZ_SIM_RESOURCE_PATH`) works as is.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from urllib.parse import unquote, urlsplit

from twin.core.errors import WorldError
from twin.world._xml import parse_file

__all__ = [
    "MAX_SDF_VERSION",
    "fallback_search",
    "find_model_dir",
    "folder_to_add",
    "fuel_cache_roots",
    "fuel_model_dir",
    "fuel_model_name",
    "missing_mesh_message",
    "model_file",
    "resolve_include",
    "resolve_resource",
    "resolve_resource_ignoring_case",
    "sdf_version",
    "search_path",
]

_log = logging.getLogger(__name__)

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
    if not name or _escapes(f"model://{name}", name):
        return None
    for base in search:
        candidate = base / name
        if candidate.is_dir():
            return candidate
    return None


def _escapes(uri: str, rest: str) -> bool:
    """True (and a warning) if `rest` climbs out of the model path with `..`: such a URI is refused."""
    if ".." not in rest.replace("\\", "/").split("/"):
        return False
    if uri not in _WARNED_ESCAPES:
        _WARNED_ESCAPES.add(uri)
        _log.warning("%s: refused: '..' would leave the model path (name the file inside a model folder)", uri)
    return True


_WARNED_ESCAPES: set[str] = set()


def model_file(model_dir: Path) -> Path:
    """Return the SDF file of a model folder, choosing from model.config as Gazebo does.

    model.config lists `<sdf version="...">file</sdf>` entries; the newest version this loader
    supports wins. Without a model.config, `model.sdf` is used.

    Raises:
        WorldError: If no SDF file can be found.
    """
    config = model_dir / "model.config"
    if config.is_file():
        # Read only for its <sdf> entries: a bare `&` in the description, which Gazebo's tinyxml2
        # lets through, must not refuse the model.
        root = parse_file(config, bare_ampersands=True)
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
    Web URIs (`http://`, `https://`) are never fetched: a Fuel URI resolves to its copy in a local
    Fuel cache (see `fuel_model_dir`), any other to None.
    """
    uri = uri.strip()
    if uri.startswith(("http://", "https://")):
        return _fuel_file(uri)
    return next((candidate for candidate in _candidates(uri, base_dir, search) if candidate.exists()), None)


def resolve_resource_ignoring_case(uri: str, *, base_dir: Path, search: Sequence[Path]) -> Path | None:
    """Return a file whose name differs only in letter case from one a URI names, in the same folder.

    For a URI `resolve_resource` does not find: Gazebo on a case-insensitive file system (macOS,
    Windows) opens `aws_spotlight_01_collision.DAE` for `.../aws_Spotlight_01_collision.DAE`.
    None for web URIs, or when no folder the URI names holds such a file.
    """
    uri = uri.strip()
    if uri.startswith(("http://", "https://")):
        return None
    for candidate in _candidates(uri, base_dir, search):
        folder, wanted = candidate.parent, candidate.name.lower()
        if not folder.is_dir():
            continue
        for entry in sorted(folder.iterdir()):
            if entry.name.lower() == wanted and entry.is_file():
                return entry
    return None


def folder_to_add(uri: str, base_dir: Path) -> Path | None:
    """Return the folder that, on the model path, would resolve a relative URI (`file://models/x/a.dae`).

    Such URIs are relative to a folder on Gazebo's resource path, usually one holding the `models`
    folder the file is in: of `base_dir` and its parents, the one where most of the URI's leading
    folders exist (the whole file, if it exists). None for `model://`, web and absolute URIs, or if
    no parent holds even the first folder of the URI.
    """
    text = uri.strip()
    if text.startswith(("model://", "package://", "http://", "https://")):
        return None
    relative = Path(text.removeprefix("file://"))
    if relative.is_absolute() or not relative.parts:
        return None
    best: tuple[int, Path] | None = None
    for folder in (base_dir, *base_dir.parents):
        depth = 0
        while depth < len(relative.parts) and (folder.joinpath(*relative.parts[: depth + 1])).exists():
            depth += 1
        if depth == len(relative.parts):
            return folder
        if depth and (best is None or depth > best[0]):
            best = (depth, folder)
    return best[1] if best is not None else None


def _candidates(uri: str, base_dir: Path, search: Sequence[Path]) -> Iterator[Path]:
    """Yield the paths a local (non-web) URI may name, in the order Gazebo tries them."""
    for scheme in ("model://", "package://"):
        if uri.startswith(scheme):
            rest = uri[len(scheme) :].lstrip("/")
            if not _escapes(uri, rest):
                yield from (base / rest for base in search)
            return
    path = Path(uri.removeprefix("file://")).expanduser()
    if path.is_absolute():
        yield path
        return
    yield from (base / path for base in (base_dir, *search))


# --- Gazebo Fuel's local cache ---------------------------------------------------------------------

#: `https://fuel.gazebosim.org/1.0/OpenRobotics/models/Radio/4/files/meshes/Radio.dae`: host, owner,
#: model name, then an optional version (a number or `tip`) and an optional `files/<path>`.
_FUEL_URI = re.compile(
    r"^/(?:[\d.]+/)?(?P<owner>[^/]+)/models/(?P<name>[^/]+)(?:/(?P<version>\d+|tip))?(?:/files/(?P<rest>.+))?/?$"
)


def fuel_cache_roots(env: Mapping[str, str] | None = None) -> tuple[Path, ...]:
    """Return the folders where gz-sim (and Ignition before it) keep downloaded Fuel models.

    `GZ_FUEL_CACHE_PATH` and `IGN_FUEL_CACHE_PATH` when set, then `~/.gz/fuel` and `~/.ignition/fuel`.
    """
    env = os.environ if env is None else env
    roots = [Path(env[name]).expanduser() for name in ("GZ_FUEL_CACHE_PATH", "IGN_FUEL_CACHE_PATH") if env.get(name)]
    home = Path(env.get("HOME") or Path.home())
    roots += [home / ".gz" / "fuel", home / ".ignition" / "fuel"]
    return tuple(dict.fromkeys(roots))


def _child(folder: Path, name: str) -> Path | None:
    """Return `folder/name`, matching the name without regard to case (Fuel lowercases owners and models)."""
    exact = folder / name
    if exact.exists():
        return exact
    if not folder.is_dir():
        return None
    wanted = name.lower()
    for entry in folder.iterdir():
        if entry.name.lower() == wanted:
            return entry
    return None


def _fuel_parts(uri: str) -> tuple[str, str, str, str | None, str | None] | None:
    parts = urlsplit(uri.strip())
    match = _FUEL_URI.match(unquote(parts.path))
    if not parts.netloc or match is None:
        return None
    version = match["version"] if match["version"] != "tip" else None
    return parts.netloc, match["owner"], match["name"], version, match["rest"]


def _fuel_version_dir(uri: str, env: Mapping[str, str] | None) -> tuple[Path, str | None] | None:
    found = _fuel_parts(uri)
    if found is None:
        return None
    host, owner, name, version, rest = found
    for root in fuel_cache_roots(env):
        folder: Path | None = root
        for part in (host, owner, "models", name):
            folder = _child(folder, part) if folder is not None else None
        model = folder
        if model is None or not model.is_dir():
            continue
        if version is not None:
            chosen = _child(model, version)
        else:
            versions = [entry for entry in model.iterdir() if entry.is_dir() and entry.name.isdigit()]
            chosen = max(versions, key=lambda entry: int(entry.name)) if versions else None
        if chosen is not None and chosen.is_dir():
            return chosen, rest
    return None


def fuel_model_dir(uri: str, env: Mapping[str, str] | None = None) -> Path | None:
    """Return the local copy of a Fuel model URI (the newest cached version unless one is named), or None.

    Gazebo keeps what it downloads under `<cache>/<host>/<owner>/models/<name>/<version>/`; a world
    written for Fuel therefore loads offline on any machine that has run it in Gazebo once.
    """
    found = _fuel_version_dir(uri, env)
    return found[0] if found is not None and found[1] is None else None


def _fuel_file(uri: str, env: Mapping[str, str] | None = None) -> Path | None:
    found = _fuel_version_dir(uri, env)
    if found is None or found[1] is None:
        return None
    path = found[0] / found[1]
    return path if path.exists() else None


def fuel_model_name(uri: str) -> str | None:
    """Return the model name a Fuel URI names (`Ground Plane`), or None if it is not a Fuel model URI."""
    found = _fuel_parts(uri)
    return found[2] if found is not None else None


def fallback_search(search: Sequence[Path], base_dir: Path) -> tuple[Path, ...]:
    """Return the model path plus the folder holding the current model folder.

    The extra entry, searched last, lets a model name itself or a sibling model
    (`model://mailbox/meshes/...` inside `.../mailbox/model.sdf`) when its parent folder is not
    on the model path, as happens with models nested inside another model's folder.
    """
    extra = base_dir.parent
    return tuple(search) if extra in search else (*search, extra)


def resolve_include(uri: str, file: Path, search: Sequence[Path]) -> Path | None:
    """Return the SDF file an `<include>` URI in `file` names (a model folder's chosen file), or None."""
    uri = uri.strip()
    path: Path | None
    search = fallback_search(search, file.parent)
    if uri.startswith(("model://", "package://")):
        name = uri.split("://", 1)[1]
        path = find_model_dir(name, search)
    elif uri.startswith(("http://", "https://")):
        # The local Fuel cache first, then a folder of the model's name on the model path.
        path = fuel_model_dir(uri) or find_model_dir(fuel_model_name(uri) or uri.rstrip("/").rsplit("/", 1)[-1], search)
    else:
        path = resolve_resource(uri, base_dir=file.parent, search=search)
    if path is None:
        return None
    return model_file(path) if path.is_dir() else path


def missing_mesh_message(where: str, uri: str, base_dir: Path, owner: str) -> str:
    """Say which collision mesh is missing and which folder the model path needs for it."""
    head = f"{where}: collision mesh {uri!r} {owner} not found (searched {base_dir} and the model path)"
    folder = folder_to_add(uri, base_dir)
    if folder is None:
        text = uri.strip()
        for scheme in ("model://", "package://"):
            if text.startswith(scheme) and (name := text[len(scheme) :].split("/", 1)[0]):
                # (the model path holds packages and models by name: the folder to add is their parent)
                return f"{head}; add the folder that holds {name}/ to the model path"
        return f"{head}; add the folder holding it to the model path"
    relative = uri.strip().removeprefix("file://")
    if (folder / relative).is_file():
        return f"{head}; it is {folder / relative}: add {folder} to the model path"
    return f"{head}; {uri!r} is relative to a folder on the model path, such as {folder}, which lacks it"
