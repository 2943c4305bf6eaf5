"""BT.CPP's scripting language: grammar and BT.CPP 4.8's typing of results."""

from __future__ import annotations

from typing import Any

import pytest

from twin.bt import Blackboard
from twin.bt.script import Environment, ScriptError, ScriptSyntaxError, parse_script, script_truth


def run(code: str, board: Blackboard | None = None, enums: dict[str, int] | None = None) -> tuple[Any, Blackboard]:
    board = board or Blackboard()
    return parse_script(code)(Environment(board, enums or {})), board


def test_integer_literals_stay_integers_but_arithmetic_gives_doubles() -> None:
    _, board = run("a := 5; b := a * 2 + 1; c := 0x1F; d := 2.5")
    assert board.get("a") == 5 and isinstance(board.get("a"), int)
    assert board.get("b") == 11.0 and isinstance(board.get("b"), float)
    assert board.get("c") == 31
    assert board.get("d") == 2.5


def test_true_and_false_are_the_integers_1_and_0() -> None:
    _, board = run("t := true; f := false")
    assert board.get("t") == 1 and type(board.get("t")) is int
    assert board.get("f") == 0


def test_compound_assignment_keeps_the_type_of_the_entry() -> None:
    _, board = run("i := 1; i += 2; d := 1.0; d += 2")
    assert board.get("i") == 3 and isinstance(board.get("i"), int)
    assert isinstance(board.get("d"), float)


def test_compound_assignment_cannot_put_a_fraction_into_an_int() -> None:
    with pytest.raises(ScriptError):
        run("i := 1; i += 0.5")


def test_concatenation_prints_numbers_as_cpp() -> None:
    _, board = run("s := 'n=' .. 3 .. ' x=' .. 1.5")
    assert board.get("s") == "n=3 x=1.500000"


def test_plus_joins_two_strings_only() -> None:
    assert run("'a' + 'b'")[0] == "ab"
    with pytest.raises(ScriptError, match="not permitted"):
        run("'a' + 1")


def test_comparisons_return_doubles_and_chain() -> None:
    assert run("1 < 2 < 3")[0] == 1.0
    assert run("3 > 2 > 2")[0] == 0.0
    assert run("'abc' < 'abd'")[0] == 1.0


def test_equality_of_doubles_has_float_epsilon_tolerance() -> None:
    assert run("0.1 + 0.2 == 0.3")[0] == 1.0


def test_a_string_compared_with_a_number_is_read_as_a_number() -> None:
    board = Blackboard()
    board.set("s", "42")
    assert run("s == 42", board)[0] == 1.0
    assert run("'true' == 1")[0] == 1.0


def test_logical_operators_share_one_precedence_level_left_to_right() -> None:
    # (1 || 1) && 0
    assert run("1 || 1 && 0")[0] == 0.0


def test_logical_operators_need_0_or_1_integers() -> None:
    with pytest.raises(ScriptError, match="castable to bool"):
        run("2 && 1")


@pytest.mark.parametrize(
    ("code", "value"),
    [
        ("10 - 4 - 3", 9.0),  # 10 - (4 - 3)
        ("2 - 3 + 4", -5.0),  # 2 - (3 + 4)
        ("100 / 10 / 2", 20.0),  # 100 / (10 / 2)
        ("12 / 2 * 3", 2.0),  # 12 / (2 * 3)
        ("2 - 3 * 4 + 1", -11.0),  # 2 - ((3 * 4) + 1)
        ("2 * 3 - 4 * 5 - 6", -8.0),  # (2 * 3) - ((4 * 5) - 6)
        ("-2 - 3 - 4", -1.0),  # (-2) - (3 - 4)
        ("2 + 3 * 4", 14.0),
        ("(10 - 4) - 3", 3.0),
    ],
)
def test_arithmetic_groups_from_the_right_within_a_level_as_btcpp_4_8_2(code: str, value: float) -> None:
    # BT.CPP issue #1029, fixed after 4.8.2; values recorded from BT.CPP 4.8.2 (case t068)
    assert run(code)[0] == value


def test_bit_and_logical_operators_group_from_the_left() -> None:
    assert run("1 | 2 ^ 3")[0] == 0.0  # (1 | 2) ^ 3
    assert run("0 && 1 || 1")[0] == 1.0  # (0 && 1) || 1


def test_a_long_subtraction_chain_folds_from_the_right() -> None:
    assert run(" - ".join(["1"] * 300))[0] == 0.0  # 1 - (1 - (1 - ...)): 300 terms alternate 1, 0


def test_bit_operators_bind_and_before_or() -> None:
    assert run("1 | 2 & 3")[0] == 3.0


def test_ternary_picks_a_branch() -> None:
    assert run("x := 1; x == 1 ? 'one' : 'other'")[0] == "one"


def test_prefix_operators_repeat() -> None:
    assert run("--3")[0] == 3.0
    assert run("!!1")[0] == 1.0


def test_enums_read_as_doubles() -> None:
    result, _ = run("color := RED; color == 2", enums={"RED": 2})
    assert result == 1.0


def test_assignment_with_equals_needs_an_existing_entry() -> None:
    with pytest.raises(ScriptError, match="doesn't exist"):
        run("missing = 1")


def test_reading_an_unknown_variable_fails() -> None:
    with pytest.raises(ScriptError, match="Variable not found: ghost"):
        run("ghost + 1")


def test_a_string_assigned_to_a_number_entry_is_parsed() -> None:
    _, board = run("n := 1; n = '2.5'")
    assert board.get("n") == 2.5


@pytest.mark.parametrize(
    "code",
    [
        "a := := 1",
        "a := 1;",
        "a := 1;; b := 2",
        "a + 1 .. 'x'",
        "'x' .. -a",
        "~a + 1",
        "a := b := 1",
        "c ? 1 : d ? 2 : 3",
        "x := 1.",
        "x := 3abc",
        "x := 'open",
        "x := trueish",
        "x := 9223372036854775808",
        "   ",
    ],
)
def test_syntax_errors_are_reported_with_a_column(code: str) -> None:
    with pytest.raises(ScriptSyntaxError) as err:
        parse_script(code)
    assert err.value.column >= 1
    assert code in str(err.value)


def test_script_results_as_conditions_follow_any_cast_to_bool() -> None:
    assert script_truth(1) is True
    assert script_truth(0.5) is True
    for bad in (2, -1.0, "true", None):
        with pytest.raises(ScriptError):
            script_truth(bad)


def test_parentheses_nested_too_deeply_are_a_syntax_error_not_a_crash() -> None:
    with pytest.raises(ScriptSyntaxError, match="nested too deeply"):
        parse_script("(" * 2000 + "1" + ")" * 2000)


def test_an_expression_too_long_to_evaluate_is_a_script_error() -> None:
    with pytest.raises(ScriptError, match="nested too deeply"):
        run(" - ".join(["1"] * 5000))
