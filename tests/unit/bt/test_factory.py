"""The Python API for custom nodes: kinds, ports, registration, enums and plugins."""

from __future__ import annotations

import enum
import importlib
from pathlib import Path

import pytest

from twin.bt import (
    BehaviorTreeFactory,
    ConditionNode,
    ControlNode,
    DecoratorNode,
    NodeKind,
    NodeStatus,
    StatefulActionNode,
    SyncActionNode,
    TickError,
    input_port,
    output_port,
)
from twin.core.errors import TreeError

from .helpers import v4


class Double(SyncActionNode):
    """Write twice the input."""

    @classmethod
    def provided_ports(cls):
        return (input_port("x", int, 21), output_port("y", int))

    def tick(self) -> NodeStatus:
        self.set_output("y", self.get_input("x") * 2)
        return NodeStatus.SUCCESS


class Countdown(StatefulActionNode):
    """RUNNING for `steps` ticks, counting its halts."""

    halts = 0

    @classmethod
    def provided_ports(cls):
        return (input_port("steps", int, required=True),)

    def on_start(self) -> NodeStatus:
        self.left = self.get_input("steps")
        return self.on_running()

    def on_running(self) -> NodeStatus:
        self.left -= 1
        return NodeStatus.RUNNING if self.left > 0 else NodeStatus.SUCCESS

    def on_halted(self) -> None:
        type(self).halts += 1


class IsPositive(ConditionNode):
    @classmethod
    def provided_ports(cls):
        return (input_port("value", int),)

    def tick(self) -> NodeStatus:
        return NodeStatus.SUCCESS if self.get_input("value") > 0 else NodeStatus.FAILURE


class Twice(DecoratorNode):
    """Tick the child twice per tick."""

    def tick(self) -> NodeStatus:
        self.set_status(NodeStatus.RUNNING)
        first = self.child.execute_tick()
        if first is NodeStatus.RUNNING:
            return first
        self.reset_child()
        return self.child.execute_tick()


class Last(ControlNode):
    """Tick every child, return the last status."""

    def tick(self) -> NodeStatus:
        status = NodeStatus.SUCCESS
        for child in self.children:
            status = child.execute_tick()
        self.reset_children()
        return status


def factory_with(*types: tuple[type, str]) -> BehaviorTreeFactory:
    factory = BehaviorTreeFactory()
    for cls, name in types:
        factory.register_node_type(cls, name)
    return factory


def test_sync_action_reads_converted_inputs_and_writes_outputs() -> None:
    tree = factory_with((Double, "Double")).create_tree_from_text(
        v4('<Sequence><Double x="5" y="{a}"/><Double x="{a}" y="{b}"/><Double y="{c}"/></Sequence>')
    )
    tree.tick_once()
    board = tree.root_blackboard
    assert (board.get("a"), board.get("b"), board.get("c")) == (10, 20, 42)


def test_stateful_action_runs_across_ticks_and_is_halted() -> None:
    Countdown.halts = 0
    xml = v4('<ReactiveSequence><ScriptCondition code="go == 1"/><Countdown steps="3"/></ReactiveSequence>')
    tree = factory_with((Countdown, "Countdown")).create_tree_from_text(xml)
    tree.root_blackboard.set("go", 1)
    assert [tree.tick_once(), tree.tick_once()] == [NodeStatus.RUNNING, NodeStatus.RUNNING]
    tree.root_blackboard.set("go", 0)
    assert tree.tick_once() is NodeStatus.FAILURE
    assert Countdown.halts == 1


def test_condition_decorator_and_control_nodes() -> None:
    factory = factory_with((IsPositive, "IsPositive"), (Twice, "Twice"), (Last, "Last"), (Double, "Double"))
    tree = factory.create_tree_from_text(
        v4('<Last><Twice><Double x="{n}" y="{n}"/></Twice><IsPositive value="{n}"/></Last>')
    )
    tree.root_blackboard.set("n", 3)
    assert tree.tick_once() is NodeStatus.SUCCESS
    assert tree.root_blackboard.get("n") == 12


def test_manifest_carries_kind_and_ports() -> None:
    manifest = factory_with((Countdown, "Countdown")).manifests["Countdown"]
    assert manifest.kind is NodeKind.ACTION
    assert manifest.ports["steps"].required


def test_an_exception_in_a_node_names_its_path() -> None:
    class Broken(SyncActionNode):
        def tick(self) -> NodeStatus:
            raise ValueError("sensor unplugged")

    tree = factory_with((Broken, "Broken")).create_tree_from_text(
        v4(
            '<Sequence name="s"><SubTree ID="Sub" name="inner"/></Sequence>',
            '<BehaviorTree ID="Sub"><Broken name="b"/></BehaviorTree>',
        )
    )
    with pytest.raises(TickError, match=r"node 'inner/b' \(Broken\): ValueError: sensor unplugged") as err:
        tree.tick_once()
    assert err.value.node_path == "inner/b"
    assert isinstance(err.value, TreeError)


def test_an_error_while_ticking_a_tree_file_names_the_file_and_line(tmp_path: Path) -> None:
    # BT.CPP loads an IfThenElse with one child and throws at its first tick: say where it is
    path = tmp_path / "t.xml"
    path.write_text(v4("<Sequence>\n<IfThenElse>\n<AlwaysSuccess/>\n</IfThenElse>\n</Sequence>"))
    tree = BehaviorTreeFactory().create_tree_from_file(path)
    with pytest.raises(TickError) as err:
        tree.tick_once()
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if "<IfThenElse>" in text)
    assert str(err.value) == (
        f"{path}:{line}: node 'IfThenElse::2' (IfThenElse): IfThenElseNode must have either 2 or 3 children"
    )


def test_a_tick_must_return_a_status() -> None:
    class Sloppy(SyncActionNode):
        def tick(self):  # type: ignore[no-untyped-def]
            return "SUCCESS"

    tree = factory_with((Sloppy, "Sloppy")).create_tree_from_text(v4("<Sloppy/>"))
    with pytest.raises(TickError, match="expected a NodeStatus"):
        tree.tick_once()


def test_a_sync_action_must_not_return_running() -> None:
    factory = BehaviorTreeFactory()
    factory.register_simple_action("Busy", lambda node: NodeStatus.RUNNING)
    with pytest.raises(TickError, match="never return RUNNING"):
        factory.create_tree_from_text(v4("<Busy/>")).tick_once()


def test_simple_nodes_from_functions() -> None:
    factory = BehaviorTreeFactory()
    seen: list[str] = []
    factory.register_simple_action(
        "Say", lambda node: seen.append(node.get_input("text")) or NodeStatus.SUCCESS, [input_port("text", str)]
    )
    factory.register_simple_condition("Yes", lambda node: NodeStatus.SUCCESS)
    factory.register_simple_decorator(
        "Flip", lambda status, node: NodeStatus.SUCCESS if status is NodeStatus.FAILURE else status
    )
    tree = factory.create_tree_from_text(v4('<Sequence><Yes/><Say text="hi"/><Flip><AlwaysFailure/></Flip></Sequence>'))
    assert tree.tick_once() is NodeStatus.SUCCESS
    assert seen == ["hi"]


def test_registering_an_id_twice_is_an_error() -> None:
    factory = factory_with((Double, "Double"))
    with pytest.raises(TreeError, match="already registered"):
        factory.register_node_type(Double, "Double")
    with pytest.raises(TreeError, match="cannot be removed"):
        factory.unregister("Sequence")


def test_a_declared_type_validates_but_cannot_be_created_until_registered() -> None:
    factory = BehaviorTreeFactory()
    factory.declare_node_type("Dock", NodeKind.ACTION, [input_port("station", str)], description="docking")
    with pytest.raises(TreeError, match="declared but has no implementation"):
        factory.create_tree_from_text(v4('<Dock station="A"/>'))
    factory.register_simple_action("Dock", lambda node: NodeStatus.SUCCESS, [input_port("station", str)])
    assert factory.create_tree_from_text(v4('<Dock station="A"/>')).tick_once() is NodeStatus.SUCCESS


def test_scripting_enums_from_an_enum_class() -> None:
    class Color(enum.IntEnum):
        RED = 1
        BLUE = 2

    factory = BehaviorTreeFactory()
    factory.register_scripting_enums(Color)
    tree = factory.create_tree_from_text(v4('<ScriptCondition code="BLUE == 2 &amp;&amp; RED != BLUE"/>'))
    assert tree.tick_once() is NodeStatus.SUCCESS
    with pytest.raises(TreeError, match="different values"):
        factory.register_scripting_enum("RED", 5)


def test_set_output_on_an_unconnected_port_returns_false() -> None:
    class Writer(SyncActionNode):
        result: bool | None = None

        @classmethod
        def provided_ports(cls):
            return (output_port("out"),)

        def tick(self) -> NodeStatus:
            type(self).result = self.set_output("out", 1)
            return NodeStatus.SUCCESS

    factory_with((Writer, "Writer")).create_tree_from_text(v4("<Writer/>")).tick_once()
    assert Writer.result is False


def _install_plugin(root: Path, name: str, module_source: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Install a distribution the way pip leaves one: a module and a dist-info with its entry point."""
    (root / f"{name}_pkg.py").write_text(module_source)
    dist = root / f"{name}_pkg-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}-pkg\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[twin.bt_nodes]\n{name} = {name}_pkg:register\n")
    monkeypatch.syspath_prepend(str(root))


def test_plugins_register_through_the_entry_point_group(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = """
from twin.bt import NodeStatus, SyncActionNode

class PluginDouble(SyncActionNode):
    def tick(self):
        return NodeStatus.SUCCESS

calls = []

def register(factory):
    calls.append(factory)
    factory.register_node_type(PluginDouble, "PluginDouble")
"""
    _install_plugin(tmp_path, "demo", source, monkeypatch)
    factory = BehaviorTreeFactory()
    assert factory.load_plugins() == ["demo"]
    module = importlib.import_module("demo_pkg")
    assert module.calls == [factory]
    assert "PluginDouble" in factory.manifests
    assert factory.create_tree_from_text(v4("<PluginDouble/>")).tick_once() is NodeStatus.SUCCESS


def test_no_plugin_installed_loads_nothing() -> None:
    assert BehaviorTreeFactory().load_plugins() == []


def test_a_broken_plugin_is_reported_with_its_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _install_plugin(tmp_path, "broken", "import no_such_module_anywhere\n", monkeypatch)
    with pytest.raises(TreeError, match="BT plugin 'broken'.*no_such_module_anywhere"):
        BehaviorTreeFactory().load_plugins()
