"""`mission_timeline`: goals and recoveries read from a tree's status changes."""

from __future__ import annotations

from twin.analysis.metrics import mission_timeline


def test_nav2s_recoveries_count_once_each_costmap_clearing_too() -> None:
    # Nav2's navigator tree names its clearing `ClearGlobalCostmap-Context`, a service leaf that goes
    # IDLE -> SUCCESS within one tick: it was never counted (the pattern had no hyphen, and only a
    # change to RUNNING counted)
    events = [
        (0.0, "NavigateRecovery", "IDLE", "RUNNING"),
        (43.0, "ClearGlobalCostmap-Context", "IDLE", "SUCCESS"),
        (43.0, "ClearGlobalCostmap-Context", "SUCCESS", "IDLE"),
        (44.0, "Spin", "IDLE", "RUNNING"),
        (46.0, "Spin", "RUNNING", "SUCCESS"),
        (46.0, "Spin", "SUCCESS", "IDLE"),
        (47.0, "ClearLocalCostmap-Subtree", "IDLE", "FAILURE"),
        (50.0, "ComputePathToPose", "IDLE", "RUNNING"),
        (60.0, "NavigateRecovery", "RUNNING", "SUCCESS"),
    ]
    timeline = mission_timeline(events)
    assert timeline is not None
    assert [name for _, name in timeline.recoveries] == [
        "ClearGlobalCostmap-Context",
        "Spin",
        "ClearLocalCostmap-Subtree",
    ]
