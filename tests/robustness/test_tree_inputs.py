"""`twin tree` refuses bad trees and options with one line and its exit code, never a traceback or exit 70.

Trees and files are written into a temporary folder; cases run in-process through `twin.cli.main`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

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

FILES = {"try_catch.xml": TRY_CATCH, "no_tree.xml": '<root BTCPP_format="4"></root>', "chain.xml": CHAIN}

CASES: dict[str, tuple[list[str], int, str]] = {
    "log_unknown_control": (["tree", "log", "{d}/try_catch.xml"], 6, "try_catch.xml:3: unknown node type <TryCatch>"),
    "show_unknown_control": (["tree", "show", "{d}/try_catch.xml"], 6, "try_catch.xml:3: unknown node type <TryCatch>"),
    "log_deep_subtrees": (["tree", "log", "{d}/chain.xml"], 6, "chain.xml:1: <BehaviorTree ID='T0'> nests nodes 601"),
    "show_deep_subtrees": (["tree", "show", "{d}/chain.xml"], 6, "twin ticks trees up to 200 levels"),
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
