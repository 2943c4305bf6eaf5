"""The recorded BT.CPP 4.8.2 cases: the shared suite and this project's own recordings."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from twin.bt.conformance import check_case, compare_run, load_case, run_case

SHARED_CASES = sorted((Path(__file__).resolve().parents[4] / "shared" / "bt_conformance" / "cases").glob("*.json"))
OWN_CASES = sorted((Path(__file__).resolve().parent / "cases").glob("*.json"))
BTCPP38_CASES = sorted((Path(__file__).resolve().parent / "cases_btcpp38").glob("*.json"))


def test_the_shared_cases_are_there() -> None:
    assert SHARED_CASES, "../shared/bt_conformance/cases is missing (CI puts ../shared beside the checkout)"


@pytest.mark.parametrize("path", SHARED_CASES, ids=lambda p: p.stem)
def test_shared_case_matches_btcpp_in_once_mode(path: Path) -> None:
    result = check_case(load_case(path), mode="once", check_v3=False)
    assert result.passed, result.first_difference


@pytest.mark.parametrize("path", [p for p in SHARED_CASES if "xml_v3" in p.read_text()], ids=lambda p: p.stem)
def test_shared_case_v3_spelling_gives_the_v4_result(path: Path) -> None:
    case = load_case(path)
    assert case.xml_v3 is not None
    result = check_case(case, mode="once", check_v3=True)
    assert result.v3_problems == (), result.first_difference


@pytest.mark.parametrize("path", SHARED_CASES, ids=lambda p: p.stem)
def test_shared_case_matches_btcpp_in_exactly_once_mode(path: Path) -> None:
    case = load_case(path)
    if "exactly_once" not in case.expected:
        pytest.fail(f"{path.name} has no alt_modes.exactly_once")
    result = check_case(case, mode="exactly_once", check_v3=False)
    assert result.passed, result.first_difference


@pytest.mark.parametrize("path", OWN_CASES, ids=lambda p: p.stem)
@pytest.mark.parametrize("mode", ["once", "exactly_once"])
def test_own_recorded_case_matches_btcpp(path: Path, mode: str) -> None:
    # A v3 spelling (`xml_v3`) is ticked as BT.CPP 3.8 ticks it, whose tickRoot() is the `once` mode:
    # 3.8 has no tickExactlyOnce() to compare it with.
    result = check_case(load_case(path), mode=mode, check_v3=mode == "once")
    assert result.passed, result.first_difference


def test_a_tree_the_engine_refuses_meets_an_error_only_if_nothing_ran_before_it(tmp_path: Path) -> None:
    """BT.CPP's refusal to load shows as an error on tick 1 before anything ran; refusing to load meets it."""
    raw = json.loads((Path(__file__).resolve().parent / "cases" / "u159_le_unknown_node.json").read_text())
    refused = tmp_path / "refused.json"
    refused.write_text(json.dumps(raw))
    case = load_case(refused)
    run = run_case(case, mode="once")
    assert run.load_error is not None and "Frobnicate" in run.load_error
    assert compare_run(case, run, mode="once") == []
    # The same refusal where BT.CPP had already run a node on that tick is a difference.
    raw["expected_trace"][0]["transitions"] = [["seq", "IDLE", "RUNNING"]]
    ran = tmp_path / "ran.json"
    ran.write_text(json.dumps(raw))
    problems = compare_run(load_case(ran), run, mode="once")
    assert problems and problems[0].startswith("the tree did not load")


@pytest.mark.parametrize("path", BTCPP38_CASES, ids=lambda p: p.stem)
def test_a_v3_file_ticks_as_btcpp_3_8_ticks_it(path: Path) -> None:
    """Nav2 Humble's BT.CPP: its one tick call, `tickRoot()`, is the runner's `once` mode for a v3 file."""
    case = load_case(path)
    assert "BTCPP_format" not in case.xml, "these cases are v3 files"
    result = check_case(case, mode="once", check_v3=False)
    assert result.passed, result.first_difference
