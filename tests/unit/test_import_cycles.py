"""No two files of ``twin/`` import each other, directly or around a longer loop.

The walker reads every ``.py`` file under the package with :mod:`ast` (nothing is imported) and
takes every ``import`` and ``from ... import`` statement anywhere in the file: at the top, inside
functions and methods, and under ``if TYPE_CHECKING:``. The last are counted on purpose: a type a
file needs from a module that needs the file back is a shared piece that belongs lower down, and an
import hidden from the interpreter is still a loop a reader has to untangle.

An edge goes from a file to the module it names: ``import twin.a.b`` and ``from twin.a.b import x``
name ``twin.a.b``; ``from twin.a import b`` names ``twin.a.b`` when ``b`` is a submodule and the
package ``twin.a`` (its ``__init__.py``) otherwise; relative imports are resolved against the file's
package. A package's ``__init__.py`` is a file like any other, so a re-export that closes a loop
(``twin/a/__init__.py`` imports ``twin/a/x.py``, which imports a name from ``twin.a``) is a cycle.
The parent packages that the interpreter initialises on the way to a submodule are not edges:
``twin.a.x`` importing ``twin.a.y`` does not depend on what ``twin/a/__init__.py`` re-exports.
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Edge:
    """One import statement from a file to another module of the package."""

    target: str
    line: int


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules(root: Path, package: str) -> dict[str, Path]:
    """Map every module of ``package`` under ``root`` to its file."""
    return {_module_name(p, root): p for p in sorted((root / package).rglob("*.py"))}


def _resolve_relative(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


def _import_module_call(node: ast.Call) -> str | None:
    """Return the module named by ``importlib.import_module("literal")`` or ``__import__("literal")``."""
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None
    if name not in {"import_module", "__import__"} or not node.args:
        return None
    first = node.args[0]
    return first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else None


def _imports(module: str, path: Path, known: Mapping[str, Path]) -> Iterator[Edge]:
    """Yield every edge from ``module`` to another module in ``known``, wherever the statement is."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            named = _import_module_call(node)
            if named in known:
                yield Edge(named, node.lineno)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in known:
                    yield Edge(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            source = _resolve_relative(module, is_package, node.level, node.module) if node.level else node.module or ""
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                if submodule in known:
                    yield Edge(submodule, node.lineno)
                elif source in known:
                    yield Edge(source, node.lineno)


def import_graph(root: Path, package: str) -> dict[str, dict[str, int]]:
    """Return ``{module: {imported module: first line}}`` for every module of ``package``."""
    known = _modules(root, package)
    graph: dict[str, dict[str, int]] = {}
    for module, path in known.items():
        edges: dict[str, int] = {}
        for edge in _imports(module, path, known):
            if edge.target != module:
                edges.setdefault(edge.target, edge.line)
        graph[module] = edges
    return graph


def _strongly_connected(graph: Mapping[str, Mapping[str, int]]) -> list[list[str]]:
    """Tarjan's algorithm, iterative; components of two or more modules, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    components: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    components.append(sorted(component))
    return sorted(components)


def _shortest_cycle(graph: Mapping[str, Mapping[str, int]], component: list[str]) -> list[str]:
    """Return the shortest loop through the component's first module, as a list of modules."""
    members = set(component)
    start = component[0]
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for child in sorted(graph[node]):
                if child not in members:
                    continue
                if child == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if child not in previous:
                    previous[child] = node
                    following.append(child)
        frontier = following
    raise AssertionError(f"no loop through {start} in {component}")  # a component always has one


def _describe(graph: Mapping[str, Mapping[str, int]], cycle: list[str], root: Path) -> str:
    steps = [f"{_path(root, a).relative_to(root)}:{graph[a][b]} imports {b}" for a, b in itertools.pairwise(cycle)]
    return " -> ".join(cycle) + "\n    " + "\n    ".join(steps)


def _path(root: Path, module: str) -> Path:
    base = root.joinpath(*module.split("."))
    return base / "__init__.py" if base.is_dir() else base.with_suffix(".py")


def find_cycles(root: Path, package: str) -> list[str]:
    """Describe one loop per group of modules that import each other, with file and line of each step."""
    graph = import_graph(root, package)
    descriptions = []
    for component in _strongly_connected(graph):
        cycle = _shortest_cycle(graph, component)
        text = _describe(graph, cycle, root)
        others = sorted(set(component) - set(cycle))
        if others:
            text += "\n    (other modules in the same knot: " + ", ".join(others) + ")"
        descriptions.append(text)
    return descriptions


def test_no_import_cycle_between_files_of_twin() -> None:
    cycles = find_cycles(ROOT, "twin")
    assert not cycles, "import cycles in twin/ (move the shared piece down or split the file):\n" + "\n".join(cycles)


# The walker itself, on small packages planted in tmp_path.


def _plant(tmp_path: Path, files: Mapping[str, str]) -> Path:
    for name, text in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path


def test_walker_passes_a_package_without_a_cycle(tmp_path: Path) -> None:
    root = _plant(
        tmp_path,
        {
            "pkg/__init__.py": "from pkg.b import B\n",
            "pkg/a.py": "X = 1\n",
            "pkg/b.py": "from pkg.a import X\nB = X\n",
            "pkg/sub/__init__.py": "",
            "pkg/sub/c.py": "from .. import a\nfrom ..b import B\nimport os\n",
        },
    )
    assert find_cycles(root, "pkg") == []


def test_walker_names_a_three_file_cycle_closed_inside_a_function(tmp_path: Path) -> None:
    root = _plant(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg.b import f\n",
            "pkg/b.py": "from . import c\ndef f():\n    return c\n",
            "pkg/c.py": "def g():\n    from .a import f\n    return f\n",
        },
    )
    (cycle,) = find_cycles(root, "pkg")
    assert cycle.splitlines()[0] == "pkg.a -> pkg.b -> pkg.c -> pkg.a"
    assert "pkg/c.py:2 imports pkg.a" in cycle


def test_walker_counts_type_checking_imports(tmp_path: Path) -> None:
    root = _plant(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.b import B\n",
            "pkg/b.py": "import pkg.a\n",
        },
    )
    assert [c.splitlines()[0] for c in find_cycles(root, "pkg")] == ["pkg.a -> pkg.b -> pkg.a"]


def test_walker_finds_a_cycle_closed_by_a_package_reexport(tmp_path: Path) -> None:
    root = _plant(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/sub/__init__.py": "from .x import X\nfrom .y import Y\n",
            "pkg/sub/x.py": "X = 1\n",
            "pkg/sub/y.py": "from pkg.sub import X\nY = X\n",
        },
    )
    assert [c.splitlines()[0] for c in find_cycles(root, "pkg")] == ["pkg.sub -> pkg.sub.y -> pkg.sub"]


@pytest.mark.parametrize(
    "statement",
    ["import pkg.b", "from pkg import b", "from . import b", "from .b import B", "importlib.import_module('pkg.b')"],
)
def test_walker_resolves_each_spelling_of_an_import(tmp_path: Path, statement: str) -> None:
    root = _plant(
        tmp_path,
        {"pkg/__init__.py": "", "pkg/a.py": statement + "\n", "pkg/b.py": "B = 1\nfrom pkg.a import *\n"},
    )
    assert [c.splitlines()[0] for c in find_cycles(root, "pkg")] == ["pkg.a -> pkg.b -> pkg.a"]
