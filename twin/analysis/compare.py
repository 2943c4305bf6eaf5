"""Two bags of one run compared: time-aligned pose error, ATE and RPE, per-topic rate differences.

Times are matched from each bag's first pose on the chosen topic, by header stamps (sim time), as
a twin run and the real run it stands in for start their clocks at different moments. Two topics
of one bag, or two bags recorded on one clock (`same_clock`), are matched on their stamps as they
are instead: a latched or old first message (an `/amcl_pose` from before `/odom` began) would
otherwise shift one track against the other by its age. B's pose is interpolated at A's stamps
where both bags cover. ATE is the RMS position error
(optionally after the rigid Umeyama alignment of B onto A); RPE is the RMS error of the relative
motion over a fixed interval (1 s by default).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.analysis import plots
from twin.analysis.collect import BagData, PoseTrack, collect
from twin.core.errors import BagError

__all__ = ["Comparison", "compare_bags", "umeyama_2d", "write_comparison"]

F64 = NDArray[np.float64]

_DEFAULT_TOPICS = ("/ground_truth/odom", "/odom")


def umeyama_2d(src: F64, dst: F64) -> tuple[F64, F64]:
    """The rotation R (2x2) and translation t minimising sum |R src_i + t - dst_i|² (no scale).

    Args:
        src: Points, shape (N, 2).
        dst: Corresponding points, shape (N, 2).
    """
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    cov = (dst - mu_d).T @ (src - mu_s) / len(src)
    u, _s, vt = np.linalg.svd(cov)
    d = np.eye(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[1, 1] = -1.0
    rot = u @ d @ vt
    return rot, mu_d - rot @ mu_s


@dataclass(frozen=True, kw_only=True, slots=True)
class Comparison:
    """The result of comparing bag B against bag A."""

    bag_a: str
    bag_b: str
    topic_a: str
    topic_b: str
    aligned: bool
    t_s: F64  # relative time of each matched pose (from A's first pose)
    xy_a: F64
    xy_b: F64  # B at A's times (after alignment when `aligned`)
    position_error_m: F64
    yaw_error_rad: F64
    ate_m: float
    rpe_m: float | None
    rpe_interval_s: float
    rates: list[dict[str, Any]]
    fields: list[dict[str, Any]]
    track_a: F64
    track_b: F64

    @property
    def max_position_error_m(self) -> float:
        """The largest position error over the matched span, m."""
        return float(self.position_error_m.max()) if len(self.position_error_m) else math.inf

    @property
    def final_position_error_m(self) -> float:
        """The position error at the end of the matched span, m."""
        return float(self.position_error_m[-1]) if len(self.position_error_m) else math.inf

    def error_at(self, t_s: float) -> float:
        """The position error at relative time `t_s` (interpolated), m."""
        return float(np.interp(t_s, self.t_s, self.position_error_m))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready numbers (no per-sample arrays but a 1 s error series)."""
        start = float(self.t_s[0]) if len(self.t_s) else 0.0  # (on one clock the match may begin after 0)
        span = float(self.t_s[-1]) - start if len(self.t_s) else 0.0
        marks = start + np.arange(0.0, span + 1e-9, 1.0)
        return {
            "bag_a": self.bag_a,
            "bag_b": self.bag_b,
            "topic_a": self.topic_a,
            "topic_b": self.topic_b,
            "aligned": self.aligned,
            "matched_poses": len(self.t_s),
            "matched_span_s": span,
            "ate_m": self.ate_m,
            "rpe_m": self.rpe_m,
            "rpe_interval_s": self.rpe_interval_s,
            "position_error_max_m": self.max_position_error_m,
            "position_error_final_m": self.final_position_error_m,
            "position_error_median_m": float(np.median(self.position_error_m)) if len(self.t_s) else None,
            "yaw_error_max_rad": float(self.yaw_error_rad.max()) if len(self.t_s) else None,
            "yaw_error_final_rad": float(self.yaw_error_rad[-1]) if len(self.t_s) else None,
            "position_error_each_s": [
                {"t_s": float(t), "error_m": self.error_at(float(t))} for t in marks if len(self.t_s)
            ],
            "topic_rates": self.rates,
            "field_differences": self.fields,
        }

    def summary_lines(self) -> list[str]:
        """The comparison for a terminal."""
        d = self.to_dict()
        lines = [
            f"A {self.bag_a} ({self.topic_a})",
            f"B {self.bag_b} ({self.topic_b}){', Umeyama-aligned' if self.aligned else ''}",
            f"  matched {d['matched_poses']} poses over {d['matched_span_s']:.2f} s",
            f"  position error  final {d['position_error_final_m']:.4f} m, max {d['position_error_max_m']:.4f} m, "
            f"median {d['position_error_median_m']:.4f} m",
            f"  yaw error       final {math.degrees(d['yaw_error_final_rad']):.2f} deg, "
            f"max {math.degrees(d['yaw_error_max_rad']):.2f} deg",
            f"  ATE {self.ate_m:.4f} m"
            + (f", RPE ({self.rpe_interval_s:g} s) {self.rpe_m:.4f} m" if self.rpe_m is not None else ""),
        ]
        for f in self.fields:
            lines.append(f"  {f['topic']} {f['field']}: RMS diff {f['rms_diff']:.4f}, max {f['max_abs_diff']:.4f}")
        for r in self.rates:
            if r["rate_a_hz"] is not None and r["rate_b_hz"] is not None:
                diff = r["rate_b_hz"] - r["rate_a_hz"]
                if abs(diff) > 0.05 * max(r["rate_a_hz"], 1e-9):
                    lines.append(f"  rate {r['topic']}: A {r['rate_a_hz']:.2f} Hz, B {r['rate_b_hz']:.2f} Hz")
            elif (r["count_a"] == 0) != (r["count_b"] == 0):
                lines.append(f"  topic {r['topic']}: A {r['count_a']} messages, B {r['count_b']}")
        return lines


def _pick_topics(a: BagData, b: BagData, topics: tuple[str, ...] | None) -> tuple[str, str]:
    if topics:
        ta, tb = (topics[0], topics[0]) if len(topics) == 1 else (topics[0], topics[1])
        for data, t in ((a, ta), (b, tb)):
            if t not in data.poses or not len(data.poses[t]):
                have = [p for p, tr in data.poses.items() if len(tr)]
                msg = f"{data.info.path}: no poses on {t}; it has {', '.join(have) or 'no pose topic'}"
                raise BagError(msg)
        return ta, tb
    for t in _DEFAULT_TOPICS:
        if t in a.poses and len(a.poses[t]) and t in b.poses and len(b.poses[t]):
            return t, t
    have_a = ", ".join(p for p, tr in a.poses.items() if len(tr)) or "none"
    have_b = ", ".join(p for p, tr in b.poses.items() if len(tr)) or "none"
    msg = (
        f"{a.info.path} and {b.info.path} share no pose topic among {', '.join(_DEFAULT_TOPICS)} "
        f"(A has {have_a}; B has {have_b}); name one per bag with --topic A_TOPIC B_TOPIC"
    )
    raise BagError(msg)


def _local(topic: str, namespace: str | None) -> str:
    """A topic as a robot's pass reads it: without the robot's namespace."""
    prefix = f"/{namespace.strip('/')}/" if namespace else ""
    return "/" + topic[len(prefix) :] if prefix and topic.startswith(prefix) else topic


def _relative(track: PoseTrack, origin_ns: int | None = None) -> tuple[F64, F64]:
    """The track's stamps in s from `origin_ns` (default: its own first stamp), in time order."""
    stamps = track.stamp_ns
    order = np.argsort(stamps, kind="stable")
    first = int(stamps[order][0]) if origin_ns is None else origin_ns
    t = (stamps[order] - first).astype(np.float64) * 1e-9
    return t, track.values[order]


def _same_bag(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False


def compare_bags(
    a: str | os.PathLike[str],
    b: str | os.PathLike[str],
    *,
    topics: tuple[str, ...] | None = None,
    align: bool = False,
    rpe_interval_s: float = 1.0,
    same_clock: bool | None = None,
    namespaces: tuple[str | None, str | None] = (None, None),
) -> Comparison:
    """Compare bag B against bag A (see the module docstring).

    `same_clock`: match the poses on their stamps as they are (True), or each from its track's first
    pose (False); None (the default) chooses True when A and B are the same bag.
    `namespaces`: the robot of each bag to compare (a fleet's bag), None for a one-robot bag; its
    topics are then read without the namespace (`topics` may be given either way).

    Raises:
        BagError: If a bag is unreadable, or they have no common pose topic (or a given one).
    """
    ns_a, ns_b = namespaces
    if topics:  # one topic stands for both bags' (each without its namespace)
        topics = (_local(topics[0], ns_a), _local(topics[-1], ns_b))
    data_a = collect(a, decoded=False, pose_topics=topics[:1] if topics else (), namespace=ns_a)
    data_b = collect(b, decoded=False, pose_topics=topics[-1:] if topics else (), namespace=ns_b)
    ta, tb = _pick_topics(data_a, data_b, topics)
    if same_clock is None:
        same_clock = _same_bag(a, b)
    origin = None
    if same_clock:
        origin = min(int(data_a.poses[ta].stamp_ns.min()), int(data_b.poses[tb].stamp_ns.min()))
    t_a, va = _relative(data_a.poses[ta], origin)
    t_b, vb = _relative(data_b.poses[tb], origin)
    inside = (t_a >= t_b[0]) & (t_a <= t_b[-1])
    t = t_a[inside]
    xy_a = va[inside, :2]
    yaw_a = va[inside, 2]
    xy_b = np.stack((np.interp(t, t_b, vb[:, 0]), np.interp(t, t_b, vb[:, 1])), axis=1)
    yaw_b = np.interp(t, t_b, np.unwrap(vb[:, 2]))
    track_b = vb[:, :2].copy()
    if align and len(t) >= 3:
        rot, shift = umeyama_2d(xy_b, xy_a)
        xy_b = xy_b @ rot.T + shift
        track_b = track_b @ rot.T + shift
        yaw_b = yaw_b + math.atan2(rot[1, 0], rot[0, 0])
    err = np.hypot(*(xy_b - xy_a).T) if len(t) else np.zeros(0)
    yaw_err = np.abs(np.remainder(yaw_b - yaw_a + math.pi, 2 * math.pi) - math.pi)
    if not len(t):
        msg = f"{a} and {b}: the poses on {ta} and {tb} do not overlap in time"
        raise BagError(msg)
    ate = float(math.sqrt(float(np.mean(err * err))))
    rpe = _rpe(t, xy_a, yaw_a, xy_b, yaw_b, interval_s=rpe_interval_s)
    fields = _field_differences(data_a, data_b, ta, tb, t, origin=origin)
    rates = []
    for name in sorted(set(data_a.health) | set(data_b.health)):
        ha, hb = data_a.health.get(name), data_b.health.get(name)
        rates.append(
            {
                "topic": name,
                "count_a": ha.count if ha else 0,
                "count_b": hb.count if hb else 0,
                "rate_a_hz": ha.rate_hz if ha else None,
                "rate_b_hz": hb.rate_hz if hb else None,
                "type_a": ha.msgtype if ha else None,
                "type_b": hb.msgtype if hb else None,
            }
        )
    return Comparison(
        bag_a=str(a),
        bag_b=str(b),
        topic_a=data_a.poses[ta].topic,  # the bag's own name (a fleet robot's under its namespace)
        topic_b=data_b.poses[tb].topic,
        aligned=align,
        t_s=t,
        xy_a=xy_a,
        xy_b=xy_b,
        position_error_m=err,
        yaw_error_rad=yaw_err,
        ate_m=ate,
        rpe_m=rpe,
        rpe_interval_s=rpe_interval_s,
        rates=rates,
        fields=fields,
        track_a=va[:, :2],
        track_b=track_b,
    )


def _field_differences(
    a: BagData, b: BagData, ta: str, tb: str, t: F64, *, origin: int | None = None
) -> list[dict[str, Any]]:
    """RMS and max differences of the velocity fields both bags carry, over the matched span.

    The pose topics' twist (`twist.twist.linear.x`, `twist.twist.angular.z`) where both are
    Odometry, interpolated at A's times; `/cmd_vel` (`linear.x`, `angular.z`) as held commands,
    both on the clock the poses were matched on (from each bag's first pose, or from `origin`, the
    one stamp both count from when they share a clock).
    """
    out: list[dict[str, Any]] = []
    t_a, va = _relative(a.poses[ta], origin)
    t_b, vb = _relative(b.poses[tb], origin)
    for col, field in ((3, "twist.twist.linear.x"), (4, "twist.twist.angular.z")):
        if np.isnan(va[:, col]).all() or np.isnan(vb[:, col]).all():
            continue
        xa = np.interp(t, t_a, va[:, col])
        xb = np.interp(t, t_b, vb[:, col])
        d = xb - xa
        out.append(
            {
                "topic": f"{ta} | {tb}" if ta != tb else ta,
                "field": field,
                "rms_diff": float(np.sqrt(np.mean(d * d))),
                "max_abs_diff": float(np.abs(d).max()),
            }
        )
    if a.cmd is not None and b.cmd is not None and len(a.cmd[0]) and len(b.cmd[0]):
        ca = [np.frombuffer(x, dtype=np.float64) for x in a.cmd]
        cb = [np.frombuffer(x, dtype=np.float64) for x in b.cmd]
        cta, ctb = _command_times(a, ta, ca[0], origin), _command_times(b, tb, cb[0], origin)
        for k, field in ((1, "linear.x"), (2, "angular.z")):
            xa = _held(cta, ca[k], t)
            xb = _held(ctb, cb[k], t)
            d = xb - xa
            out.append(
                {
                    "topic": "/cmd_vel",
                    "field": field,
                    "rms_diff": float(np.sqrt(np.mean(d * d))),
                    "max_abs_diff": float(np.abs(d).max()),
                }
            )
    return out


def _command_times(data: BagData, pose_topic: str, t_s: F64, origin: int | None = None) -> F64:
    """Command times on the pose topic's clock: sim time through /clock when the bag has it, from its first pose.

    With `origin` (a stamp both bags' times count from), from that instead.
    """
    record_ns = data.start_ns + t_s * 1e9
    stamps = data.poses[pose_topic].stamp_ns
    sim = data.clock_at(record_ns.astype(np.int64))
    if sim is None:  # no /clock: record times, from the pose topic's first record time (or the origin)
        first = float(data.poses[pose_topic].t_ns.min()) if origin is None else float(origin)
        return (record_ns - first) * 1e-9
    return (sim - (int(stamps.min()) if origin is None else origin)).astype(np.float64) * 1e-9


def _held(times: F64, values: F64, at: F64) -> F64:
    """The last value at or before each time in `at` (0 before the first)."""
    i = np.searchsorted(times, at, side="right") - 1
    return np.where(i >= 0, values[np.clip(i, 0, None)], 0.0)


def _rpe(t: F64, xy_a: F64, yaw_a: F64, xy_b: F64, yaw_b: F64, *, interval_s: float) -> float | None:
    """RMS of the difference in relative motion (in the start pose's frame) over `interval_s`."""
    j = np.searchsorted(t, t + interval_s)
    ok = j < len(t)
    i = np.flatnonzero(ok)
    j = j[ok]
    if not len(i):
        return None

    def local(xy: F64, yaw: F64) -> F64:
        d = xy[j] - xy[i]
        c, s = np.cos(yaw[i]), np.sin(yaw[i])
        return np.stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]), axis=1)

    diff = local(xy_a, yaw_a) - local(xy_b, yaw_b)
    return float(math.sqrt(float(np.mean(np.sum(diff * diff, axis=1)))))


def write_comparison(result: Comparison, out_dir: Path, *, walls: F64 | None = None) -> list[Path]:
    """Write comparison.json, overlay.png (both trajectories) and compare_error.png into `out_dir`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    label_a = f"A {Path(result.bag_a).name} {result.topic_a}"
    label_b = f"B {Path(result.bag_b).name} {result.topic_b}{' (aligned)' if result.aligned else ''}"
    files = [out_dir / "comparison.json", out_dir / "overlay.png", out_dir / "compare_error.png"]
    files[0].write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    title = f"ATE {result.ate_m:.3f} m, final error {result.final_position_error_m:.3f} m"
    files[1].write_bytes(plots.overlay_plot({label_a: result.track_a, label_b: result.track_b}, walls, title))
    files[2].write_bytes(
        plots.localization_plot(
            result.t_s,
            result.position_error_m,
            result.yaw_error_rad,
            f"B ({result.topic_b}) vs A ({result.topic_a}): pose error",
            xlabel="time from each bag's first pose (s)",
        )
    )
    return files
