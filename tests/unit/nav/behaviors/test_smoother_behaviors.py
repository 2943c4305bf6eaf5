from __future__ import annotations

import math

import numpy as np
import pytest

from tests.unit.nav.costmaps import grid
from twin.nav.behaviors.behavior_server import make_behavior
from twin.nav.behaviors.timed_behavior import BehaviorStatus
from twin.nav.velocity_smoother.velocity_smoother import SmootherParams, VelocitySmoother

MS = 1_000_000


def test_smoother_limits_acceleration_per_20hz_cycle() -> None:
    smoother = VelocitySmoother()
    smoother.command((0.22, 0.0, 1.0), 0)
    out = [smoother.step(k * 50 * MS) for k in range(1, 6)]
    assert out[0] == pytest.approx((0.125, 0.0, 0.16))  # 2.5 / 20 and 3.2 / 20
    assert out[1] == pytest.approx((0.22, 0.0, 0.32))
    assert out[4] == pytest.approx((0.22, 0.0, 0.8))


def test_smoother_clamps_to_code_default_limits_and_deadband() -> None:
    smoother = VelocitySmoother(SmootherParams(deadband_velocity=(0.05, 0.0, 0.0)))
    smoother.command((0.9, 0.0, 0.0), 0)
    for k in range(1, 20):
        out = smoother.step(k * 50 * MS)
    assert out == pytest.approx((0.5, 0.0, 0.0))
    smoother.command((0.04, 0.0, 0.0), 1000 * MS)
    assert smoother.step(1050 * MS) == pytest.approx((0.375, 0.0, 0.0))  # decelerating towards 0.04
    for k in range(22, 26):
        out = smoother.step(k * 50 * MS)
    # Nav2 zeroes what it publishes inside the deadband, and smooths on from the value before
    assert out == (0.0, 0.0, 0.0)
    smoother.command((0.2, 0.0, 0.0), 1300 * MS)
    assert smoother.step(1350 * MS) == pytest.approx((0.04 + 0.125, 0.0, 0.0))


def test_smoother_scale_velocities_keeps_the_command_direction() -> None:
    plain, scaled = VelocitySmoother(), VelocitySmoother(SmootherParams(scale_velocities=True))
    for smoother in (plain, scaled):
        smoother.command((0.22, 0.0, 0.1), 0)
    assert plain.step(50 * MS) == pytest.approx((0.125, 0.0, 0.1))  # each component on its own
    vx, _, wz = scaled.step(50 * MS)  # both scaled by the linear axis' limit: 0.125 / 0.22 of the way
    assert vx == pytest.approx(0.125) and wz == pytest.approx(0.1 * 0.125 / 0.22)


def test_smoother_ramps_down_after_the_timeout_then_stops_publishing() -> None:
    smoother = VelocitySmoother()
    assert smoother.step(0) is None  # nothing received yet
    smoother.command((0.2, 0.0, 0.0), 0)
    for k in range(1, 21):
        smoother.step(k * 50 * MS)  # 1.0 s, still within the timeout
    assert smoother.step(1050 * MS) == pytest.approx((0.075, 0.0, 0.0))
    assert smoother.step(1100 * MS) == pytest.approx((0.0, 0.0, 0.0))
    assert smoother.step(1150 * MS) is None


def _empty():  # type: ignore[no-untyped-def]
    return grid(np.zeros((100, 100), dtype=np.uint8))


def _run(server: str, request: dict, costmap, pose=(2.5, 2.5, 0.0)):  # type: ignore[no-untyped-def]
    behavior = make_behavior(server)
    behavior.start(request, pose, 0)
    x, y, yaw = pose
    cmds = []
    for k in range(400):
        step = behavior.step(k * 100 * MS, (x, y, yaw), costmap)
        if step.status is not BehaviorStatus.RUNNING:
            return step, (x, y, yaw), cmds, k
        v, w = step.cmd
        cmds.append(step.cmd)
        x += v * math.cos(yaw) * 0.1
        y += v * math.sin(yaw) * 0.1
        yaw += w * 0.1
    raise AssertionError("did not finish")


def test_spin_turns_the_requested_angle_within_speed_limits() -> None:
    step, pose, cmds, _ = _run("spin", {"target_yaw": 1.57, "time_allowance": 10.0}, _empty())
    assert step.status is BehaviorStatus.SUCCEEDED
    assert pose[2] == pytest.approx(1.57, abs=0.1)
    w = np.array(cmds)[:, 1]
    assert (w >= 0.4 - 1e-9).all() and (w <= 1.0 + 1e-9).all()


def test_backup_reverses_the_distance_at_the_speed() -> None:
    step, pose, cmds, k = _run("backup", {"target_x": 0.30, "speed": 0.05, "time_allowance": 10.0}, _empty())
    assert step.status is BehaviorStatus.SUCCEEDED
    assert pose[0] == pytest.approx(2.2, abs=0.01)
    assert {c[0] for c in cmds} == {-0.05}
    assert k == pytest.approx(60, abs=1)


def test_drive_on_heading_stops_before_an_obstacle_ahead() -> None:
    cost = np.zeros((100, 100), dtype=np.uint8)
    cost[:, 60:] = 254  # a wall at x = 3 m
    step, pose, _, _ = _run("drive_on_heading", {"target_x": 2.0, "speed": 0.2, "time_allowance": 20.0}, grid(cost))
    assert step.status is BehaviorStatus.FAILED and "Collision Ahead" in step.reason
    # 2 s ahead at 0.2 m/s: stopped with the 0.22 m footprint 0.4 m short of the wall, not at it
    assert 3.0 - 0.22 - 0.4 - 0.05 < pose[0] < 3.0 - 0.22


def test_a_spin_whose_footprint_touches_a_lethal_cell_is_refused_at_once() -> None:
    # Nav2 checks the footprint's edges on the local costmap: TB3's 0.22 m circle 0.21 m from a wall
    # reaches into it, so the spin fails (a rectangular body would scrape the wall). Humble's check
    # simulates only as far ahead as the spin has turned so far: nothing on the first cycle.
    cost = np.zeros((100, 100), dtype=np.uint8)
    cost[:, 55:] = 254  # the wall's face at x = 2.75 m
    step, _, cmds, _ = _run("spin", {"target_yaw": 1.57, "time_allowance": 10.0}, grid(cost), pose=(2.54, 2.5, 0.0))
    assert step.status is BehaviorStatus.FAILED and step.reason == "Collision Ahead - Exiting Spin"
    assert cmds == [(0.0, 1.0)]
    clear, _, _, _ = _run("spin", {"target_yaw": 1.57, "time_allowance": 10.0}, grid(cost), pose=(2.5, 2.5, 0.0))
    assert clear.status is BehaviorStatus.SUCCEEDED  # 0.25 m away the circle stays clear


def test_the_footprint_kernel_reads_the_cells_the_python_checker_reads() -> None:
    # The C footprint check (what every behaviour cycle runs) against the Python reference: the house's
    # inflated costmap and a random one (lethal and unknown cells), poses on, across and off the edges,
    # the TB3 circle and a rectangle.
    from tests.unit.nav.costmaps import house_costmap
    from twin.nav.behaviors.timed_behavior import BehaviorParams
    from twin.nav.costmap_2d._native import load_kernel
    from twin.nav.costmap_2d.footprint import footprint_cost, footprint_cost_py

    assert load_kernel() is not None  # the tests run where the kernels build; the Python path is the fallback
    rng = np.random.default_rng(7)
    random_cost = rng.choice(np.array([0, 1, 50, 128, 252, 253, 254, 255], dtype=np.uint8), size=(80, 120))
    maps = [house_costmap(), grid(random_cost, resolution_m=0.05, origin_m=(-1.3, 0.7))]
    footprints = [BehaviorParams().footprint, ((0.2, 0.15), (0.2, -0.15), (-0.2, -0.15), (-0.2, 0.15))]
    costs = set()
    for costmap in maps:
        w, h = costmap.cols * costmap.resolution_m, costmap.rows * costmap.resolution_m
        for footprint in footprints:
            for _ in range(3000):
                pose = (
                    costmap.origin_x_m - 0.4 + rng.random() * (w + 0.8),
                    costmap.origin_y_m - 0.4 + rng.random() * (h + 0.8),
                    float(rng.uniform(-7.0, 7.0)),
                )
                expected = footprint_cost_py(costmap, footprint, pose)
                assert footprint_cost(costmap, footprint, pose) == expected, (pose, footprint)
                costs.add(expected)
    assert {0, 254} <= costs and len(costs) > 4  # free, lethal (and off the map) and costs between were met


def test_wait_lasts_its_duration_and_times_out_are_failures() -> None:
    step, _, cmds, k = _run("wait", {"time_s": 5.0}, _empty())
    assert step.status is BehaviorStatus.SUCCEEDED and k == 50 and cmds == [(0.0, 0.0)] * 50
    slow, _, _, _ = _run("drive_on_heading", {"target_x": 2.0, "speed": 0.05, "time_allowance": 5.0}, _empty())
    assert slow.status is BehaviorStatus.FAILED
