"""`twin tree` refuses bad trees and options with one line and its exit code, never a traceback or exit 70.

Trees and files are written into a temporary folder; cases run in-process through `twin.cli.main`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.robustness.helpers import assert_one_line_error
from twin.cli import main

# BT.CPP's TryCatch test tree (tests/gtest_try_catch.cpp): a control node 4.8.2 does not have.
TRY_CATCH = """<root BTCPP_format="4">
  <BehaviorTree ID="MainTree">
    <TryCatch>
      <TestA/>
      <TestB/>
    </TryCatch>
  </BehaviorTree>
</root>
"""

# A chain of 300 SubTrees, each inside a Sequence: 601 levels of nodes.
CHAIN = (
    '<root BTCPP_format="4" main_tree_to_execute="T0">'
    + "".join(
        f'<BehaviorTree ID="T{i}"><Sequence><SubTree ID="T{i + 1}"/></Sequence></BehaviorTree>' for i in range(300)
    )
    + '<BehaviorTree ID="T300"><AlwaysSuccess/></BehaviorTree></root>'
)

_CASE = '{"id": "x", "xml": "<root BTCPP_format=\\"4\\"><BehaviorTree ID=\\"M\\"><Leaf name=\\"A\\"/></BehaviorTree></root>", '

# Nav2's FollowPath with a port the twin's Nav2 declarations do not have (validate and show refuse it).
FOLLOW_PATH = (
    '<root BTCPP_format="4"><BehaviorTree ID="M">\n'
    '<FollowPath path="{path}" controller_id="FollowPath" tracking_feedback="{fb}"/>\n'
    "</BehaviorTree></root>"
)

FILES = {
    "try_catch.xml": TRY_CATCH,
    "follow_path.xml": FOLLOW_PATH,
    "no_tree.xml": '<root BTCPP_format="4"></root>',
    "chain.xml": CHAIN,
    "bad_ticks.json": _CASE + '"ticks": "x", "expected_trace": []}',
    "bad_sleeps.json": _CASE + '"ticks": 2, "sleep_before_tick_ms": [0, "a"], "expected_trace": []}',
    "bad_scripts.json": _CASE + '"ticks": 1, "leaf_scripts": [1], "expected_trace": []}',
    "bad_alt_modes.json": _CASE + '"ticks": 1, "alt_modes": {"exactly_once": 1}, "expected_trace": []}',
}
NAV_TREE_QUEUE = str(REPO / "trees" / "nav_tree_queue.xml")

CASES: dict[str, tuple[list[str], int, str]] = {
    "log_unknown_control": (["tree", "log", "{d}/try_catch.xml"], 6, "try_catch.xml:3: unknown node type <TryCatch>"),
    "show_unknown_control": (["tree", "show", "{d}/try_catch.xml"], 6, "try_catch.xml:3: unknown node type <TryCatch>"),
    "log_unknown_port_of_a_nav2_leaf": (
        ["tree", "log", "{d}/follow_path.xml"],
        6,
        "follow_path.xml:2: unknown port 'tracking_feedback' of <FollowPath>",
    ),
    "show_unknown_port_of_a_nav2_leaf": (
        ["tree", "show", "{d}/follow_path.xml"],
        6,
        "follow_path.xml:2: unknown port 'tracking_feedback' of <FollowPath>",
    ),
    "log_deep_subtrees": (["tree", "log", "{d}/chain.xml"], 6, "chain.xml:1: <BehaviorTree ID='T0'> nests nodes 601"),
    "show_deep_subtrees": (["tree", "show", "{d}/chain.xml"], 6, "twin ticks trees up to 200 levels"),
    "log_polls_to_arrive_0": (["tree", "log", NAV_TREE_QUEUE, "--polls-to-arrive", "0"], 2, "--polls-to-arrive"),
    "log_save_in_missing_folder": (
        ["tree", "log", NAV_TREE_QUEUE, "--save", "{d}/no/x.jsonl"],
        6,
        "--save: cannot write",
    ),
    "log_scripts_file_missing": (
        ["tree", "log", NAV_TREE_QUEUE, "--scripts", "{d}/none.json"],
        6,
        "none.json: file not found",
    ),
    "log_location_file_missing": (
        ["tree", "log", NAV_TREE_QUEUE, "--location-file", "{d}/none.yaml"],
        2,
        "--location-file",
    ),
    "log_case_with_bad_ticks": (["tree", "log", "{d}/bad_ticks.json"], 6, "ticks must be a whole number, got 'x'"),
    "log_no_behavior_tree": (["tree", "log", "{d}/no_tree.xml"], 6, "no_tree.xml:1: the file has no <BehaviorTree>"),
}


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("case", CASES, ids=str)
def test_a_bad_tree_or_option_is_one_line(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    argv, exit_code, contains = CASES[case]
    code, _, err = run([a.replace("{d}", str(tmp_path)) for a in argv], capsys)
    assert code == exit_code, err
    assert_one_line_error(err, contains=contains)


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("bad_ticks.json", "ticks must be a whole number, got 'x'"),
        ("bad_sleeps.json", "each entry of sleep_before_tick_ms must be a whole number, got 'a'"),
        ("bad_scripts.json", "not a case in the format of bt_conformance/README.md"),
        ("bad_alt_modes.json", "not a case in the format of bt_conformance/README.md"),
    ],
)
def test_a_malformed_conformance_case_fails_in_one_line(
    name: str, problem: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / name).write_text(FILES[name])
    code, out, err = run(["tree", "conformance", str(tmp_path / name)], capsys)
    assert code == 1, out + err
    assert out.startswith(f"FAIL {tmp_path / name}: ") and problem in out and out.count("\n") == 1
    assert "Traceback" not in out + err and "internal error" not in out + err
