"""BT.CPP XML files: parsing with line numbers, v3 → v4 normalisation, includes, checks, instantiation.

A file that declares `BTCPP_format="4"` is read as BT.CPP 4.x reads it. A file without it (or with
`BTCPP_format="3"`) is a v3 file and is normalised first: `SequenceStar` → `SequenceWithMemory`,
`SubTreePlus` → `SubTree` (`__autoremap` → `_autoremap`), a v3 `SubTree`'s unbraced values become
`{key}` remappings and `__shared_blackboard="true"` becomes `_autoremap="true"`,
`RetryUntilSuccesful` → `RetryUntilSuccessful`, Parallel's `success_threshold`/`failure_threshold`
→ `success_count`/`failure_count`. A v3-only name in a v4 file is an error naming its replacement.

Every error is one line `file:line: what; the fix` (a `TreeError`).
"""

from __future__ import annotations

import dataclasses
import difflib
import re
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Final, Protocol
from xml.parsers import expat

from twin.bt.blackboard import Blackboard
from twin.bt.node import ControlNode, DecoratorNode, NodeConfig, NodeManifest, TreeNode, remapped_key, strip_pointer
from twin.bt.ports import (
    NO_DEFAULT,
    POST_CONDITIONS,
    PRE_CONDITIONS,
    PortSpec,
    is_allowed_port_name,
    is_reserved_attribute,
)
from twin.bt.script import Script, ScriptSyntaxError, parse_script
from twin.bt.status import NodeKind, PortDirection
from twin.bt.tree import SubtreeInstance, Tree
from twin.bt.values import ConversionError, PortType
from twin.core.config import read_text_file, suggest
from twin.core.errors import TreeError

__all__ = ["Document", "NodeTypes", "TreeParser", "XmlElement", "model_ports", "parse_xml"]

BUILTIN_TAGS: Final = {kind.value: kind for kind in NodeKind}

# v3 name → v4 name, accepted (and renamed) in v3 files, an error in v4 files.
V3_RENAMES: Final = {
    "SequenceStar": "SequenceWithMemory",
    "SubTreePlus": "SubTree",
    "RetryUntilSuccesful": "RetryUntilSuccessful",
}
# v3 names without a v4 node, with what to use instead.
V3_REMOVED: Final = {
    **{
        f"BlackboardCheck{kind}": 'Precondition if="...", a _skipIf/_failureIf pre-condition or ScriptCondition'
        for kind in ("Int", "Double", "String", "Bool")
    },
    **{f"Switch{n}": "nested Switch6 nodes (BT.CPP 4 has Switch2 to Switch6)" for n in range(7, 11)},
    "ManualSelector": "another control node (ManualSelector was removed in BT.CPP 4)",
}
# v3-only attributes (node type, attribute) → v4 attribute.
V3_ATTRIBUTES: Final = {
    ("Parallel", "success_threshold"): "success_count",
    ("Parallel", "failure_threshold"): "failure_count",
    ("Parallel", "threshold"): "success_count",
    ("SubTree", "__shared_blackboard"): '_autoremap="true"',
    ("SubTree", "__autoremap"): "_autoremap",
}


class XmlElement:
    """One XML element with its line, kept mutable while the file is normalised."""

    __slots__ = ("attrs", "children", "line", "source", "tag")

    def __init__(self, tag: str, attrs: dict[str, str], line: int, source: str) -> None:
        self.tag = tag
        self.attrs = attrs
        self.children: list[XmlElement] = []
        self.line = line
        self.source = source

    @property
    def location(self) -> str:
        """`file:line`."""
        return f"{self.source}:{self.line}"

    @property
    def type_name(self) -> str:
        """The node type: the `ID` of `<Action ID=...>`-style elements, else the tag."""
        if self.tag in BUILTIN_TAGS:
            return self.attrs.get("ID", "")
        return self.tag

    def set_type_name(self, name: str) -> None:
        """Rename the node type (in `ID` or in the tag)."""
        if self.tag in BUILTIN_TAGS and "ID" in self.attrs:
            self.attrs["ID"] = name
        else:
            self.tag = name

    def iter(self) -> Iterator[XmlElement]:
        """This element and all below it, depth first."""
        yield self
        for child in self.children:
            yield from child.iter()

    def __repr__(self) -> str:
        return f"<{self.tag} {self.attrs} @{self.location}>"


MAX_XML_DEPTH: Final = 100
"""Deepest element nesting a tree file may have (the loader and ticks recurse per level)."""

MAX_TREE_DEPTH: Final = 200
"""Deepest node nesting a tree may have, counted from its root through its SubTrees (a tick
recurses up to three Python frames per level; 200 levels stay well inside Python's stack)."""

# What tinyxml2 (BT.CPP's parser) reads as markup: comments, CDATA, processing instructions, and
# tags, whose quoted attribute values may hold any character but their own quote.
_MARKUP: Final = re.compile(
    r"""<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<[^<>"']*(?:(?:"[^"]*"|'[^']*')[^<>"']*)*>""", re.DOTALL
)
_QUOTED: Final = re.compile(r""""[^"]*"|'[^']*'""")
# An `&` that starts no entity tinyxml2 knows: the five predefined ones and character references.
_BARE_AMP: Final = re.compile(r"&(?!(?:amp|lt|gt|quot|apos|#[0-9]+|#x[0-9a-fA-F]+);)")


def _escape_as_tinyxml2_reads(text: str) -> str:
    """Escape what tinyxml2 accepts and expat does not: a bare `&`, and `<` in an attribute value.

    tinyxml2 keeps an `&` that starts no entity as it is, and reads an attribute value up to its
    closing quote (`if="A>-B && color != BLUE"` is fine for BT.CPP). Escaping them adds no line, so
    expat's line numbers stay the file's. A DOCTYPE (never in a tree file) is left to expat.
    """
    if "<!DOCTYPE" in text:
        return text
    out: list[str] = []
    end = 0
    for match in _MARKUP.finditer(text):
        out.append(_BARE_AMP.sub("&amp;", text[end : match.start()]))
        markup = match.group()
        if markup.startswith(("<!--", "<![CDATA[", "<?")):
            out.append(markup)
        else:
            out.append(_QUOTED.sub(_escape_quoted, markup))
        end = match.end()
    out.append(_BARE_AMP.sub("&amp;", text[end:]))
    return "".join(out)


def _escape_quoted(match: re.Match[str]) -> str:
    return _BARE_AMP.sub("&amp;", match.group()).replace("<", "&lt;")


def parse_xml(text: str, source: str) -> XmlElement:
    """Parse XML text into elements with line numbers.

    Raises:
        TreeError: `source:line: malformed XML: ...`.
    """
    parser = expat.ParserCreate()
    stack: list[XmlElement] = []
    roots: list[XmlElement] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        if len(stack) >= MAX_XML_DEPTH:
            msg = (
                f"{source}:{parser.CurrentLineNumber}: elements nested deeper than {MAX_XML_DEPTH} levels; "
                "twin reads trees up to that depth: split the tree into <SubTree>s"
            )
            raise TreeError(msg)
        element = XmlElement(tag, dict(attrs), parser.CurrentLineNumber, source)
        (stack[-1].children if stack else roots).append(element)
        stack.append(element)

    def end(tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(_escape_as_tinyxml2_reads(text), True)
    except expat.ExpatError as err:
        msg = f"{source}:{err.lineno}: malformed XML: {expat.ErrorString(err.code)} (column {err.offset + 1})"
        raise TreeError(msg) from None
    if not roots:
        msg = f"{source}:1: malformed XML: no root element"
        raise TreeError(msg)
    return roots[0]


Report = Callable[[str, str], None]
StubBuilder = Callable[[NodeManifest, str, NodeConfig], TreeNode]


def _raise(location: str, message: str) -> None:
    raise TreeError(f"{location}: {message}")


@dataclasses.dataclass(kw_only=True)
class Document:
    """One loaded XML file (includes are separate documents).

    Attributes:
        source: the file path, or `<string>`.
        base_dir: where relative `<include path=...>` are resolved.
        root: the `<root>` element, normalised to v4.
        version: 4 for `BTCPP_format="4"`, else 3.
    """

    source: str
    base_dir: Path
    root: XmlElement
    version: int

    @property
    def main_tree_to_execute(self) -> str | None:
        """The `main_tree_to_execute` attribute of `<root>`."""
        return self.root.attrs.get("main_tree_to_execute")

    def behavior_trees(self) -> Iterator[XmlElement]:
        """The `<BehaviorTree>` elements."""
        return (child for child in self.root.children if child.tag == "BehaviorTree")


def _is_pointer(value: str) -> bool:
    return len(value) >= 3 and value[0] == "{" and value[-1] == "}"


def _normalise_v3(root: XmlElement) -> None:
    """Rewrite a v3 document in v4 terms (in place)."""
    for tree in root.children:
        if tree.tag != "BehaviorTree":
            continue
        for element in tree.iter():
            original = element.type_name
            renamed = V3_RENAMES.get(original)
            if original == "SubTreePlus":
                element.tag = "SubTree"
                if "__autoremap" in element.attrs:
                    element.attrs["_autoremap"] = element.attrs.pop("__autoremap")
            elif renamed is not None:
                element.set_type_name(renamed)
            elif original == "SubTree" or (element.tag == "SubTree" and original):
                attrs: dict[str, str] = {}
                for name, value in element.attrs.items():
                    if name in ("ID", "name"):
                        attrs[name] = value
                    elif name == "__shared_blackboard":
                        try:
                            shared = PortType.BOOL.parse(value)
                        except ConversionError:
                            shared = False
                        if shared:
                            attrs["_autoremap"] = "true"
                    elif is_allowed_port_name(name) and not _is_pointer(value):
                        attrs[name] = "{" + value + "}"
                    else:
                        attrs[name] = value
                element.attrs = attrs
            if element.type_name == "Parallel":
                for old, new in (("success_threshold", "success_count"), ("failure_threshold", "failure_count")):
                    if old in element.attrs:
                        element.attrs[new] = element.attrs.pop(old)
                if "threshold" in element.attrs:
                    element.attrs.setdefault("success_count", element.attrs.pop("threshold"))


def _check_v4_names(root: XmlElement, report: Report, strict: bool) -> None:
    """Report v3-only node names (and, when strict, v3-only attributes) in a v4 document."""
    for tree in root.children:
        if tree.tag != "BehaviorTree":
            continue
        for element in tree.iter():
            name = "SubTree" if element.tag == "SubTree" else element.type_name
            if name in V3_RENAMES:
                report(
                    element.location,
                    f'<{name}> is a BT.CPP v3 name; this file declares BTCPP_format="4", so write <{V3_RENAMES[name]}>',
                )
            elif name in V3_REMOVED:
                report(element.location, f"<{name}> was removed in BT.CPP 4; use {V3_REMOVED[name]}")
            for attr in element.attrs:
                replacement = V3_ATTRIBUTES.get((name, attr))
                if replacement is None:
                    continue
                if strict or name == "Parallel":
                    report(
                        element.location,
                        f'<{name}> attribute {attr!r} is BT.CPP v3; this file declares BTCPP_format="4", '
                        f"so write {replacement}",
                    )


def model_ports(element: XmlElement, report: Report) -> dict[str, PortSpec]:
    """Ports of one `<TreeNodesModel>` entry (untyped; defaults kept as strings)."""
    ports: dict[str, PortSpec] = {}
    directions = {
        "input_port": PortDirection.INPUT,
        "output_port": PortDirection.OUTPUT,
        "inout_port": PortDirection.INOUT,
    }
    for port in element.children:
        direction = directions.get(port.tag)
        if direction is None:
            continue
        name = port.attrs.get("name")
        if not name:
            report(port.location, f"<{port.tag}> without a name in the model of {element.attrs.get('ID', '?')}")
            continue
        default = port.attrs.get("default")
        ports[name] = PortSpec(
            name=name,
            direction=direction,
            type=PortType.ANY,
            default=default if default is not None else NO_DEFAULT,
            default_str=default or "",
            description=port.attrs.get("description", "") or "".join(()),
        )
    return ports


class NodeTypes(Protocol):
    """What the loader needs of a `BehaviorTreeFactory`: its node types and a way to build one."""

    @property
    def manifests(self) -> Mapping[str, NodeManifest]:
        """Every registered or declared node type by ID."""
        ...

    @property
    def enums(self) -> Mapping[str, int]:
        """The scripting enums by name."""
        ...

    def build_node(self, node_id: str, name: str, config: NodeConfig) -> TreeNode:
        """Create one node of a registered type."""
        ...


class TreeParser:
    """Loads XML documents and instantiates trees from them (BT.CPP `XMLParser`).

    Args:
        factory: where node types are looked up (a `BehaviorTreeFactory`).
        strict: also report what BT.CPP accepts silently but is almost surely a mistake
            (v3-only attributes in a v4 file); used by `validate`.
    """

    def __init__(self, factory: NodeTypes, *, strict: bool = False) -> None:
        self.factory = factory
        self.strict = strict
        self.documents: list[Document] = []
        self.tree_roots: dict[str, tuple[XmlElement, Document]] = {}
        self.subtree_models: dict[str, dict[str, PortSpec]] = {}
        self.node_models: dict[str, NodeManifest] = {}
        self._suffix = 0
        self._loading: list[Path] = []
        self.report: Report = _raise

    # -- loading -------------------------------------------------------------------------------

    def load_file(self, path: Path, *, included_from: str | None = None) -> Document:
        """Load a file and its includes.

        Raises:
            TreeError: If the file cannot be read or is not a valid tree file.
        """
        resolved = path.resolve()
        where = f"{included_from}: " if included_from else ""
        if resolved in self._loading:
            chain = " -> ".join(str(p) for p in [*self._loading, resolved])
            msg = f"{where}<include> loops back to a file being loaded ({chain})"
            raise TreeError(msg)
        try:
            text = read_text_file(path, TreeError, what="a BehaviorTree.CPP XML file")
        except TreeError as err:
            raise err.with_context(before=where) from None
        self._loading.append(resolved)
        try:
            return self.load_text(text, source=str(path), base_dir=resolved.parent)
        finally:
            self._loading.pop()

    def load_text(self, text: str, *, source: str = "<string>", base_dir: Path | None = None) -> Document:
        """Load XML text and its includes.

        Raises:
            TreeError: If the text is not a valid tree file.
        """
        root = parse_xml(text, source)
        if root.tag != "root":
            msg = f"{root.location}: the XML must have a root node called <root>, not <{root.tag}>"
            raise TreeError(msg)
        declared = root.attrs.get("BTCPP_format")
        if declared not in (None, "3", "4"):
            msg = (
                f'{root.location}: BTCPP_format="{declared}" is not supported; use "4" (or leave it out for a v3 file)'
            )
            raise TreeError(msg)
        version = 4 if declared == "4" else 3
        document = Document(source=source, base_dir=base_dir or Path.cwd(), root=root, version=version)
        self.documents.append(document)  # first, so that the main file stays documents[0]
        if version == 3:
            _normalise_v3(root)
        else:
            _check_v4_names(root, self.report, self.strict)
        for include in (child for child in root.children if child.tag == "include"):
            self._load_include(include, document)
        self._verify(document)
        self._load_models(document)
        for tree in document.behavior_trees():
            tree_id = tree.attrs.get("ID")
            if not tree_id:
                tree_id = f"BehaviorTree_{self._suffix}"
                self._suffix += 1
            self.tree_roots[tree_id] = (tree, document)
        return document

    def _load_include(self, include: XmlElement, document: Document) -> None:
        path_attr = include.attrs.get("path")
        if not path_attr:
            self.report(include.location, "<include> needs a 'path' attribute")
            return
        if "ros_pkg" in include.attrs:
            self.report(
                include.location,
                f"<include ros_pkg={include.attrs['ros_pkg']!r}> needs ROS; give a path relative to this file instead",
            )
            return
        path = Path(path_attr)
        if not path.is_absolute():
            path = document.base_dir / path
        self.load_file(path, included_from=include.location)

    def _known_types(self) -> dict[str, NodeKind]:
        known = {node_id: manifest.kind for node_id, manifest in self.factory.manifests.items()}
        if self.strict:
            for node_id, manifest in self.node_models.items():
                known.setdefault(node_id, manifest.kind)
        return known

    def _verify(self, document: Document) -> None:
        """BT.CPP's `VerifyXML`: structure, known node types and numbers of children."""
        report = self.report
        root = document.root
        models = [child for child in root.children if child.tag == "TreeNodesModel"]
        if len(models) > 1:
            report(models[1].location, "only a single <TreeNodesModel> is supported")
        for model in models:
            for entry in model.children:
                if entry.tag in BUILTIN_TAGS and not entry.attrs.get("ID"):
                    report(entry.location, f"<{entry.tag}> in <TreeNodesModel> needs an ID attribute")
        if self.strict:
            for model in models:
                for entry in model.children:
                    if entry.tag in BUILTIN_TAGS and entry.tag != "SubTree" and entry.attrs.get("ID"):
                        self.node_models.setdefault(
                            entry.attrs["ID"],
                            NodeManifest(
                                kind=BUILTIN_TAGS[entry.tag],
                                registration_id=entry.attrs["ID"],
                                ports=model_ports(entry, report),
                                description=f"declared in <TreeNodesModel> of {document.source}",
                                bound=False,
                            ),
                        )
        known = self._known_types()
        top_level = len(root.children)
        for tree in document.behavior_trees():
            tree_id = tree.attrs.get("ID", "")
            if not tree_id and top_level > 1:
                report(tree.location, "<BehaviorTree> needs an ID attribute when the file has several elements")
            if tree_id in known:
                report(
                    tree.location, f"<BehaviorTree ID={tree_id!r}> uses the name of a registered node type; rename it"
                )
            if len(tree.children) != 1:
                report(
                    tree.location,
                    f"<BehaviorTree ID={tree_id!r}> must have exactly 1 child, it has {len(tree.children)}",
                )
            for child in tree.children:
                for element in child.iter():
                    self._verify_element(element, known, document.version)

    def _verify_element(self, element: XmlElement, known: Mapping[str, NodeKind], document_version: int) -> None:
        report = self.report
        tag = element.tag
        is_builtin = tag in BUILTIN_TAGS
        node_id = element.attrs.get("ID", "")
        count = len(element.children)
        if is_builtin and not node_id:
            report(element.location, f"<{tag}> needs an ID attribute")
            return
        if tag == "SubTree":
            if count:
                report(element.location, f"<SubTree ID={node_id!r}> must not have children")
            if node_id in known:
                report(element.location, f"<SubTree ID={node_id!r}> uses the name of a registered node type")
            return
        name = node_id if is_builtin else tag
        kind = known.get(name)
        if kind is None:
            if document_version == 4 and (name in V3_RENAMES or name in V3_REMOVED):
                return  # already reported with its v4 replacement
            close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            report(
                element.location,
                f"unknown node type <{name}>{hint}; register it on the factory (or fix the name)",
            )
            return
        if not is_builtin and node_id:
            report(
                element.location,
                f"attribute ID is not allowed in <{tag}>; write <{tag} name=...> or <Action ID={tag!r}>",
            )
        if kind is NodeKind.DECORATOR and count != 1:
            report(element.location, f"the decorator <{name}> must have exactly 1 child, it has {count}")
        elif kind is NodeKind.CONTROL and count == 0:
            report(element.location, f"the control node <{name}> must have 1 or more children")
        elif name == "ReactiveSequence" and sum(child.type_name == "AsyncSequence" for child in element.children) > 1:
            # BT.CPP 4.8.2's VerifyXML counts only <AsyncSequence> children as async (the other names
            # it checks are C++ class names, never a registered control); ReactiveFallback is not checked.
            report(
                element.location,
                "a <ReactiveSequence> cannot have more than one async child (<AsyncSequence>), as in BT.CPP; "
                "make all but one of them a <Sequence>, or move them out of the <ReactiveSequence>",
            )
        elif kind in (NodeKind.ACTION, NodeKind.CONDITION) and count:
            report(element.location, f"the {kind.value.lower()} <{name}> must not have children")

    def _load_models(self, document: Document) -> None:
        """SubTree models from `<TreeNodesModel>`: ports that every SubTree instance must remap."""
        for model in (child for child in document.root.children if child.tag == "TreeNodesModel"):
            for entry in model.children:
                if entry.tag == "SubTree" and entry.attrs.get("ID"):
                    self.subtree_models.setdefault(entry.attrs["ID"], {}).update(model_ports(entry, self.report))

    # -- depth ---------------------------------------------------------------------------------

    def tree_depths(self) -> dict[str, tuple[int, str | None]]:
        """Each tree's node depth through its SubTrees, and the SubTree on its deepest path.

        A tree's own root node is level 1, a SubTree node adds the depth of the tree it holds.
        SubTrees that name no tree or that loop back are left out (they are reported elsewhere).
        Iterative, so that a chain of thousands of SubTrees does not exhaust the stack.
        """
        roots = self.tree_roots
        subtrees: dict[str, tuple[int, list[tuple[int, str]]]] = {}
        for tree_id, (tree, _) in roots.items():
            own = 0
            refs: list[tuple[int, str]] = []
            stack = [(child, 1) for child in tree.children]
            while stack:
                element, level = stack.pop()
                own = max(own, level)
                if element.tag == "SubTree" and element.attrs.get("ID") in roots:
                    refs.append((level, element.attrs["ID"]))
                stack.extend((child, level + 1) for child in element.children)
            subtrees[tree_id] = (own, refs)
        depths: dict[str, tuple[int, str | None]] = {}
        for start in roots:
            if start in depths:
                continue
            path = [start]
            on_path = {start}
            pending = [iter(subtrees[start][1])]
            while path:
                ref = next(pending[-1], None)
                if ref is not None:
                    child = ref[1]
                    if child not in depths and child not in on_path:
                        path.append(child)
                        on_path.add(child)
                        pending.append(iter(subtrees[child][1]))
                    continue
                tree_id = path.pop()
                on_path.discard(tree_id)
                pending.pop()
                own, refs = subtrees[tree_id]
                best: tuple[int, str | None] = (own, None)
                for level, child in refs:
                    if child in depths and level + depths[child][0] > best[0]:
                        best = (level + depths[child][0], child)
                depths[tree_id] = best
        return depths

    def check_depth(self, tree_id: str, depths: Mapping[str, tuple[int, str | None]] | None = None) -> str | None:
        """The problem with tree `tree_id` nesting deeper than `MAX_TREE_DEPTH`, or None."""
        depths = depths if depths is not None else self.tree_depths()
        depth = depths[tree_id][0] if tree_id in depths else 0
        if depth <= MAX_TREE_DEPTH:
            return None
        chain = [tree_id]
        while (following := depths[chain[-1]][1]) is not None:
            chain.append(following)
        shown = " -> ".join(chain) if len(chain) <= 6 else " -> ".join([*chain[:3], "...", *chain[-2:]])
        tree, _ = self.tree_roots[tree_id]
        return (
            f"{tree.location}: <BehaviorTree ID={tree_id!r}> nests nodes {depth} levels deep through "
            f"{len(chain) - 1} nested SubTrees ({shown}); twin ticks trees up to {MAX_TREE_DEPTH} levels: "
            "flatten some of the SubTrees"
        )

    # -- instantiation -------------------------------------------------------------------------

    def main_tree_id(self, main_tree: str | None = None) -> str:
        """The tree to instantiate: `main_tree`, else `main_tree_to_execute`, else the only tree.

        Raises:
            TreeError: If none can be chosen.
        """
        if main_tree:
            return main_tree
        if not self.documents:
            msg = "no behaviour tree file was loaded"
            raise TreeError(msg)
        first = self.documents[0]
        if not self.tree_roots:
            msg = f'{first.root.location}: the file has no <BehaviorTree>; put the tree in <BehaviorTree ID="MainTree">'
            raise TreeError(msg)
        if first.main_tree_to_execute:
            if first.main_tree_to_execute not in self.tree_roots:
                msg = (
                    f"{first.root.location}: main_tree_to_execute={first.main_tree_to_execute!r} names no tree "
                    f"in the file{suggest(first.main_tree_to_execute, list(self.tree_roots))}"
                )
                raise TreeError(msg)
            return first.main_tree_to_execute
        if len(self.tree_roots) == 1:
            return next(iter(self.tree_roots))
        ids = ", ".join(sorted(self.tree_roots))
        msg = (
            f"{first.root.location}: the file has several trees ({ids}) and no main_tree_to_execute; "
            f'add <root main_tree_to_execute="..."> or pick one'
        )
        raise TreeError(msg)

    def instantiate(
        self,
        *,
        main_tree: str | None = None,
        blackboard: Blackboard | None = None,
        clock: Callable[[], int],
        stub: StubBuilder | None = None,
    ) -> Tree:
        """Build the main tree.

        Args:
            main_tree: the tree ID (default: `main_tree_id()`).
            blackboard: the root blackboard (default: a new one).
            clock: simulation time in integer nanoseconds.
            stub: builds a placeholder for node types that are declared but not implemented (for
                validation and display); without it such a type is an error.

        Raises:
            TreeError: `file:line: ...` for the first problem.
        """
        tree_id = self.main_tree_id(main_tree)
        problem = self.check_depth(tree_id)
        if problem is not None:
            raise TreeError(problem)
        builder = _Builder(self, stub)
        builder.create_subtree(tree_id, _Scope("", "", blackboard or Blackboard(), ()), None, None)
        nodes = builder.nodes
        _, document = self.tree_roots[tree_id]
        return Tree(root=nodes[0], nodes=nodes, subtrees=builder.subtrees, clock=clock, btcpp3=document.version == 3)


def parse_conditions(
    element: XmlElement, report: Report
) -> tuple[tuple[Script | None, ...], tuple[Script | None, ...]]:
    """Parse the pre- and post-condition attributes of an element."""

    def parse(names: tuple[str, ...]) -> tuple[Script | None, ...]:
        scripts: list[Script | None] = []
        for name in names:
            text = element.attrs.get(name)
            script = None
            if text is not None:
                try:
                    script = parse_script(text)
                except ScriptSyntaxError as err:
                    report(element.location, f"{name}: {err}")
            scripts.append(script)
        return tuple(scripts)

    return parse(PRE_CONDITIONS), parse(POST_CONDITIONS)


def check_ports(
    element: XmlElement, manifest: NodeManifest, enums: Mapping[str, int], report: Report
) -> tuple[dict[str, str], dict[str, str]]:
    """Check an element's attributes against its type's ports; return (ports, other attributes)."""
    ports: dict[str, str] = {}
    others: dict[str, str] = {}
    for name, value in element.attrs.items():
        if is_allowed_port_name(name):
            spec = manifest.ports.get(name)
            if spec is None:
                known = sorted(manifest.ports)
                listing = f"; its ports are {', '.join(known)}" if known else "; it has no ports"
                hint = suggest(name, known) if known else ""
                if hint.startswith("; valid:"):
                    hint = ""  # the listing below names them
                report(element.location, f"unknown port {name!r} of <{manifest.registration_id}>{hint}{listing}")
                continue
            if not _is_pointer(value) and spec.type.has_converter and spec.type.strongly_typed:
                try:
                    spec.type.parse(value, enums)
                except ConversionError as err:
                    report(
                        element.location,
                        f"port {name!r} of <{manifest.registration_id}>: {value!r} cannot be converted to "
                        f"{spec.type.name} ({err})",
                    )
            ports[name] = value
        elif not is_reserved_attribute(name):
            others[name] = value
    return ports, others


@dataclasses.dataclass(frozen=True, slots=True)
class _Scope:
    """Where nodes are created: the (sub)tree instance's path and prefix, blackboard and ancestry."""

    instance_name: str
    prefix: str
    blackboard: Blackboard
    stack: tuple[str, ...]


class _Builder:
    """Creates the nodes of one tree, depth first (BT.CPP `recursivelyCreateSubtree`)."""

    def __init__(self, parser: TreeParser, stub: StubBuilder | None) -> None:
        self.parser = parser
        self.stub = stub
        self.factory = parser.factory
        self.nodes: list[TreeNode] = []
        self.subtrees: list[SubtreeInstance] = []
        self.uid = 0

    def create_subtree(
        self, tree_id: str, scope: _Scope, parent: TreeNode | None, referenced_at: XmlElement | None
    ) -> None:
        """Create the nodes of tree `tree_id` as an instance described by `scope`."""
        roots = self.parser.tree_roots
        where = referenced_at.location if referenced_at is not None else self.parser.documents[0].root.location
        if tree_id not in roots:
            hint = suggest(tree_id, list(roots))
            msg = f"{where}: no <BehaviorTree ID={tree_id!r}> in the loaded files{hint}"
            raise TreeError(msg)
        if tree_id in scope.stack:
            chain = " -> ".join((*scope.stack, tree_id))
            msg = f"{where}: SubTree {tree_id!r} includes itself ({chain}); a tree cannot contain itself"
            raise TreeError(msg)
        element, _ = roots[tree_id]
        self.subtrees.append(
            SubtreeInstance(instance_name=scope.instance_name, tree_id=tree_id, blackboard=scope.blackboard)
        )
        self._step(parent, element.children[0], dataclasses.replace(scope, stack=(*scope.stack, tree_id)))

    def _step(self, parent: TreeNode | None, element: XmlElement, scope: _Scope) -> None:
        blackboard = scope.blackboard
        node = self._create_node(element, blackboard, parent, scope.prefix)
        self.nodes.append(node)
        if node.kind is not NodeKind.SUBTREE:
            for child in element.children:
                self._step(node, child, scope)
            return
        subtree_id = element.attrs["ID"]
        child_board = Blackboard(blackboard)
        remapping: dict[str, str] = {}
        autoremap = False
        for name, raw in element.attrs.items():
            value = "{" + name + "}" if raw == "{=}" else raw
            if name == "_autoremap":
                try:
                    autoremap = bool(PortType.BOOL.parse(value))
                except ConversionError:
                    msg = f"{element.location}: _autoremap={value!r} is not a boolean; use true or false"
                    raise TreeError(msg) from None
                child_board.enable_auto_remapping(autoremap)
                continue
            if is_allowed_port_name(name):
                remapping[name] = value
        model = self.parser.subtree_models.get(subtree_id)
        if model is not None:
            for name, spec in model.items():
                if name not in remapping and not autoremap:
                    if not spec.default_str:
                        msg = (
                            f"{element.location}: <TreeNodesModel> declares a mandatory port {name!r} of SubTree "
                            f'{subtree_id!r}, but this SubTree does not remap it; add {name}="{{key}}"'
                        )
                        raise TreeError(msg)
                    remapping[name] = spec.default_str
        for name, value in remapping.items():
            key = strip_pointer(value)
            if key is not None:
                child_board.add_subtree_remapping(name, key)
            else:
                child_board.enable_auto_remapping(False)
                child_board.set(name, value)
                child_board.enable_auto_remapping(autoremap)
        path = f"{scope.instance_name}/" if scope.instance_name else ""
        path += element.attrs.get("name") or f"{subtree_id}::{node.uid}"
        self.create_subtree(subtree_id, _Scope(path, path + "/", child_board, scope.stack), node, element)

    def _create_node(
        self, element: XmlElement, blackboard: Blackboard, parent: TreeNode | None, prefix: str
    ) -> TreeNode:
        factory = self.factory
        tag = element.tag
        kind = BUILTIN_TAGS.get(tag)
        if kind is None:
            type_id = tag
        else:
            type_id = element.attrs.get("ID", "")
            if not type_id:
                _raise(element.location, f"<{tag}> needs an ID attribute")
        instance_name = element.attrs.get("name", type_id)
        self.uid += 1
        uid = self.uid
        path = prefix + instance_name
        if type_id == instance_name:
            path += f"::{uid}"
        pre, post = parse_conditions(element, _raise)
        common: dict[str, Any] = {
            "path": path,
            "uid": uid,
            "blackboard": blackboard,
            "enums": factory.enums,
            "pre_conditions": pre,
            "post_conditions": post,
            "location": element.location,
        }
        if kind is NodeKind.SUBTREE:
            manifest = factory.manifests["SubTree"]
            ports, others = {}, {}
            for name, value in element.attrs.items():
                if is_allowed_port_name(name):
                    ports[name] = value
                elif not is_reserved_attribute(name):
                    others[name] = value
            config = NodeConfig(input_ports=ports, manifest=manifest, other_attributes=others, **common)
            node = factory.build_node("SubTree", instance_name, config)
            node.subtree_id = type_id  # type: ignore[attr-defined]
        else:
            manifest_or_none = factory.manifests.get(type_id)
            if manifest_or_none is None and self.stub is not None:
                manifest_or_none = self.parser.node_models.get(type_id)
            if manifest_or_none is None:
                known = list(factory.manifests)
                _raise(element.location, f"unknown node type <{type_id}>{suggest(type_id, known)}")
            manifest = manifest_or_none  # type: ignore[assignment]
            if not manifest.bound and self.stub is None:
                _raise(
                    element.location,
                    f"node type <{type_id}> ({manifest.description}) is declared but has no implementation; "
                    f"register one with factory.register_node_type(...)",
                )
            ports, others = check_ports(element, manifest, factory.enums, _raise)
            self._create_entries(element, manifest, ports, blackboard)
            inputs: dict[str, str] = {}
            outputs: dict[str, str] = {}
            for name, value in ports.items():
                spec = manifest.ports[name]
                if spec.is_input:
                    inputs[name] = value
                if spec.is_output:
                    outputs[name] = value
            for name, spec in manifest.ports.items():
                if spec.default_str:
                    if spec.is_input and name not in inputs:
                        inputs[name] = spec.default_str
                    if spec.is_output and name not in outputs and _is_pointer(spec.default_str):
                        outputs[name] = spec.default_str
            config = NodeConfig(
                input_ports=inputs, output_ports=outputs, manifest=manifest, other_attributes=others, **common
            )
            try:
                if manifest.bound:
                    node = factory.build_node(type_id, instance_name, config)
                else:
                    assert self.stub is not None
                    node = self.stub(manifest, instance_name, config)
            except TreeError as err:
                msg = f"{element.location}: cannot create <{type_id}> '{path}': {err}"
                raise TreeError(msg) from None
        if parent is not None:
            if isinstance(parent, ControlNode):
                parent.add_child(node)
            elif isinstance(parent, DecoratorNode):
                parent.set_child(node)
            else:
                _raise(element.location, f"<{parent.registration_id}> '{parent.full_path}' cannot have children")
        return node

    @staticmethod
    def _create_entries(
        element: XmlElement, manifest: NodeManifest, ports: Mapping[str, str], board: Blackboard
    ) -> None:
        """Create the blackboard entries of `{key}` ports with the ports' types (BT.CPP does this at load)."""
        for name, spec in manifest.ports.items():
            value = ports.get(name)
            if value is None:
                continue
            key = remapped_key(name, value)
            if key is None:
                continue
            previous = board.get_entry(key)
            try:
                if previous is not None:
                    prev_type = previous.info
                    mismatch = prev_type.strongly_typed and spec.type.strongly_typed and prev_type != spec.type
                    if mismatch and prev_type != PortType.STRING:
                        _raise(
                            element.location,
                            f"the entry [{key}] was first used with type [{prev_type.name}] and here with type "
                            f"[{spec.type.name}] (port {name!r}); use one type per blackboard entry",
                        )
                else:
                    board.create_entry(key, spec.type)
            except TreeError as err:
                if str(err).startswith(element.location):
                    raise
                msg = f"{element.location}: {err}"
                raise TreeError(msg) from None
