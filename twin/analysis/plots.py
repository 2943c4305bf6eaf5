"""The report's plots as PNG bytes (matplotlib's Agg canvas; no pyplot, no global state, no display).

Each function takes arrays and returns the PNG; none reads a bag or writes a file.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from numpy.typing import NDArray

__all__ = [
    "MapLayers",
    "clearance_plot",
    "distance_plot",
    "localization_plot",
    "map_plot",
    "overlay_plot",
    "series_plot",
    "timeline_plot",
    "velocity_plot",
]

F64 = NDArray[np.float64]

_DPI = 80
_MAX_POINTS = 4000
_COLORS = {"/ground_truth/odom": "tab:green", "/amcl_pose": "tab:blue", "/odom": "tab:orange"}
_RESULT_COLORS = {"SUCCESS": "tab:green", "FAILURE": "tab:red", "running": "tab:gray"}


def _thin(*arrays: F64) -> tuple[F64, ...]:
    n = len(arrays[0])
    if n <= _MAX_POINTS:
        return arrays
    idx = np.linspace(0, n - 1, _MAX_POINTS).astype(np.int64)
    return tuple(a[idx] for a in arrays)


def _png(fig: Figure) -> bytes:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


class MapLayers:
    """What goes on the top-down map; every layer is optional."""

    def __init__(
        self,
        *,
        walls: F64 | None = None,
        occupancy: tuple[F64, float, float, float] | None = None,
        scan_points: F64 | None = None,
        tracks: Mapping[str, F64] | None = None,
        plans: Sequence[F64] = (),
        goals: F64 | None = None,
        contacts: F64 | None = None,
        background: str = "",
    ) -> None:
        self.walls = walls
        self.occupancy = occupancy
        self.scan_points = scan_points
        self.tracks = dict(tracks or {})
        self.plans = list(plans)
        self.goals = goals
        self.contacts = contacts
        self.background = background


def map_plot(layers: MapLayers, title: str) -> bytes:
    """Top-down map: background (walls, map or scan endpoints), trajectories, plans, goals, contacts."""
    fig = Figure(figsize=(7, 6.5))
    ax = fig.add_subplot()
    if layers.occupancy is not None:
        grid, res, ox, oy = layers.occupancy
        if grid.size:
            shown = np.where(grid < 0, 0.5, 1.0 - grid / 100.0)
            h, w = grid.shape
            ax.imshow(shown, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(ox, ox + w * res, oy, oy + h * res))
    if layers.scan_points is not None and len(layers.scan_points):
        ax.scatter(layers.scan_points[:, 0], layers.scan_points[:, 1], s=3, c="0.3", marker="s", linewidths=0)
    if layers.walls is not None and len(layers.walls):
        segs = layers.walls.reshape(-1, 2, 2)
        ax.add_collection(LineCollection(list(segs), colors="0.2", linewidths=1.2))
    for i, plan in enumerate(layers.plans):
        if len(plan):
            label = "/plan" if i == 0 else None
            ax.plot(plan[:, 0], plan[:, 1], "--", color="tab:purple", lw=0.8, alpha=0.6, label=label)
    for topic, xy in layers.tracks.items():
        if len(xy):
            (x, y) = _thin(xy[:, 0], xy[:, 1])
            lw = 3.0 if topic == "/ground_truth/odom" else 1.2  # the truth under the estimates
            ax.plot(x, y, color=_COLORS.get(topic), lw=lw, label=topic, alpha=0.8)
            ax.plot(x[:1], y[:1], "o", color=_COLORS.get(topic), ms=5)
    if layers.goals is not None and len(layers.goals):
        ax.plot(layers.goals[:, 0], layers.goals[:, 1], "*", color="gold", mec="k", ms=13, label="goals")
    if layers.contacts is not None and len(layers.contacts):
        ax.plot(layers.contacts[:, 0], layers.contacts[:, 1], "x", color="red", ms=10, mew=2, label="contacts")
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{title}\nbackground: {layers.background or 'none'}", fontsize=10)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return _png(fig)


def velocity_plot(
    cmd: tuple[F64, F64, F64] | None, actual: tuple[F64, F64, F64] | None, actual_label: str, title: str
) -> bytes:
    """Commanded vs actual forward speed and yaw rate over time; each series as (t s, v, ω)."""
    fig = Figure(figsize=(8, 5))
    ax_v, ax_w = fig.subplots(2, 1, sharex=True)
    if cmd is not None and len(cmd[0]):
        t, v, w = cmd
        ax_v.step(t, v, where="post", color="tab:red", lw=1.0, label="/cmd_vel (commanded)")
        ax_w.step(t, w, where="post", color="tab:red", lw=1.0, label="/cmd_vel (commanded)")
    if actual is not None and len(actual[0]):
        t, v, w = _thin(*actual)
        ax_v.plot(t, v, color="tab:blue", lw=1.0, label=f"{actual_label} (actual)")
        ax_w.plot(t, w, color="tab:blue", lw=1.0, label=f"{actual_label} (actual)")
    ax_v.set_ylabel("v (m/s)")
    ax_w.set_ylabel("ω (rad/s)")
    ax_w.set_xlabel("time from bag start (s)")
    ax_v.set_title(title, fontsize=10)
    for ax in (ax_v, ax_w):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return _png(fig)


def localization_plot(
    t_s: F64, pos_err_m: F64, yaw_err_rad: F64, title: str, xlabel: str = "time from bag start (s)"
) -> bytes:
    """Position and yaw error of the estimate over time."""
    fig = Figure(figsize=(8, 3.5))
    ax = fig.add_subplot()
    t, p, y = _thin(t_s, pos_err_m, yaw_err_rad)
    ax.plot(t, p * 100.0, color="tab:blue", lw=1.0, label="position error (cm)")
    ax.set_ylabel("position error (cm)")
    ax.set_xlabel(xlabel)
    ax2 = ax.twinx()
    ax2.plot(t, np.degrees(y), color="tab:orange", lw=0.8, alpha=0.8, label="yaw error (deg)")
    ax2.set_ylabel("|yaw error| (deg)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="upper left", fontsize=8)
    fig.tight_layout()
    return _png(fig)


def clearance_plot(t_s: F64, min_range_m: F64, title: str) -> bytes:
    """The smallest valid lidar range of each scan over time."""
    fig = Figure(figsize=(8, 3))
    ax = fig.add_subplot()
    t, r = _thin(t_s, min_range_m)
    ax.plot(t, r, color="tab:blue", lw=1.0)
    if len(r) and not np.all(np.isnan(r)):
        i = int(np.nanargmin(r))
        ax.plot(t[i], r[i], "v", color="red", ms=8, label=f"min {r[i]:.3f} m at {t[i]:.1f} s")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel("min lidar range (m)")
    ax.set_xlabel("time from bag start (s)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _png(fig)


def distance_plot(t_s: F64, pairs: Mapping[str, F64], title: str, ylabel: str) -> bytes:
    """The distance between robots over time: one line per pair, the smallest marked."""
    fig = Figure(figsize=(8, 3))
    ax = fig.add_subplot()
    best: tuple[float, float, str] | None = None
    for label, d in pairs.items():
        t, dd = _thin(t_s, d)
        ax.plot(t, dd, lw=1.0, label=label)
        if len(d):
            i = int(np.argmin(d))
            if best is None or float(d[i]) < best[0]:
                best = (float(d[i]), float(t_s[i]), label)
    if best is not None:
        ax.plot(best[1], best[0], "v", color="red", ms=8, label=f"min {best[0]:.3f} m at {best[1]:.1f} s ({best[2]})")
    if pairs:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_xlabel("time from bag start (s)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _png(fig)


def timeline_plot(
    goals: Sequence[tuple[str, float, float, str]], recoveries: Sequence[tuple[float, str]], end_s: float, title: str
) -> bytes:
    """The mission's goals as bars (coloured by result) and its recoveries as marks, over time."""
    fig = Figure(figsize=(8, 0.9 + 0.45 * max(len(goals), 1)))
    ax = fig.add_subplot()
    for i, (name, start, end, result) in enumerate(goals):
        ax.barh(i, end - start, left=start, color=_RESULT_COLORS.get(result, "tab:gray"), alpha=0.8)
        ax.text(start + 0.01 * max(end_s, 1.0), i, f"{name}: {result} ({end - start:.1f} s)", va="center", fontsize=8)
    for t, name in recoveries:
        ax.axvline(t, color="tab:red", lw=0.8, ls=":")
        ax.text(t, len(goals) - 0.5, name, rotation=90, fontsize=7, color="tab:red", va="top")
    ax.set_yticks([])
    ax.set_xlim(0, max(end_s, 1e-3))
    ax.set_xlabel("time from bag start (s)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    return _png(fig)


def overlay_plot(tracks: Mapping[str, F64], walls: F64 | None, title: str) -> bytes:
    """Trajectories of two bags overlaid (label -> (N, 2) xy)."""
    fig = Figure(figsize=(7, 6.5))
    ax = fig.add_subplot()
    if walls is not None and len(walls):
        ax.add_collection(LineCollection(list(walls.reshape(-1, 2, 2)), colors="0.2", linewidths=1.2))
    for (label, xy), color in zip(tracks.items(), ("tab:blue", "tab:red", "tab:green"), strict=False):
        if len(xy):
            x, y = _thin(xy[:, 0], xy[:, 1])
            ax.plot(x, y, color=color, lw=1.4, label=label)
            ax.plot(x[:1], y[:1], "o", color=color, ms=5)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return _png(fig)


def series_plot(
    t_s: F64, values: F64, columns: Sequence[str], panels: Sequence[tuple[str, Sequence[int]]], title: str
) -> bytes:
    """Columns of `values` (shape (N, C)) against time, one panel per (y label, column indices)."""
    fig = Figure(figsize=(8, 1.0 + 2.0 * len(panels)))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    idx = np.arange(len(t_s))
    (keep,) = _thin(idx.astype(np.float64))
    k = keep.astype(np.int64)
    for ax, (label, cols) in zip(axes, panels, strict=True):
        for c in cols:
            ax.plot(t_s[k], values[k, c], lw=1.0, label=columns[c])
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        if len(cols) > 1:
            ax.legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("time from bag start (s)")
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def frames_sheet(frames: Sequence[tuple[str, NDArray[np.generic]]], title: str) -> bytes:
    """Camera frames side by side (up to four per row), each titled with its label."""
    n = max(1, len(frames))
    cols = min(4, n)
    rows = -(-n // cols)
    fig = Figure(figsize=(3.2 * cols, 2.6 * rows + 0.4))
    for i, (label, image) in enumerate(frames):
        ax = fig.add_subplot(rows, cols, i + 1)
        ax.imshow(image, cmap="gray" if image.ndim == 2 else None)
        ax.set_title(label, fontsize=8)
        ax.set_axis_off()
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return _png(fig)
