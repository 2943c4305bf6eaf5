"""A loaded tree: ticking on the simulation clock, timers, wake-ups and status listeners.

`Tree.tick_once()` is BT.CPP's `Tree::tickOnce()`: it fires the timers that are due, ticks the root,
and ticks it again at once while the root is RUNNING and some node emitted a wake-up signal (a
`SequenceWithMemory`, `Repeat` or `RetryUntilSuccessful` after an instant child, a timer that
fired), at most `MAX_WAKE_UP_RETICKS` times. `tick_exactly_once()` ticks the root once. A
completed root is reset to IDLE. A tree from a v3 file (`btcpp3`) ticks as BT.CPP 3.8 does:
`tick_once()` is its `tickRoot()`, one pass whatever wake-ups were emitted.

Time comes from the clock the tree is given (a callable returning integer nanoseconds). Timers
(`Delay`, `Timeout`, `Sleep`) are due at `start + delay` on that clock and fire at the start of the
first tick at or after that time: what BT.CPP's timer thread does during the sleep between two
ticks happens here, deterministically, before the root is ticked. A timer of 0 ms started during
a `tick_once()` pass (v4) fires before the wake-up check of that pass, as BT.CPP's timer thread
almost always does.

Listeners get every stored status change: `listener(t_ns, node_path, uid, prev, new)`.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterator, Sequence
from typing import Final

from twin.bt.blackboard import Blackboard
from twin.bt.node import TreeNode
from twin.bt.status import FAILURE, RUNNING, SUCCESS, NodeStatus
from twin.bt.ticking import TickContext
from twin.core.errors import TreeError

_NEVER: Final = 2**63 - 1  # a settled tick with no wake time repeats until something changes

#: How many times one `tick_once()` ticks the root again on wake-ups. BT.CPP's loop has no count:
#: a node that wakes the tree on every pass (a RetryUntilSuccessful over a failing child) spins
#: until wall time lets a timer fire. A tick takes no simulated time, so such a loop would never
#: end here; past this many re-ticks the tick returns the root's status (RUNNING) and the loop
#: goes on at the next tick, a later simulated time. The recorded cases need at most 3.
MAX_WAKE_UP_RETICKS: Final = 1000

_log = logging.getLogger(__name__)

__all__ = [
    "MAX_WAKE_UP_RETICKS",
    "ManualClock",
    "StatusListener",
    "SubtreeInstance",
    "Tree",
]

StatusListener = Callable[[int, str, int, NodeStatus, NodeStatus], None]


class ManualClock:
    """A clock a caller advances by hand; call it for the time in nanoseconds.

    Args:
        start_ns: the initial time.
    """

    __slots__ = ("t_ns",)

    def __init__(self, start_ns: int = 0) -> None:
        self.t_ns = start_ns

    def __call__(self) -> int:
        """The current time in nanoseconds."""
        return self.t_ns

    def advance(self, dt_ns: int) -> None:
        """Move the time forward.

        Raises:
            ValueError: If `dt_ns` is negative.
        """
        if dt_ns < 0:
            msg = f"the clock cannot go back ({dt_ns} ns)"
            raise ValueError(msg)
        self.t_ns += dt_ns


@dataclasses.dataclass(frozen=True, kw_only=True, slots=True)
class SubtreeInstance:
    """One instantiated (sub)tree: its path (empty for the main tree), tree ID and blackboard."""

    instance_name: str
    tree_id: str
    blackboard: Blackboard


class Tree(TickContext):
    """A tree ready to tick. Build it with `BehaviorTreeFactory.create_tree_*`.

    Args:
        root: the root node.
        nodes: every node, in creation order (uid order).
        subtrees: the main tree first, then each SubTree instance.
        clock: simulation time in integer nanoseconds.
        btcpp3: tick as BT.CPP 3.8 (Nav2 Humble's) ticks a v3 file: `tick_once` is its `tickRoot()`,
            one pass of the root whatever wake-ups were emitted, and no node asks for one (3.8's
            SequenceStar, Repeat and RetryUntilSuccessful go on past an instant child in the same
            tick, where 4.x returns RUNNING and wakes the tree).
    """

    def __init__(
        self,
        *,
        root: TreeNode,
        nodes: Sequence[TreeNode],
        subtrees: Sequence[SubtreeInstance],
        clock: Callable[[], int],
        btcpp3: bool = False,
    ) -> None:
        super().__init__(clock)
        self.btcpp3 = btcpp3
        self.root = root
        self.nodes: tuple[TreeNode, ...] = tuple(nodes)
        self.subtrees: tuple[SubtreeInstance, ...] = tuple(subtrees)
        self._listeners: tuple[StatusListener, ...] = ()
        self._reticks_capped = False
        self._by_uid = {node.uid: node for node in self.nodes}
        for node in self.nodes:
            node._attach(self, None)
        # settled ticks (see tick_unless_settled)
        self._timers_fired = 0
        self._settled: tuple[int, object, int] | None = None
        self._timed = tuple(node for node in self.nodes if type(node).wake_ns is not TreeNode.wake_ns)
        self.log = _log
        """Where the tree's own warnings go (its owner's node logger names the node and the robot)."""

    # -- introspection -------------------------------------------------------------------------

    @property
    def root_blackboard(self) -> Blackboard:
        """The blackboard of the main tree."""
        return self.subtrees[0].blackboard

    def node(self, path: str) -> TreeNode:
        """The node with a full path.

        Raises:
            KeyError: If there is none.
        """
        for node in self.nodes:
            if node.full_path == path:
                return node
        raise KeyError(path)

    def node_by_uid(self, uid: int) -> TreeNode:
        """The node with a uid.

        Raises:
            KeyError: If there is none.
        """
        return self._by_uid[uid]

    def walk(self) -> Iterator[tuple[int, TreeNode]]:
        """(depth, node) in depth-first order from the root."""
        stack: list[tuple[int, TreeNode]] = [(0, self.root)]
        while stack:
            depth, node = stack.pop()
            yield depth, node
            stack.extend((depth + 1, child) for child in reversed(node.children_nodes()))

    # -- listeners -----------------------------------------------------------------------------

    def add_listener(self, listener: StatusListener) -> Callable[[], None]:
        """Call `listener(t_ns, node_path, uid, prev, new)` on every status change.

        Returns:
            A function that removes the listener.
        """
        self._set_listeners((*self._listeners, listener))

        def remove() -> None:
            self._set_listeners(tuple(item for item in self._listeners if item is not listener))

        return remove

    def _set_listeners(self, listeners: tuple[StatusListener, ...]) -> None:
        # Nodes call the dispatcher only while someone listens: no call per change otherwise.
        self._listeners = listeners
        notify = self._dispatch if listeners else None
        for node in self.nodes:
            node._notify = notify

    def _dispatch(self, node: TreeNode, prev: NodeStatus, new: NodeStatus) -> None:
        listeners = self._listeners
        if listeners:
            t_ns = self._now_ns
            config = node._config
            for listener in listeners:
                listener(t_ns, config.path, config.uid, prev, new)

    # -- ticking -------------------------------------------------------------------------------

    def _begin_tick(self) -> None:
        now = self.clock()
        if now < self._now_ns:
            msg = f"the tree's clock went back from {self._now_ns} ns to {now} ns"
            raise TreeError(msg)
        self._now_ns = now
        self._timers_fired = self.timers.fire_due(now)

    def _woken_again(self) -> bool:
        """Whether the pass just made woke the tree (`tick_once`'s loop asks after every pass).

        A timer of 0 ms started in the pass is already due: BT.CPP's timer thread fires it, and it
        wakes the tree, before `tickOnce` looks for a wake-up (almost always: it is a race there), so
        it fires here at the same moment. Longer timers wait for a later tick, as in `_begin_tick`.
        """
        if self.btcpp3:  # 3.8's tickRoot() ticks once; a wake-up only ends the sleep before the next tick
            self._take_wake_up()
            return False
        self._timers_fired += self.timers.fire_due(self._now_ns)
        return self._take_wake_up()

    def tick_once(self) -> NodeStatus:
        """Tick the root; tick it again at once while it is RUNNING and a wake-up was emitted (v4 files).

        A tree from a v3 file (`btcpp3`) is ticked once, as BT.CPP 3.8's `tickRoot()` does. At most
        `MAX_WAKE_UP_RETICKS` re-ticks: then the root's status (RUNNING) is returned and the next
        call goes on.

        Raises:
            TickError: If a node fails; the tree keeps the state it had at that point.
        """
        return self._tick(None)

    def tick_unless_settled(self, external: Callable[[], object] | None = None) -> NodeStatus | None:
        """Tick as `tick_once`, or return None when that tick would repeat the previous one exactly.

        A tick settles when it ticked only nodes whose type `settles`, changed no node's status,
        wrote nothing to the blackboard, fired no timer, emitted no wake-up, left `external()` (what
        the tree's leaves read from outside it, e.g. the state of the servers they call) as it found
        it, and returned RUNNING. Ticking again repeats it exactly until the blackboard or `external()`
        changes or the clock reaches a timer or a node's `wake_ns()`: until then this returns None and
        ticks nothing. Skipped ticks change nothing a listener or the blackboard could see.

        Raises:
            TickError: If a node fails.
        """
        settled = self._settled
        if settled is not None:
            version, seen, wake_ns = settled
            if (
                self.clock() < wake_ns
                and self.subtrees[0].blackboard.version == version
                and (external is None or external() == seen)
            ):
                return None
        return self._tick(external)

    def _tick(self, external: Callable[[], object] | None) -> NodeStatus:
        board = self.subtrees[0].blackboard
        version, changes = board.version, self._status_changes
        seen = external() if external is not None else None
        self._settled = None
        self._unsettled = False
        self._begin_tick()
        root = self.root
        status = root.execute_tick()
        woken = False
        reticks = 0
        while status is RUNNING and self._woken_again():
            woken = True
            if reticks == MAX_WAKE_UP_RETICKS:
                self._note_reticks_capped()
                break
            reticks += 1
            status = root.execute_tick()
        if status is SUCCESS or status is FAILURE:
            root.reset_status()
        elif (
            not self._unsettled
            and not woken
            and self._timers_fired == 0
            and self._status_changes == changes
            and board.version == version
            and (external is None or external() == seen)
        ):
            wakes = [w for node in self._timed if (w := node.wake_ns()) is not None]
            due = self.timers.next_due_ns()
            if due is not None:
                wakes.append(due)
            self._settled = (version, seen, min(wakes, default=_NEVER))
        return status

    def _note_reticks_capped(self) -> None:
        if not self._reticks_capped:
            self._reticks_capped = True
            self.log.warning(
                "the tree woke itself up %d times in one tick at t=%.3f s (a loop BT.CPP ends only when "
                "wall time passes); it goes on at the next tick",
                MAX_WAKE_UP_RETICKS,
                self._now_ns * 1e-9,
            )

    def tick_exactly_once(self) -> NodeStatus:
        """Tick the root once, whatever wake-ups were emitted.

        Raises:
            TickError: If a node fails.
        """
        self._settled = None
        self._begin_tick()
        root = self.root
        status = root.execute_tick()
        if status is SUCCESS or status is FAILURE:
            root.reset_status()
        return status

    def halt_tree(self) -> None:
        """Halt every node (the root first, then each node as a safety net) and reset the root."""
        self._settled = None
        self._now_ns = max(self._now_ns, self.clock())
        self.root.halt_node()
        for _, node in self.walk():
            node.halt_node()
        self.root.reset_status()
