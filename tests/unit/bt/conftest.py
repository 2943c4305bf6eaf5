"""Helpers for the behaviour-tree tests: build a tree from XML with recording leaves."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import pytest

from twin.bt import BehaviorTreeFactory, ManualClock, NodeStatus, Tree
from twin.bt.conformance import LeafCallRecorder, ScriptedAction, ScriptedCondition, Step


@dataclass
class Rig:
    """A tree with scripted leaves `Leaf`/`Cond` and a record of transitions and leaf calls."""

    tree: Tree
    clock: ManualClock
    recorder: LeafCallRecorder
    transitions: list[tuple[str, str, str]] = field(default_factory=list)

    def tick(self, *, exactly_once: bool = False, advance_ms: int = 0) -> NodeStatus:
        self.clock.advance(advance_ms * 1_000_000)
        self.transitions.clear()
        self.recorder.calls = []
        return self.tree.tick_exactly_once() if exactly_once else self.tree.tick_once()

    @property
    def calls(self) -> list[list[object]]:
        return self.recorder.calls

    def changes_of(self, path: str) -> list[tuple[str, str]]:
        return [(prev, new) for p, prev, new in self.transitions if p == path]


def _steps(raw: Sequence[str]) -> tuple[Step, ...]:
    return tuple(Step(status=NodeStatus[s], outputs={}) for s in raw)


@pytest.fixture
def rig() -> Callable[..., Rig]:
    """`rig(xml, scripts={path: [statuses]}, factory=None)` builds a tree on a manual clock."""

    def build(
        xml: str, scripts: dict[str, Sequence[str]] | None = None, factory: BehaviorTreeFactory | None = None
    ) -> Rig:
        recorder = LeafCallRecorder()
        leaf_scripts = {path: _steps(steps) for path, steps in (scripts or {}).items()}
        factory = factory or BehaviorTreeFactory()
        factory.register_node_type(ScriptedAction, "Leaf", leaf_scripts, recorder)
        factory.register_node_type(ScriptedCondition, "Cond", leaf_scripts, recorder)
        clock = ManualClock()
        tree = factory.create_tree_from_text(xml, clock=clock)
        result = Rig(tree=tree, clock=clock, recorder=recorder)
        tree.add_listener(lambda t, path, uid, prev, new: result.transitions.append((path, prev.name, new.name)))
        return result

    return build
