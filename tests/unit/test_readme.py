"""The README's two set-up commands are the contract with a new user; CI must run the same test command."""

from __future__ import annotations

import re
from pathlib import Path


def _setup_commands(repo: Path) -> list[str]:
    text = (repo / "README.md").read_text()
    section = text.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", section)


def test_readme_has_exactly_two_setup_commands(repo: Path) -> None:
    commands = _setup_commands(repo)
    assert len(commands) == 2, commands
    assert commands[0].endswith("twin simulate")
    assert "pytest" in commands[1]


def test_ci_runs_the_readme_test_command_verbatim(repo: Path) -> None:
    test_command = _setup_commands(repo)[1]
    ci_lines = (repo / ".ci" / "run").read_text().splitlines()
    assert test_command in ci_lines
