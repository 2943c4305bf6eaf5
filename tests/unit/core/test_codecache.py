"""The code cache: dataclasses made with it are the same classes; a second process compiles nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]

# Dataclasses with every feature whose methods `dataclasses` writes as text, described as JSON.
_CHILD = r"""
import dataclasses, inspect, json, sys
from dataclasses import InitVar, dataclass, field
from typing import ClassVar
if sys.argv[1] == "on":
    from twin.core import codecache
    codecache.enable()

@dataclass(frozen=True, kw_only=True, slots=True)
class Frozen:
    name: str
    size: float = 1.5
    tags: tuple[str, ...] = ()
    LIMIT: ClassVar[int] = 3

@dataclass(order=True)
class Plain:
    a: int
    b: list[int] = field(default_factory=list)
    c: int = field(default=7, repr=False, compare=False)
    d: int = field(init=False, default=0)
    scale: InitVar[int] = 2
    def __post_init__(self, scale):
        self.d = self.a * scale

f1, f2 = Frozen(name="x"), Frozen(name="x", tags=("t",))
p = Plain(1, [2], scale=5)
try:
    f1.name = "y"
    frozen = "assigned"
except dataclasses.FrozenInstanceError as err:
    frozen = type(err).__name__
out = {
    "repr": [repr(f1), repr(f2), repr(p)],
    "eq": [f1 == Frozen(name="x"), f1 == f2, p == Plain(1, [2], scale=5), Plain(1) < Plain(2)],
    "hash": hash(f1) == hash(Frozen(name="x")),
    "frozen": frozen,
    "post_init": p.d,
    "signatures": [str(inspect.signature(Frozen)), str(inspect.signature(Plain))],
    "init_annotations": [repr(Frozen.__init__.__annotations__), repr(Plain.__init__.__annotations__)],
    "defaults_fresh": Plain(1).b is not Plain(1).b,
}
if sys.argv[1] == "on":
    out["compiled"] = codecache.compiled_count()
print(json.dumps(out))
"""


def _child(mode: str, cache: Path, **env: str) -> dict[str, object]:
    run_env = {k: v for k, v in os.environ.items() if k != "TWIN_NO_CODE_CACHE"}
    run_env.update(TWIN_CACHE_DIR=str(cache), PYTHONPATH=str(REPO), **env)
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, mode], env=run_env, capture_output=True, text=True, check=False, timeout=120
    )
    assert out.returncode == 0, out.stderr
    result: dict[str, object] = json.loads(out.stdout)
    return result


def _table(cache: Path) -> Path:
    (table,) = (cache / "pycode").glob("dataclasses-*.marshal")
    return table


def test_classes_are_the_same_and_a_second_process_compiles_nothing(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    plain = _child("off", cache)
    first = _child("on", cache)
    second = _child("on", cache)
    assert int(str(first.pop("compiled"))) > 0
    assert second.pop("compiled") == 0  # every method's code came from the table
    assert first == plain and second == plain
    assert plain["frozen"] == "FrozenInstanceError" and plain["post_init"] == 5


def test_a_damaged_table_is_ignored_and_written_again(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    plain = _child("off", cache)
    _child("on", cache)
    table = _table(cache)
    table.write_bytes(b"\x00 not marshal data " * 50)
    again = _child("on", cache)
    assert int(str(again.pop("compiled"))) > 0
    assert again == plain
    assert _child("on", cache)["compiled"] == 0  # the table was written whole again


def test_it_can_be_turned_off(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    result = _child("on", cache, TWIN_NO_CODE_CACHE="1")
    assert result["compiled"] == 0
    assert not (cache / "pycode").exists()


@pytest.mark.parametrize("command", ["--version", "simulate --help"])
def test_the_twin_command_enables_it_and_a_library_import_does_not(tmp_path: Path, command: str) -> None:
    code = (
        "import dataclasses, sys, twin.cli\n"
        "library = 'exec' in vars(dataclasses)\n"
        f"sys.argv = ['twin', *{command.split()!r}]\n"
        "try:\n    twin.cli.run()\nexcept SystemExit:\n    pass\n"
        "print(library, 'exec' in vars(dataclasses))\n"
    )
    env = {**os.environ, "TWIN_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(REPO)}
    env.pop("TWIN_NO_CODE_CACHE", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-2:] == ["False", "True"]


def test_each_command_keeps_its_own_table(tmp_path: Path) -> None:
    """`twin simulate` loads only the methods its own classes need, not every command's."""
    cache = tmp_path / "cache"
    env = {k: v for k, v in os.environ.items() if k != "TWIN_NO_CODE_CACHE"}
    env.update(TWIN_CACHE_DIR=str(cache), PYTHONPATH=str(REPO))
    code = (
        "import sys\nfrom twin.core import codecache\ncodecache.enable(sys.argv[1])\n"
        "from dataclasses import dataclass\n@dataclass(frozen=True)\nclass Only:\n    x: int = 0\n"
    )
    for command in ("simulate", "analyze"):
        out = subprocess.run(
            [sys.executable, "-c", code, command], env=env, capture_output=True, text=True, check=False
        )
        assert out.returncode == 0, out.stderr
    names = sorted(p.name.split("-")[1] for p in (cache / "pycode").glob("dataclasses-*.marshal"))
    assert names == ["analyze", "simulate"]
