"""How twin.nav and the mission sit in the package: who imports whom, and the C sources a wheel ships."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
TWIN = REPO / "twin"


def _imports(path: Path) -> set[str]:
    """Every module a file imports, at the top, inside functions or under TYPE_CHECKING."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module)
    return found


def _offenders(package: str, forbidden: tuple[str, ...]) -> list[str]:
    return sorted(
        f"{path.relative_to(REPO)} imports {module}"
        for path in (TWIN / package).rglob("*.py")
        for module in _imports(path)
        if module.startswith(forbidden)
    )


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [
        ("bt", ("twin.nav", "twin.mission")),  # the engine knows neither Nav2 nor the mission
        ("nav", ("twin.mission", "twin.sim", "twin.cli")),  # Nav2's parts know no mission and no composition
        ("mission", ("twin.sim", "twin.cli")),
    ],
)
def test_a_package_imports_nothing_it_must_not_know(package: str, forbidden: tuple[str, ...]) -> None:
    assert _offenders(package, forbidden) == []


def test_every_c_source_under_twin_is_package_data() -> None:
    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["twin"]
    shipped = {p for pattern in patterns for p in TWIN.glob(pattern) if p.suffix == ".c"}
    sources = set(TWIN.rglob("*.c"))
    assert sources and sources <= shipped, sorted(str(p.relative_to(REPO)) for p in sources - shipped)


def test_every_native_kernel_sits_beside_the_python_that_loads_it() -> None:
    for source in (TWIN / "nav").rglob("*.c"):
        loaders = [p for p in source.parent.glob("*.py") if f'"{source.name}"' in p.read_text(encoding="utf-8")]
        assert loaders, f"{source.relative_to(REPO)}: no module beside it loads it"
