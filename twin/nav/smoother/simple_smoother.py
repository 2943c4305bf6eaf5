"""nav2_smoother's SimpleSmoother, as smoother_server runs it for a SmoothPath goal."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["smooth_path"]

F64 = NDArray[np.float64]


def smooth_path(
    path: F64, *, w_data: float = 0.2, w_smooth: float = 0.3, tolerance: float = 1e-10, max_its: int = 1000
) -> F64:
    """Nav2's SimpleSmoother: pull interior points towards their neighbours and their original place.

    The end points stay; orientations of the interior poses follow the smoothed segments.
    """
    poses = np.asarray(path, dtype=np.float64).reshape(-1, 3)
    if len(poses) < 3:
        return poses.copy()
    orig = poses[:, :2].copy()
    new = orig.copy()
    for _ in range(max_its):
        change = 0.0
        for i in range(1, len(new) - 1):  # Gauss-Seidel, point by point, as the smoother iterates
            before = new[i].copy()
            new[i] += w_data * (orig[i] - new[i]) + w_smooth * (new[i - 1] + new[i + 1] - 2.0 * new[i])
            change += float(np.abs(new[i] - before).sum())
        if change < tolerance:
            break
    out = poses.copy()
    out[:, :2] = new
    d = np.diff(new, axis=0)
    out[1:-1, 2] = np.arctan2(d[:-1, 1] + d[1:, 1], d[:-1, 0] + d[1:, 0])
    return out
