"""The README's "What a run looks like" is what `twin simulate` prints: a newcomer compares the two."""

from __future__ import annotations

import re
from pathlib import Path

from tests.conftest import REPO, run_twin

_SPEED = re.compile(r" in [0-9.]+ s \([0-9]+x real time\)")  # the machine's, not the twin's
_BAG = re.compile(r": \S+$")  # where the bag went


def _readme_example() -> list[str]:
    text = (REPO / "README.md").read_text()
    section = text.split("## What a run looks like", 1)[1].split("\n## ", 1)[0]
    block = section.split("```\n", 1)[1].split("```", 1)[0]
    lines = block.splitlines()
    assert lines[0] == "$ twin simulate", lines[0]
    return lines[1:]


def _comparable(line: str) -> str:
    return _BAG.sub(": BAG", _SPEED.sub(" in T s (Nx real time)", line))


def test_the_readme_run_is_what_twin_simulate_prints(tmp_path: Path) -> None:
    expected = _readme_example()
    result = run_twin("simulate", "--out", str(tmp_path / "bag"))
    assert result.returncode == 0, result.stderr
    printed = [line for line in (result.stderr + result.stdout).splitlines() if line.strip()]
    assert [_comparable(line) for line in printed] == [_comparable(line) for line in expected]
    # the bag path the README shows is one `twin simulate` makes without --out
    assert re.search(r": bags/house_waffle_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d$", expected[-1]), expected[-1]
