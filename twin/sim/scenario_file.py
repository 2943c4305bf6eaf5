"""Read a scenario file for a run: the YAML laid over the packaged defaults, a replay mission's start from its bag."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from twin.core.config import load_config
from twin.sim.replay import with_replay_start
from twin.sim.scenario import DEFAULTS_PATH, Scenario

__all__ = ["load_scenario", "without_retired_keys"]


def load_scenario(path: Path) -> Scenario:
    """Load a scenario file laid over the packaged defaults.

    A `type: replay` mission with `initial_pose: bag` sets `robot.initial_pose` to the bag's
    first pose.

    Raises:
        ConfigError: Naming file, line and key, if the file is unreadable or any key is wrong.
        BagError: If a replay mission's bag is unreadable or lacks its command or pose topic.
    """
    scenario = load_config(Scenario, path, defaults=DEFAULTS_PATH)
    # A scenario recorded in a bag (`--from-bag`) keeps the file it came from, where its nodes' modules are.
    source = scenario.source_path or Path(path).resolve()
    return with_replay_start(dataclasses.replace(scenario, source_path=source))


_RETIRED_TREE_MISSION_KEYS = ("follower", "planner", "progress")  # the grid stand-in's, retired with it


def without_retired_keys(text: str) -> str:
    """A recorded scenario (a bag's provenance) without the keys an older twin wrote for the grid stand-in.

    An older twin recorded `mission.follower`, `mission.planner` and `mission.progress` of every
    behaviour-tree mission (their defaults, which only the retired grid navigator read); they are
    dropped so that `--from-bag` re-runs such a bag. A scenario a user writes gets no such leniency.
    """
    data = yaml.safe_load(text)
    mission = data.get("mission") if isinstance(data, dict) else None
    if not isinstance(mission, dict) or mission.get("type") != "behavior_tree":
        return text
    if not any(key in mission for key in _RETIRED_TREE_MISSION_KEYS):
        return text
    for key in _RETIRED_TREE_MISSION_KEYS:
        mission.pop(key, None)
    return str(yaml.safe_dump(data, sort_keys=False, allow_unicode=True))
