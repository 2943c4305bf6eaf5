"""The TurtleBot3 mission nodes of the thesis and the sea-bass behaviour demos.

* `SetLocations` reads the location file named on the blackboard (`location_file`), shuffles the
  names with the seeded RNG it was given, and writes `num_locs`, `loc_names` (a queue) and
  `loc_poses` (name → pose). FAILURE if the file is unreadable or empty.
* `GetLocationFromQueue` pops the first name of `loc_names` into `target_location` and writes the
  shorter queue back; FAILURE when the queue is empty.
* `GoToPose` sends a navigation goal (x, y, yaw in frame `map`) for the location `loc` and is
  RUNNING until the navigator reports a result. The pose comes from `loc_poses` when that port is
  set, else from the location file on the blackboard (the thesis's v3 `tree.xml` only sets `loc`).
  Like the original, `on_halted` does not cancel the goal.

The navigator is anything with `send_goal(pose, frame_id) -> goal_id` and
`goal_status(goal_id) -> NavigationStatus` (see `Navigator`). `ScriptedNavigator` is a stand-in
that reaches each goal after a fixed number of polls, for tests and `twin tree log`.
"""

from __future__ import annotations

import difflib
import enum
import logging
import random
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, Protocol

from twin.bt.node import NodeConfig, StatefulActionNode, SyncActionNode, strip_pointer
from twin.bt.ports import PortSpec, bidirectional_port, input_port, output_port
from twin.bt.status import NodeStatus
from twin.bt.tree import Tree
from twin.bt.values import PortType
from twin.core.config import build, load_yaml
from twin.core.errors import ConfigError, TreeError

if TYPE_CHECKING:
    from twin.bt.factory import BehaviorTreeFactory

__all__ = [
    "LOCATION_NAMES",
    "LOCATION_POSES",
    "GetLocationFromQueue",
    "GoToPose",
    "NavigationStatus",
    "Navigator",
    "Pose2D",
    "ScriptedNavigator",
    "SetLocations",
    "load_locations",
    "register_mission_nodes",
]

_log = logging.getLogger(__name__)

LOCATION_FILE_KEY = "location_file"
MAP_FRAME = "map"


class Pose2D(NamedTuple):
    """A planar pose in the map frame."""

    x_m: float
    y_m: float
    yaw_rad: float


class NavigationStatus(enum.Enum):
    """What a navigator reports about a goal."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class Navigator(Protocol):
    """What `GoToPose` needs from the navigation stack (Nav2's NavigateToPose action)."""

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        """Start navigating to `pose`; a new goal replaces the previous one. Returns a goal id."""
        ...

    def goal_status(self, goal_id: int) -> NavigationStatus:
        """The state of a goal sent earlier."""
        ...


def _parse_names(text: str) -> deque[str]:
    return deque(part for part in text.split(";") if part) if text else deque()


LOCATION_NAMES = PortType("std::deque<std::string>", "sequence", py_type=deque, parse=_parse_names)
LOCATION_POSES = PortType("std::map<std::string, Pose>", "custom", py_type=dict)


def load_locations(path: Path) -> dict[str, Pose2D]:
    """Read a location file: a mapping of names to `[x, y, theta]` in the map frame.

    Raises:
        ConfigError: With file, line and key when the file is unreadable or malformed.
    """
    raw = build(dict[str, tuple[float, float, float]], load_yaml(Path(path)), key="")
    return {name: Pose2D(*values) for name, values in raw.items()}


def _location_file(node: SyncActionNode | StatefulActionNode) -> Path | None:
    entry = node.blackboard.get_entry(LOCATION_FILE_KEY)
    if entry is None or entry.value is None:
        return None
    return Path(str(entry.value))


class SetLocations(SyncActionNode):
    """Read the location file and write the shuffled names, their number and their poses."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """num_locs, loc_names, loc_poses (outputs)."""
        return (
            output_port("num_locs", int, description="number of locations in the file"),
            output_port("loc_names", LOCATION_NAMES, description="the location names, shuffled"),
            output_port("loc_poses", LOCATION_POSES, description="location name -> pose [x, y, theta]"),
        )

    def __init__(self, name: str, config: NodeConfig, rng: random.Random, log: logging.Logger = _log) -> None:
        super().__init__(name, config)
        self._rng = rng
        self._log = log

    def tick(self) -> NodeStatus:
        """Load, shuffle and publish the locations."""
        path = _location_file(self)
        if path is None:
            self._log.warning("%s: no %r on the blackboard", self.full_path, LOCATION_FILE_KEY)
            return NodeStatus.FAILURE
        try:
            locations = load_locations(path)
        except ConfigError as err:
            self._log.warning("%s: cannot load the locations: %s", self.full_path, err)
            return NodeStatus.FAILURE
        if not locations:
            self._log.warning("%s: no locations in %s", self.full_path, path)
            return NodeStatus.FAILURE
        names = list(locations)
        self._rng.shuffle(names)
        self.set_output("num_locs", len(names))
        # The behaviour demos' vision trees give only num_locs: their node writes the queue and the
        # poses to the blackboard's `loc_names` and `loc_poses` itself, and so does this one then.
        for port, value in (("loc_names", deque(names)), ("loc_poses", dict(locations))):
            if port in self.config.output_ports:
                self.set_output(port, value)
            else:
                self.blackboard.set(port, value)
        return NodeStatus.SUCCESS


class GetLocationFromQueue(SyncActionNode):
    """Pop the next location name from `loc_names` into `target_location`."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """loc_names (inout queue) and target_location (output)."""
        return (
            bidirectional_port("loc_names", LOCATION_NAMES, description="the queue of names left to visit"),
            output_port("target_location", str, description="the name taken from the queue"),
        )

    def __init__(self, name: str, config: NodeConfig, log: logging.Logger = _log) -> None:
        super().__init__(name, config)
        self._log = log

    def tick(self) -> NodeStatus:
        """Pop one name; FAILURE when the queue is empty."""
        remapped = "loc_names" in self.config.output_ports  # else the blackboard's, as the demos' trees use it
        if remapped:
            queue = deque(self.get_input("loc_names"))
        else:
            entry = self.blackboard.get_entry("loc_names")
            queue = deque(entry.value) if entry is not None and entry.value is not None else deque()
        if not queue:
            return NodeStatus.FAILURE
        target = queue.popleft()
        self.set_output("target_location", target)
        if remapped:
            self.set_output("loc_names", queue)
        else:
            self.blackboard.set("loc_names", queue)
        self._log.info("%s: targeting location %s", self.full_path, target)
        return NodeStatus.SUCCESS


class GoToPose(StatefulActionNode):
    """Navigate to a named location; RUNNING until the navigator reports success or failure."""

    @classmethod
    def provided_ports(cls) -> tuple[PortSpec, ...]:
        """The ports loc (required) and loc_poses."""
        return (
            input_port("loc", str, description="the name of the location to go to", required=True),
            input_port("loc_poses", LOCATION_POSES, description="location name -> pose (else the location file)"),
        )

    def __init__(self, name: str, config: NodeConfig, navigator: Navigator, log: logging.Logger = _log) -> None:
        super().__init__(name, config)
        self._navigator = navigator
        self._log = log
        self._goal_id: int | None = None
        self._file_cache: dict[Path, dict[str, Pose2D]] = {}
        self._location = ""
        self.failure: tuple[int, str] | None = None
        """(tree time, why) of this node's last failed goal, for the run's summary."""

    def _poses(self) -> Mapping[str, Pose2D] | None:
        if "loc_poses" in self.config.input_ports:
            ok, poses = self.read_input("loc_poses")
            if not ok:
                self._log.warning("%s: cannot read loc_poses: %s", self.full_path, poses)
                return None
            return poses  # type: ignore[no-any-return]
        path = _location_file(self)
        if path is None:
            self._log.warning("%s: neither loc_poses nor %r on the blackboard", self.full_path, LOCATION_FILE_KEY)
            return None
        if path not in self._file_cache:
            try:
                self._file_cache[path] = load_locations(path)
            except ConfigError as err:
                self._log.warning("%s: cannot load the locations: %s", self.full_path, err)
                return None
        return self._file_cache[path]

    def on_start(self) -> NodeStatus:
        """Send the goal of location `loc`."""
        ok, location = self.read_input("loc")
        self._location = str(location)
        if not ok:
            self._log.warning("%s: cannot read loc: %s", self.full_path, location)
            return NodeStatus.FAILURE
        poses = self._poses()
        if poses is None:
            self.failure = (
                self.now_ns(),
                f"goal {self._location!r} ({self.full_path}): no location poses (see the warning above)",
            )
            return NodeStatus.FAILURE
        if location not in poses:
            raise TreeError(unknown_location(str(location), poses))
        pose = Pose2D(*poses[location])
        self._goal_id = self._navigator.send_goal(pose, MAP_FRAME)
        self._log.info("%s: sent goal %s (%.3f, %.3f, %.3f) in %s", self.full_path, location, *pose, MAP_FRAME)
        return NodeStatus.RUNNING

    def on_running(self) -> NodeStatus:
        """Poll the navigator."""
        if self._goal_id is None:
            return NodeStatus.FAILURE
        status = self._navigator.goal_status(self._goal_id)
        if status is NavigationStatus.RUNNING:
            return NodeStatus.RUNNING
        if status is NavigationStatus.SUCCEEDED:
            self._log.info("%s: goal reached", self.full_path)
            return NodeStatus.SUCCESS
        reason_of = getattr(self._navigator, "failure_reason", None)
        reason = reason_of(self._goal_id) if reason_of is not None else ""
        self.failure = (
            self.now_ns(),
            f"goal {self._location!r} ({self.full_path}) failed: {reason or 'the navigator reported failure'}",
        )
        self._log.info("%s: failed to reach the goal", self.full_path)
        return NodeStatus.FAILURE

    def on_halted(self) -> None:
        """Nothing: like the original node, a halt does not cancel the goal."""


class ScriptedNavigator:
    """A stand-in navigator: each goal is RUNNING for `polls_to_arrive` polls, then succeeds.

    Args:
        polls_to_arrive: polls of `goal_status` before a goal reports its outcome (≥ 1).
        failing_goals: indices (0-based, in sending order) of goals that fail instead.
    """

    def __init__(self, polls_to_arrive: int = 3, failing_goals: Sequence[int] = ()) -> None:
        if polls_to_arrive < 1:
            msg = f"polls_to_arrive must be at least 1, got {polls_to_arrive}"
            raise ValueError(msg)
        self.polls_to_arrive = polls_to_arrive
        self.failing_goals = frozenset(failing_goals)
        self.goals: list[tuple[Pose2D, str]] = []
        self._polls: dict[int, int] = {}

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        """Record the goal and return its index."""
        self.goals.append((pose, frame_id))
        goal_id = len(self.goals) - 1
        self._polls[goal_id] = 0
        return goal_id

    def goal_status(self, goal_id: int) -> NavigationStatus:
        """RUNNING until the goal has been polled `polls_to_arrive` times."""
        self._polls[goal_id] = self._polls.get(goal_id, 0) + 1
        if self._polls[goal_id] < self.polls_to_arrive:
            return NavigationStatus.RUNNING
        return NavigationStatus.FAILED if goal_id in self.failing_goals else NavigationStatus.SUCCEEDED


def register_mission_nodes(
    factory: BehaviorTreeFactory, *, navigator: Navigator, rng: random.Random, log: logging.Logger = _log
) -> None:
    """Register SetLocations (shuffling with `rng`), GetLocationFromQueue and GoToPose (using `navigator`).

    Their lines go to `log`: the mission node's logger, which names the robot in a fleet.
    """
    factory.register_node_type(SetLocations, "SetLocations", rng, log)
    factory.register_node_type(GetLocationFromQueue, "GetLocationFromQueue", log)
    factory.register_node_type(GoToPose, "GoToPose", navigator, log)


def unknown_location(location: str, poses: Mapping[str, object]) -> str:
    """Say that `location` is not among `poses`: the nearest name, and the names (a long list cut short)."""
    return f"unknown location {location!r}{_nearest(location, poses)}"


def _nearest(location: str, poses: Mapping[str, object]) -> str:
    """`; did you mean 'x'? (the locations are a, b, ... and N more)` for a name not among `poses`."""
    names = sorted(poses)
    close = difflib.get_close_matches(location, names, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    shown = ", ".join(names[:10]) + (f" and {len(names) - 10} more" if len(names) > 10 else "")
    return f"{hint} (the locations are {shown or 'none'})"


def unknown_literal_location(tree: Tree, locations: Path) -> str | None:
    """A `GoToPose` whose `loc` names, as written in the tree, a location the file lacks (file:line), or None.

    Such a goal fails when it is first ticked, seconds into a run; said before the run instead. A
    `loc` read from the blackboard (`{location}`), or one of a node with `loc_poses`, is not judged.
    """
    poses = load_locations(locations)
    for _, node in tree.walk():
        if not isinstance(node, GoToPose):
            continue
        ports = node.config.input_ports
        written = ports.get("loc")
        if written is None or "loc_poses" in ports or strip_pointer(written) is not None or written in poses:
            continue
        where = f"{node.config.location}: " if node.config.location else ""
        return f"{where}<GoToPose loc={written!r}>: {locations} has no location {written!r}{_nearest(written, poses)}"
    return None
