"""Small console manners: a node's lines carry its name, durations keep their digits, help has examples."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import pytest

from twin.cli import _ConsoleFormatter, main
from twin.cli.simulate import _duration
from twin.sweep.report import _write_parquet


def _line(logger: str, message: str) -> str:
    record = logging.LogRecord(logger, logging.INFO, __file__, 1, "%s", (message,), None)
    return _ConsoleFormatter("twin: %(levelname)s: %(message)s").format(record)


def test_a_nodes_console_lines_carry_its_name() -> None:
    assert _line("twin.node.wall_follower", "wall found") == "twin: INFO: [wall_follower] wall found"
    # library modules and FMU instances (which name themselves) are not nodes
    assert _line("twin.sim.simulation", "scenario x") == "twin: INFO: scenario x"
    assert (
        _line("twin.node.fmu.left", "DcMotorWheel instance 'left': ok")
        == "twin: INFO: DcMotorWheel instance 'left': ok"
    )
    # a fleet robot's node, as rcl names it: even in a namespace that starts like a module's name
    assert _line("twin.node.robot1.amcl", "pose set") == "twin: INFO: [robot1.amcl] pose set"
    assert _line("twin.node.node1.planner_server", "no path") == "twin: INFO: [node1.planner_server] no path"
    assert _line("twin.node.fmu_bot.diff_drive", "clamped") == "twin: INFO: [fmu_bot.diff_drive] clamped"


@pytest.mark.parametrize(
    ("seconds", "digits", "text"),
    [(0.1, 1, "0.100 s"), (0.0016, 2, "1.6 ms"), (0.70, 2, "0.70 s"), (125.5, 1, "125.5 s"), (20.0, 1, "20.0 s")],
)
def test_a_duration_is_printed_with_the_digits_it_has(seconds: float, digits: int, text: str) -> None:
    assert _duration(seconds, digits) == text  # never "0.00 s" beside a 63x speed-up


def test_scenario_check_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["scenario", "check", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out and "twin scenario check scenarios/house_burger.yaml" in out and "--json" in out


def test_results_parquet_without_pyarrow_is_said(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import fails, as where it is not installed
    with caplog.at_level(logging.WARNING):
        assert _write_parquet(tmp_path / "results.parquet", ["a"], [{"a": 1}]) is None
    (line,) = [r.getMessage() for r in caplog.records]
    assert "results.parquet not written" in line and "pyarrow" in line and "results.csv" in line


def test_a_log_line_printed_under_a_progress_line_starts_on_a_clean_line() -> None:
    import io

    from twin.cli import _ConsoleHandler
    from twin.cli.progress import Progress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal = Terminal()
    bar = Progress(60.0, stream=terminal, min_interval_s=0.0)
    bar.update(12.0, 500)
    handler = _ConsoleHandler(terminal)
    handler.setFormatter(_ConsoleFormatter("twin: %(levelname)s: %(message)s"))
    handler.emit(logging.LogRecord("twin.sim.simulation", logging.WARNING, __file__, 1, "careful", (), None))
    bar.update(13.0, 520)
    text = terminal.getvalue()
    drawn, warning = text.split("twin: WARNING: careful\n")
    assert drawn.startswith("\rsim    12.0/60.0 s") and drawn.endswith("\r\x1b[K")  # cleared before the line
    assert warning.startswith("\rsim    13.0/60.0 s")  # and drawn again under it
