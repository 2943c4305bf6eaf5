"""Loading BT.CPP XML: v3 normalisation, includes, several trees, SubTrees, and one-line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.bt import BehaviorTreeFactory, NodeStatus
from twin.core.errors import TreeError

from .helpers import v4


def load(xml: str, **kwargs):
    return BehaviorTreeFactory().create_tree_from_text(xml, source="t.xml", **kwargs)


def error_of(xml: str) -> str:
    with pytest.raises(TreeError) as err:
        load(xml)
    return str(err.value)


def test_a_file_without_btcpp_format_is_read_as_v3_and_normalised() -> None:
    tree = load(
        '<root main_tree_to_execute="Main"><BehaviorTree ID="Main">'
        '<SequenceStar name="s"><RetryUntilSuccesful num_attempts="2"><AlwaysSuccess/></RetryUntilSuccesful></SequenceStar>'
        "</BehaviorTree></root>"
    )
    assert [node.registration_id for node in tree.nodes] == [
        "SequenceWithMemory",
        "RetryUntilSuccessful",
        "AlwaysSuccess",
    ]
    assert tree.tick_once() is NodeStatus.SUCCESS


def test_a_v3_subtree_remaps_keys_written_without_braces() -> None:
    tree = load(
        '<root main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>'
        '<Script code="target := 3"/><SubTree ID="Sub" goal="target"/></Sequence></BehaviorTree>'
        '<BehaviorTree ID="Sub"><Script code="goal := goal + 1"/></BehaviorTree></root>'
    )
    tree.tick_once()
    assert tree.root_blackboard.get("target") == 4.0


def test_a_v4_subtree_value_without_braces_is_a_literal_string() -> None:
    tree = load(
        v4(
            '<SubTree ID="Sub" name="s" goal="target"/>',
            '<BehaviorTree ID="Sub"><ScriptCondition code="goal == \'target\'"/></BehaviorTree>',
        )
    )
    assert tree.tick_once() is NodeStatus.SUCCESS


def test_a_v3_name_in_a_v4_file_names_its_replacement_and_line() -> None:
    message = error_of(
        '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<SequenceStar><AlwaysSuccess/></SequenceStar>\n</BehaviorTree></root>'
    )
    assert message.startswith("t.xml:3:")
    assert "SequenceWithMemory" in message


def test_v3_parallel_thresholds_in_a_v4_file_name_the_v4_ports() -> None:
    message = error_of(v4('<Parallel success_threshold="1"><AlwaysSuccess/></Parallel>'))
    assert "success_count" in message


def test_malformed_xml_reports_the_line() -> None:
    message = error_of('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Sequence>\n</BehaviorTree></root>')
    assert message.startswith("t.xml:4: malformed XML")


def test_unknown_node_type_reports_the_line_and_a_suggestion() -> None:
    message = error_of('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n  <Sequense/>\n</BehaviorTree></root>')
    assert message.startswith("t.xml:3:")
    assert "'Sequence'" in message


def test_unknown_port_names_the_known_ones() -> None:
    message = error_of(v4('<Repeat num_cycle="3"><AlwaysSuccess/></Repeat>'))
    assert "unknown port 'num_cycle'" in message and "num_cycles" in message


def test_literals_of_typed_ports_must_convert() -> None:
    assert "cannot be converted to int" in error_of(v4('<Repeat num_cycles="three"><AlwaysSuccess/></Repeat>'))


def test_script_syntax_errors_fail_the_load_with_the_line() -> None:
    message = error_of(
        '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Script code="x := := 1"/>\n</BehaviorTree></root>'
    )
    assert message.startswith("t.xml:3:") and "script syntax error" in message


def test_recursive_subtrees_are_an_error() -> None:
    message = error_of(
        v4(
            '<SubTree ID="A"/>',
            '<BehaviorTree ID="A"><SubTree ID="B"/></BehaviorTree><BehaviorTree ID="B"><SubTree ID="A"/></BehaviorTree>',
        )
    )
    assert "includes itself (MainTree -> A -> B -> A)" in message


def test_a_missing_subtree_is_an_error() -> None:
    assert "no <BehaviorTree ID='Nav'>" in error_of(v4('<SubTree ID="Nav"/>'))


def test_wrong_numbers_of_children_are_errors() -> None:
    assert "exactly 1 child" in error_of(v4("<Inverter><AlwaysSuccess/><AlwaysSuccess/></Inverter>"))
    assert "must not have children" in error_of(v4("<AlwaysSuccess><AlwaysSuccess/></AlwaysSuccess>"))
    assert "1 or more children" in error_of(v4("<Sequence/>"))


def test_main_tree_comes_from_the_attribute_the_argument_or_the_only_tree() -> None:
    two = '<root BTCPP_format="4"><BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree><BehaviorTree ID="B"><AlwaysFailure/></BehaviorTree></root>'
    assert load(two, main_tree="B").tick_once() is NodeStatus.FAILURE
    assert "main_tree_to_execute" in error_of(two)
    one = '<root BTCPP_format="4"><BehaviorTree ID="Only"><AlwaysFailure/></BehaviorTree></root>'
    assert load(one).tick_once() is NodeStatus.FAILURE


def test_action_and_condition_id_forms() -> None:
    tree = load(
        v4('<Sequence><Action ID="AlwaysSuccess" name="a"/><Condition ID="ScriptCondition" code="true"/></Sequence>')
    )
    assert tree.tick_once() is NodeStatus.SUCCESS


def test_nodes_without_a_name_get_type_and_uid_in_their_path() -> None:
    tree = load(
        v4(
            '<Sequence><AlwaysSuccess/><SubTree ID="S"/></Sequence>',
            '<BehaviorTree ID="S"><AlwaysSuccess name="x"/></BehaviorTree>',
        )
    )
    assert [node.full_path for node in tree.nodes] == ["Sequence::1", "AlwaysSuccess::2", "S::3", "S::3/x"]


def test_includes_are_resolved_relative_to_the_including_file(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "sub.xml").write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="Sub"><AlwaysSuccess/></BehaviorTree></root>'
    )
    main = tmp_path / "main.xml"
    main.write_text(
        '<root BTCPP_format="4" main_tree_to_execute="Main"><include path="lib/sub.xml"/>'
        '<BehaviorTree ID="Main"><SubTree ID="Sub"/></BehaviorTree></root>'
    )
    tree = BehaviorTreeFactory().create_tree_from_file(main)
    assert tree.tick_once() is NodeStatus.SUCCESS


def test_an_include_loop_is_an_error(tmp_path: Path) -> None:
    a = tmp_path / "a.xml"
    a.write_text(
        '<root BTCPP_format="4"><include path="a.xml"/><BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree></root>'
    )
    with pytest.raises(TreeError, match="loops back"):
        BehaviorTreeFactory().create_tree_from_file(a)


def test_subtree_models_demand_their_mandatory_ports() -> None:
    model = '<TreeNodesModel><SubTree ID="Sub"><input_port name="goal"/><input_port name="speed" default="0.2"/></SubTree></TreeNodesModel>'
    sub = '<BehaviorTree ID="Sub"><ScriptCondition code="speed == \'0.2\'"/></BehaviorTree>'
    assert "mandatory port 'goal'" in error_of(v4('<SubTree ID="Sub"/>', sub + model))
    assert load(v4('<SubTree ID="Sub" goal="x"/>', sub + model)).tick_once() is NodeStatus.SUCCESS


def test_ports_pre_create_typed_entries_and_reject_conflicting_types() -> None:
    message = error_of(v4('<Sequence><Repeat num_cycles="{n}"><AlwaysSuccess/></Repeat><Sleep msec="{n}"/></Sequence>'))
    assert "[int]" in message and "[unsigned int]" in message


# BT.CPP's Reactive.TwoAsyncNodesInReactiveSequence (tests/gtest_reactive.cpp), with built-in leaves.
TWO_ASYNC = """<root BTCPP_format="4">
  <BehaviorTree ID="MainTree">
    <ReactiveSequence>
      <AsyncSequence name="first"><AlwaysSuccess/><AlwaysSuccess/></AsyncSequence>
      <AsyncSequence name="second"><AlwaysSuccess/><AlwaysSuccess/></AsyncSequence>
    </ReactiveSequence>
  </BehaviorTree>
</root>"""


def test_a_reactive_sequence_with_two_async_sequences_is_refused_at_its_line() -> None:
    message = error_of(TWO_ASYNC)
    assert message.startswith("t.xml:3: a <ReactiveSequence> cannot have more than one async child")


@pytest.mark.parametrize(
    "body",
    [
        # BT.CPP 4.8.2 counts only <AsyncSequence> children (oracle: all three load and run)
        "<ReactiveSequence><AsyncSequence><AlwaysSuccess/></AsyncSequence><Sequence><AsyncSequence><AlwaysSuccess/>"
        "</AsyncSequence></Sequence></ReactiveSequence>",
        "<ReactiveSequence><AsyncFallback><AlwaysSuccess/></AsyncFallback><AsyncFallback><AlwaysSuccess/>"
        "</AsyncFallback></ReactiveSequence>",
        "<ReactiveFallback><AsyncSequence><AlwaysSuccess/></AsyncSequence><AsyncSequence><AlwaysSuccess/>"
        "</AsyncSequence></ReactiveFallback>",
    ],
    ids=["one_direct", "async_fallbacks", "reactive_fallback"],
)
def test_other_async_children_are_accepted_as_btcpp_accepts_them(body: str) -> None:
    assert load(v4(body)).tick_once() is NodeStatus.SUCCESS


def test_raw_ampersands_and_angle_brackets_in_attributes_load_as_tinyxml2_reads_them() -> None:
    tree = load(
        v4(
            "<Sequence><Script code=\"a := 1; b := 2; ok := a &lt; b &amp;&amp; b > a; s := 'x &foo; &amp; y'\"/>"
            '<Precondition if="a>-b && ok != 0 && s == \'x &foo; & y\'" else="FAILURE">'
            '<Script code="c := a < b"/></Precondition></Sequence>'
        )
    )
    assert tree.tick_once() is NodeStatus.SUCCESS
    assert tree.root_blackboard.get("c") == 1.0


def test_escaping_keeps_line_numbers_and_leaves_comments_alone() -> None:
    message = error_of(
        '<root BTCPP_format="4">\n<!-- a & b < c -->\n<BehaviorTree ID="M">\n'
        '<Sequence><Script code="x := 1 && 2 < 3"/>\n<Teleport/>\n</Sequence></BehaviorTree></root>'
    )
    assert message.startswith("t.xml:5: unknown node type <Teleport>")


def test_a_lt_outside_any_attribute_is_still_malformed() -> None:
    assert "t.xml:1: malformed XML" in error_of(v4("<Sequence>a < b<AlwaysSuccess/></Sequence>"))


@pytest.mark.parametrize("root", ['<root BTCPP_format="4">', '<root BTCPP_format="4" main_tree_to_execute="M">'])
def test_a_file_without_behavior_tree_says_so(root: str) -> None:
    assert error_of(f"{root}</root>").startswith("t.xml:1: the file has no <BehaviorTree>")


def subtree_chain(n: int, wrap: bool = True) -> str:
    """T0 holds T1 holds ... holds Tn, each inside a Sequence when `wrap`."""
    trees = "".join(
        f'<BehaviorTree ID="T{i}">{"<Sequence>" if wrap else ""}<SubTree ID="T{i + 1}"/>{"</Sequence>" if wrap else ""}'
        "</BehaviorTree>"
        for i in range(n)
    )
    return f'<root BTCPP_format="4" main_tree_to_execute="T0">{trees}<BehaviorTree ID="T{n}"><AlwaysSuccess/></BehaviorTree></root>'


def test_a_subtree_chain_within_the_depth_limit_ticks() -> None:
    assert load(subtree_chain(99)).tick_once() is NodeStatus.SUCCESS  # 199 levels


@pytest.mark.parametrize(("n", "wrap", "levels"), [(100, True, 201), (1200, False, 1201)])
def test_a_subtree_chain_nesting_too_deep_is_one_short_line(n: int, wrap: bool, levels: int) -> None:
    message = error_of(subtree_chain(n, wrap))
    assert message.startswith(f"t.xml:1: <BehaviorTree ID='T0'> nests nodes {levels} levels deep through {n} nested")
    assert f"(T0 -> T1 -> T2 -> ... -> T{n - 1} -> T{n})" in message
    assert len(message) < 300
