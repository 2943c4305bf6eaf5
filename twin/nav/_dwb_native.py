"""DWB's trajectory roll-out and BaseObstacle check in C, for every sampled command at once.

Same arithmetic, in the same order, as `DwbController._trajectories` + the BaseObstacle part of
`DwbController._rollout` (numpy, the reference and fallback): per sample, `steps` time steps of
`sim_time / steps`; the velocity after time t accelerates from the current one towards the command
under the limits; yaw after a step adds w dt, the position adds v cos(yaw before) dt; each pose
(the start included) is moved into the costmap frame and its cell's cost read.

    void twin_dwb_rollout(int n, const double *cmd, const long *steps, const double *lim,
                          const double *geo, const unsigned char *cost, int rows, int cols,
                          double *ends, double *max_cost, unsigned char *ok)
        cmd (n, 2) vx, wz; lim = acc_x, decel_x, acc_w, decel_w, sim_time, v0, w0;
        geo = robot x, y, yaw, costmap origin x, y, resolution; outputs: ends (n, 3) in the costmap
        frame, max_cost (n), ok (n: every pose on the grid and below 253).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library

__all__ = ["load_dwb_kernel"]

_SOURCE = r"""
#include <math.h>

static double ramp(double v0, double target, double acc, double decel, double t) {
    if (target >= v0) { double v = v0 + acc * t; return target < v ? target : v; }
    double v = v0 + decel * t; return target > v ? target : v;
}

void twin_dwb_rollout(int n, const double *cmd, const long *steps, const double *lim, const double *geo,
                      const unsigned char *cost, int rows, int cols, double *ends, double *max_cost,
                      unsigned char *ok) {
    double px = geo[0], py = geo[1], pyaw = geo[2], ox = geo[3], oy = geo[4], res = geo[5];
    double c = cos(pyaw), s = sin(pyaw);
    for (int i = 0; i < n; ++i) {
        long nsteps = steps[i];
        double dt = lim[4] / (double)nsteps;
        double yaw = 0.0, x = 0.0, y = 0.0, worst = 0.0;
        int legal = 1;
        for (long k = 0; k <= nsteps; ++k) {
            if (k > 0) {
                double t = (double)k * dt;
                double v = ramp(lim[5], cmd[2 * i], lim[0], lim[1], t);
                double w = ramp(lim[6], cmd[2 * i + 1], lim[2], lim[3], t);
                double yaw_after = yaw + w * dt;
                double yaw_before = yaw_after - w * dt;
                x = x + v * cos(yaw_before) * dt;
                y = y + v * sin(yaw_before) * dt;
                yaw = yaw_after;
            }
            double wx = px + c * x - s * y, wy = py + s * x + c * y;
            long col = (long)floor((wx - ox) / res), row = (long)floor((wy - oy) / res);
            double cv = 255.0;
            if (row >= 0 && row < rows && col >= 0 && col < cols) cv = (double)cost[row * cols + col];
            else legal = 0;
            if (cv >= 253.0) legal = 0;
            if (cv > worst) worst = cv;
        }
        ends[3 * i] = px + c * x - s * y;
        ends[3 * i + 1] = py + s * x + c * y;
        ends[3 * i + 2] = pyaw + yaw;
        max_cost[i] = worst;
        ok[i] = (unsigned char)legal;
    }
}
"""

_LIB = CLibrary(name="twin_dwb", source=_SOURCE)


@functools.cache
def load_dwb_kernel() -> ctypes.CDLL | None:
    """Return the DWB kernel with its signature set, or None (no compiler, or TWIN_NO_NATIVE)."""
    lib = load_library(_LIB)
    if lib is None:
        return None
    dbl = ctypes.POINTER(ctypes.c_double)
    u8 = ctypes.POINTER(ctypes.c_ubyte)
    lib.twin_dwb_rollout.argtypes = [
        ctypes.c_int,
        dbl,
        ctypes.POINTER(ctypes.c_long),
        dbl,
        dbl,
        u8,
        ctypes.c_int,
        ctypes.c_int,
        dbl,
        dbl,
        u8,
    ]
    lib.twin_dwb_rollout.restype = None
    return lib
