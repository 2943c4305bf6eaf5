"""Spin, BackUp, DriveOnHeading and their collision checks against Nav2 Humble's own: every case in
`behavior_cases/` (see its README).

Equal means bit for bit: whether the goal is accepted, then per cycle the same status and the same
command. The tests below the replay pin what the twin's behaviours did differently before they were
held to these cases.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid
from twin.nav.actions import ActionGoal, ActionState
from twin.nav.behaviors.behavior_server import BehaviorServer, make_behavior
from twin.nav.behaviors.timed_behavior import BehaviorParams, BehaviorStatus
from twin.nav.conformance import check_case, load_case
from twin.nav.params import load_nav2_params
from twin.nav.server_params import nav2_config

CASES = Path(__file__).with_name("behavior_cases")
FILES = sorted(CASES.glob("*.npz"))
S = 1_000_000_000


def test_the_recorded_set_covers_the_issue() -> None:
    cases = [load_case(f) for f in FILES]
    metas = [m for m, _ in cases]
    assert len(metas) >= 55
    assert {m["oracle"] for m in metas} == {"re-typed"}
    assert len({m["nav2_commit"] for m in metas}) == 1
    kinds = [m["kind"] for m in metas if m["component"] == "behavior"]
    assert {kinds.count(k) >= 10 for k in ("spin", "backup", "drive_on_heading")} == {True}
    statuses = set(np.concatenate([a["out_status"] for m, a in cases if m["component"] == "behavior"]).tolist())
    assert statuses == {0, 1, 2, 3}  # running, succeeded, out of time, collision ahead
    assert {m["run_ok"] for m in metas if m["component"] == "behavior"} == {True, False}
    batches = [(m, a) for m, a in cases if m["component"] == "behavior_collision"]
    poses = sum(len(a["poses"]) for _, a in batches)
    edges = [a for m, a in batches if m["name"].startswith("collision_cell_edges")]
    free = np.concatenate([a["out_free"] for m, a in batches if not m["name"].startswith("collision_cell_edges")])
    assert poses >= 1900 and 0.2 < free.mean() < 0.8  # free and blocked poses both well represented
    assert len(edges) >= 4 and {bool(v) for a in edges for v in a["out_free"]} == {True, False}


@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_behavior_equals_nav2(case: Path) -> None:
    result = check_case(case)
    assert result.component in ("behavior", "behavior_collision")
    assert result.equal, "; ".join(result.differences)


def _open() -> object:
    return grid(np.zeros((120, 120), dtype=np.uint8), origin_m=(-3.0, -3.0))


def _server(finished: list[tuple[ActionState, str]]) -> BehaviorServer:
    """A behaviour server on an open costmap with the robot at the origin, its finished goals listed."""

    class _Frames:
        odom_pose = (0.0, 0.0, 0.0)

    class _Costmap:
        footprint = BehaviorParams().footprint
        grid = _open()

    return BehaviorServer(
        BehaviorParams(),
        _Frames(),  # type: ignore[arg-type]
        _Costmap(),  # type: ignore[arg-type]
        finish=lambda goal, state, reason="": finished.append((state, reason)),
    )


def test_a_zero_time_allowance_means_no_limit() -> None:
    spin = make_behavior("spin")
    assert spin.start({"target_yaw": 1.0, "time_allowance": 0.0}, (0.0, 0.0, 0.0), 0) == ""
    step = spin.step(5 * S, (0.0, 0.0, 0.0), _open())  # type: ignore[arg-type]
    assert step.status is BehaviorStatus.RUNNING and step.cmd == (0.0, 1.0)


def test_drive_on_heading_drives_backwards_with_negative_distance_and_speed() -> None:
    drive = make_behavior("drive_on_heading")
    assert drive.start({"target_x": -0.2, "speed": -0.05, "time_allowance": 10.0}, (0.0, 0.0, 0.0), 0) == ""
    assert drive.step(0, (0.0, 0.0, 0.0), _open()).cmd == (-0.05, 0.0)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("server", "request_", "reason"),
    [
        ("drive_on_heading", {"target_x": 0.2, "speed": -0.05}, "Speed and command sign did not match"),
        ("drive_on_heading", {"target_x": 0.2, "target_y": 0.1, "speed": 0.05}, "DrivingOnHeading in Y and Z"),
        ("backup", {"target_x": 0.2, "target_y": 0.1, "speed": 0.05}, "Backing up in Y and Z"),
    ],
)
def test_a_goal_nav2_refuses_fails_at_once(server: str, request_: dict[str, float], reason: str) -> None:
    finished: list[tuple[ActionState, str]] = []
    server_ = _server(finished)
    goal = ActionGoal(server=server, request={**request_, "time_allowance": 10.0})
    server_.start(goal, 0)
    assert finished and finished[0][0] is ActionState.FAILED and finished[0][1].startswith(reason)
    assert server_.active is None and server_.cycle(S) is None


def test_backup_limits_come_from_the_behaviour_server_section(fixtures: Path) -> None:
    overrides = {
        "behavior_server.backup.acceleration_limit": 0.5,
        "behavior_server.backup.deceleration_limit": -0.5,
        "behavior_server.backup.minimum_speed": 0.02,
    }
    params = load_nav2_params(fixtures / "nav2" / "nav2_humble" / "nav2_params.yaml", overrides=overrides)
    behaviors = nav2_config(params).behaviors
    assert behaviors.backup_limits == (0.5, -0.5, 0.02) and behaviors.drive_on_heading_limits == (0.0, 0.0, 0.0)
    backup = make_behavior("backup", behaviors)
    backup.start({"target_x": 0.5, "speed": 0.2, "time_allowance": 10.0}, (0.0, 0.0, 0.0), 0)
    assert backup.step(0, (0.0, 0.0, 0.0), _open()).cmd == (-0.05, 0.0)  # type: ignore[arg-type]  # 0.5 / 10 Hz


@pytest.mark.parametrize("server", ["spin", "wait"])
def test_a_canceled_behaviour_stops_the_robot_once(server: str) -> None:
    # TimedBehavior::execute: a cancel request calls stopRobot (a zero twist on cmd_vel), Wait's too
    behaviors = _server([])
    goal = ActionGoal(server=server, request={"target_yaw": 1.57, "time_s": 5.0, "time_allowance": 10.0})
    behaviors.start(goal, 0)
    assert behaviors.cycle(S // 10) == ((0.0, 1.0) if server == "spin" else None)
    behaviors.cancel(goal)
    assert behaviors.cycle(2 * S // 10) == (0.0, 0.0)
    assert behaviors.cycle(3 * S // 10) is None
