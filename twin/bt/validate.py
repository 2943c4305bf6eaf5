"""Static checks of a tree file: everything `twin tree validate` reports, each as `file:line: ...`.

Beyond what BT.CPP itself rejects when loading (malformed XML, unknown node types, unknown ports,
literals that do not convert, script syntax errors, SubTree references that do not resolve or
recurse, v3-only names in a v4 file), validation also reports required ports that are not set
(BT.CPP would only fail when the node reads them) and v3-only attributes that BT.CPP 4 silently
ignores. Every tree of the file is checked, not only the main one. Node types declared in the
file's `<TreeNodesModel>` or on the factory without an implementation count as known; the report
lists them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from twin.bt.factory import BehaviorTreeFactory
from twin.bt.loader import BUILTIN_TAGS, TreeParser, XmlElement, check_ports, model_ports, parse_conditions, parse_xml
from twin.bt.node import (
    ConditionNode,
    ControlNode,
    DecoratorNode,
    NodeConfig,
    NodeManifest,
    SyncActionNode,
    TreeNode,
    remapped_key,
)
from twin.bt.script import ScriptSyntaxError, parse_script
from twin.bt.status import NodeKind, NodeStatus
from twin.bt.tree import ManualClock, Tree
from twin.bt.values import ConversionError, PortType
from twin.core.config import read_text_file, suggest
from twin.core.errors import TreeError

__all__ = [
    "ValidationReport",
    "declare_node_models",
    "load_for_display",
    "stub_node",
    "validate_file",
    "validate_text",
]

_SCRIPT_PORTS = {"Script": "code", "ScriptCondition": "code", "Precondition": "if"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class ValidationReport:
    """The outcome of validating one file.

    Attributes:
        source: the file.
        problems: one line each, `file:line: what; the fix`.
        trees: the IDs of the trees found.
        main_tree: the tree that would be instantiated, if it can be chosen.
        declared_only: node types used that are declared but have no implementation.
        version: 4 for `BTCPP_format="4"`, 3 otherwise.
    """

    source: str
    problems: tuple[str, ...]
    trees: tuple[str, ...] = ()
    main_tree: str | None = None
    declared_only: tuple[str, ...] = ()
    version: int = 4

    @property
    def ok(self) -> bool:
        """True when there is no problem."""
        return not self.problems


class _Stub:
    """A placeholder for a node type without implementation; ticking it is an error."""

    def tick(self) -> NodeStatus:
        msg = "this node type has no implementation (validation placeholder)"
        raise TreeError(msg)


class _StubAction(_Stub, SyncActionNode):
    pass


class _StubCondition(_Stub, ConditionNode):
    pass


class _StubControl(_Stub, ControlNode):
    pass


class _StubDecorator(_Stub, DecoratorNode):
    pass


_STUBS: dict[NodeKind, type[TreeNode]] = {
    NodeKind.ACTION: _StubAction,
    NodeKind.CONDITION: _StubCondition,
    NodeKind.CONTROL: _StubControl,
    NodeKind.DECORATOR: _StubDecorator,
}


def stub_node(manifest: NodeManifest, name: str, config: NodeConfig) -> TreeNode:
    """A placeholder node of the manifest's kind (for display and validation)."""
    return _STUBS[manifest.kind](name, config)


# Control nodes whose child count BT.CPP checks only when they are ticked (the loader takes any).
_TWO_OR_THREE = frozenset({"IfThenElse", "WhileDoElse"})


def _check_element(
    parser: TreeParser, element: XmlElement, report: Callable[[str, str], None], declared_only: set[str]
) -> None:
    factory = parser.factory
    parse_conditions(element, report)
    if element.tag == "SubTree":
        subtree_id = element.attrs.get("ID", "")
        if subtree_id and subtree_id not in parser.tree_roots:
            hint = suggest(subtree_id, list(parser.tree_roots))
            report(element.location, f"SubTree {subtree_id!r} does not match any <BehaviorTree ID=...>{hint}")
        remap = element.attrs.get("_autoremap")
        if remap is not None:
            try:
                PortType.BOOL.parse(remap)
            except ConversionError:
                report(element.location, f"_autoremap={remap!r} is not a boolean; use true or false")
        model = parser.subtree_models.get(subtree_id, {})
        if remap is None or remap in ("false", "0", "False", "FALSE"):
            for name, spec in model.items():
                if name not in element.attrs and not spec.default_str:
                    report(
                        element.location, f"SubTree {subtree_id!r} must remap its port {name!r} (see <TreeNodesModel>)"
                    )
        return
    type_id = element.type_name
    manifest = factory.manifests.get(type_id) or parser.node_models.get(type_id)
    if manifest is None:
        return
    if type_id in _TWO_OR_THREE and manifest.bound and len(element.children) not in (2, 3):
        report(
            element.location,
            f"<{type_id}> needs 2 or 3 children (a condition, then one or two branches), it has "
            f"{len(element.children)}; "
            "BT.CPP loads it but fails when it is first ticked",
        )
    if not manifest.bound:
        declared_only.add(type_id)
    check_ports(element, manifest, factory.enums, report)
    for name, value in element.attrs.items():
        port = manifest.ports.get(name)
        if port is None or port.type.kind != "status" or remapped_key(name, value) is not None:
            continue
        try:
            port.type.convert(value)
        except ConversionError:
            # BT.CPP has no load-time converter for an enum port: it fails only when the node reads it.
            report(
                element.location,
                f"<{type_id}> {name}={value!r} is not a status; use one of {', '.join(s.name for s in NodeStatus)} "
                "(BT.CPP loads it but fails when the node reads it)",
            )
    for name, spec in manifest.ports.items():
        if spec.required and name not in element.attrs and not spec.default_str:
            what = f" ({spec.description})" if spec.description else ""
            report(element.location, f'<{type_id}> needs the port {name!r}{what}; add {name}="..."')
    script_port = _SCRIPT_PORTS.get(type_id)
    code = element.attrs.get(script_port) if script_port else None
    if code is not None and not (code.startswith("{") and code.endswith("}")) and code:
        try:
            parse_script(code)
        except ScriptSyntaxError as err:
            report(element.location, f"<{type_id}> {script_port}: {err}")


def _check_recursion(parser: TreeParser, report: Callable[[str, str], None]) -> None:
    """Report SubTrees that include themselves: one depth-first walk, without recursion."""
    edges: dict[str, list[tuple[str, XmlElement]]] = {}
    for tree_id, (tree, _) in parser.tree_roots.items():
        edges[tree_id] = [(e.attrs["ID"], e) for e in tree.iter() if e.tag == "SubTree" and e.attrs.get("ID")]
    done: set[str] = set()
    for start, start_edges in edges.items():
        if start in done:
            continue
        path = [start]
        pending = [iter(start_edges)]
        while path:
            edge = next(pending[-1], None)
            if edge is None:
                done.add(path.pop())
                pending.pop()
                continue
            child, element = edge
            if child in path:
                chain = " -> ".join((*path[path.index(child) :], child))
                report(element.location, f"SubTree {child!r} includes itself ({chain}); a tree cannot contain itself")
            elif child in edges and child not in done:
                path.append(child)
                pending.append(iter(edges[child]))


def _check_depth(parser: TreeParser, report: Callable[[str, str], None]) -> bool:
    """Report the trees no other tree holds that nest deeper than twin ticks; True if none does."""
    depths = parser.tree_depths()
    held = {e.attrs.get("ID") for tree, _ in parser.tree_roots.values() for e in tree.iter() if e.tag == "SubTree"}
    too_deep = [(tree_id, problem) for tree_id in parser.tree_roots if (problem := parser.check_depth(tree_id, depths))]
    for _, problem in [item for item in too_deep if item[0] not in held] or too_deep[:1]:
        location, _, message = problem.partition(": ")
        report(location, message)
    return not too_deep


def _validate(
    load: Callable[[TreeParser], None], source: str, factory: BehaviorTreeFactory, *, main_tree: str | None = None
) -> ValidationReport:
    problems: list[str] = []

    def report(location: str, message: str) -> None:
        line = f"{location}: {message}"
        if line not in problems:
            problems.append(line)

    try:
        return _check_all(load, source, factory, problems, report, chosen=main_tree)
    except RecursionError:  # a safety net: the loader and checks bound what they recurse on
        line = f"{source}: the tree nests too deeply for twin to check it; flatten some SubTrees or nodes"
        return ValidationReport(source=source, problems=(*problems, line))


def _check_all(
    load: Callable[[TreeParser], None],
    source: str,
    factory: BehaviorTreeFactory,
    problems: list[str],
    report: Callable[[str, str], None],
    *,
    chosen: str | None,
) -> ValidationReport:
    parser = TreeParser(factory, strict=True)
    parser.report = report
    try:
        load(parser)
    except TreeError as err:
        return ValidationReport(source=source, problems=(*problems, str(err)))
    declared_only: set[str] = set()
    for tree, _ in parser.tree_roots.values():
        for element in tree.iter():
            if element is not tree:
                _check_element(parser, element, report, declared_only)
    _check_recursion(parser, report)
    depth_ok = _check_depth(parser, report)
    main_tree: str | None = None
    if chosen and chosen not in parser.tree_roots:
        problems.append(
            f"{source}: --main-tree {chosen!r} names no tree in the file{suggest(chosen, list(parser.tree_roots))}"
        )
    else:
        try:
            main_tree = parser.main_tree_id(chosen)
        except TreeError as err:
            problems.append(str(err))
    if not problems and depth_ok:
        for tree_id in parser.tree_roots:
            try:
                parser.instantiate(main_tree=tree_id, clock=ManualClock(), stub=stub_node)
            except TreeError as err:
                report_line = str(err)
                if report_line not in problems:
                    problems.append(report_line)
    version = parser.documents[0].version if parser.documents else 4
    return ValidationReport(
        source=source,
        problems=tuple(problems),
        trees=tuple(parser.tree_roots),
        main_tree=main_tree,
        declared_only=tuple(sorted(declared_only)),
        version=version,
    )


def declare_node_models(factory: BehaviorTreeFactory, path: Path) -> list[str]:
    """Declare every node type of a `<TreeNodesModel>` file on the factory, without implementation.

    Such a file is a node palette: Groot's export, or Nav2's `nav2_tree_nodes.xml` listing every
    Nav2 plugin with its ports. Types with an implementation keep their own ports; a bare
    declaration (the twin's own list of Nav2 leaves follows one Nav2 release) takes the palette's
    ports besides its own.
    Returns the IDs declared.

    Raises:
        TreeError: If the file cannot be read, is malformed, has no `<TreeNodesModel>`, or an
            entry has no ID (each `file:line: ...`).
    """
    text = read_text_file(Path(path), TreeError, what="a TreeNodesModel XML file")
    root = parse_xml(text, str(path))
    models = [root] if root.tag == "TreeNodesModel" else [c for c in root.children if c.tag == "TreeNodesModel"]
    if not models:
        msg = f"{root.location}: no <TreeNodesModel> here; --nodes takes a node palette such as nav2_tree_nodes.xml"
        raise TreeError(msg)

    def fail(location: str, message: str) -> NoReturn:
        raise TreeError(f"{location}: {message}")

    declared = []
    for entry in (e for model in models for e in model.children):
        kind = BUILTIN_TAGS.get(entry.tag)
        if kind is None or kind is NodeKind.SUBTREE:
            continue
        node_id = entry.attrs.get("ID")
        if not node_id:
            fail(entry.location, f"<{entry.tag}> in <TreeNodesModel> needs an ID attribute")
        existing = factory.manifests.get(node_id)
        ports = model_ports(entry, fail)
        if existing is not None:
            if existing.bound:
                continue  # an implementation declares its own ports
            # A declaration only (the twin's Nav2 leaves): the palette may be another release's, and
            # palettes lag their code (Humble's lists no `is_recovery` of Spin, which Humble's Spin
            # has), so the node takes the ports of both, the palette's where both name one.
            ports = {**existing.ports, **ports}
            factory.unregister(node_id)
        factory.declare_node_type(node_id, kind, ports.values(), description=f"declared in {path}")
        declared.append(node_id)
    return declared


def validate_file(path: Path, factory: BehaviorTreeFactory, *, main_tree: str | None = None) -> ValidationReport:
    """Check a tree file (and its includes) against the factory's node types.

    `main_tree` names the tree to execute, as BT.CPP's `createTree(ID)` does for a file without
    `main_tree_to_execute` (it must name one of the file's trees).
    """

    def load(parser: TreeParser) -> None:
        parser.load_file(Path(path))

    return _validate(load, str(path), factory, main_tree=main_tree)


def validate_text(text: str, factory: BehaviorTreeFactory, *, source: str = "<string>") -> ValidationReport:
    """Check XML text against the factory's node types."""

    def load(parser: TreeParser) -> None:
        parser.load_text(text, source=source)

    return _validate(load, source, factory)


def load_for_display(path: Path, factory: BehaviorTreeFactory, *, main_tree: str | None = None) -> Tree:
    """Instantiate a tree for display, with placeholders for declared-only node types.

    Raises:
        TreeError: If the file does not load.
    """
    parser = TreeParser(factory, strict=True)
    parser.load_file(Path(path))
    return parser.instantiate(main_tree=main_tree, clock=ManualClock(), stub=stub_node)
