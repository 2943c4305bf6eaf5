"""`--help` teaches with files that exist: every project path an example names is in the repository."""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator

import pytest

from tests.conftest import REPO
from twin.cli import build_parser

# Paths into the project or the shared fixtures; other names (my.yaml, vendor_motor.fmu, bags/run1)
# stand for the user's own files.
_PROJECT_PATH = re.compile(r"(?<![\w/.])((?:\.\./shared|scenarios|trees|sdf|fmus)/[\w./-]*)")


def _parsers(parser: argparse.ArgumentParser, name: str) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


HELP = {name: f"{p.description or ''}\n{p.epilog or ''}" for name, p in _parsers(build_parser(), "twin")}


@pytest.mark.parametrize("command", sorted(HELP))
def test_help_examples_name_files_that_exist(command: str) -> None:
    missing = [path for path in _PROJECT_PATH.findall(HELP[command]) if not (REPO / path).exists()]
    assert not missing, f"`{command} --help` names files that do not exist: {missing}"
