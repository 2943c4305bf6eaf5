"""The factory: node types by name, scripting enums, plugins, and tree creation from XML.

    factory = BehaviorTreeFactory()                 # BT.CPP 4.x built-ins
    factory.register_node_type(GoToPose, "GoToPose", navigator)
    tree = factory.create_tree_from_file(Path("trees/tree.xml"), clock=sim_clock)
    status = tree.tick_once()

Plugins are packages that expose, in the entry-point group `twin.bt_nodes`, a callable taking the
factory (like BT.CPP's `BT_REGISTER_NODES`); `load_plugins()` calls each of them.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from twin.bt import actions, controls, decorators
from twin.bt.blackboard import Blackboard
from twin.bt.loader import TreeParser
from twin.bt.node import (
    DecoratorFunction,
    NodeConfig,
    NodeManifest,
    SimpleActionNode,
    SimpleConditionNode,
    SimpleDecoratorNode,
    TickFunction,
    TreeNode,
)
from twin.bt.ports import PortSpec
from twin.bt.status import NodeKind, NodeStatus
from twin.bt.tree import ManualClock, Tree
from twin.bt.values import PortType
from twin.core.errors import TreeError

__all__ = ["PLUGIN_GROUP", "BehaviorTreeFactory", "NodeBuilder"]

PLUGIN_GROUP: Final = "twin.bt_nodes"


def _may_declare_group(group: str) -> bool:
    """Whether any installed distribution's `entry_points.txt` names `group` (a cheap look before the real one).

    Reads the metadata directories on `sys.path` directly; anything it cannot read this way (a zip or egg
    file on the path, an unreadable directory) answers True, so `importlib.metadata` then decides.
    """
    import os
    import sys

    header = f"[{group}]"
    for entry in sys.path:
        directory = entry or "."
        if not os.path.isdir(directory):
            if os.path.exists(directory):
                return True  # a zip or egg: let importlib.metadata read it
            continue
        try:
            names = os.listdir(directory)
        except OSError:
            return True
        for name in names:
            if not name.endswith((".dist-info", ".egg-info")):
                continue
            try:
                with open(os.path.join(directory, name, "entry_points.txt"), encoding="utf-8") as f:
                    if header in f.read():
                        return True
            except FileNotFoundError:
                continue
            except OSError:
                return True
    return False


NodeBuilder = Callable[[str, NodeConfig], TreeNode]


def _builtin_types() -> list[tuple[str, type[TreeNode], tuple[Any, ...]]]:
    """BT.CPP 4.8's built-in registrations: (ID, class, extra constructor arguments)."""
    items: list[tuple[str, type[TreeNode], tuple[Any, ...]]] = [
        ("Fallback", controls.FallbackNode, ()),
        ("AsyncFallback", controls.FallbackNode, (True,)),
        ("Sequence", controls.SequenceNode, ()),
        ("AsyncSequence", controls.SequenceNode, (True,)),
        ("SequenceWithMemory", controls.SequenceWithMemory, ()),
        ("Parallel", controls.ParallelNode, ()),
        ("ParallelAll", controls.ParallelAllNode, ()),
        ("ReactiveSequence", controls.ReactiveSequence, ()),
        ("ReactiveFallback", controls.ReactiveFallback, ()),
        ("IfThenElse", controls.IfThenElseNode, ()),
        ("WhileDoElse", controls.WhileDoElseNode, ()),
        ("Inverter", decorators.InverterNode, ()),
        ("RetryUntilSuccessful", decorators.RetryNode, ()),
        ("KeepRunningUntilFailure", decorators.KeepRunningUntilFailureNode, ()),
        ("Repeat", decorators.RepeatNode, ()),
        ("Timeout", decorators.TimeoutNode, ()),
        ("Delay", decorators.DelayNode, ()),
        ("RunOnce", decorators.RunOnceNode, ()),
        ("ForceSuccess", decorators.ForceSuccessNode, ()),
        ("ForceFailure", decorators.ForceFailureNode, ()),
        ("AlwaysSuccess", actions.AlwaysSuccessNode, ()),
        ("AlwaysFailure", actions.AlwaysFailureNode, ()),
        ("Script", actions.ScriptNode, ()),
        ("ScriptCondition", actions.ScriptCondition, ()),
        ("SetBlackboard", actions.SetBlackboardNode, ()),
        ("Sleep", actions.SleepNode, ()),
        ("UnsetBlackboard", actions.UnsetBlackboardNode, ()),
        ("SubTree", decorators.SubTreeNode, ()),
        ("Precondition", decorators.PreconditionNode, ()),
        *((f"Switch{n}", controls.switch_node_type(n), ()) for n in range(2, 7)),
        ("LoopInt", decorators.loop_node_type("LoopInt", PortType.INT), ()),
        ("LoopBool", decorators.loop_node_type("LoopBool", PortType.BOOL), ()),
        ("LoopDouble", decorators.loop_node_type("LoopDouble", PortType.DOUBLE), ()),
        ("LoopString", decorators.loop_node_type("LoopString", PortType.STRING), ()),
        ("WasEntryUpdated", actions.EntryUpdatedAction, ()),
        ("SkipUnlessUpdated", decorators.EntryUpdatedDecorator, (NodeStatus.SKIPPED,)),
        ("WaitValueUpdate", decorators.EntryUpdatedDecorator, (NodeStatus.RUNNING,)),
    ]
    return items


def _v3_types() -> list[tuple[str, type[TreeNode], tuple[Any, ...]]]:
    """BT.CPP 3 nodes that v3 files may still use (a v4 file naming them is an error)."""
    return [
        (f"BlackboardCheck{name}", decorators.blackboard_check_type(f"BlackboardCheck{name}", ptype), ())
        for name, ptype in (
            ("Int", PortType.INT),
            ("Double", PortType.DOUBLE),
            ("String", PortType.STRING),
            ("Bool", PortType.BOOL),
        )
    ]


class BehaviorTreeFactory:
    """Registry of node types and entry point for loading trees.

    Args:
        builtins: register BT.CPP 4.x's built-in nodes (and the v3 BlackboardCheck nodes).

    Nav2's control nodes and leaves live in `twin.nav.bt_navigator.factory` (`nav2_factory`),
    registered as BT.CPP plugins are; the engine itself knows nothing of Nav2.
    """

    def __init__(self, *, builtins: bool = True) -> None:
        self._builders: dict[str, NodeBuilder | None] = {}
        self._manifests: dict[str, NodeManifest] = {}
        self.enums: dict[str, int] = {}
        self._parser: TreeParser | None = None
        if builtins:
            for node_id, cls, args in (*_builtin_types(), *_v3_types()):
                self.register_node_type(cls, node_id, *args)
        self.builtin_ids: frozenset[str] = frozenset(self._manifests)

    # -- registration --------------------------------------------------------------------------

    @property
    def manifests(self) -> Mapping[str, NodeManifest]:
        """Every registered or declared node type by ID."""
        return self._manifests

    def register_builder(self, manifest: NodeManifest, builder: NodeBuilder | None) -> None:
        """Register a node type from its manifest and a `builder(name, config) -> node`.

        A declared type (no builder) may later be replaced by a registration under the same ID.

        Raises:
            TreeError: If the ID is already registered with an implementation.
        """
        node_id = manifest.registration_id
        if node_id in self._builders and self._builders[node_id] is not None:
            msg = f"node type {node_id!r} is already registered"
            raise TreeError(msg)
        self._builders[node_id] = builder
        self._manifests[node_id] = manifest

    def register_node_type(
        self, cls: type[TreeNode], registration_id: str | None = None, *args: Any, **kwargs: Any
    ) -> None:
        """Register a node class; extra arguments are passed to its constructor after (name, config).

        Raises:
            TreeError: If the ID is taken or the class declares the same port twice.
        """
        node_id = registration_id or cls.__name__
        ports: dict[str, PortSpec] = {}
        for spec in cls.provided_ports():
            if spec.name in ports:
                msg = f"node type {node_id!r} declares the port {spec.name!r} twice"
                raise TreeError(msg)
            ports[spec.name] = spec
        manifest = NodeManifest(kind=cls.kind, registration_id=node_id, ports=ports, description=_summary(cls))

        def build(name: str, config: NodeConfig) -> TreeNode:
            return cls(name, config, *args, **kwargs)

        self.register_builder(manifest, build)

    def register_simple_action(self, node_id: str, function: TickFunction, ports: Iterable[PortSpec] = ()) -> None:
        """Register a synchronous action whose tick is `function(node) -> NodeStatus`."""
        manifest = NodeManifest(kind=NodeKind.ACTION, registration_id=node_id, ports={p.name: p for p in ports})
        self.register_builder(manifest, lambda name, config: SimpleActionNode(name, config, function))

    def register_simple_condition(self, node_id: str, function: TickFunction, ports: Iterable[PortSpec] = ()) -> None:
        """Register a condition whose tick is `function(node) -> NodeStatus`."""
        manifest = NodeManifest(kind=NodeKind.CONDITION, registration_id=node_id, ports={p.name: p for p in ports})
        self.register_builder(manifest, lambda name, config: SimpleConditionNode(name, config, function))

    def register_simple_decorator(
        self, node_id: str, function: DecoratorFunction, ports: Iterable[PortSpec] = ()
    ) -> None:
        """Register a decorator whose tick is `function(child_status, node) -> NodeStatus`."""
        manifest = NodeManifest(kind=NodeKind.DECORATOR, registration_id=node_id, ports={p.name: p for p in ports})
        self.register_builder(manifest, lambda name, config: SimpleDecoratorNode(name, config, function))

    def declare_node_type(
        self, node_id: str, kind: NodeKind, ports: Iterable[PortSpec] = (), *, description: str = ""
    ) -> None:
        """Declare a node type without implementation: trees using it validate but cannot be created."""
        manifest = NodeManifest(
            kind=kind, registration_id=node_id, ports={p.name: p for p in ports}, description=description, bound=False
        )
        self.register_builder(manifest, None)

    def unregister(self, node_id: str) -> bool:
        """Remove a non-built-in node type; False if it was not registered.

        Raises:
            TreeError: For a built-in type.
        """
        if node_id in self.builtin_ids:
            msg = f"the built-in node type {node_id!r} cannot be removed"
            raise TreeError(msg)
        self._manifests.pop(node_id, None)
        return self._builders.pop(node_id, None) is not None

    def register_scripting_enum(self, name: str, value: int) -> None:
        """Let scripts use `name` for the integer `value`.

        Raises:
            TreeError: If the name is already registered with another value.
        """
        previous = self.enums.get(name)
        if previous is not None and previous != value:
            msg = f"scripting enum {name!r} registered twice with different values ({previous} and {value})"
            raise TreeError(msg)
        self.enums[name] = int(value)

    def register_scripting_enums(self, enum_class: type[enum.Enum]) -> None:
        """Register every member of an integer enum by its name."""
        for member in enum_class:
            self.register_scripting_enum(member.name, int(member.value))

    def load_plugins(self, group: str = PLUGIN_GROUP) -> list[str]:
        """Call every `register(factory)` found in the entry-point group; return their names.

        Raises:
            TreeError: If a plugin cannot be imported or fails while registering.
        """
        loaded: list[str] = []
        if not _may_declare_group(group):
            return loaded
        import importlib.metadata  # 30-60 ms to import: only when some distribution declares the group

        for entry_point in sorted(importlib.metadata.entry_points(group=group), key=lambda ep: ep.name):
            try:
                register = entry_point.load()
                register(self)
            except TreeError as err:
                msg = f"BT plugin {entry_point.name!r} ({entry_point.value}): {err}"
                raise TreeError(msg) from None
            except Exception as err:
                msg = f"BT plugin {entry_point.name!r} ({entry_point.value}) failed: {type(err).__name__}: {err}"
                raise TreeError(msg) from err
            loaded.append(entry_point.name)
        return loaded

    def build_node(self, node_id: str, name: str, config: NodeConfig) -> TreeNode:
        """Create one node (the loader calls this).

        Raises:
            TreeError: If the type is unknown or unbound, or its constructor fails.
        """
        builder = self._builders.get(node_id)
        if builder is None:
            msg = f"node type {node_id!r} has no implementation registered"
            raise TreeError(msg)
        try:
            return builder(name, config)
        except TreeError:
            raise
        except Exception as err:
            msg = f"{type(err).__name__}: {err}"
            raise TreeError(msg) from err

    # -- trees ---------------------------------------------------------------------------------

    def register_behavior_tree_from_file(self, path: Path) -> None:
        """Load a file whose trees `create_tree(tree_id)` can then instantiate.

        Raises:
            TreeError: If the file is invalid.
        """
        self._registered_parser().load_file(path)

    def register_behavior_tree_from_text(self, text: str, *, source: str = "<string>") -> None:
        """Load XML text whose trees `create_tree(tree_id)` can then instantiate.

        Raises:
            TreeError: If the text is invalid.
        """
        self._registered_parser().load_text(text, source=source)

    def registered_behavior_trees(self) -> list[str]:
        """The IDs of the trees loaded with `register_behavior_tree_from_*`."""
        return sorted(self._parser.tree_roots) if self._parser else []

    def _registered_parser(self) -> TreeParser:
        if self._parser is None:
            self._parser = TreeParser(self)
        return self._parser

    def create_tree(
        self,
        tree_id: str | None = None,
        *,
        clock: Callable[[], int] | None = None,
        blackboard: Blackboard | None = None,
    ) -> Tree:
        """Instantiate a registered tree (by default `main_tree_to_execute` of the first file).

        Raises:
            TreeError: If no file was registered or the tree cannot be built.
        """
        if self._parser is None:
            msg = "no behaviour tree file was registered; call register_behavior_tree_from_file() first"
            raise TreeError(msg)
        return self._parser.instantiate(main_tree=tree_id, blackboard=blackboard, clock=clock or ManualClock())

    def create_tree_from_text(
        self,
        text: str,
        *,
        main_tree: str | None = None,
        clock: Callable[[], int] | None = None,
        blackboard: Blackboard | None = None,
        source: str = "<string>",
        base_dir: Path | None = None,
    ) -> Tree:
        """Load XML text and instantiate its main tree.

        Args:
            text: the XML.
            main_tree: the tree ID to instantiate (default: `main_tree_to_execute`, or the only tree).
            clock: simulation time in integer nanoseconds (default: a `ManualClock` at 0).
            blackboard: the root blackboard (default: a new one).
            source: the name used in error messages.
            base_dir: where relative includes are resolved (default: the working directory).

        Raises:
            TreeError: `file:line: ...` for the first problem.
        """
        parser = TreeParser(self)
        parser.load_text(text, source=source, base_dir=base_dir)
        return parser.instantiate(main_tree=main_tree, blackboard=blackboard, clock=clock or ManualClock())

    def create_tree_from_file(
        self,
        path: Path,
        *,
        main_tree: str | None = None,
        clock: Callable[[], int] | None = None,
        blackboard: Blackboard | None = None,
    ) -> Tree:
        """Load a file (and its includes) and instantiate its main tree.

        Raises:
            TreeError: `file:line: ...` for the first problem.
        """
        parser = TreeParser(self)
        parser.load_file(Path(path))
        return parser.instantiate(main_tree=main_tree, blackboard=blackboard, clock=clock or ManualClock())

    def node_types(self, kinds: Sequence[NodeKind] | None = None) -> list[NodeManifest]:
        """The manifests, sorted by ID, optionally only of some kinds."""
        return [m for _, m in sorted(self._manifests.items()) if kinds is None or m.kind in kinds]


def _summary(cls: type) -> str:
    doc = (cls.__doc__ or "").strip().splitlines()
    return doc[0] if doc else ""
