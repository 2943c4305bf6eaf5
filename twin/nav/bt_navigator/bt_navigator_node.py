"""nav2_bt_navigator's node: ticks the navigation tree while a goal runs; its log and NavigateToPose feedback.

Status changes go to `/behavior_tree_log` (one message per tick that changed something, as Nav2's
RosTopicLogger); feedback (current pose, navigation time, distance remaining, recoveries) to
`/navigate_to_pose/feedback` (twin_msgs/NavigationFeedback, the fields of NavigateToPose's
feedback) at 10 Hz.
"""

from __future__ import annotations

from typing import Any

from twin.bag import BehaviorTreeLogEncoder, NavigationFeedbackEncoder
from twin.nav.bt_navigator.navigator import BtNavigator
from twin.nav.frames import Frames
from twin.node import PRIORITY_TREE, Encoded, Node

__all__ = ["BtNavigatorNode"]


class BtNavigatorNode(Node):
    """bt_navigator: ticks the navigation tree every bt_loop_duration while a goal runs."""

    FEEDBACK_TOPIC = "navigate_to_pose/feedback"

    def __init__(self, navigator: BtNavigator, frames: Frames) -> None:
        super().__init__("bt_navigator")
        log_pub = self.create_publisher(BehaviorTreeLogEncoder.msgtype, "behavior_tree_log", 10)
        log_encode = BehaviorTreeLogEncoder().encode
        feedback_pub = self.create_publisher(NavigationFeedbackEncoder.msgtype, self.FEEDBACK_TOPIC, 10)
        feedback_encode = NavigationFeedbackEncoder().encode
        tree = navigator.tree
        changes = navigator.changes
        loops = [0]
        period = max(1, round(0.1 / max(navigator.servers.config.bt_loop_duration_s, 1e-3)))

        def on_timer(t_ns: int) -> None:
            if not navigator.active:
                return
            running = navigator.tick()
            flushed = changes.flush()
            if flushed:
                events = [(c.t_ns, tree.node_by_uid(c.uid).name, c.prev.name, c.new.name) for c in flushed]
                log_pub.publish(Encoded((log_encode, (t_ns, events), events)))
            loops[0] += 1
            if running and loops[0] % period == 0:
                args = self._feedback(navigator, frames, t_ns)
                feedback_pub.publish(Encoded((feedback_encode, args, args)))

        rate = 1.0 / navigator.servers.config.bt_loop_duration_s
        self.create_rate_timer(rate, on_timer, priority=PRIORITY_TREE + 1)

    @staticmethod
    def _feedback(navigator: BtNavigator, frames: Frames, t_ns: int) -> tuple[Any, ...]:
        """NavigateToPose's feedback now, as NavigationFeedbackEncoder.encode takes it."""
        pose = frames.map_pose()
        remaining = navigator.distance_remaining(pose)
        speed = abs(frames.velocity[0])
        eta_ns = round(remaining / speed * 1e9) if speed > 0.01 else 0
        recoveries = navigator.servers.recoveries - navigator.recoveries_at_start
        return (t_ns, pose, (max(0, t_ns - navigator.started_ns), eta_ns), recoveries, remaining)
