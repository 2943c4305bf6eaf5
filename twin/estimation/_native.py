"""The odometry EKF's step in C: predict, the stacked update with its gate, and the estimate's covariances.

`SolvedEkf` (filterpy, BLAS) is the reference; this kernel does the same arithmetic in one call
without Python in between: ~50 µs per step becomes a few. It is built on first use with the system
C compiler (`twin.core.native`); without one, `OdometryFilter` steps through filterpy.

One `double` workspace holds the filter; its layout is the C enum below, which `twin_ekf_layout`
reports so that the Python side never hard-codes an offset:

    X      state (8)                      P      covariance (8x8, row-major, kept exactly symmetric)
    PAD    0.0 and the unobserved variance, right after P: targets of the ROS covariance gather
    PAR    1/R, B/2, rate random walks (v, yaw rate, bias), slip variance per rad, slip release, gate
           (negative: none), fuse gyro (0/1), gyro sample variance, standstill speed and yaw-rate variances
    STILL  readings in a row without a tick
    H      three 3x8 measurement matrices: wheel angles, wheel speeds, standstill
    IN     dt, kind (0 angles, 1 speeds), moving (0/1), the two wheel readings, their variance,
           the gyro's heading change over the interval and its sample count (0: no gyro), output row
    OUT    x, y, yaw (wrapped to [-pi, pi)), v, yaw rate, gyro bias
    GATHER where each of the 72 published covariance entries comes from: an index into P and PAD

`twin_ekf_step(ws, ros)` runs `OdometryFilter._step` (standstill detection, gyro fusion, slip
release and gate) and `SolvedEkf.predict`/`update_linear`, and writes the pose and twist
covariances (6x6 each, ROS order) to row `IN.row` of `ros` (rows of 72 doubles). It returns
0 (updated), 1 (the gate fired: the wheels' say on the yaw was dropped and the update redone) or
-1 (an innovation covariance not positive definite; nothing after the predict was applied).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library, native_disabled

__all__ = ["LAYOUT_NAMES", "load_ekf_kernel"]

# Names of the workspace regions, in the order twin_ekf_layout reports their offsets (then the size).
LAYOUT_NAMES = ("X", "P", "PAD", "PAR", "STILL", "H", "IN", "OUT", "GATHER", "SIZE")

_SOURCE = r"""
#include <math.h>

enum { N = 8 };
enum {
    WS_X = 0,
    WS_P = WS_X + N,
    WS_PAD = WS_P + N * N,
    WS_PAR = WS_PAD + 2,
    WS_STILL = WS_PAR + 12,
    WS_H = WS_STILL + 1,
    WS_IN = WS_H + 3 * 3 * N,
    WS_OUT = WS_IN + 9,
    WS_GATHER = WS_OUT + 6,
    WS_SIZE = WS_GATHER + 72
};
enum { PAR_GATE = 7, PAR_FUSE = 8, PAR_GYRO_VAR = 9, PAR_STILL_SPEED_VAR = 10, PAR_STILL_RATE_VAR = 11 };
enum { KIND_ANGLES = 0, KIND_SPEEDS = 1, KIND_STILL = 2 };

int twin_ekf_layout(long *out) {
    const long layout[] = {WS_X, WS_P, WS_PAD, WS_PAR, WS_STILL, WS_H, WS_IN, WS_OUT, WS_GATHER, WS_SIZE};
    for (int i = 0; i < 10; ++i) out[i] = layout[i];
    return 10;
}

/* P = F (P + Q_w dt) F^T (+ slip variance on the wheel angles); x advanced by the unicycle model
   (rates first, then the pose and the wheels with the new rates: midpoint rule). */
static void predict(double *ws, double dt) {
    double *x = ws + WS_X, *P = ws + WS_P;
    const double *par = ws + WS_PAR;
    P[3 * N + 3] += par[2] * dt;
    P[4 * N + 4] += par[3] * dt;
    P[5 * N + 5] += par[4] * dt;
    double yaw = x[2], v = x[3], rate = x[4];
    double heading = yaw + 0.5 * rate * dt;
    double c = cos(heading), s = sin(heading);
    double step = v * dt, wheel_v = dt * par[0], wheel_r = par[1] * wheel_v, half = 0.5 * dt * step;
    /* F = I + E, with E's eleven entries (row, column, value): */
    const int ei[] = {0, 0, 0, 1, 1, 1, 2, 6, 6, 7, 7};
    const int ek[] = {2, 3, 4, 2, 3, 4, 4, 3, 4, 3, 4};
    const double ev[] = {-step * s, dt * c, -half * s, step * c, dt * s, half * c, dt,
                         wheel_v, -wheel_r, wheel_v, wheel_r};
    double travel_left = v * wheel_v - rate * wheel_r, travel_right = v * wheel_v + rate * wheel_r;
    x[0] = x[0] + step * c;
    x[1] = x[1] + step * s;
    x[2] = yaw + rate * dt;
    x[6] = x[6] + travel_left;
    x[7] = x[7] + travel_right;
    double FP[N][N], FPF[N][N];  /* F P, then F P F^T */
    for (int i = 0; i < N; ++i)
        for (int j = 0; j < N; ++j) FP[i][j] = P[i * N + j];
    for (int e = 0; e < 11; ++e)
        for (int j = 0; j < N; ++j) FP[ei[e]][j] += ev[e] * P[ek[e] * N + j];
    for (int i = 0; i < N; ++i)
        for (int j = 0; j < N; ++j) FPF[i][j] = FP[i][j];
    for (int e = 0; e < 11; ++e)
        for (int i = 0; i < N; ++i) FPF[i][ei[e]] += ev[e] * FP[i][ek[e]];
    for (int i = 0; i < N; ++i)
        for (int j = i; j < N; ++j) P[i * N + j] = P[j * N + i] = FPF[i][j];
    if (par[5] != 0.0) {
        P[6 * N + 6] += par[5] * fabs(travel_left);
        P[7 * N + 7] += par[5] * fabs(travel_right);
    }
}

/* Linear update with the first m rows of H, in Joseph form, the gain solved through the Cholesky
   factor of S = H P H^T + R (never an inverse):
     S [K^T | w] = [H P | y],   P <- P - K H P - P H^T K^T + (L^T K^T)^T (L^T K^T),   S = L L^T.
   The last term is a Gram matrix; P's upper triangle is formed and mirrored, so P stays exactly
   symmetric. With gate >= 0, returns 0 without updating when y^T w exceeds it.
   Returns 1 (updated), 0 (gated) or -1 (S not positive definite). */
static int update(double *restrict ws, const double *restrict H, int m, const double *z, const double R[3][3],
                  double gate) {
    double *restrict x = ws + WS_X, *restrict P = ws + WS_P;
    double HP[3][N], W[3][N + 1], L[3][3] = {{0}};
    int nonzero[3][N], count[3];  /* H's rows have one or two entries: skip the zeros */
    for (int i = 0; i < m; ++i) {
        count[i] = 0;
        for (int k = 0; k < N; ++k)
            if (H[i * N + k] != 0.0) nonzero[i][count[i]++] = k;
    }
    for (int i = 0; i < m; ++i) {
        double hx = 0.0;
        for (int j = 0; j < N; ++j) HP[i][j] = 0.0;
        for (int t = 0; t < count[i]; ++t) {
            int k = nonzero[i][t];
            double h = H[i * N + k];
            hx += h * x[k];
            for (int j = 0; j < N; ++j) HP[i][j] += h * P[k * N + j];
        }
        for (int j = 0; j < N; ++j) W[i][j] = HP[i][j];
        W[i][N] = z[i] - hx;
    }
    double y[3] = {W[0][N], m > 1 ? W[1][N] : 0.0, m > 2 ? W[2][N] : 0.0};
    for (int i = 0; i < m; ++i)
        for (int j = 0; j <= i; ++j) {
            double acc = R[i][j];
            for (int t = 0; t < count[j]; ++t) acc += HP[i][nonzero[j][t]] * H[j * N + nonzero[j][t]];
            for (int k = 0; k < j; ++k) acc -= L[i][k] * L[j][k];
            if (i == j) {
                if (!(acc > 0.0)) return -1;
                L[i][i] = sqrt(acc);
            } else {
                L[i][j] = acc / L[j][j];
            }
        }
    for (int c = 0; c <= N; ++c) {
        for (int i = 0; i < m; ++i) {  /* L a = b */
            double acc = W[i][c];
            for (int k = 0; k < i; ++k) acc -= L[i][k] * W[k][c];
            W[i][c] = acc / L[i][i];
        }
        for (int i = m - 1; i >= 0; --i) {  /* L^T w = a */
            double acc = W[i][c];
            for (int k = i + 1; k < m; ++k) acc -= L[k][i] * W[k][c];
            W[i][c] = acc / L[i][i];
        }
    }
    if (gate >= 0.0) {
        double nis = 0.0;
        for (int i = 0; i < m; ++i) nis += y[i] * W[i][N];
        if (nis > gate) return 0;
    }
    double M[3][N];  /* L^T K^T */
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < N; ++j) {
            double acc = 0.0;
            for (int k = i; k < m; ++k) acc += L[k][i] * W[k][j];
            M[i][j] = acc;
        }
    for (int j = 0; j < N; ++j) {
        double acc = 0.0;
        for (int i = 0; i < m; ++i) acc += y[i] * W[i][j];
        x[j] += acc;
    }
    for (int a = 0; a < N; ++a)
        for (int b = a; b < N; ++b) {
            double khp = 0.0, gram = 0.0;
            for (int i = 0; i < m; ++i) {
                khp += W[i][a] * HP[i][b] + HP[i][a] * W[i][b];
                gram += M[i][a] * M[i][b];
            }
            P[a * N + b] = P[b * N + a] = (P[a * N + b] - khp) + gram;
        }
    return 1;
}

/* Set the wheels' differential travel over this interval free: in P for wheel angles, in R for
   wheel speeds; at standstill the zero yaw rate is dropped. */
static void release(double *ws, int kind, double R[3][3]) {
    double big = ws[WS_PAR + 6], *P = ws + WS_P;
    if (kind == KIND_ANGLES) {
        P[6 * N + 6] += big; P[7 * N + 7] += big;
        P[6 * N + 7] -= big; P[7 * N + 6] -= big;
    } else if (kind == KIND_SPEEDS) {
        R[0][0] += big; R[1][1] += big;
        R[0][1] -= big; R[1][0] -= big;
    } else {
        R[1][1] += big;
    }
}

/* Python's float %: the result takes the divisor's sign. */
static double wrap_angle(double a) {
    double r = fmod(a + M_PI, 2.0 * M_PI);
    if (r != 0.0) {
        if (r < 0.0) r += 2.0 * M_PI;
    } else {
        r = 0.0;
    }
    return r - M_PI;
}

int twin_ekf_step(double *ws, double *ros) {
    const double *in = ws + WS_IN, *par = ws + WS_PAR;
    double dt = in[0], gyro_count = in[7];
    int kind = (int)in[1], moving = in[2] != 0.0;
    double z[3] = {in[3], in[4], 0.0};
    double R[3][3] = {{in[5], 0.0, 0.0}, {0.0, in[5], 0.0}, {0.0, 0.0, 0.0}};
    ws[WS_STILL] = moving ? 0.0 : ws[WS_STILL] + 1.0;
    if (ws[WS_STILL] >= 2.0) {  /* no tick for two intervals: a zero-velocity update */
        kind = KIND_STILL;
        z[0] = z[1] = 0.0;
        R[0][0] = par[PAR_STILL_SPEED_VAR];
        R[1][1] = par[PAR_STILL_RATE_VAR];
    }
    int fuse = par[PAR_FUSE] != 0.0 && gyro_count > 0.0;
    if (fuse) {
        z[2] = in[6] / dt;
        R[2][2] = par[PAR_GYRO_VAR] / gyro_count;
    }
    const double *H = ws + WS_H + kind * 3 * N;
    int status = 0;
    predict(ws, dt);
    if (fuse) {
        if (moving) release(ws, kind, R);  /* the gyro owns the yaw: turning wheels may slip */
        int done = update(ws, H, 3, z, R, par[PAR_GATE]);
        if (done < 0) return -1;
        if (done == 0) {
            status = 1;
            if (!moving) release(ws, kind, R);
            if (update(ws, H, 3, z, R, -1.0) < 0) return -1;
        }
    } else if (update(ws, H, 2, z, R, -1.0) < 0) {
        return -1;
    }
    double *out = ws + WS_OUT, *x = ws + WS_X;
    out[0] = x[0]; out[1] = x[1]; out[2] = wrap_angle(x[2]);
    out[3] = x[3]; out[4] = x[4]; out[5] = x[5];
    double *row = ros + 72 * (long)in[8];
    for (int i = 0; i < 72; ++i) row[i] = ws[WS_P + (int)ws[WS_GATHER + i]];
    return status;
}
"""


def load_ekf_kernel() -> ctypes.CDLL | None:
    """Return the compiled EKF step, building it on first use; None without a C compiler or with `TWIN_NO_NATIVE`."""
    return None if native_disabled() else _load()


@functools.cache
def _load() -> ctypes.CDLL | None:
    # Compiled without FMA contraction: the products and sums round as numpy's do.
    flags = ("-O3", "-shared", "-fPIC", "-ffp-contract=off")
    lib = load_library(CLibrary(name="odometry_ekf", source=_SOURCE, flags=flags), keep_gil=True)  # a 1 µs call
    if lib is None:
        return None
    lib.twin_ekf_layout.restype = ctypes.c_int
    lib.twin_ekf_layout.argtypes = [ctypes.c_void_p]
    lib.twin_ekf_step.restype = ctypes.c_int  # no argtypes: called with prebuilt pointers
    return lib
