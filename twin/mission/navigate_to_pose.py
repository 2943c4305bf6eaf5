"""GoToPose's navigator on Nav2: each goal is a NavigateToPose goal to bt_navigator.

The mission's `GoToPose` (`twin.mission.bt_nodes`) talks to any `Navigator`; `Nav2Navigator` is the
one for Nav2's stack, as the thesis's GoToPose is a NavigateToPose action client.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from twin.mission.bt_nodes import NavigationStatus, Pose2D
from twin.nav.actions import ActionState
from twin.nav.bt_navigator.navigator import BtNavigator

__all__ = ["Nav2Navigator"]

_STATUS = {
    ActionState.RUNNING: NavigationStatus.RUNNING,
    ActionState.SUCCEEDED: NavigationStatus.SUCCEEDED,
    ActionState.FAILED: NavigationStatus.FAILED,
}


class Nav2Navigator:
    """The mission's navigator: `GoToPose` sends NavigateToPose goals to the bt_navigator."""

    #: The mission node publishes the navigator's own plans; Nav2's planner_server publishes its paths itself.
    plans = 0
    path: Sequence[tuple[float, float]] = ()

    def __init__(self, navigator: Callable[[], BtNavigator | None]) -> None:
        self._navigator = navigator

    def _nav(self) -> BtNavigator:
        nav = self._navigator()
        if nav is None:
            msg = "the mission sent a goal before bt_navigator was started"
            raise RuntimeError(msg)
        return nav

    def send_goal(self, pose: Pose2D, frame_id: str) -> int:
        """Send a NavigateToPose goal (map frame)."""
        return self._nav().navigate((pose.x_m, pose.y_m, pose.yaw_rad))

    def goal_status(self, goal_id: int) -> NavigationStatus:
        """The goal's state."""
        return _STATUS[self._nav().status(goal_id)]

    def failure_reason(self, goal_id: int) -> str:
        """Why the goal failed."""
        return self._nav().reason(goal_id)

    def command(self, t_ns: int, x_m: float, y_m: float, yaw_rad: float) -> tuple[float, float]:
        """Nav2 commands the robot itself; the mission publishes nothing."""
        return (0.0, 0.0)
