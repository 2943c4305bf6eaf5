"""What every robustness case asserts: the exit code, one line on stderr, no traceback, a bag that reads back."""

from __future__ import annotations

from pathlib import Path

from twin.bag import open_bag, read_messages

DATA = Path(__file__).resolve().parent / "data"


def error_lines(stderr: str) -> list[str]:
    """The `twin: error:` lines (warnings and progress may come before them)."""
    return [line for line in stderr.splitlines() if line.startswith("twin: error:")]


def assert_one_line_error(stderr: str, *, contains: str = "") -> str:
    """Assert stderr holds exactly one error line and no traceback; return that line."""
    assert "Traceback" not in stderr, stderr
    assert "internal error" not in stderr, stderr
    lines = error_lines(stderr)
    assert len(lines) == 1, stderr
    assert contains in lines[0], lines[0]
    return lines[0]


def assert_bag_reads_back(bag: Path) -> int:
    """Open the bag, read and decode every message; return how many there are."""
    info = open_bag(bag)
    messages = list(read_messages(bag))
    assert len(messages) == info.message_count
    assert all(m.msg is not None for m in messages)
    return len(messages)
