"""SDF loading as Gazebo reads SDFormat 1.3 to 1.11 (Classic and gz-sim).

What is understood:

- `<world>`, `<model>` (nested), `<include>` (`model://`, `package://`, `file://` and relative
  URIs; `<name>`, `<pose>`, `<static>`, `<placement_frame>`, `<plugin>`, `merge="true"`), with
  model.config's choice of SDF file;
- `<static>`, links, joints, `<frame>` elements and pose composition: defaults of every SDF version
  (link poses in the model frame, joint poses in the child link frame, collision/visual/sensor poses
  in the link frame) and SDF 1.7+ `relative_to` (any frame of the scope, `::` into nested models,
  `__model__`), `placement_frame` (1.8), `degrees` and `quat_xyzw` poses (1.9);
- joint axes expressed in the model frame (SDF 1.4, `use_parent_model_frame` in 1.5/1.6,
  `expressed_in` in 1.7+), converted to the joint frame;
- a world's `<state>` block: model and link poses (world frame), nested model states,
  `<insertions>` and `<deletions>`, as Gazebo Classic applies it when it loads a world;
- collision geometry: box, cylinder, cone, sphere, plane, capsule, ellipsoid, polyline, mesh.

A missing visual mesh, an include that cannot be resolved offline, a plugin the twin does not run
and an element it does not know are warnings (each once), collected in `World.warnings`. A
missing collision mesh, malformed XML, a file that is not SDF, a missing `model://` include and a
frame that does not exist are `WorldError`s naming file and line.

This module assembles a world (or a model) from the parts: reading the documents and following
includes (`twin.world.sdf_parse`), where include and mesh URIs point (`twin.world.paths`), and
frames and poses (`twin.world.sdf_frames`).
"""

from __future__ import annotations

import contextlib
import gc
import logging
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from twin.core.errors import WorldError
from twin.world._xml import FarPoseError, XmlNode, parse_pose
from twin.world.paths import find_model_dir, model_file, search_path
from twin.world.sdf_frames import ModelBuilder, Scope, StateOverrides, collect_state
from twin.world.sdf_parse import UNSUPPORTED_WORLD, MissingIncludes, RawModel, SdfReader, second_model_message
from twin.world.types import Light, Model, Physics, Plugin, World, frozen_matrix

__all__ = ["MissingIncludes", "load_model", "load_world"]

_log = logging.getLogger(__name__)


def _physics(world: XmlNode) -> Physics:
    nodes = list(world.findall("physics"))
    chosen = next((n for n in nodes if (n.get("default") or "").lower() in ("1", "true")), nodes[0] if nodes else None)
    gravity_node = world.find("gravity")
    if gravity_node is None and chosen is not None:
        gravity_node = chosen.find("gravity")
    gravity = gravity_node.as_floats(3) if gravity_node is not None and gravity_node.text else (0.0, 0.0, -9.8)
    if chosen is None:
        return Physics(gravity_mps2=(gravity[0], gravity[1], gravity[2]))
    return Physics(
        max_step_size_s=chosen.float_at("max_step_size", 0.001),
        real_time_update_rate_hz=chosen.float_at("real_time_update_rate", 1000.0),
        real_time_factor=chosen.float_at("real_time_factor", 1.0),
        gravity_mps2=(gravity[0], gravity[1], gravity[2]),
    )


def _vector3(node: XmlNode, tag: str, default: tuple[float, float, float]) -> tuple[float, float, float]:
    child = node.find(tag)
    if child is None or not child.text:
        return default
    x, y, z = child.as_floats(3)
    return (x, y, z)


def _rgba(
    node: XmlNode | None, tag: str, default: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    """A colour element (`r g b [a]`), or `default` where it is absent."""
    child = node.find(tag) if node is not None else None
    if child is None or not child.text:
        return default
    values = child.as_floats()
    if len(values) not in (3, 4):
        msg = f"{child.where}: <{tag}> needs 3 or 4 numbers (r g b [a]), got {len(values)}"
        raise WorldError(msg)
    return (values[0], values[1], values[2], values[3] if len(values) == 4 else 1.0)


def _world_from_node(loader: SdfReader, world_node: XmlNode, version: tuple[int, int], path: Path) -> World:
    raw_models: list[RawModel] = []
    lights: list[Light] = []
    plugins: list[Plugin] = []
    frames: list[XmlNode] = []
    state_nodes: list[XmlNode] = []
    for child in world_node.children:
        tag = child.tag
        if tag == "model":
            raw_models.append(loader.parse_model(child, version, path, parent_static=False))
        elif tag == "include":
            included = loader.include(child, path, parent_static=False)
            if included is not None:
                raw_models.append(included)
        elif tag == "frame":
            frames.append(child)
        elif tag == "plugin":
            plugins.append(loader.plugin(child))
        elif tag == "light":
            lights.append(
                Light(
                    name=child.get("name") or "",
                    type=child.get("type") or "",
                    T_world=frozen_matrix(parse_pose(child.find("pose"))),
                    direction=_vector3(child, "direction", (0.0, 0.0, -1.0)),
                    diffuse_rgba=_rgba(child, "diffuse", (1.0, 1.0, 1.0, 1.0)),
                )
            )
        elif tag == "state":
            state_nodes.append(child)
        elif tag in UNSUPPORTED_WORLD:
            loader.unknown.append(child)
            loader.warn(f"unsupported:{tag}", f"{child.where}: <{tag}> is not supported: {UNSUPPORTED_WORLD[tag]}")
        else:
            loader.check_known("world", child)

    # <state>: deletions and insertions change the model list; poses override placement.
    for state in state_nodes:
        deleted = {n.text for d in state.findall("deletions") for n in d.findall("name")}
        if deleted:
            raw_models = [m for m in raw_models if m.name not in deleted]
        for insertions in state.findall("insertions"):
            for model_node in insertions.findall("model"):
                raw_models.append(loader.parse_model(model_node, version, path, parent_static=False))
    names: dict[str, RawModel] = {}
    for raw in raw_models:
        if raw.name in names:
            raise WorldError(second_model_message(raw, names[raw.name], "the world"))
        names[raw.name] = raw
    overrides = StateOverrides()
    for state in state_nodes:
        found = collect_state(loader, state, names)
        overrides.models.update(found.models)
        overrides.links.update(found.links)
        overrides.far.update(found.far)

    # The world is a scope too: models and frames may be placed relative to each other (SDF 1.7+).
    world_raw = RawModel(
        name=world_node.get("name") or "default", node=world_node, version=version, file=path, static=True, pose=None
    )
    world_raw.models = raw_models
    world_raw.frames = frames
    loader.frames_named_apart(world_raw)
    scope = Scope(world_raw)
    # Inside the world scope "__model__" is the world frame; SDF spells it "world".
    scope.define("world", np.eye(4))
    models = []
    for raw in raw_models:
        try:
            far = overrides.far.get(raw.name)
            if far is not None:
                raise far
            T = scope.T(raw.name, raw.node.where)
            models.append(ModelBuilder(loader).build_model(raw, scope.nested(raw.name), T, "", overrides))
        except FarPoseError as err:  # e.g. furniture that fell through the floor before the world was saved
            loader.warn(
                f"far:{raw.name}",
                f"{err.where}: a <pose> {err.distance_m:g} m from its frame's origin, beyond any world, places "
                f"model {raw.name!r}: left out",
            )
    return World(
        name=world_raw.name,
        models=tuple(models),
        lights=tuple(lights),
        plugins=tuple(plugins),
        physics=_physics(world_node),
        ambient_rgba=_rgba(world_node.find("scene"), "ambient", (0.4, 0.4, 0.4, 1.0)),
        background_rgba=_rgba(world_node.find("scene"), "background", (0.7, 0.7, 0.7, 1.0)),
        unknown=tuple(loader.unknown),
        warnings=tuple(loader.warnings),
        source=path,
        sdf_version=f"{version[0]}.{version[1]}",
    )


def load_world(
    path: Path | str,
    *,
    model_path: Sequence[Path | str] = (),
    missing_includes: MissingIncludes = "error",
    env: dict[str, str] | None = None,
) -> World:
    """Load an SDF world file (or a model file, as a world holding just that model).

    Args:
        path: A `.world`/`.sdf` file, or a model folder with a model.config.
        model_path: Folders holding model folders, searched for `model://NAME` after
            `TWIN_MODEL_PATH` and before `GAZEBO_MODEL_PATH` / `GZ_SIM_RESOURCE_PATH`.
        missing_includes: `"error"` (default) fails on a `model://` include that is not on the
            model path; `"warn"` skips it with a warning, as Gazebo Classic does. Web URIs
            (Fuel) never fail: Ground Plane and Sun have built-in stand-ins, others are skipped
            with a warning.
        env: Environment to read those variables from (defaults to `os.environ`).

    Raises:
        WorldError: On malformed XML (file:line:column), a file that is not SDF, an include that
            is not on the model path, a missing collision mesh, or an inconsistent frame graph.
    """
    # The loader makes a few hundred thousand small objects and no garbage cycles: the cyclic
    # collector, run thousands of times meanwhile over them all, would cost a third of the time.
    with _collector_paused():
        return _load_world(Path(path), model_path=model_path, missing_includes=missing_includes, env=env)


@contextlib.contextmanager
def _collector_paused() -> Iterator[None]:
    """Pause Python's cyclic garbage collector (reference counting still frees everything else)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _load_world(
    path: Path, *, model_path: Sequence[Path | str], missing_includes: MissingIncludes, env: dict[str, str] | None
) -> World:
    loader = SdfReader(search_path(model_path, env), missing_includes)
    if path.is_dir():
        path = model_file(path)
    root, version = loader.read_sdf(path)
    world_node = root.find("world")
    if world_node is not None:
        others = [w for w in root.findall("world") if w is not world_node]
        if others:  # (Gazebo too runs the first; the others would be ignored without a word)
            names = ", ".join(repr(w.get("name") or "") for w in others)
            loader.warn(
                "worlds",
                f"{path}:{others[0].line}: the file holds {len(others) + 1} worlds; the twin loads the first, "
                f"{world_node.get('name') or ''!r}, and not {names}",
            )
        return _world_from_node(loader, world_node, version, path)
    model_node = root.find("model")
    if model_node is None:
        children = ", ".join(f"<{c.tag}>" for c in root.children) or "nothing"
        msg = f"{path}:{root.line}: <sdf> holds {children}; expected a <world> or a <model>"
        raise WorldError(msg)
    loader.include_stack.append(path)
    raw = loader.parse_model(model_node, version, path, parent_static=False)
    holder = RawModel(name="__world__", node=root, version=version, file=path, static=True, pose=None)
    holder.models = [raw]
    scope = Scope(holder)
    model = ModelBuilder(loader).build_model(
        raw, scope.nested(raw.name), scope.T(raw.name, raw.node.where), "", StateOverrides()
    )
    return World(
        name=raw.name,
        models=(model,),
        unknown=tuple(loader.unknown),
        warnings=tuple(loader.warnings),
        source=path,
        sdf_version=f"{version[0]}.{version[1]}",
    )


def load_model(
    name_or_path: Path | str, *, model_path: Sequence[Path | str] = (), env: dict[str, str] | None = None
) -> Model:
    """Load one model by name (`turtlebot3_waffle`, `model://turtlebot3_waffle`) or path.

    The model's own `<pose>` is dropped: the model frame is the world frame, as when a robot is
    spawned at the origin. Problems that do not stop loading (a missing visual mesh, a plugin the
    twin does not run) are logged as warnings.

    Raises:
        WorldError: If the model cannot be found or loaded.
    """
    search = search_path(model_path, env)
    text = str(name_or_path)
    candidate = Path(text).expanduser()
    if candidate.exists():
        path = model_file(candidate) if candidate.is_dir() else candidate
    else:
        name = text.split("://", 1)[1] if "://" in text else text
        folder = find_model_dir(name, search)
        if folder is None:
            msg = (
                f"model {text!r} not found: it is not a file and no folder {name!r} is on the model path "
                f"[{', '.join(str(p) for p in search) or 'empty'}]; add the folder holding it to the model path "
                "(a scenario's world.model_path, --model-path or TWIN_MODEL_PATH)"
            )
            raise WorldError(msg)
        path = model_file(folder)
    loader = SdfReader(search)
    root, version = loader.read_sdf(path)
    node = root.find("model")
    if node is None:
        what = "a world" if root.find("world") is not None else "no <model>"
        msg = f"{path}:{root.line}: expected a <model>, but the file holds {what}"
        raise WorldError(msg)
    loader.include_stack.append(path)
    raw = loader.parse_model(node, version, path, parent_static=False)
    raw.pose = None
    raw.pose_override = None
    holder = RawModel(name="__spawn__", node=root, version=version, file=path, static=True, pose=None)
    holder.models = [raw]
    scope = Scope(holder)
    model = ModelBuilder(loader).build_model(raw, scope.nested(raw.name), np.eye(4), "", StateOverrides())
    for warning in loader.warnings:
        _log.warning("%s", warning)
    return model
