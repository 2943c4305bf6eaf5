"""`validate`: every kind of bad input gives one line with file and line."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from twin.bt import BehaviorTreeFactory
from twin.bt.validate import validate_file, validate_text
from twin.mission.bt_nodes import ScriptedNavigator, register_mission_nodes
from twin.mission.look_for_object import ImageSlot, register_vision_nodes
from twin.nav.bt_navigator.factory import nav2_factory

TREES = Path(__file__).resolve().parents[3] / "trees"


@pytest.fixture
def factory() -> BehaviorTreeFactory:
    factory = nav2_factory()
    register_mission_nodes(factory, navigator=ScriptedNavigator(), rng=random.Random(0))
    register_vision_nodes(factory, slot=ImageSlot())  # the behaviour demos' LookForObject, as a run registers it
    return factory


def doc(body: str, *, extra: str = "", fmt: str = ' BTCPP_format="4"') -> str:
    return f'<root{fmt} main_tree_to_execute="Main">\n<BehaviorTree ID="Main">\n{body}\n</BehaviorTree>{extra}\n</root>'


@pytest.mark.parametrize("tree_file", sorted(p.name for p in TREES.glob("*.xml")))
def test_the_shipped_trees_are_valid(factory: BehaviorTreeFactory, tree_file: str) -> None:
    report = validate_file(TREES / tree_file, factory)
    assert report.ok, report.problems


@pytest.mark.parametrize(
    ("body", "extra", "fmt", "expected"),
    [
        ("<Sequence>\n<AlwaysSuccess>", "", ' BTCPP_format="4"', "t.xml:5: malformed XML"),
        ("<Teleport/>", "", ' BTCPP_format="4"', "t.xml:3: unknown node type <Teleport>"),
        ("<Repeat><AlwaysSuccess/></Repeat>", "", ' BTCPP_format="4"', "t.xml:3: <Repeat> needs the port 'num_cycles'"),
        ('<GoToPose name="g"/>', "", ' BTCPP_format="4"', "t.xml:3: <GoToPose> needs the port 'loc'"),
        (
            '<Timeout msec="1" sec="2"><AlwaysSuccess/></Timeout>',
            "",
            ' BTCPP_format="4"',
            "t.xml:3: unknown port 'sec'",
        ),
        (
            '<SubTree ID="Loop"/>',
            '<BehaviorTree ID="Loop"><SubTree ID="Main"/></BehaviorTree>',
            ' BTCPP_format="4"',
            "includes itself (Main -> Loop -> Main)",
        ),
        ('<Script code="x := (1"/>', "", ' BTCPP_format="4"', "t.xml:3: <Script> code: script syntax error"),
        ('<AlwaysSuccess _skipIf="a =="/>', "", ' BTCPP_format="4"', "t.xml:3: _skipIf: script syntax error"),
        (
            "<SequenceStar><AlwaysSuccess/></SequenceStar>",
            "",
            ' BTCPP_format="4"',
            't.xml:3: <SequenceStar> is a BT.CPP v3 name; this file declares BTCPP_format="4", so write <SequenceWithMemory>',
        ),
        (
            '<SubTree ID="S" __shared_blackboard="true"/>',
            '<BehaviorTree ID="S"><AlwaysSuccess/></BehaviorTree>',
            ' BTCPP_format="4"',
            'so write _autoremap="true"',
        ),
        ('<SubTree ID="Missing"/>', "", ' BTCPP_format="4"', "t.xml:3: SubTree 'Missing' does not match"),
        (
            "<ReactiveSequence><AsyncSequence><AlwaysSuccess/></AsyncSequence>"
            "<AsyncSequence><AlwaysSuccess/></AsyncSequence></ReactiveSequence>",
            "",
            ' BTCPP_format="4"',
            "t.xml:3: a <ReactiveSequence> cannot have more than one async child",
        ),
        (  # BT.CPP loads these and throws at their first tick: validate says so before a run
            "<IfThenElse><AlwaysSuccess/></IfThenElse>",
            "",
            ' BTCPP_format="4"',
            "t.xml:3: <IfThenElse> needs 2 or 3 children (a condition, then one or two branches), it has 1",
        ),
        (
            "<WhileDoElse><AlwaysSuccess/><AlwaysSuccess/><AlwaysSuccess/><AlwaysSuccess/></WhileDoElse>",
            "",
            ' BTCPP_format="4"',
            "t.xml:3: <WhileDoElse> needs 2 or 3 children",
        ),
        (  # a status port: BT.CPP has no load-time converter for it, and fails when the node reads it
            '<Precondition if="true" else="success"><AlwaysSuccess/></Precondition>',
            "",
            ' BTCPP_format="4"',
            "t.xml:3: <Precondition> else='success' is not a status; use one of IDLE, RUNNING, SUCCESS, FAILURE",
        ),
    ],
)
def test_each_problem_is_one_line_with_file_and_line(factory, body: str, extra: str, fmt: str, expected: str) -> None:
    report = validate_text(doc(body, extra=extra, fmt=fmt), factory, source="t.xml")
    assert not report.ok
    assert any(expected in problem for problem in report.problems), report.problems
    assert all("\n" not in problem and problem.startswith("t.xml:") for problem in report.problems)


def test_v3_files_are_valid_with_v3_names(factory: BehaviorTreeFactory) -> None:
    report = validate_text(doc("<SequenceStar><AlwaysSuccess/></SequenceStar>", fmt=""), factory, source="t.xml")
    assert report.ok, report.problems
    assert report.version == 3


def test_types_declared_in_the_tree_nodes_model_count_as_known(factory: BehaviorTreeFactory) -> None:
    # A node type the factory does not have (LookForObject, used here before, is registered now).
    model = '<TreeNodesModel><Action ID="FindCharger"><input_port name="color"/></Action></TreeNodesModel>'
    report = validate_text(doc('<FindCharger color="blue"/>', extra=model), factory, source="t.xml")
    assert report.ok, report.problems
    assert report.declared_only == ("FindCharger",)
    bad = validate_text(doc('<FindCharger colour="blue"/>', extra=model), factory, source="t.xml")
    assert any("unknown port 'colour'" in p for p in bad.problems)


def test_every_tree_is_checked_not_only_the_main_one(factory: BehaviorTreeFactory) -> None:
    report = validate_text(
        doc("<AlwaysSuccess/>", extra='<BehaviorTree ID="Other"><Repeat><AlwaysSuccess/></Repeat></BehaviorTree>'),
        factory,
        source="t.xml",
    )
    assert any("num_cycles" in p for p in report.problems)


def test_a_deep_subtree_chain_is_one_problem_not_a_recursion_error(factory: BehaviorTreeFactory) -> None:
    trees = "".join(f'<BehaviorTree ID="T{i}"><SubTree ID="T{i + 1}"/></BehaviorTree>' for i in range(1200))
    xml = f'<root BTCPP_format="4" main_tree_to_execute="T0">{trees}<BehaviorTree ID="T1200"><AlwaysSuccess/></BehaviorTree></root>'
    report = validate_text(xml, factory, source="t.xml")
    assert len(report.problems) == 1
    assert report.problems[0].startswith("t.xml:1: <BehaviorTree ID='T0'> nests nodes 1201 levels deep")


def test_a_long_subtree_cycle_is_reported_without_recursion(factory: BehaviorTreeFactory) -> None:
    trees = "".join(f'<BehaviorTree ID="T{i}"><SubTree ID="T{(i + 1) % 1500}"/></BehaviorTree>' for i in range(1500))
    report = validate_text(f'<root BTCPP_format="4" main_tree_to_execute="T0">{trees}</root>', factory, source="t.xml")
    assert any("includes itself (T0 -> T1 -> " in problem for problem in report.problems), report.problems


def test_an_unknown_port_lists_the_ports_once(factory: BehaviorTreeFactory) -> None:
    report = validate_text(doc('<Timeout msec="1" zzz="2"><AlwaysSuccess/></Timeout>'), factory, source="t.xml")
    (problem,) = report.problems
    assert "unknown port 'zzz' of <Timeout>; its ports are msec" in problem and "valid:" not in problem


def test_main_tree_picks_the_tree_of_a_file_of_several(factory: BehaviorTreeFactory, tmp_path: Path) -> None:
    # BT.CPP's examples register such a file and create one of its trees by ID.
    path = tmp_path / "two.xml"
    path.write_text(
        '<root BTCPP_format="4">\n<BehaviorTree ID="MainTree"><SubTree ID="Sub"/></BehaviorTree>\n'
        '<BehaviorTree ID="Sub"><AlwaysSuccess/></BehaviorTree>\n</root>'
    )
    assert any("several trees (MainTree, Sub)" in p for p in validate_file(path, factory).problems)
    report = validate_file(path, factory, main_tree="MainTree")
    assert report.ok, report.problems
    assert report.main_tree == "MainTree"
    wrong = validate_file(path, factory, main_tree="MainTre")
    assert wrong.problems == (f"{path}: --main-tree 'MainTre' names no tree in the file; did you mean 'MainTree'?",)


def test_a_status_port_from_the_blackboard_or_spelled_right_is_valid(factory: BehaviorTreeFactory) -> None:
    body = (
        '<Sequence><Precondition if="true" else="SKIPPED"><AlwaysSuccess/></Precondition>'
        '<Precondition if="true" else="{fallback}"><AlwaysSuccess/></Precondition>'
        '<Precondition if="true" else="="><AlwaysSuccess/></Precondition></Sequence>'
    )
    report = validate_text(doc(body), factory, source="t.xml")
    assert report.ok, report.problems
