"""Hold the twin's velocity smoother to a case recorded from Nav2 Humble's (`twin nav conformance`).

A case (`tests/unit/nav/velocity_smoother/smoother_cases/README.md`) is Nav2's parameters, a sequence
of events — a cmd_vel received, an odometry message received (with its stamp), a timer tick — and what
Nav2 published on each tick, if anything. The twin's `VelocitySmoother` gets the same events in the same
order; equal means it publishes on the same ticks the same three doubles, bit for bit, and its timer
has Nav2's period.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.nav.velocity_smoother.velocity_smoother import Feedback, SmootherParams, VelocitySmoother

__all__ = ["check_velocity_smoother", "params_of"]

_AXES = ("linear.x", "linear.y", "angular.z")


def params_of(params: Mapping[str, Any]) -> SmootherParams:
    """The twin's parameters from a case's `params` (Nav2's names and units)."""

    def triple(key: str) -> tuple[float, float, float]:
        x, y, theta = (float(v) for v in params[key])
        return (x, y, theta)

    return SmootherParams(
        smoothing_frequency_hz=float(params["smoothing_frequency"]),
        feedback=Feedback(params["feedback"]),
        odom_duration_s=float(params["odom_duration"]),
        max_velocity=triple("max_velocity"),
        min_velocity=triple("min_velocity"),
        max_accel=triple("max_accel"),
        max_decel=triple("max_decel"),
        deadband_velocity=triple("deadband_velocity"),
        velocity_timeout_s=float(params["velocity_timeout"]),
        scale_velocities=bool(params["scale_velocities"]),
    )


def _bits(a: NDArray[np.float64]) -> NDArray[np.uint64]:
    return np.ascontiguousarray(a, dtype="<f8").view("<u8")


def check_velocity_smoother(meta: Mapping[str, Any], arrays: Mapping[str, NDArray[Any]], native: bool) -> list[str]:
    """The ways the twin's velocity smoother differs from Nav2's on one case (empty: equal).

    `native` is accepted for the registry's signature; the smoother is Python only.
    """
    del native
    params = params_of(meta["params"])
    codes = meta["event_codes"]
    cmd_code, odom_code, tick_code = int(codes["cmd_vel"]), int(codes["odom"]), int(codes["tick"])
    out: list[str] = []
    if params.period_ns != int(meta["timer_period_ns"]):
        out.append(f"timer period: twin {params.period_ns} ns, Nav2 {meta['timer_period_ns']} ns")
    smoother = VelocitySmoother(params)
    kinds, times = arrays["event_kind"].tolist(), arrays["event_t_ns"].tolist()
    stamps, twists = arrays["event_stamp_ns"].tolist(), arrays["event_twist"].tolist()
    got_published: list[bool] = []
    got: list[tuple[float, float, float]] = []
    for kind, t_ns, stamp_ns, twist in zip(kinds, times, stamps, twists, strict=True):
        if kind == tick_code:
            result = smoother.step(t_ns)
            got_published.append(result is not None)
            got.append(result if result is not None else (0.0, 0.0, 0.0))
        elif kind == cmd_code:
            # Nav2 drops a twist with a NaN or infinity in any of its six components; the twin's core
            # sees (x, y, theta), so a non-finite component it does not carry is passed in one it does.
            bad = next((v for v in (twist[2], twist[3], twist[4]) if not np.isfinite(v)), None)
            smoother.command((twist[0], twist[1], twist[5] if bad is None else bad), t_ns)
        elif kind == odom_code:
            smoother.odometry((twist[0], twist[1], twist[5]), stamp_ns)
        else:
            out.append(f"event kind {kind} at {t_ns} ns is not one the case's event_codes name")
            return out
    want_published = arrays["published"].astype(bool)
    published = np.array(got_published, dtype=bool)
    if published.shape != want_published.shape:
        out.append(f"ticks: twin {published.size}, Nav2 {want_published.size}")
        return out
    times_ns = np.asarray(arrays["event_t_ns"])[np.asarray(arrays["event_kind"]) == tick_code]
    if (differ := np.flatnonzero(published != want_published)).size:
        k = int(differ[0])
        did = "published" if want_published[k] else "published nothing"
        out.append(f"{differ.size} ticks differ in publishing, first tick {k} at {int(times_ns[k])} ns: Nav2 {did}")
    values = np.array(got, dtype=np.float64).reshape(-1, 3)
    both = published & want_published
    want = np.asarray(arrays["output"], dtype=np.float64)
    mismatch = both[:, None] & (_bits(values) != _bits(want))
    if (rows := np.flatnonzero(mismatch.any(axis=1))).size:
        k = int(rows[0])
        axis = int(np.flatnonzero(mismatch[k])[0])
        out.append(
            f"{rows.size} published twists differ, first tick {k} at {int(times_ns[k])} ns, {_AXES[axis]}: "
            f"twin {values[k, axis]!r}, Nav2 {want[k, axis]!r}"
        )
    return out
