"""C kernels for AMCL's laser model and the costmap's ray tracing, built once per machine.

Both loops are short per element but run over thousands of elements per call (2000 particles x
60 beams; 360 rays x 60 cells); in C they cost a fraction of the numpy version. Without a C
compiler (or with `TWIN_NO_NATIVE=1`) the callers use their numpy implementations, which give the
same cells and the same weights up to the order of a floating-point sum (the tests compare them).
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library

_SOURCE = r"""
#include <math.h>
#include <stdlib.h>

/* AMCL likelihood field: out[j] = 1 + sum_i cubes[row, col] over the beams' endpoints.
   poses (n, 3); beam endpoints (bx, by) in the base frame; cubes (rows, cols) padded by `pad`.
   Beam by beam over all particles: one beam's endpoints from a cluster of particles fall in a few
   neighbouring cells, which keeps the lookups in cache. Returns -1 when memory runs out. */
int twin_amcl_likelihood(const double *poses, long n, const double *bx, const double *by, long nb,
                         const double *cubes, long rows, long cols, long pad,
                         double ox, double oy, double res, double *out) {
    double *cs = malloc(2 * sizeof(double) * (size_t)(n > 0 ? n : 1));
    if (!cs) return -1;
    double *sn = cs + n;
    for (long j = 0; j < n; ++j) {
        cs[j] = cos(poses[3 * j + 2]);
        sn[j] = sin(poses[3 * j + 2]);
        out[j] = 0.0;
    }
    for (long i = 0; i < nb; ++i) {
        double ex = bx[i], ey = by[i];
        for (long j = 0; j < n; ++j) {
            double hx = poses[3 * j] + cs[j] * ex - sn[j] * ey;
            double hy = poses[3 * j + 1] + sn[j] * ex + cs[j] * ey;
            double fc = (hx - ox) / res + 0.5, fr = (hy - oy) / res + 0.5;
            long col = (long)fc, row = (long)fr;   /* floor without a libm call: truncate, step down below 0 */
            col -= (double)col > fc;
            row -= (double)row > fr;
            col += pad;
            row += pad;
            if (col < 0) col = 0;
            if (col > cols - 1) col = cols - 1;
            if (row < 0) row = 0;
            if (row > rows - 1) row = rows - 1;
            out[j] += cubes[row * cols + col];
        }
    }
    for (long j = 0; j < n; ++j) out[j] += 1.0;
    free(cs);
    return 0;
}

/* Costmap2D::raytraceLine from (x0, y0) to each (x1[k], y1[k]): set visited cells to `value`.
   bounds[4] (row min, row max, col min, col max) grow to cover the cells written. */
void twin_raytrace(unsigned char *cost, long rows, long cols, long x0, long y0,
                   const long *x1, const long *y1, long n, double max_cells, double min_cells,
                   unsigned char value, long *bounds) {
    for (long k = 0; k < n; ++k) {
        long dxf = x1[k] - x0, dyf = y1[k] - y0;
        double dist = hypot((double)dxf, (double)dyf);
        if (dist < min_cells) continue;
        long sx0 = x0, sy0 = y0;
        if (dist > 0.0) {
            sx0 = (long)(x0 + dxf / dist * min_cells);
            sy0 = (long)(y0 + dyf / dist * min_cells);
        }
        long dx = x1[k] - sx0, dy = y1[k] - sy0;
        long adx = dx < 0 ? -dx : dx, ady = dy < 0 ? -dy : dy;
        long sx = (dx > 0) - (dx < 0), sy = (dy > 0) - (dy < 0);
        double scale = dist == 0.0 ? 1.0 : (max_cells / dist < 1.0 ? max_cells / dist : 1.0);
        long da, db, sa_x, sa_y, sb_x, sb_y;
        if (adx >= ady) { da = adx; db = ady; sa_x = sx; sa_y = 0; sb_x = 0; sb_y = sy; }
        else { da = ady; db = adx; sa_x = 0; sa_y = sy; sb_x = sx; sb_y = 0; }
        long end = (long)(scale * da);
        if (end > da) end = da;
        long error = da / 2, cx = sx0, cy = sy0;
        for (long i = 0; i <= end; ++i) {
            if (cy >= 0 && cy < rows && cx >= 0 && cx < cols) {
                cost[cy * cols + cx] = value;
                if (cy < bounds[0]) bounds[0] = cy;
                if (cy > bounds[1]) bounds[1] = cy;
                if (cx < bounds[2]) bounds[2] = cx;
                if (cx > bounds[3]) bounds[3] = cx;
            }
            if (i == end) break;
            cx += sa_x; cy += sa_y;
            error += db;
            if (error >= da) { cx += sb_x; cy += sb_y; error -= da; }
        }
    }
}

/* ObstacleLayer for one observation: clip each endpoint's ray to the grid as raytraceFreespace
   does, clear it (twin_raytrace), then mark endpoints within [min_range, max_range) LETHAL (254).
   pts (n, 2) in the grid's frame; bounds as in twin_raytrace. */
void twin_obstacle_update(unsigned char *cost, long rows, long cols, double gx, double gy, double res,
                          double ox, double oy, const double *pts, long n, int clearing, int marking,
                          double ray_max_cells, double ray_min_cells,
                          double mark_max_m, double mark_min_m, long *bounds) {
    double map_end_x = gx + cols * res, map_end_y = gy + rows * res;
    double fx0 = (ox - gx) / res, fy0 = (oy - gy) / res;
    if (clearing && fx0 >= 0.0 && fy0 >= 0.0 && fx0 < cols && fy0 < rows) {
        long x0 = (long)fx0, y0 = (long)fy0;
        for (long k = 0; k < n; ++k) {
            double wx = pts[2 * k], wy = pts[2 * k + 1];
            double a = wx - ox, b = wy - oy, t;
            if (wx < gx) { t = (gx - ox) / a; wx = gx; wy = oy + b * t; }
            if (wy < gy) { t = (gy - oy) / b; wx = ox + a * t; wy = gy; }
            if (wx > map_end_x) { t = (map_end_x - ox) / a; wx = map_end_x - 0.001; wy = oy + b * t; }
            if (wy > map_end_y) { t = (map_end_y - oy) / b; wx = ox + a * t; wy = map_end_y - 0.001; }
            long x1 = (long)((wx - gx) / res), y1 = (long)((wy - gy) / res);
            if (x1 < 0) x1 = 0;
            if (x1 > cols - 1) x1 = cols - 1;
            if (y1 < 0) y1 = 0;
            if (y1 > rows - 1) y1 = rows - 1;
            twin_raytrace(cost, rows, cols, x0, y0, &x1, &y1, 1, ray_max_cells, ray_min_cells, 0, bounds);
        }
    }
    if (!marking) return;
    for (long k = 0; k < n; ++k) {
        double dx = pts[2 * k] - ox, dy = pts[2 * k + 1] - oy;
        double d2 = dx * dx + dy * dy;
        if (d2 >= mark_max_m * mark_max_m || d2 < mark_min_m * mark_min_m) continue;
        double fx = (pts[2 * k] - gx) / res, fy = (pts[2 * k + 1] - gy) / res;
        if (fx < 0.0 || fy < 0.0 || fx >= cols || fy >= rows) continue;
        long c = (long)fx, r = (long)fy;
        cost[r * cols + c] = 254;
        if (r < bounds[0]) bounds[0] = r;
        if (r > bounds[1]) bounds[1] = r;
        if (c < bounds[2]) bounds[2] = c;
        if (c > bounds[3]) bounds[3] = c;
    }
}

/* Felzenszwalb-Huttenlocher 1D squared distance transform of f (n values, stride `step`). */
static void dt1d(const double *f, long n, long step, double *d, long *v, double *z, double *tmp) {
    for (long q = 0; q < n; ++q) tmp[q] = f[q * step];
    long k = 0;
    v[0] = 0; z[0] = -HUGE_VAL; z[1] = HUGE_VAL;
    for (long q = 1; q < n; ++q) {
        double s = ((tmp[q] + (double)q * q) - (tmp[v[k]] + (double)v[k] * v[k])) / (2.0 * q - 2.0 * v[k]);
        while (s <= z[k]) {
            --k;
            s = ((tmp[q] + (double)q * q) - (tmp[v[k]] + (double)v[k] * v[k])) / (2.0 * q - 2.0 * v[k]);
        }
        ++k; v[k] = q; z[k] = s; z[k + 1] = HUGE_VAL;
    }
    k = 0;
    for (long q = 0; q < n; ++q) {
        while (z[k + 1] < q) ++k;
        d[q * step] = (double)(q - v[k]) * (q - v[k]) + tmp[v[k]];
    }
}

/* Inflation: squared distance (cells) of every cell to the nearest seed (seeds[i] != 0), then
   out[i] = table[d2] when d2 <= max_d2, else 0. Returns -1 when memory runs out. */
int twin_inflate(const unsigned char *seeds, long rows, long cols, const unsigned char *table,
                 long max_d2, unsigned char *out) {
    long n = rows > cols ? rows : cols;
    double *grid = malloc(sizeof(double) * (size_t)(rows * cols));
    double *tmp = malloc(sizeof(double) * (size_t)n);
    double *z = malloc(sizeof(double) * (size_t)(n + 1));
    long *v = malloc(sizeof(long) * (size_t)n);
    if (!grid || !tmp || !z || !v) { free(grid); free(tmp); free(z); free(v); return -1; }
    for (long i = 0; i < rows * cols; ++i) grid[i] = seeds[i] ? 0.0 : 1e20;
    for (long c = 0; c < cols; ++c) dt1d(grid + c, rows, cols, grid + c, v, z, tmp);
    for (long r = 0; r < rows; ++r) dt1d(grid + r * cols, cols, 1, grid + r * cols, v, z, tmp);
    for (long i = 0; i < rows * cols; ++i) {
        double d2 = grid[i];
        out[i] = d2 <= (double)max_d2 ? table[(long)d2] : 0;
    }
    free(grid); free(tmp); free(z); free(v);
    return 0;
}

/* Set the cells whose centres lie inside a polygon (even-odd) to `value`; bounds grow as in raytrace. */
void twin_fill_polygon(unsigned char *cost, long rows, long cols, double ox, double oy, double res,
                       const double *poly, long n, unsigned char value, long *bounds) {
    double xmin = poly[0], xmax = poly[0], ymin = poly[1], ymax = poly[1];
    for (long i = 1; i < n; ++i) {
        if (poly[2 * i] < xmin) xmin = poly[2 * i];
        if (poly[2 * i] > xmax) xmax = poly[2 * i];
        if (poly[2 * i + 1] < ymin) ymin = poly[2 * i + 1];
        if (poly[2 * i + 1] > ymax) ymax = poly[2 * i + 1];
    }
    long c0 = (long)((xmin - ox) / res), c1 = (long)((xmax - ox) / res) + 1;
    long r0 = (long)((ymin - oy) / res), r1 = (long)((ymax - oy) / res) + 1;
    if (c0 < 0) c0 = 0;
    if (r0 < 0) r0 = 0;
    if (c1 > cols) c1 = cols;
    if (r1 > rows) r1 = rows;
    for (long r = r0; r < r1; ++r) {
        double y = oy + (r + 0.5) * res;
        for (long c = c0; c < c1; ++c) {
            double x = ox + (c + 0.5) * res;
            int inside = 0;
            for (long i = 0; i < n; ++i) {
                double x1 = poly[2 * i], y1 = poly[2 * i + 1];
                double x2 = poly[2 * ((i + 1) % n)], y2 = poly[2 * ((i + 1) % n) + 1];
                if ((y1 > y) != (y2 > y)) {
                    double xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1);
                    if (x < xc) inside = !inside;
                }
            }
            if (inside) {
                cost[r * cols + c] = value;
                if (r < bounds[0]) bounds[0] = r;
                if (r > bounds[1]) bounds[1] = r;
                if (c < bounds[2]) bounds[2] = c;
                if (c > bounds[3]) bounds[3] = c;
            }
        }
    }
}
"""


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled kernels, building them on first use; None if unavailable."""
    lib = load_library(CLibrary(name="nav_loc", source=_SOURCE), keep_gil=True)
    if lib is None:
        return None
    ptr, long_, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    lib.twin_amcl_likelihood.restype = ctypes.c_int
    lib.twin_amcl_likelihood.argtypes = [ptr, long_, ptr, ptr, long_, ptr, long_, long_, long_, dbl, dbl, dbl, ptr]
    lib.twin_raytrace.restype = None
    lib.twin_raytrace.argtypes = [
        ptr, long_, long_, long_, long_, ptr, ptr, long_, dbl, dbl, ctypes.c_ubyte, ptr,
    ]  # fmt: skip
    lib.twin_obstacle_update.restype = None
    lib.twin_obstacle_update.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, dbl, dbl, ptr, long_, ctypes.c_int, ctypes.c_int,
        dbl, dbl, dbl, dbl, ptr,
    ]  # fmt: skip
    lib.twin_inflate.restype = ctypes.c_int
    lib.twin_inflate.argtypes = [ptr, long_, long_, ptr, long_, ptr]
    lib.twin_fill_polygon.restype = None
    lib.twin_fill_polygon.argtypes = [ptr, long_, long_, dbl, dbl, dbl, ptr, long_, ctypes.c_ubyte, ptr]
    return lib
