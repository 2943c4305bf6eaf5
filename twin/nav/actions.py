"""Nav2's actions as the twin runs them in process: a goal's state, its result, and its record.

The BT leaves (action clients) send goals by Nav2's action names and poll them; the servers
(planner, controller, behaviours) finish them. In ROS this is rclcpp_action's goal handle.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["ActionGoal", "ActionState", "ActionUpdate"]


class ActionState(enum.Enum):
    """State of a goal on an action server."""

    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


@dataclass(frozen=True, kw_only=True, slots=True)
class ActionUpdate:
    """A goal's state and, once it succeeded, its result fields (e.g. `path`)."""

    state: ActionState
    result: Mapping[str, Any] = field(default_factory=dict)


@dataclass(slots=True)
class ActionGoal:
    """One goal on an action server: its request, state, result and failure reason."""

    server: str
    request: dict[str, Any]
    state: ActionState = ActionState.RUNNING
    result: dict[str, Any] = field(default_factory=dict)
    reason: str = ""
