"""The tree: listeners with simulation time, wake-ups, timers, the clock, halting."""

from __future__ import annotations

import pytest

from twin.bt import BehaviorTreeFactory, ManualClock, NodeStatus
from twin.bt.ticking import TimerQueue
from twin.bt.tree import MAX_WAKE_UP_RETICKS
from twin.core.errors import TreeError

from .helpers import v4


def test_listeners_get_time_path_uid_and_statuses(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A"/></Sequence>'), {"A": ["RUNNING", "SUCCESS"]})
    seen: list[tuple] = []
    r.tree.add_listener(lambda *event: seen.append(event))
    r.tick()
    r.tick(advance_ms=500)
    assert seen[0] == (0, "s", 1, NodeStatus.IDLE, NodeStatus.RUNNING)
    assert seen[2] == (500_000_000, "A", 2, NodeStatus.RUNNING, NodeStatus.SUCCESS)


def test_a_removed_listener_hears_nothing(rig) -> None:
    r = rig(v4('<Leaf name="A"/>'), {"A": ["SUCCESS"]})
    seen: list[tuple] = []
    remove = r.tree.add_listener(lambda *event: seen.append(event))
    remove()
    r.tick()
    assert seen == []


def test_skipped_is_never_stored_nor_reported(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A" _skipIf="true"/><Leaf name="B"/></Sequence>'), {"B": ["SUCCESS"]})
    r.tick()
    assert all("SKIPPED" not in (prev, new) for _, prev, new in r.transitions)
    assert r.tree.node("A").status is NodeStatus.IDLE


def test_the_root_is_reset_after_it_completes(rig) -> None:
    r = rig(v4('<Leaf name="A"/>'), {"A": ["FAILURE"]})
    assert r.tick() is NodeStatus.FAILURE
    assert r.tree.root.status is NodeStatus.IDLE


def test_a_clock_going_back_is_an_error() -> None:
    clock = ManualClock(1_000)
    tree = BehaviorTreeFactory().create_tree_from_text(v4("<AlwaysSuccess/>"), clock=clock)
    tree.tick_once()
    clock.t_ns = 0
    with pytest.raises(TreeError, match="went back"):
        tree.tick_once()


def test_halt_tree_halts_running_nodes(rig) -> None:
    r = rig(v4('<Sequence name="s"><Leaf name="A"/></Sequence>'), {"A": ["RUNNING"]})
    r.tick()
    r.recorder.calls = []
    r.tree.halt_tree()
    assert r.recorder.calls == [["A", "onHalted"]]
    assert all(node.status is NodeStatus.IDLE for node in r.tree.nodes)


def test_timers_fire_in_due_order_once_and_cancelled_ones_report_aborted() -> None:
    queue = TimerQueue()
    fired: list[tuple[str, bool]] = []
    queue.add(200, lambda aborted: fired.append(("late", aborted)))
    queue.add(100, lambda aborted: fired.append(("early", aborted)))
    cancelled = queue.add(150, lambda aborted: fired.append(("cancelled", aborted)))
    assert cancelled.cancel()
    queue.fire_due(99)
    assert fired == [("cancelled", True)]
    queue.fire_due(200)
    queue.fire_due(300)
    assert fired == [("cancelled", True), ("early", False), ("late", False)]
    assert queue.next_due_ns() is None


def test_walk_visits_nodes_depth_first_with_their_depth() -> None:
    tree = BehaviorTreeFactory().create_tree_from_text(
        v4(
            '<Sequence name="s"><Inverter name="i"><AlwaysFailure name="f"/></Inverter><AlwaysSuccess name="a"/></Sequence>'
        )
    )
    assert [(depth, node.name) for depth, node in tree.walk()] == [(0, "s"), (1, "i"), (2, "f"), (1, "a")]


# BT.CPP's Parallel.PauseWithRetry (tests/gtest_parallel.cpp): the Retry wakes the tree on every pass,
# a loop BT.CPP ends only when its Sleep timer fires on wall time.
PAUSE_WITH_RETRY = """
<root BTCPP_format="4">
  <BehaviorTree ID="TestTree">
    <Parallel>
      <Sequence>
        <Sleep msec="150"/>
        <Script code="paused := false"/>
        <Sleep msec="150"/>
      </Sequence>
      <Sequence>
        <Script code="paused := true; done := false"/>
        <RetryUntilSuccessful _while="paused" num_attempts="-1" _onHalted="done = true">
          <AlwaysFailure/>
        </RetryUntilSuccessful>
      </Sequence>
    </Parallel>
  </BehaviorTree>
</root>
"""


def test_a_tree_that_wakes_itself_forever_returns_running_after_the_re_tick_cap(caplog) -> None:
    clock = ManualClock()
    tree = BehaviorTreeFactory().create_tree_from_text(PAUSE_WITH_RETRY, clock=clock)
    passes = 0

    def count(t_ns, path, uid, prev, new) -> None:
        nonlocal passes
        passes += path == "AlwaysFailure::9" and new is NodeStatus.FAILURE

    tree.add_listener(count)
    assert tree.tick_once() is NodeStatus.RUNNING
    assert passes == MAX_WAKE_UP_RETICKS + 1
    assert "woke itself up 1000 times in one tick" in caplog.text
    assert tree.root_blackboard.get("done") == 0  # BT.CPP stores the script's false as int 0


def test_a_capped_tick_goes_on_at_a_later_time_as_btcpp_does() -> None:
    clock = ManualClock()
    tree = BehaviorTreeFactory().create_tree_from_text(PAUSE_WITH_RETRY, clock=clock)
    assert tree.tick_once() is NodeStatus.RUNNING
    clock.advance(150_000_000)
    assert tree.tick_once() is NodeStatus.RUNNING  # the first Sleep fired: paused := false halts the Retry
    assert tree.root_blackboard.get("done") == 1
    clock.advance(150_000_000)
    assert tree.tick_once() is NodeStatus.SUCCESS
