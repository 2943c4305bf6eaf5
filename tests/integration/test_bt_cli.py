"""`twin tree ...` end to end, in a subprocess as a user runs it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CASES = REPO.parent / "shared" / "bt_conformance" / "cases"


def twin(*args: str | Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "twin", *map(str, args)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_validate_accepts_the_thesis_tree() -> None:
    result = twin("tree", "validate", "trees/tree.xml")
    assert result.returncode == 0, result.stderr
    assert "trees/tree.xml: ok (BTCPP_format 3" in result.stdout


@pytest.mark.parametrize(
    ("xml", "expected"),
    [
        ('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Sequence>\n</BehaviorTree></root>', ":4: malformed XML"),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Wobble/>\n</BehaviorTree></root>',
            ":3: unknown node type <Wobble>",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Delay><AlwaysSuccess/></Delay>\n</BehaviorTree></root>',
            ":3: <Delay> needs the port 'delay_msec'",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Sleep ms="3"/>\n</BehaviorTree></root>',
            ":3: unknown port 'ms'",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<SubTree ID="M"/>\n</BehaviorTree></root>',
            ":3: SubTree 'M' includes itself",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Script code="a := "/>\n</BehaviorTree></root>',
            ":3: <Script> code: script syntax error",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<SubTreePlus ID="X"/>\n</BehaviorTree></root>',
            ":3: <SubTreePlus> is a BT.CPP v3 name",
        ),
    ],
)
def test_validate_reports_bad_input_in_one_line_and_fails(tmp_path: Path, xml: str, expected: str) -> None:
    path = tmp_path / "bad.xml"
    path.write_text(xml)
    result = twin("tree", "validate", path)
    assert result.returncode == 6
    first = result.stderr.splitlines()[0]
    assert first.startswith(str(path)) and expected in first, result.stderr
    assert "Traceback" not in result.stderr


def test_validate_json_report(tmp_path: Path) -> None:
    result = twin("tree", "validate", "trees/navigate_to_pose_w_replanning_and_recovery.xml", "--json")
    report = json.loads(result.stdout)
    assert report["ok"] and "Spin" in report["declared_only"]


def test_show_prints_an_indented_outline() -> None:
    result = twin("tree", "show", "trees/tree.xml")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[1] == 'Sequence "sequence"'
    assert lines[2] == '├── GoToPose "go_to_location1" loc="location1"'
    assert lines[-1] == '└── GoToPose "go_to_location4" loc="location4"'


def test_conformance_passes_every_shared_case() -> None:
    cases = sorted(CASES.glob("*.json"))
    result = twin("tree", "conformance", *cases)
    assert result.returncode == 0, result.stdout
    assert result.stdout.splitlines() == [f"PASS {json.loads(p.read_text())['id']}" for p in cases]


def test_conformance_reports_the_first_difference_and_fails(tmp_path: Path) -> None:
    case = json.loads((CASES / "001_sequence_all_success.json").read_text())
    case["expected_trace"][0]["root_status"] = "FAILURE"
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(case))
    result = twin("tree", "conformance", path, "--json")
    assert result.returncode == 1
    report = json.loads(result.stdout)
    assert report["failed"] == 1
    assert report["cases"][0]["problems"][0] == "tick 1: root status expected FAILURE, got SUCCESS"


def test_log_runs_the_thesis_mission_on_the_simulated_clock(tmp_path: Path) -> None:
    saved = tmp_path / "run.jsonl"
    result = twin("tree", "log", "trees/tree.xml", "--polls-to-arrive", "2", "--save", saved)
    assert result.returncode == 0, result.stderr
    assert "4.000  go_to_location4" in result.stdout
    assert result.stdout.splitlines()[-1].endswith("-- tick 9: root SUCCESS")
    again = twin("tree", "log", saved)
    assert again.stdout == result.stdout


def test_log_scripts_unimplemented_nodes(tmp_path: Path) -> None:
    tree = tmp_path / "t.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence name="s"><Dock name="dock"/><Spin name="spin"/></Sequence></BehaviorTree></root>'
    )
    result = twin("tree", "log", tree, "--scripts", '{"dock": ["RUNNING", "SUCCESS"]}', "--json")
    assert result.returncode == 0, result.stderr
    log = json.loads(result.stdout)
    assert [t["status"] for t in log["ticks"]] == ["RUNNING", "SUCCESS"]
    assert ["spin", "SUCCESS"] in [[c["path"], c["new"]] for c in log["changes"]]


def test_log_warns_of_a_script_that_names_no_scripted_leaf(tmp_path: Path) -> None:
    # `sequence` is a control node and `spim` names nothing: neither script can be played.
    tree = tmp_path / "t.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence name="s"><Dock name="dock"/></Sequence></BehaviorTree></root>'
    )
    scripts = '{"dock": ["FAILURE"], "s": ["RUNNING"], "spim": ["RUNNING"]}'
    result = twin("tree", "log", tree, "--scripts", scripts, "--json")
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if "names no scripted leaf" in line]
    assert len(warnings) == 2 and "'s'" in warnings[0] and "'spim'" in warnings[1], result.stderr
    assert "(scripted leaves: dock)" in warnings[0]
    assert [t["status"] for t in json.loads(result.stdout)["ticks"]] == ["FAILURE"]


def test_log_of_a_conformance_case_uses_its_sleeps_as_time() -> None:
    result = twin("tree", "log", CASES / "037_timeout_wall_time_halts_child.json")
    assert result.returncode == 0, result.stderr
    assert "0.300  A" in result.stdout and "RUNNING -> IDLE" in result.stdout


def test_errors_of_a_bad_tree_are_one_line_without_traceback(tmp_path: Path) -> None:
    tree = tmp_path / "t.xml"
    tree.write_text('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Sequence>\n</BehaviorTree></root>')
    result = twin("tree", "show", tree)
    assert result.returncode == 6
    assert result.stderr.strip().count("\n") == 0
    assert f"{tree}:4: malformed XML" in result.stderr


_PALETTE = """<root BTCPP_format="4">
  <TreeNodesModel>
    <Action ID="DriveOnHeading">
      <input_port name="dist_to_travel" default="0.15"/>
      <input_port name="speed" default="0.025"/>
      <output_port name="error_code_id"/>
    </Action>
    <Action ID="FollowPath">
      <input_port name="path"/>
      <input_port name="controller_id"/>
      <output_port name="tracking_feedback"/>
    </Action>
    <Condition ID="IsBatteryLow"><input_port name="min_battery"/></Condition>
  </TreeNodesModel>
</root>
"""

_USES_PALETTE = """<root BTCPP_format="4" main_tree_to_execute="M">
  <BehaviorTree ID="M">
    <Sequence>
      <Inverter><IsBatteryLow min_battery="0.2"/></Inverter>
      <DriveOnHeading dist_to_travel="2.0" speed="0.2"/>
      <FollowPath path="{path}" controller_id="FollowPath" tracking_feedback="{fb}"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def test_validate_and_show_take_node_types_from_a_palette(tmp_path: Path) -> None:
    palette = tmp_path / "nodes.xml"
    palette.write_text(_PALETTE)
    tree = tmp_path / "calibrate.xml"
    tree.write_text(_USES_PALETTE)
    without = twin("tree", "validate", tree)
    assert without.returncode == 6
    assert "unknown port 'tracking_feedback' of <FollowPath>" in without.stderr  # the built-in Nav2 list's ports
    assert "unknown node type" not in without.stderr  # twin.nav declares every Humble leaf, IsBatteryLow too
    with_palette = twin("tree", "validate", tree, "--nodes", palette)
    assert with_palette.returncode == 0, with_palette.stderr
    assert "Nav2 nodes run by `twin simulate` (declared only here): DriveOnHeading, FollowPath, IsBatteryLow" in (
        with_palette.stdout
    )
    shown = twin("tree", "show", tree, "--nodes", palette)
    assert shown.returncode == 0, shown.stderr
    assert "DriveOnHeading" in shown.stdout and "IsBatteryLow" in shown.stdout
    # the palette's ports are checked like any other: a typo is still one line
    tree.write_text(_USES_PALETTE.replace('speed="0.2"', 'sped="0.2"'))
    typo = twin("tree", "validate", tree, "--nodes", palette)
    assert typo.returncode == 6
    assert f"{tree}:5: unknown port 'sped' of <DriveOnHeading>" in typo.stderr


def test_nav2s_own_trees_validate_with_nav2s_own_palette() -> None:
    # Humble's palette lags its code (no `is_recovery` of Spin, which Humble's odometry_calibration.xml
    # and Spin itself have): a palette adds ports to the twin's Nav2 declarations, it takes none away.
    humble = REPO.parent / "shared" / "fixtures" / "nav2" / "nav2_humble"
    trees = sorted((humble / "behavior_trees").glob("*.xml"))
    assert len(trees) == 12
    for tree in trees:
        result = twin("tree", "validate", tree, "--nodes", humble / "nav2_tree_nodes.xml")
        assert result.returncode == 0, result.stderr


def test_a_palette_without_tree_nodes_model_is_one_clear_line(tmp_path: Path) -> None:
    not_palette = tmp_path / "tree.xml"
    not_palette.write_text(_USES_PALETTE)
    result = twin("tree", "validate", REPO / "trees" / "tree.xml", "--nodes", not_palette)
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "no <TreeNodesModel> here" in lines[0] and str(not_palette) in lines[0]
    assert "Traceback" not in result.stderr


def test_validate_tells_the_nav2_nodes_a_run_has_from_those_it_cannot_create(tmp_path: Path) -> None:
    # Iron's and Jazzy's trees: ComputePathThroughPoses' error_code_id was an unknown port, and the one
    # "declared without implementation" list held FollowPath (which runs) beside WouldAPlannerRecoveryHelp
    tree = tmp_path / "through.xml"
    tree.write_text(
        '<root BTCPP_format="4" main_tree_to_execute="MainTree"><BehaviorTree ID="MainTree"><Sequence>'
        '<ComputePathThroughPoses goals="{goals}" path="{path}" error_code_id="{code}"/>'
        '<WouldAPlannerRecoveryHelp error_code="{code}"/><FollowPath path="{path}"/><NavigateToPose goal="{g}"/>'
        "</Sequence></BehaviorTree></root>"
    )
    done = twin("tree", "validate", tree)
    assert done.returncode == 0, done.stderr
    assert (
        "Nav2 nodes run by `twin simulate` (declared only here): ComputePathThroughPoses, FollowPath, "
        "WouldAPlannerRecoveryHelp"
    ) in done.stdout
    assert "declared without implementation (a run cannot create them): NavigateToPose" in done.stdout
