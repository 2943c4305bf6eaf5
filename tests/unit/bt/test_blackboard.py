"""Blackboard entries: typing on first write, remapping into SubTrees, and the root prefix @."""

from __future__ import annotations

import pytest

from twin.bt import Blackboard, PortType
from twin.core.errors import TreeError


def test_a_string_creates_an_untyped_entry_that_a_number_can_replace() -> None:
    board = Blackboard()
    board.set("k", "42")
    board.set("k", 7)
    assert board.get("k") == 7
    assert board.get_entry("k").info == PortType.INT


def test_a_typed_entry_parses_strings_written_to_it() -> None:
    board = Blackboard()
    board.create_entry("n", PortType.INT)
    board.set("n", "12")
    assert board.get("n") == 12


def test_a_typed_entry_keeps_its_type_against_other_values() -> None:
    board = Blackboard()
    board.set("n", 3)
    board.set("n", 4.0)  # an exact double fits an int entry
    assert board.get("n") == 4
    with pytest.raises(TreeError, match="shall not change"):
        board.set("n", 4.5)


def test_each_write_counts_in_the_sequence_number() -> None:
    board = Blackboard()
    board.set("k", 1)
    board.set("k", 2)
    assert board.get_entry("k").seq == 2


def test_subtree_remapping_reads_and_writes_the_parent_entry() -> None:
    parent = Blackboard()
    parent.set("target", "kitchen")
    child = Blackboard(parent)
    child.add_subtree_remapping("goal", "target")
    assert child.get("goal") == "kitchen"
    child.set("goal", "hall")
    assert parent.get("target") == "hall"
    assert "goal" not in parent


def test_without_remapping_a_subtree_is_isolated() -> None:
    parent = Blackboard()
    parent.set("x", 1)
    child = Blackboard(parent)
    assert child.get_entry("x") is None
    child.set("x", 5)
    assert parent.get("x") == 1


def test_autoremap_shares_every_key_except_private_ones() -> None:
    parent = Blackboard()
    child = Blackboard(parent)
    child.enable_auto_remapping(True)
    child.create_entry("shared", PortType.ANY)
    child.create_entry("_private", PortType.ANY)
    assert parent.keys() == ["shared"]
    assert child.keys() == ["_private"]


def test_at_prefix_reaches_the_root_from_any_depth() -> None:
    root = Blackboard()
    inner = Blackboard(Blackboard(root))
    inner.set("@counter", 3)
    assert root.get("counter") == 3
    assert inner.get_entry("@counter") is root.get_entry("counter")


def test_reading_an_empty_entry_is_an_error() -> None:
    board = Blackboard()
    board.create_entry("k", PortType.ANY)
    with pytest.raises(TreeError, match="initialized"):
        board.get("k")
