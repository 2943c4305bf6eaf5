"""The recorded BT.CPP 4.8.2 cases: the shared suite and this project's own recordings."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.bt.conformance import check_case, load_case

SHARED_CASES = sorted((Path(__file__).resolve().parents[4] / "shared" / "bt_conformance" / "cases").glob("*.json"))
OWN_CASES = sorted((Path(__file__).resolve().parent / "cases").glob("*.json"))


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
    result = check_case(load_case(path), mode=mode)
    assert result.passed, result.first_difference
