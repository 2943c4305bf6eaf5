"""What the fleet tests share: a one-goal tree, each robot's location file, a run read back from its bag."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader

from tests.conftest import run_twin

# Each robot's tree: go to the pose its own location file names `goal`.
ONE_GOAL_TREE = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree"><GoToPose name="go" loc="goal"/></BehaviorTree>
</root>
"""

Messages = dict[str, list[tuple[int, Any]]]


def write_goals(folder: Path, goals: Mapping[str, tuple[float, float, float]]) -> tuple[Path, dict[str, Path]]:
    """Write the one-goal tree and a location file per robot (`goal: [x, y, yaw]`); return their paths."""
    tree = folder / "tree.xml"
    tree.write_text(ONE_GOAL_TREE)
    files = {}
    for name, (x, y, yaw) in goals.items():
        files[name] = folder / f"{name}_locations.yaml"
        files[name].write_text(f"goal: [{x}, {y}, {yaw}]\n")
    return tree, files


def simulate_and_read(scenario: Path, bag: Path, decode: Callable[[Any], bool]) -> tuple[dict[str, Any], Messages]:
    """Run `twin simulate SCENARIO --json` into `bag` (exit 0 asserted); return its summary and the bag's messages.

    Each topic's messages are (log time, message), the message decoded with rosbags where
    `decode(connection)` says so and None elsewhere (counted, not read).
    """
    result = run_twin("simulate", str(scenario), "--out", str(bag), "--json")
    assert result.returncode == 0, result.stderr
    messages: Messages = {}
    with AnyReader([bag]) as reader:
        for con, t_ns, raw in reader.messages():
            messages.setdefault(con.topic, []).append(
                (t_ns, reader.deserialize(raw, con.msgtype) if decode(con) else None)
            )
    return json.loads(result.stdout), messages
