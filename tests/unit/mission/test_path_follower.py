"""The waypoints mission's go-to-point follower."""

from __future__ import annotations

import math

import pytest

from twin.mission.path_follower import FollowerParams, PathFollower


def test_follower_turns_in_place_then_drives_then_turns_to_the_final_heading() -> None:
    follower = PathFollower(FollowerParams())
    follower.set_path([(1.0, 0.0)], final_yaw_rad=math.pi / 2)
    assert follower.command(0.0, 0.0, math.pi) == (0.0, pytest.approx(-1.0))  # heading error pi: turn, capped
    v, w = follower.command(0.0, 0.0, 0.0)
    assert v == pytest.approx(0.22) and w == pytest.approx(0.0)
    assert follower.command(0.95, 0.0, 0.0) == (0.0, pytest.approx(1.0))  # at the point: turn to pi/2
    assert follower.command(0.95, 0.0, math.pi / 2) == (0.0, 0.0)
    assert follower.done
