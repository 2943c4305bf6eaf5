"""Every TwinError subclass keeps its class, attributes and message when re-raised with context or pickled."""

from __future__ import annotations

import importlib
import inspect
import pickle
import pkgutil

import pytest

import twin
from twin.core.errors import TwinError


def all_error_classes() -> list[type[TwinError]]:
    """Import every twin module and return every TwinError subclass (TwinError included)."""
    for module in pkgutil.walk_packages(twin.__path__, "twin."):
        if module.name != "twin.__main__":
            importlib.import_module(module.name)
    found: list[type[TwinError]] = []
    todo: list[type[TwinError]] = [TwinError]
    while todo:
        cls = todo.pop()
        found.append(cls)
        todo.extend(cls.__subclasses__())
    return sorted(set(found), key=lambda c: f"{c.__module__}.{c.__qualname__}")


def make_error(cls: type[TwinError]) -> TwinError:
    """Build an instance whatever the class's __init__ takes (text, numbers by their annotation)."""
    params = [p for p in inspect.signature(cls.__init__).parameters.values() if p.name != "self"]
    if all(p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in params):
        return cls(f"original {cls.__name__} text")
    values = {}
    for p in params:
        if p.default is not p.empty:
            continue
        values[p.name] = 3 if p.annotation in ("int", int, "float", float) else f"original {cls.__name__} {p.name}"
    return cls(**values)


ERRORS = all_error_classes()


def test_the_hierarchy_is_found() -> None:
    names = {cls.__name__ for cls in ERRORS}
    assert {"TickError", "ScriptSyntaxError", "ScriptError", "ConfigError", "SimulationError"} <= names


@pytest.mark.parametrize("cls", ERRORS, ids=lambda c: c.__name__)
def test_with_context_keeps_class_attributes_and_text(cls: type[TwinError]) -> None:
    err = make_error(cls)
    original = str(err)
    again = err.with_context(before="scenario.yaml: ", after=" (at t=1.000 s)")
    assert type(again) is cls
    assert str(again) == f"scenario.yaml: {original} (at t=1.000 s)"
    assert again.exit_code == cls.exit_code
    for name, value in vars(err).items():
        assert getattr(again, name) == value
    assert str(err) == original  # the original is unchanged


@pytest.mark.parametrize("cls", ERRORS, ids=lambda c: c.__name__)
def test_pickles_with_its_message(cls: type[TwinError]) -> None:
    err = make_error(cls).with_context(after=" (context)")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is cls
    assert str(back) == str(err)
    assert vars(back) == vars(err)


def test_a_message_is_one_line() -> None:
    assert str(TwinError("first\nsecond")) == "first second"
