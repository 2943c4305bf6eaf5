"""Which robot model recorded a bag: its `/robot_description` matched against the model folders.

A replay must run the robot the bag was recorded with: a Burger replayed as a Waffle turns with the
wrong wheel separation. The URDF's `<robot name>` is looked up first among the user's model
folders, then the project's own models; a name found in neither is matched by its drive wheels
(joint names, separation and radius, as `twin.world.urdf_wheels` reads them), so a Waffle Pi bag
runs on the Waffle's chassis, which has the same wheels. Nothing matched is an error naming what
the bag says and how to choose.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from twin.core.errors import ConfigError, WorldError
from twin.sim.scenario import PACKAGED_MODELS
from twin.world.urdf_wheels import UrdfWheels, wheels_from_urdf

__all__ = ["BagRobot", "robot_from_bag", "robot_from_urdf"]

_log = logging.getLogger(__name__)

#: How far a model's wheels may be from the URDF's to count as the same drive, m.
_SEPARATION_TOL_M = 0.002
_RADIUS_TOL_M = 0.001


@dataclass(frozen=True, kw_only=True, slots=True)
class BagRobot:
    """The model chosen for a bag's robot and why."""

    model: str
    reason: str


def _model_dirs(model_path: Sequence[Path]) -> list[Path]:
    """Model folders (with a model.config) on the user's path, then the project's, first name wins."""
    seen: set[str] = set()
    out: list[Path] = []
    for folder in (*model_path, PACKAGED_MODELS):
        if not folder.is_dir():
            continue
        for d in sorted(folder.iterdir()):
            if d.name not in seen and (d / "model.config").is_file():
                seen.add(d.name)
                out.append(d)
    return out


def _urdf_text(bag: Path) -> str | None:
    from twin.bag import open_bag, read_messages  # the bag readers load only for a replay

    if "/robot_description" not in {t.name for t in open_bag(bag).topics}:
        return None
    for m in read_messages(bag, ["/robot_description"]):
        return str(m.msg.data)
    return None


def _mentions(folder: Path, words: Sequence[str]) -> bool:
    """Whether one of the folder's SDF files names all `words` (cheap: no model is loaded for it)."""
    for sdf in folder.glob("*.sdf"):
        try:
            text = sdf.read_text(errors="replace")
        except OSError:
            continue
        if all(w in text for w in words):
            return True
    return False


def _same_wheels(folder: Path, wheels: UrdfWheels, model_path: Sequence[Path]) -> bool:
    from twin.world import load_robot

    if not _mentions(folder, (wheels.left_joint, wheels.right_joint)):
        return False
    try:
        drive = load_robot(folder.name, model_path=[folder.parent, *model_path]).drive
    except WorldError as err:
        _log.debug("model %s not compared with the bag's robot: %s", folder, err)
        return False
    return (
        drive is not None
        and drive.left_joint == wheels.left_joint
        and drive.right_joint == wheels.right_joint
        and abs(drive.wheel_separation_m - wheels.wheel_separation_m) <= _SEPARATION_TOL_M
        and abs(drive.wheel_radius_m - wheels.wheel_radius_m) <= _RADIUS_TOL_M
    )


def robot_from_urdf(urdf: str, model_path: Sequence[Path], *, where: str) -> BagRobot:
    """Choose the model for a robot described by `urdf` (see the module docstring).

    Args:
        urdf: The URDF text (a bag's `/robot_description`).
        model_path: The user's model folders, searched before the project's own models.
        where: What the URDF came from, for messages (the bag's path).

    Raises:
        ConfigError: If no model has the URDF's name or its wheels.
    """
    match = re.search(r"<robot\s[^>]*name\s*=\s*[\"']([^\"']+)", urdf)
    name = match.group(1) if match else None
    dirs = _model_dirs(model_path)
    if name is not None:
        for d in dirs:
            if d.name == name:
                return BagRobot(model=name, reason=f"/robot_description names {name}, found in {d.parent}")
    wheels = wheels_from_urdf(urdf)
    said = f"robot {name!r}" if name else "a robot without a name"
    if wheels is not None:
        said += (
            f" with wheels {wheels.left_joint}/{wheels.right_joint}, separation {wheels.wheel_separation_m:.4g} m, "
            f"radius {wheels.wheel_radius_m:.4g} m"
        )
        for d in dirs:
            if _same_wheels(d, wheels, model_path):
                return BagRobot(
                    model=d.name,
                    reason=f"/robot_description names {name!r}, not on the model path; {d.name} has its wheels "
                    f"({wheels.left_joint}/{wheels.right_joint}, {wheels.wheel_separation_m:.4g} m apart, "
                    f"radius {wheels.wheel_radius_m:.4g} m)",
                )
    names = ", ".join(d.name for d in dirs if d.parent == PACKAGED_MODELS) or "none"
    msg = (
        f"{where}: /robot_description describes {said}, and no model on the model path has that name or those "
        f"wheels; add its model folder with --model-path, or choose a model with --robot (the project has {names})"
    )
    raise ConfigError(msg)


def robot_from_bag(bag: Path, model_path: Sequence[Path]) -> BagRobot:
    """Choose the model for the robot a bag recorded, from its `/robot_description`.

    Raises:
        ConfigError: If the bag has no `/robot_description`, or nothing on the model path matches it.
        BagError: If the bag is unreadable.
    """
    urdf = _urdf_text(bag)
    if urdf is None:
        names = ", ".join(d.name for d in _model_dirs(()) if d.parent == PACKAGED_MODELS)
        msg = f"{bag}: no /robot_description says which robot recorded it; choose a model with --robot (e.g. {names})"
        raise ConfigError(msg)
    return robot_from_urdf(urdf, model_path, where=str(bag))
