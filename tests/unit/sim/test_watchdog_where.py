"""The watchdog's one-line answer to "where is the run stuck?" names the tree node, wherever it looks."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from twin.bt import BehaviorTreeFactory, ManualClock
from twin.sim.watchdog import WatchdogAbort, describe_thread, interrupt_main_thread

FOREVER = Path(__file__).resolve().parents[2] / "robustness" / "data" / "forever.xml"


def test_a_tree_spinning_on_wake_ups_is_named_at_every_sample() -> None:
    # Repeat forever over AlwaysSuccess never returns from one tick: the main thread alternates between the
    # nodes' ticks and the tree's own wake-up loop. Every sample must name a tree node, not only those that
    # land inside a node (the flaky case: a sample in Tree._take_wake_up named none).
    tree = BehaviorTreeFactory().create_tree_from_file(FOREVER, clock=ManualClock())
    main = threading.get_ident()
    wheres: list[str] = []
    waited: list[str] = []  # what the watcher saw before the main thread was in the tick

    def watch() -> None:
        # Sample only once the main thread is in the tick: on a loaded machine it may not have reached
        # `tick_once` by the first sample (that sample would name the test, rightly).
        deadline = time.monotonic() + 120.0
        while "tree node '" not in (seen := describe_thread(main)[0]) and time.monotonic() < deadline:
            waited.append(seen)
            time.sleep(0.001)
        for _ in range(80):
            time.sleep(0.002)
            wheres.append(describe_thread(main)[0])
        # As the watchdog stops a run: an exception raised in the main thread, whatever SIGINT's handler
        # is (an earlier test of the suite can leave one that does not raise, or SIG_IGN).
        interrupt_main_thread(main)

    threading.Thread(target=watch, daemon=True).start()
    try:
        tree.tick_once()  # a capped tick: 1000 re-ticks, about 40 s here
        raise AssertionError(f"the tree returned; the watcher saw: {(waited or wheres)[-3:]}")
    except WatchdogAbort:
        pass
    assert len(wheres) == 80
    unnamed = [w for w in wheres if "tree node '" not in w]
    assert not unnamed, unnamed[:3]
