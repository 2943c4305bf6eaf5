"""Node statuses, node kinds and port directions, spelled as BehaviorTree.CPP spells them."""

from __future__ import annotations

import enum
from typing import Final

__all__ = ["FAILURE", "IDLE", "RUNNING", "SKIPPED", "SUCCESS", "NodeKind", "NodeStatus", "PortDirection"]


class NodeStatus(enum.IntEnum):
    """The status of a node; the names are the strings of BT.CPP and of Nav2's BehaviorTreeLog."""

    IDLE = 0
    RUNNING = 1
    SUCCESS = 2
    FAILURE = 3
    SKIPPED = 4

    @property
    def is_completed(self) -> bool:
        """True for SUCCESS and FAILURE."""
        return self is NodeStatus.SUCCESS or self is NodeStatus.FAILURE

    @property
    def is_active(self) -> bool:
        """True for RUNNING, SUCCESS and FAILURE (BT.CPP `isStatusActive`)."""
        return self is not NodeStatus.IDLE and self is not NodeStatus.SKIPPED


IDLE: Final = NodeStatus.IDLE
RUNNING: Final = NodeStatus.RUNNING
SUCCESS: Final = NodeStatus.SUCCESS
FAILURE: Final = NodeStatus.FAILURE
SKIPPED: Final = NodeStatus.SKIPPED


class NodeKind(enum.Enum):
    """What a node type is; the values are the XML tags of `<TreeNodesModel>`."""

    ACTION = "Action"
    CONDITION = "Condition"
    CONTROL = "Control"
    DECORATOR = "Decorator"
    SUBTREE = "SubTree"


class PortDirection(enum.Enum):
    """The direction of a port; the values are the XML tags of `<TreeNodesModel>` without `_port`."""

    INPUT = "input"
    OUTPUT = "output"
    INOUT = "inout"
