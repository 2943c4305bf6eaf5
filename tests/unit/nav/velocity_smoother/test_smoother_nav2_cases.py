"""The velocity smoother against Nav2 Humble's own: every case in `smoother_cases/` (see its README).

Equal means bitwise: on every timer tick the twin publishes or stays silent as Nav2 did, and what it
publishes is the same three doubles, bit for bit. No tolerance is needed because the twin does Nav2's
double operations in Nav2's order (clamps, the accelerate-or-decelerate choice, `accel / frequency`,
`eta * dv`, the odometry window's running sum and its division by the count), and a tolerance would
hide the one-ulp drift a reordered sum gives. The tests below the replay each pin one behaviour the
twin did not have before it was held to these cases, on the recorded inputs that show it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from twin.nav.conformance import check_case, load_case
from twin.nav.velocity_smoother.conformance_check import params_of
from twin.nav.velocity_smoother.velocity_smoother import Feedback, SmootherParams, VelocitySmoother

CASES = Path(__file__).with_name("smoother_cases")
FILES = sorted(CASES.glob("*.npz"))
MS = 1_000_000


def test_the_recorded_set_covers_the_issue() -> None:
    metas = [load_case(f)[0] for f in FILES]
    assert len(metas) >= 200
    assert {m["component"] for m in metas} == {"velocity_smoother"}
    assert {m["oracle"] for m in metas} == {"re-typed"}
    assert len({m["nav2_commit"] for m in metas}) == 1  # one pinned Nav2 commit
    groups = {m["group"] for m in metas}
    assert {
        "steps",
        "reversals",
        "saturation",
        "timeouts",
        "deadband",
        "random",
        "closed_loop",
        "house_mission",
    } <= groups
    params = [m["params"] for m in metas]
    assert {p["feedback"] for p in params} == {"OPEN_LOOP", "CLOSED_LOOP"}
    assert {p["scale_velocities"] for p in params} == {True, False}
    assert any(p["deadband_velocity"] != [0.0, 0.0, 0.0] for p in params)
    assert any(p["max_velocity"][1] > 0.0 for p in params)  # a holonomic base: linear.y smoothed too
    silent = sum(not load_case(f)[1]["published"].all() for f in FILES)
    assert silent >= 20  # the timeout's stop (and the wait for a first command) is in the record


@pytest.mark.parametrize("case", FILES, ids=[f.stem for f in FILES])
def test_velocity_smoother_equals_nav2(case: Path) -> None:
    result = check_case(case)
    assert result.component == "velocity_smoother"
    assert result.equal, "; ".join(result.differences)


def test_a_difference_is_named_with_its_tick(tmp_path: Path) -> None:
    """The checker is not blind: one published value moved by one ulp, one tick's silence, are reported."""
    source = CASES / "step_fwd_nav2file_open_loop_plain.npz"
    meta, arrays = load_case(source)
    arrays["output"] = arrays["output"].copy()
    arrays["output"][2, 0] = np.nextafter(arrays["output"][2, 0], 1.0)
    arrays["published"] = arrays["published"].copy()
    arrays["published"][5] = False
    changed = tmp_path / source.name
    np.savez(changed, meta=json.dumps(meta), **arrays)
    result = check_case(changed)
    assert result.differences[0] == "1 ticks differ in publishing, first tick 5 at 300000000 ns: Nav2 published nothing"
    assert result.differences[1].startswith("1 published twists differ, first tick 2 at 150000000 ns, linear.x: ")


def _replay(name: str) -> tuple[VelocitySmoother, list[tuple[float, float, float] | None], dict[str, np.ndarray]]:
    meta, arrays = load_case(CASES / f"{name}.npz")
    smoother = VelocitySmoother(params_of(meta["params"]))
    out: list[tuple[float, float, float] | None] = []
    for kind, t, stamp, tw in zip(
        arrays["event_kind"], arrays["event_t_ns"].tolist(), arrays["event_stamp_ns"].tolist(),
        arrays["event_twist"].tolist(), strict=True,
    ):  # fmt: skip
        if kind == 0:  # a non-finite linear.z, angular.x or .y (not carried) makes the command invalid too
            smoother.command((tw[0], tw[1], tw[5] if np.isfinite(tw[2:5]).all() else float("nan")), t)
        elif kind == 1:
            smoother.odometry((tw[0], tw[1], tw[5]), stamp)
        else:
            out.append(smoother.step(t))
    return smoother, out, arrays


def _values(out: list[tuple[float, float, float] | None]) -> np.ndarray:
    return np.array([o or (0.0, 0.0, 0.0) for o in out], dtype=np.float64).reshape(-1, 3)


def test_closed_loop_smooths_from_the_odometry_window_mean() -> None:
    # CLOSED_LOOP: the current velocity is the mean odometry twist over odom_duration, not the last output
    _, out, arrays = _replay("closed_loop_odom_0p1s_noise0p0_lat0ms")
    assert out[0] is not None and arrays["published"][0]
    assert [o for o in out if o is not None] == [tuple(v) for v in arrays["output"][arrays["published"]].tolist()]
    smoother = VelocitySmoother(SmootherParams(feedback=Feedback.CLOSED_LOOP, odom_duration_s=0.1))
    smoother.command((0.5, 0.0, 0.0), 0)
    for k, v in enumerate((0.0, 0.1, 0.2, 0.3)):
        smoother.odometry((v, 0.0, 0.0), k * 40 * MS)  # at 120 ms the window holds 40, 80 and 120 ms
    assert smoother.step(120 * MS) == pytest.approx((0.2 + 0.125, 0.0, 0.0), abs=1e-12)  # mean 0.2, plus 2.5 / 20


def test_linear_y_is_smoothed_with_its_own_limits() -> None:
    _, out, arrays = _replay("step_mixed_holonomic_open_loop_plain")
    assert out[0] == (0.1, 0.075, -0.16)  # 2.0 / 20, 1.5 / 20, 3.2 / 20
    assert np.array_equal(_values(out), arrays["output"])


def test_a_command_with_a_nan_or_infinity_is_ignored() -> None:
    smoother = VelocitySmoother()
    smoother.command((0.2, 0.0, 0.0), 0)
    smoother.command((float("nan"), 0.0, 0.0), 10 * MS)
    smoother.command((0.0, 0.0, float("inf")), 20 * MS)
    assert smoother.step(50 * MS) == (0.125, 0.0, 0.0)
    _, out, arrays = _replay("invalid_commands_open_loop")
    assert np.array_equal(_values(out), arrays["output"])


def test_the_timer_period_is_whole_milliseconds() -> None:
    # Nav2's timer: std::chrono::milliseconds(int(1000 / smoothing_frequency)); 30 Hz ticks every 33 ms
    assert SmootherParams(smoothing_frequency_hz=30.0).period_ns == 33 * MS
    assert SmootherParams(smoothing_frequency_hz=7.0).period_ns == 142 * MS
    assert SmootherParams().period_ns == 50 * MS
    meta, _ = load_case(CASES / "frequency_30hz_open_loop.npz")
    assert meta["timer_period_ns"] == 33 * MS


def test_the_timeout_is_truncated_to_nanoseconds_as_rclcpp_does() -> None:
    # 1.001 s * 1e9 is 1000999999.99...: rclcpp's Duration truncates, so a command 1.001 s old has timed out
    assert SmootherParams(velocity_timeout_s=1.001).timeout_ns == 1_000_999_999
    _, out, arrays = _replay("timeout_truncated_1p001_open_loop")
    tick_t = arrays["event_t_ns"][arrays["event_kind"] == 2]
    k = int(np.flatnonzero(tick_t == 1050 * MS)[0])  # the command came at 49 ms
    assert out[k - 1] == (0.2, 0.0, 0.4) and out[k] == (0.2 - 2.5 / 20, 0.0, 0.4 - 3.2 / 20)  # ramping down
