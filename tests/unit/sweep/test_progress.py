"""`twin sweep`'s progress line: runs done, failed and the ETA on a terminal; nothing in a pipe or file."""

from __future__ import annotations

import io

from twin.cli.sweep import _Bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_progress_line_shows_done_failed_and_eta_on_a_terminal() -> None:
    stream = _Terminal()
    bar = _Bar(stream)
    bar(12, 1, 50, 65.0)
    assert "runs 12/50 [#####-------------------] failed 1  ETA 1m05s" in stream.getvalue()
    bar.close()
    assert stream.getvalue().endswith("\r\x1b[K")


def test_no_progress_line_when_stderr_is_not_a_terminal() -> None:
    stream = io.StringIO()
    bar = _Bar(stream)
    bar(12, 1, 50, 65.0)
    bar.close()
    assert stream.getvalue() == ""
