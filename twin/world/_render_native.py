"""The camera's C kernel: a z-buffer rasteriser and the pass that turns face ids into pixels.

Built on first use with the system C compiler (`twin.core.native`) like the ray caster's kernel.
`twin.world.render` holds a numpy implementation of the same arithmetic, used without a compiler
(`TWIN_NO_NATIVE=1`); the tests compare the two.
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library

_SOURCE = r"""
#include <math.h>
#include <stdint.h>

/* One triangle, vertices as (sx, sy, 1/z) in pixels: keep the nearest face id and its depth z per
   pixel whose centre (x + 0.5, y + 0.5) it covers (edges included). Back faces (screen-space
   clockwise here, as the mesh's counter-clockwise outside is seen through an image whose y points
   down) are culled, as OGRE culls them. */
static void raster(const double *a, const double *b, const double *c, int id, int w, int h,
                   double far, float *depth, int32_t *ids) {
    double area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    if (!(area < 0.0)) return;
    const double *t = b; b = c; c = t; area = -area;
    double lo_x = fmin(a[0], fmin(b[0], c[0])), hi_x = fmax(a[0], fmax(b[0], c[0]));
    double lo_y = fmin(a[1], fmin(b[1], c[1])), hi_y = fmax(a[1], fmax(b[1], c[1]));
    lo_x = fmax(lo_x, -1.0); hi_x = fmin(hi_x, (double)w + 1.0);
    lo_y = fmax(lo_y, -1.0); hi_y = fmin(hi_y, (double)h + 1.0);
    int x0 = (int)ceil(lo_x - 0.5), x1 = (int)floor(hi_x - 0.5);
    int y0 = (int)ceil(lo_y - 0.5), y1 = (int)floor(hi_y - 0.5);
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x1 > w - 1) x1 = w - 1;
    if (y1 > h - 1) y1 = h - 1;
    for (int y = y0; y <= y1; ++y) {
        double py = y + 0.5;
        /* The row's covered span from each edge's half-plane, widened a pixel each side; the
           per-pixel test below decides (so the span only saves work, never changes a pixel). */
        double span_lo = lo_x, span_hi = hi_x;
        const double *e0[3] = {b, c, a}, *e1[3] = {c, a, b};
        int empty = 0;
        for (int j = 0; j < 3; ++j) {
            double ex = e1[j][0] - e0[j][0], ey = e1[j][1] - e0[j][1];
            double rhs = ex * (py - e0[j][1]);
            if (ey > 0.0) span_hi = fmin(span_hi, e0[j][0] + rhs / ey);
            else if (ey < 0.0) span_lo = fmax(span_lo, e0[j][0] + rhs / ey);
            else if (rhs < 0.0) empty = 1;
        }
        if (empty) continue;
        int sx0 = (int)ceil(fmax(span_lo, -2.0) - 0.5) - 1, sx1 = (int)floor(fmin(span_hi, (double)w + 2.0) - 0.5) + 1;
        if (sx0 < x0) sx0 = x0;
        if (sx1 > x1) sx1 = x1;
        for (int x = sx0; x <= sx1; ++x) {
            double px = x + 0.5;
            double w0 = (c[0] - b[0]) * (py - b[1]) - (c[1] - b[1]) * (px - b[0]);
            double w1 = (a[0] - c[0]) * (py - c[1]) - (a[1] - c[1]) * (px - c[0]);
            double w2 = (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]);
            if (w0 < 0.0 || w1 < 0.0 || w2 < 0.0) continue;
            double z = area / (w0 * a[2] + w1 * b[2] + w2 * c[2]);
            if (z > far) continue;
            long k = (long)y * w + x;
            if (z < (double)depth[k]) { depth[k] = (float)z; ids[k] = id; }
        }
    }
}

static void project(const double *p, double f, double cx, double cy, double *out) {
    out[0] = cx + f * p[0] / p[2];
    out[1] = cy + f * p[1] / p[2];
    out[2] = 1.0 / p[2];
}

static void clip_point(const double *p, const double *q, double near, double *out) {
    double t = (near - p[2]) / (q[2] - p[2]);
    out[0] = p[0] + t * (q[0] - p[0]);
    out[1] = p[1] + t * (q[1] - p[1]);
    out[2] = near;
}

/* v: (nv, 3) vertices in the optical frame (x right, y down, z forward), m. faces: (nf, 3).
   Clears depth to +inf and ids to -1, then draws every face clipped at z = near. */
int twin_render(const double *v, const int32_t *faces, long nf, double f, double cx, double cy,
                double near, double far, int w, int h, float *depth, int32_t *ids) {
    long n = (long)w * h;
    for (long k = 0; k < n; ++k) { depth[k] = INFINITY; ids[k] = -1; }
    for (long i = 0; i < nf; ++i) {
        const double *p[3] = {v + 3 * faces[3 * i], v + 3 * faces[3 * i + 1], v + 3 * faces[3 * i + 2]};
        int inside = (p[0][2] >= near) + (p[1][2] >= near) + (p[2][2] >= near);
        if (inside == 0) continue;
        if (p[0][2] > far && p[1][2] > far && p[2][2] > far) continue;
        double poly[4][3];
        int m = 0;
        for (int j = 0; j < 3; ++j) {
            const double *s = p[j], *e = p[(j + 1) % 3];
            int s_in = s[2] >= near, e_in = e[2] >= near;
            if (s_in) { poly[m][0] = s[0]; poly[m][1] = s[1]; poly[m][2] = s[2]; ++m; }
            if (s_in != e_in) { clip_point(s, e, near, poly[m]); ++m; }
        }
        double q[4][3];
        for (int j = 0; j < m; ++j) project(poly[j], f, cx, cy, q[j]);
        for (int j = 1; j + 1 < m; ++j) raster(q[0], q[j], q[j + 1], (int)i, w, h, far, depth, ids);
    }
    return 0;
}

static inline uint64_t splitmix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

static inline unsigned char level(int32_t v) {
    v >>= 8;
    return (unsigned char)(v < 0 ? 0 : v > 255 ? 255 : v);
}

/* Pixels from face ids: the face's colour levels (the background's where none), or with noise the
   face's colour plus one Gaussian sample per pixel added to its three channels, clamped to [0, 1],
   to 8 bits. Colours and samples are in 1/256ths of a level (`fixed`: round(c * 255 * 256) + 128,
   the 128 rounding to the nearest level; `table`: round(n * 255 * 256) for 4096 normal quantiles at
   (i + 0.5) / 4096, already scaled by the noise's stddev and shifted by its mean). A sample is
   picked by 12 of 16 bits of a counter-based hash of seed and pixel index (four pixels per hash). */
void twin_resolve(const int32_t *ids, const unsigned char *levels, const int32_t *fixed, long n,
                  const int32_t *table, uint64_t seed, unsigned char *rgb) {
    if (table == 0) {
        for (long k = 0; k < n; ++k) {
            const unsigned char *c = levels + 3 * (ids[k] + 1);
            unsigned char *out = rgb + 3 * k;
            out[0] = c[0]; out[1] = c[1]; out[2] = c[2];
        }
        return;
    }
    for (long k = 0; k < n; k += 4) {
        uint64_t bits = splitmix64(seed + (uint64_t)(k >> 2));
        for (int j = 0; j < 4 && k + j < n; ++j) {
            int32_t noise = table[(bits >> (16 * j)) & 0xFFF];
            const int32_t *c = fixed + 3 * (ids[k + j] + 1);
            unsigned char *out = rgb + 3 * (k + j);
            out[0] = level(c[0] + noise);
            out[1] = level(c[1] + noise);
            out[2] = level(c[2] + noise);
        }
    }
}
"""


@functools.cache
def load_render_kernel() -> ctypes.CDLL | None:
    """Return the compiled rasteriser, building it on first use; None if unavailable."""
    lib = load_library(CLibrary(name="render", source=_SOURCE))
    if lib is None:
        return None
    ptr = ctypes.c_void_p
    dbl = ctypes.c_double
    lib.twin_render.restype = ctypes.c_int
    lib.twin_render.argtypes = [ptr, ptr, ctypes.c_long, dbl, dbl, dbl, dbl, dbl, ctypes.c_int, ctypes.c_int, ptr, ptr]
    lib.twin_resolve.restype = None
    lib.twin_resolve.argtypes = [ptr, ptr, ptr, ctypes.c_long, ptr, ctypes.c_uint64, ptr]
    return lib
