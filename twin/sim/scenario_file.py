"""Read a scenario file for a run: the YAML laid over the packaged defaults, a replay mission's start from its bag."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from twin.core.config import load_config
from twin.sim.replay import with_replay_start
from twin.sim.scenario import DEFAULTS_PATH, Scenario

__all__ = ["load_scenario"]


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
