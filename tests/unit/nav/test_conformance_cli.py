"""`twin nav conformance`: the recorded Nav2 cases replayed from the command line, a difference named, bad files refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from twin.cli import main
from twin.nav.conformance import COMPONENTS, load_case

NAVFN = Path(__file__).resolve().parent / "planner" / "navfn_cases"
INFLATION = Path(__file__).resolve().parent / "costmap_2d" / "inflation_cases"
SMOOTHER = Path(__file__).resolve().parent / "velocity_smoother" / "smoother_cases"
AMCL = Path(__file__).resolve().parent / "amcl" / "amcl_cases"
RPP = Path(__file__).resolve().parent / "controller" / "rpp_cases"
BEHAVIORS = Path(__file__).resolve().parent / "behaviors" / "behavior_cases"
AMCL_RUN = Path(__file__).resolve().parent / "amcl" / "amcl_run_cases"


def test_the_recorded_sets_all_equal_nav2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["nav", "conformance"]) == 0
    out = capsys.readouterr()
    for component, folder, how in (
        ("navfn", NAVFN, "compiled kernel"),
        ("inflation", INFLATION, "compiled kernel"),
        ("velocity_smoother", SMOOTHER, "Python path"),  # it has no C kernel
        ("rpp", RPP, "Python path"),
    ):
        count = len(list(folder.glob("*.npz")))
        assert f"{component} ({how}): {count} of {count} cases equal Nav2's answer" in out.err
    amcl = [load_case(p)[0]["component"] for p in AMCL.glob("*.npz")]
    assert set(amcl) == {"amcl_motion_model", "amcl_likelihood_field", "amcl_resample", "amcl_estimate"}
    for component in set(amcl):
        count = amcl.count(component)
        assert f"{component} (compiled kernel): {count} of {count} cases equal Nav2's answer" in out.err
    behaviors = [load_case(p)[0]["component"] for p in BEHAVIORS.glob("*.npz")]
    for component in ("behavior", "behavior_collision"):
        count = behaviors.count(component)
        assert f"{component} (Python path): {count} of {count} cases equal Nav2's answer" in out.err
    assert "DIFFERS" not in out.out
    runs = len(list(AMCL_RUN.glob("*.npz")))
    assert runs >= 1 and f"amcl_run (compiled kernel): {runs} of {runs} cases equal Nav2's answer" in out.err


def test_a_case_that_differs_is_named_with_its_first_difference_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shutil.copy(NAVFN / "corridor.npz", tmp_path / "corridor.npz")
    meta, arrays = load_case(NAVFN / "corridor.npz")
    meta["name"] = "corridor_moved"
    arrays["path"] = arrays["path"] + np.array([0.05, 0.0])  # Nav2's path one cell to the side
    np.savez(tmp_path / "corridor_moved.npz", meta=json.dumps(meta), **arrays)
    assert main(["nav", "conformance", str(tmp_path), "--python", "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["components"] == {"navfn": {"equal": 1, "cases": 2}}
    (moved,) = [c for c in report["cases"] if not c["equal"]]
    assert moved["name"] == "corridor_moved"
    assert moved["differences"][0].startswith("path: ")
    assert main(["nav", "conformance", str(tmp_path / "corridor_moved.npz")]) == 1
    assert "DIFFERS navfn corridor_moved" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"not a zip file", "not a recorded Nav2 case (an .npz with a `meta` entry): it is not an .npz archive"),
        (None, "no `meta` entry"),
    ],
)
def test_a_file_that_is_not_a_case_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes | None, expected: str
) -> None:
    path = tmp_path / "case.npz"
    if content is None:
        np.savez(path, cost=np.zeros((2, 2), dtype=np.uint8))
    else:
        path.write_bytes(content)
    assert main(["nav", "conformance", str(path)]) == 2
    err = capsys.readouterr().err
    assert expected in err and str(path) in err
    assert "pickle" not in err  # numpy's offer to unpickle the file is not the user's business
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_case_for_a_component_the_twin_does_not_check_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    np.savez(tmp_path / "dwb.npz", meta=json.dumps({"component": "dwb_critics"}))
    assert main(["nav", "conformance", str(tmp_path / "dwb.npz")]) == 2
    err = capsys.readouterr().err
    assert f"a case for dwb_critics; the twin checks {', '.join(sorted(COMPONENTS))}" in err
    assert "amcl_estimate, amcl_likelihood_field, amcl_motion_model, amcl_resample" in err
