"""The YAML loader: libyaml's parser for speed, read exactly as the pure-Python parser reads."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from twin.core import yaml_numbers
from twin.core.config import load_yaml
from twin.core.errors import ConfigError
from twin.core.yaml_numbers import Loader, compose, safe_load

REPO = Path(__file__).resolve().parents[3]
SHIPPED = sorted(
    p for folder in ("scenarios", "twin/data", "fmus", "trees", "examples") for p in (REPO / folder).rglob("*.yaml")
)
FIXTURES = sorted((REPO.parent / "shared" / "fixtures").rglob("*.yaml"))


def test_pyyaml_has_libyaml_here() -> None:
    # The speed comes from libyaml (PyYAML's wheels carry it); without it the pure parser still reads.
    assert yaml_numbers._CLoader is not None


def _tree(node: yaml.Node | None) -> object:
    """A node tree with every node's tag, marks (file, line, column) and value."""
    if node is None:
        return None
    mark = (node.start_mark.name, node.start_mark.line, node.start_mark.column)
    if isinstance(node, yaml.MappingNode):
        return (node.tag, mark, [(_tree(k), _tree(v)) for k, v in node.value])
    if isinstance(node, yaml.SequenceNode):
        return (node.tag, mark, [_tree(v) for v in node.value])
    return (node.tag, mark, node.value)


def _python_compose(text: str, name: str) -> yaml.Node | None:
    loader = Loader(text)
    loader.name = name
    try:
        node: yaml.Node | None = loader.get_single_node()
        return node
    finally:
        loader.dispose()


@pytest.mark.parametrize("path", SHIPPED + FIXTURES, ids=lambda p: str(p.relative_to(REPO.parent)))
def test_every_shipped_and_fixture_yaml_reads_as_the_python_parser_reads_it(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    assert _tree(compose(text, str(path))) == _tree(_python_compose(text, str(path)))
    assert safe_load(text) == yaml.load(text, Loader=Loader)


def test_yaml_12_floats_are_numbers_with_libyaml_too() -> None:
    assert safe_load("a: 1e12\nb: 2e+3\nc: -1.5E-3\nd: 1e\n") == {"a": 1e12, "b": 2e3, "c": -1.5e-3, "d": "1e"}


def test_nesting_libyaml_refuses_is_read_as_before(tmp_path: Path) -> None:
    # libyaml stops at 1,000 flow levels; the pure-Python parser reads on until the recursion limit.
    deep = tmp_path / "deep.yaml"
    deep.write_text("a: " + "[" * 1500 + "]" * 1500 + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_yaml(deep)
    fine = tmp_path / "fine.yaml"
    fine.write_text("a: " + "[" * 200 + "1" + "]" * 200 + "\n", encoding="utf-8")
    node = load_yaml(fine)
    assert node.value[0][0].value == "a"
