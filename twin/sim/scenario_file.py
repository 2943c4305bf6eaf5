"""Read a scenario file for a run: the YAML laid over the packaged defaults, a replay mission's start from its bag."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from twin.core.config import ConfigNode, build, load_yaml, location, merge
from twin.core.errors import ConfigError
from twin.sim.replay import with_replay_start
from twin.sim.scenario import DEFAULTS_PATH, ROBOT_SECTIONS, Scenario

__all__ = ["load_scenario", "with_fleet", "without_retired_keys"]


def load_scenario(path: Path) -> Scenario:
    """Load a scenario file laid over the packaged defaults.

    A `type: replay` mission with `initial_pose: bag` sets `robot.initial_pose` to the bag's
    first pose. Each `robots:` entry's sections are laid over the top-level ones (`with_fleet`).

    Raises:
        ConfigError: Naming file, line and key, if the file is unreadable or any key is wrong.
        BagError: If a replay mission's bag is unreadable or lacks its command or pose topic.
    """
    own = load_yaml(path)
    node = with_fleet(merge(load_yaml(DEFAULTS_PATH), own))
    scenario: Scenario = build(Scenario, node, key="")
    if scenario.tf.mode == "frame_prefix" and not scenario.robots:
        where = next((k for k, _ in own.value if k.value == "tf"), own) if isinstance(own, yaml.MappingNode) else own
        msg = (
            f"{location(where)}: tf.mode: frame_prefix names each robot's frames after its namespace and needs "
            "robots:; remove tf, or list the robots under robots:"
        )
        raise ConfigError(msg)
    # A scenario recorded in a bag (`--from-bag`) keeps the file it came from, where its nodes' modules are.
    source = scenario.source_path or Path(path).resolve()
    return with_replay_start(dataclasses.replace(scenario, source_path=source))


def with_fleet(node: ConfigNode) -> ConfigNode:
    """The scenario's node with each `robots:` entry laid over the top-level robot sections.

    A fleet of identical robots is then a list of names and poses; anything else about an entry
    (not a mapping, an unknown key) is left for the builder to name.
    """
    if not isinstance(node, yaml.MappingNode):
        return node
    fleet = next((v for k, v in node.value if k.value == "robots"), None)
    if not isinstance(fleet, yaml.SequenceNode):
        return node
    top = {k.value: (k, v) for k, v in node.value if k.value in ROBOT_SECTIONS}
    entries = []
    for entry in fleet.value:
        if not isinstance(entry, yaml.MappingNode):
            entries.append(entry)
            continue
        base = yaml.MappingNode("tag:yaml.org,2002:map", list(top.values()))
        base.start_mark = base.end_mark = entry.start_mark
        entries.append(merge(base, entry))
    laid = yaml.SequenceNode(fleet.tag, entries)
    laid.start_mark, laid.end_mark = fleet.start_mark, fleet.end_mark
    out = yaml.MappingNode(node.tag, [(k, laid if k.value == "robots" else v) for k, v in node.value])
    out.start_mark, out.end_mark = node.start_mark, node.end_mark
    return out


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
