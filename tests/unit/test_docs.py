"""The docs a newcomer reads hold: their links lead somewhere, and docs/architecture.md's layers are the code's."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from tests.conftest import REPO

_DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
_LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", _DOCS, ids=[str(p.relative_to(REPO)) for p in _DOCS])
def test_every_relative_link_of_a_doc_leads_to_a_file(doc: Path) -> None:
    targets = [m.split("#", 1)[0] for m in _LINK.findall(doc.read_text())]
    missing = [t for t in targets if t and "://" not in t and not (doc.parent / t).exists()]
    assert not missing, f"{doc.relative_to(REPO)} links to files that do not exist: {missing}"


def _layers() -> dict[str, int]:
    """Package -> layer, from the table under "## Layers" in docs/architecture.md."""
    text = (REPO / "docs" / "architecture.md").read_text()
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    layers: dict[str, int] = {}
    for row in re.findall(r"^\| (\d+) \| ([^|]+) \|", section, flags=re.MULTILINE):
        for package in re.findall(r"`twin\.(\w+)`", row[1]):
            layers[package] = int(row[0])
    return layers


def _rows() -> dict[str, str]:
    """Package -> its table row's package cell: packages named in one row form one unit."""
    text = (REPO / "docs" / "architecture.md").read_text()
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    return {
        package: cell
        for cell in re.findall(r"^\| \d+ \| ([^|]+) \|", section, flags=re.MULTILINE)
        for package in re.findall(r"`twin\.(\w+)`", cell)
    }


def _imports_of(path: Path) -> set[str]:
    """The twin packages a file imports, at the top or inside a function."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        found.update(name.split(".")[1] for name in names if name.startswith("twin.") and "." in name)
    return found


def test_the_layer_table_names_every_package_of_twin() -> None:
    layers = _layers()
    packages = {p.parent.name for p in (REPO / "twin").glob("*/__init__.py")}
    unlisted = sorted(packages - set(layers))
    assert not unlisted, f"docs/architecture.md: add {unlisted} to the table under '## Layers'"


def test_a_package_imports_only_lower_layers_as_docs_architecture_says() -> None:
    layers, rows = _layers(), _rows()
    wrong = []
    for path in sorted((REPO / "twin").glob("*/**/*.py")):
        package = path.relative_to(REPO / "twin").parts[0]
        for target in sorted(_imports_of(path) - {package}):
            same_row = rows.get(target) == rows.get(package)
            if package in layers and target in layers and layers[target] >= layers[package] and not same_row:
                wrong.append(
                    f"{path.relative_to(REPO)} (layer {layers[package]}) imports twin.{target} (layer {layers[target]})"
                )
    assert not wrong, "\n".join(
        [*wrong, "move the shared piece down a layer, or change docs/architecture.md's table if the design changed"]
    )
