"""A small C kernel for the ray caster, built once per machine with the system C compiler.

numpy pays a few microseconds per call on small arrays, and a scan needs dozens of calls; the
same loop in C costs a few microseconds in all. The kernel is compiled on first use into the
twin cache folder and loaded with ctypes (`twin.core.native`). Without a C compiler the ray
caster uses its numpy implementation, which gives the same ranges (the tests compare them).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library

_SOURCE = r"""
#include <math.h>
#include <stdlib.h>

#define TWO_PI 6.283185307179586476925286766559
#define EPS_ANGLE 1e-9

static inline double seg_hit(const double *s, double ox, double oy, double c, double sn,
                             double tmin) {
    double wx = s[0] - ox, wy = s[1] - oy;
    double ex = s[2] - s[0], ey = s[3] - s[1];
    double denom = c * ey - sn * ex;
    if (denom == 0.0) return INFINITY;
    double t = (wx * ey - wy * ex) / denom;
    double u = (wx * sn - wy * c) / denom;
    if (u < -1e-12 || u > 1.0 + 1e-12 || t < tmin) return INFINITY;
    return t;
}

static inline double circ_hit(const double *k, double ox, double oy, double c, double sn,
                              double tmin) {
    double qx = k[0] - ox, qy = k[1] - oy, r = k[2];
    double b = c * qx + sn * qy;
    double disc = b * b - (qx * qx + qy * qy - r * r);
    if (disc < 0.0) return INFINITY;
    double root = sqrt(disc);
    double t = b - root;
    if (t < tmin) t = b + root;
    if (t < tmin) return INFINITY;
    return t;
}

static void visit_interval(double lo, double span, double start, double inc, int n,
                           int is_seg, const double *shape, double ox, double oy,
                           const double *cosb, const double *sinb, double tmin, double *out) {
    double u = fmod(lo - start, TWO_PI);
    if (u < 0.0) u += TWO_PI;
    for (int turn = -1; turn <= 1; ++turn) {
        double a = u + turn * TWO_PI;
        long first = (long)ceil(a / inc);
        long last = (long)floor((a + span) / inc);
        if (first < 0) first = 0;
        if (last > n - 1) last = n - 1;
        for (long i = first; i <= last; ++i) {
            double t = is_seg ? seg_hit(shape, ox, oy, cosb[i], sinb[i], tmin)
                              : circ_hit(shape, ox, oy, cosb[i], sinb[i], tmin);
            if (t < out[i]) out[i] = t;
        }
    }
}

/* Lower out[i] to each shape's hit along beam i (cosb, sinb); a null index visits every shape. */
static void fan_accumulate(const double *seg, const long *seg_idx, long n_seg,
                           const double *circ, const long *circ_idx, long n_circ,
                           double ox, double oy, double start, double inc, int n,
                           const double *cosb, const double *sinb, double tmin, double *out) {
    for (long k = 0; k < n_seg; ++k) {
        const double *s = seg + 4 * (seg_idx ? seg_idx[k] : k);
        double a0 = atan2(s[1] - oy, s[0] - ox);
        double a1 = atan2(s[3] - oy, s[2] - ox);
        double span = fmod(a1 - a0, TWO_PI);
        if (span < 0.0) span += TWO_PI;
        double lo = a0;
        if (span > M_PI) { lo = a1; span = TWO_PI - span; }
        visit_interval(lo - EPS_ANGLE, span + 2 * EPS_ANGLE, start, inc, n, 1, s, ox, oy,
                       cosb, sinb, tmin, out);
    }
    for (long k = 0; k < n_circ; ++k) {
        const double *c = circ + 3 * (circ_idx ? circ_idx[k] : k);
        double qx = c[0] - ox, qy = c[1] - oy, r = c[2];
        double dist = sqrt(qx * qx + qy * qy);
        double half = dist <= r ? M_PI : asin(r / dist);
        double centre = atan2(qy, qx);
        visit_interval(centre - half - EPS_ANGLE, 2 * half + 2 * EPS_ANGLE, start, inc, n, 0, c,
                       ox, oy, cosb, sinb, tmin, out);
    }
}

/* Evenly spaced beams: start + i * inc, i < n (inc > 0). out[n] receives the ranges. */
int twin_cast_fan(const double *seg, const long *seg_idx, long n_seg,
                  const double *circ, const long *circ_idx, long n_circ,
                  double ox, double oy, double start, double inc, int n,
                  double tmin, double tmax, double *out) {
    double *cosb = malloc(2 * (size_t)n * sizeof(double));
    if (!cosb) return -1;
    double *sinb = cosb + n;
    for (int i = 0; i < n; ++i) {
        double a = start + i * inc;
        cosb[i] = cos(a);
        sinb[i] = sin(a);
        out[i] = INFINITY;
    }
    fan_accumulate(seg, seg_idx, n_seg, circ, circ_idx, n_circ, ox, oy, start, inc, n, cosb, sinb,
                   tmin, out);
    for (int i = 0; i < n; ++i) if (out[i] > tmax) out[i] = INFINITY;
    free(cosb);
    return 0;
}

/* REP 117 masking of a fan's ranges (+inf at or beyond tmax, -inf at or below tmin) and, when
   noise is given, noise added to the in-range values, clamped to [tmin, tmax]. */
static void mask_ranges(const double *raw, int n, double tmin, double tmax, const double *noise,
                        float *out) {
    for (int i = 0; i < n; ++i) {
        double r = raw[i];
        if (r >= tmax) { out[i] = INFINITY; continue; }
        if (r <= tmin) { out[i] = -INFINITY; continue; }
        if (noise) {
            r += noise[i];
            if (r < tmin) r = tmin;
            if (r > tmax) r = tmax;
        }
        out[i] = (float)r;
    }
}

/* A lidar scan: the fan above, then mask_ranges. */
int twin_scan(const double *seg, const long *seg_idx, long n_seg,
              const double *circ, const long *circ_idx, long n_circ,
              double ox, double oy, double start, double inc, int n,
              double tmin, double tmax, const double *noise, float *out) {
    double *raw = malloc((size_t)n * sizeof(double));
    if (!raw) return -1;
    if (twin_cast_fan(seg, seg_idx, n_seg, circ, circ_idx, n_circ, ox, oy, start, inc, n,
                      tmin, tmax, raw) != 0) {
        free(raw);
        return -1;
    }
    mask_ranges(raw, n, tmin, tmax, noise, out);
    free(raw);
    return 0;
}

/* A lidar scan as twin_scan, seeing a second set of shapes too (seg2, circ2: every one of them). */
int twin_scan_with(const double *seg, const long *seg_idx, long n_seg,
                   const double *circ, const long *circ_idx, long n_circ,
                   const double *seg2, long n_seg2, const double *circ2, long n_circ2,
                   double ox, double oy, double start, double inc, int n,
                   double tmin, double tmax, const double *noise, float *out) {
    double *cosb = malloc(3 * (size_t)n * sizeof(double));
    if (!cosb) return -1;
    double *sinb = cosb + n, *raw = cosb + 2 * (size_t)n;
    for (int i = 0; i < n; ++i) {
        double a = start + i * inc;
        cosb[i] = cos(a);
        sinb[i] = sin(a);
        raw[i] = INFINITY;
    }
    fan_accumulate(seg, seg_idx, n_seg, circ, circ_idx, n_circ, ox, oy, start, inc, n, cosb, sinb,
                   tmin, raw);
    fan_accumulate(seg2, 0, n_seg2, circ2, 0, n_circ2, ox, oy, start, inc, n, cosb, sinb, tmin, raw);
    mask_ranges(raw, n, tmin, tmax, noise, out);
    free(cosb);
    return 0;
}

/* Arbitrary beam angles: every beam against every candidate. */
void twin_cast_rays(const double *seg, const long *seg_idx, long n_seg,
                    const double *circ, const long *circ_idx, long n_circ,
                    double ox, double oy, int n, const double *angles,
                    double tmin, double tmax, double *out) {
    for (int i = 0; i < n; ++i) {
        double c = cos(angles[i]), sn = sin(angles[i]);
        double best = INFINITY;
        for (long k = 0; k < n_seg; ++k) {
            double t = seg_hit(seg + 4 * seg_idx[k], ox, oy, c, sn, tmin);
            if (t < best) best = t;
        }
        for (long k = 0; k < n_circ; ++k) {
            double t = circ_hit(circ + 3 * circ_idx[k], ox, oy, c, sn, tmin);
            if (t < best) best = t;
        }
        out[i] = best > tmax ? INFINITY : best;
    }
}
"""


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled ray-casting kernel, building it on first use; None if unavailable.

    Set `TWIN_NO_NATIVE=1` to force the numpy implementation (`twin.core.native`).
    """
    lib = load_library(CLibrary(name="raycast", source=_SOURCE))
    if lib is None:
        return None
    ptr = ctypes.c_void_p
    lib.twin_cast_fan.restype = ctypes.c_int
    lib.twin_cast_fan.argtypes = [
        ptr, ptr, ctypes.c_long, ptr, ptr, ctypes.c_long,
        ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int,
        ctypes.c_double, ctypes.c_double, ptr,
    ]  # fmt: skip
    lib.twin_scan.restype = ctypes.c_int
    lib.twin_scan.argtypes = [
        ptr, ptr, ctypes.c_long, ptr, ptr, ctypes.c_long,
        ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int,
        ctypes.c_double, ctypes.c_double, ptr, ptr,
    ]  # fmt: skip
    lib.twin_scan_with.restype = ctypes.c_int
    lib.twin_scan_with.argtypes = [
        ptr, ptr, ctypes.c_long, ptr, ptr, ctypes.c_long, ptr, ctypes.c_long, ptr, ctypes.c_long,
        ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int,
        ctypes.c_double, ctypes.c_double, ptr, ptr,
    ]  # fmt: skip
    lib.twin_cast_rays.restype = None
    lib.twin_cast_rays.argtypes = [
        ptr, ptr, ctypes.c_long, ptr, ptr, ctypes.c_long,
        ctypes.c_double, ctypes.c_double, ctypes.c_int, ptr,
        ctypes.c_double, ctypes.c_double, ptr,
    ]  # fmt: skip
    return lib
