"""Every TwinError subclass raised inside a run reaches the user as one line with its own text and exit code.

The error is raised from inside `Simulation.run` (where a tree tick, an FMU step or the bag can
fail), so it goes through the whole CLI path: `twin simulate` adds where the bag ends, `twin.cli`
prints the line and returns the class's exit code.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.robustness.helpers import assert_bag_reads_back, assert_one_line_error
from tests.unit.core.test_errors import ERRORS, make_error
from twin.cli import main
from twin.core.errors import TwinError
from twin.sim.simulation import Simulation


@pytest.mark.parametrize("cls", ERRORS, ids=lambda c: c.__name__)
def test_error_in_a_run_is_one_line_with_its_text(
    cls: type[TwinError], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    err = make_error(cls)

    def failing_run(self: Simulation, **kwargs: object) -> None:
        raise err

    monkeypatch.setattr(Simulation, "run", failing_run)
    bag = tmp_path / "bag"
    code = main(["simulate", "--duration", "1", "--out", str(bag)])
    captured = capsys.readouterr()
    assert code == cls.exit_code
    line = assert_one_line_error(captured.err, contains=str(err))
    assert f"the bag up to t=0.000 s is in {bag}" in line
    assert_bag_reads_back(bag)
