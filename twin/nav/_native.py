"""C kernels for AMCL and the costmaps, built once per machine.

AMCL: the laser model, resampling with KLD-sampling's count, histogram clusters and the estimate.
Costmaps: ray tracing, marking, footprint clearing, and the layers' composition with inflation.

The loops are short per element but run over thousands of elements per call (2000 particles x
60 beams; 360 rays x 60 cells; a 170 x 170 cell window); in C they cost a fraction of the numpy
version. Without a C compiler (or with `TWIN_NO_NATIVE=1`) the callers use their numpy
implementations, which give the same cells, counts and clusters, and the same weights up to the
order of a floating-point sum (the tests compare them). Random numbers are always drawn in Python.
"""

from __future__ import annotations

import ctypes
import functools

from twin.core.native import CLibrary, load_library

# -O3 lets the compiler vectorise the inflation's row minimum; no contraction into fused
# multiply-adds, so the kernels round every product and sum as the numpy paths do.
_FLAGS = ("-O3", "-ffp-contract=off", "-shared", "-fPIC")

_SOURCE = r"""
#include <math.h>
#include <stdlib.h>

/* AMCL likelihood field: out[j] = 1 + sum_i pz3[row, col] over the beams' endpoints, in beam order.
   Particle j at poses[j] = (x, y, yaw) has the grid position gx = (x - ox) * inv_res + 0.5 (likewise
   gy) and heading cos, sin; beam i's endpoint in the base frame in cells is (ex, ey). The endpoint's
   cell is (floor(gx + c ex - s ey), floor(gy + s ex + c ey)), AMCL's rounding lookup; off the map it
   weighs `off_value`. Beam by beam over all particles: one beam's endpoints from a cluster of
   particles fall in a few neighbouring cells, which keeps the lookups in cache. Returns -1 when
   memory runs out. */
int twin_amcl_likelihood(const double *poses, long n, double ox, double oy, double inv_res,
                         const double *ex, const double *ey, long nb,
                         const double *pz3, long rows, long cols, double off_value, double *out) {
    double *buf = malloc(4 * sizeof(double) * (size_t)(n > 0 ? n : 1));
    if (!buf) return -1;
    double *gx = buf, *gy = buf + n, *c = buf + 2 * n, *s = buf + 3 * n;
    for (long j = 0; j < n; ++j) {
        gx[j] = (poses[3 * j] - ox) * inv_res + 0.5;
        gy[j] = (poses[3 * j + 1] - oy) * inv_res + 0.5;
        c[j] = cos(poses[3 * j + 2]);
        s[j] = sin(poses[3 * j + 2]);
        out[j] = 0.0;
    }
    for (long i = 0; i < nb; ++i) {
        double bx = ex[i], by = ey[i];
        for (long j = 0; j < n; ++j) {
            double fc = gx[j] + c[j] * bx - s[j] * by;
            double fr = gy[j] + s[j] * bx + c[j] * by;
            long col = (long)fc, row = (long)fr;   /* floor without a libm call: truncate, step down below 0 */
            col -= (double)col > fc;
            row -= (double)row > fr;
            out[j] += (col >= 0 && col < cols && row >= 0 && row < rows) ? pz3[row * cols + col] : off_value;
        }
    }
    for (long j = 0; j < n; ++j) out[j] += 1.0;
    free(buf);
    return 0;
}

/* The differential motion model's sampling (DifferentialMotionModel::odometryUpdate) given the
   standard normal draws (3 per particle): rot1 - n0 sd_rot1, trans - n1 sd_trans, rot2 - n2 sd_rot2
   applied to each pose; headings are not folded. */
void twin_amcl_motion(double *poses, long n, const double *noise, double rot1, double trans, double rot2,
                      double sd_rot1, double sd_trans, double sd_rot2) {
    for (long j = 0; j < n; ++j) {
        double r1 = rot1 - noise[3 * j] * sd_rot1;
        double t = trans - noise[3 * j + 1] * sd_trans;
        double r2 = rot2 - noise[3 * j + 2] * sd_rot2;
        double heading = poses[3 * j + 2] + r1;
        poses[3 * j] += t * cos(heading);
        poses[3 * j + 1] += t * sin(heading);
        poses[3 * j + 2] += r1 + r2;
    }
}

/* Nav2 AMCL's likelihood-field distances (map_update_cspace): every occupied cell starts at 0 in a
   priority queue (a binary heap kept as libstdc++'s std::priority_queue keeps it: push_heap and
   pop_heap, smallest distance on top), pushed column by column; while the queue is not empty the
   top cell's four neighbours (x - 1, y - 1, x + 1, y + 1) not yet reached take the distance in cells
   from the top cell's source (sqrt(dx^2 + dy^2), if it is at most int(max_dist / scale)) times
   scale and join the queue, then the top is popped (whichever cell is on top by then). Cells never
   reached keep max_dist. occupied and out are row-major (row = y). Returns -1 when memory runs out. */
typedef struct { double key; int i, j, si, sj; } twin_cell;

static void cell_push(twin_cell *h, long hole, long top, twin_cell v) {   /* std::__push_heap */
    long parent = (hole - 1) / 2;
    while (hole > top && h[parent].key > v.key) { h[hole] = h[parent]; hole = parent; parent = (hole - 1) / 2; }
    h[hole] = v;
}

static void cell_pop(twin_cell *h, long len) {   /* std::pop_heap: __pop_heap then __adjust_heap */
    if (len < 2) return;
    long last = len - 1;
    twin_cell v = h[last];
    h[last] = h[0];
    long n = last, hole = 0, child = 0;
    while (child < (n - 1) / 2) {
        child = 2 * (child + 1);
        if (h[child].key > h[child - 1].key) child--;   /* comp(right, left): right is "less" */
        h[hole] = h[child];
        hole = child;
    }
    if ((n & 1) == 0 && child == (n - 2) / 2) {
        child = 2 * (child + 1);
        h[hole] = h[child - 1];
        hole = child - 1;
    }
    cell_push(h, hole, 0, v);
}

int twin_amcl_distances(const unsigned char *occupied, long width, long height, double scale, double max_dist,
                        double *out) {
    long cells = width * height;
    int radius = (int)(max_dist / scale);
    unsigned char *marked = calloc((size_t)(cells > 0 ? cells : 1), 1);
    twin_cell *heap = malloc(sizeof(twin_cell) * (size_t)(cells > 0 ? cells : 1));
    double *table = malloc(sizeof(double) * (size_t)(radius + 2) * (size_t)(radius + 2));
    if (!marked || !heap || !table) { free(marked); free(heap); free(table); return -1; }
    for (int a = 0; a <= radius + 1; ++a)
        for (int b = 0; b <= radius + 1; ++b) table[a * (radius + 2) + b] = sqrt((double)(a * a + b * b));
    long len = 0;
    for (long i = 0; i < width; ++i) {
        for (long j = 0; j < height; ++j) {
            long k = j * width + i;
            if (occupied[k]) {
                out[k] = 0.0;
                marked[k] = 1;
                twin_cell c = {0.0, (int)i, (int)j, (int)i, (int)j};
                cell_push(heap, len++, 0, c);
            } else {
                out[k] = max_dist;
            }
        }
    }
    while (len > 0) {
        twin_cell cur = heap[0];
        for (int nb = 0; nb < 4; ++nb) {
            long i = cur.i + (nb == 0 ? -1 : nb == 2 ? 1 : 0), j = cur.j + (nb == 1 ? -1 : nb == 3 ? 1 : 0);
            if (i < 0 || j < 0 || i >= width || j >= height) continue;
            long k = j * width + i;
            if (marked[k]) continue;
            long di = i > cur.si ? i - cur.si : cur.si - i, dj = j > cur.sj ? j - cur.sj : cur.sj - j;
            double d = table[di * (radius + 2) + dj];
            if (d > radius) continue;
            out[k] = d * scale;
            twin_cell c = {out[k], (int)i, (int)j, cur.si, cur.sj};
            cell_push(heap, len++, 0, c);
            marked[k] = 1;
        }
        cell_pop(heap, len--);
    }
    free(marked); free(heap); free(table);
    return 0;
}

/* KLD-sampling's stop (pf_update_resample): particles are taken in order, each counted into its
   (x, y, yaw) histogram bin (keys, 3 per particle); the count stops at the first n with
   n > limit[k], k the bins occupied by the first n. Returns n (m when it never stops), or -1 when
   memory runs out. */
long twin_kld_count(const long *keys, long m, const double *limit) {
    long size = 1;
    while (size < 2 * m + 2) size <<= 1;
    long *table = malloc(sizeof(long) * 3 * (size_t)size);
    char *used = calloc((size_t)size, 1);
    if (!table || !used) { free(table); free(used); return -1; }
    long k = 0, n = m;
    for (long i = 0; i < m; ++i) {
        const long *key = keys + 3 * i;
        unsigned long h = (unsigned long)key[0] * 73856093UL ^ (unsigned long)key[1] * 19349663UL
                          ^ (unsigned long)key[2] * 83492791UL;
        long slot = (long)(h & (unsigned long)(size - 1));
        for (;;) {
            if (!used[slot]) {
                used[slot] = 1;
                table[3 * slot] = key[0]; table[3 * slot + 1] = key[1]; table[3 * slot + 2] = key[2];
                ++k;
                break;
            }
            if (table[3 * slot] == key[0] && table[3 * slot + 1] == key[1] && table[3 * slot + 2] == key[2]) break;
            slot = (slot + 1) & (size - 1);
        }
        if ((double)(i + 1) > limit[k]) { n = i + 1; break; }
    }
    free(table); free(used);
    return n;
}

/* pf_update_resample without recovery draws: sample j is the particle whose cumulative weight
   first exceeds u[j] (numpy's searchsorted, side right, capped at n - 1), counted into its
   histogram bin (floor of pose / bin_size), until the count exceeds limit[bins] as in
   twin_kld_count. Writes the kept poses to out; returns their number, or -1 when memory runs out. */
long twin_pf_resample(const double *poses, long n, const double *cumulative, const double *u, long m,
                      const double *bin_size, const double *limit, double *out) {
    long size = 1;
    while (size < 2 * m + 2) size <<= 1;
    long *table = malloc(sizeof(long) * 3 * (size_t)size);
    char *used = calloc((size_t)size, 1);
    if (!table || !used) { free(table); free(used); return -1; }
    long k = 0, kept = m;
    for (long j = 0; j < m; ++j) {
        double v = u[j];
        const double *b = cumulative;   /* branch-free search: the count of cumulative values <= v */
        long len = n;
        while (len > 1) {
            long half = len >> 1;
            b += (b[half] <= v) ? half : 0;
            len -= half;
        }
        long lo = (long)(b - cumulative) + (*b <= v);
        if (lo > n - 1) lo = n - 1;
        const double *p = poses + 3 * lo;
        double *o = out + 3 * j;
        o[0] = p[0]; o[1] = p[1]; o[2] = p[2];
        long key0 = (long)floor(p[0] / bin_size[0]), key1 = (long)floor(p[1] / bin_size[1]);
        long key2 = (long)floor(p[2] / bin_size[2]);
        unsigned long h = (unsigned long)key0 * 73856093UL ^ (unsigned long)key1 * 19349663UL
                          ^ (unsigned long)key2 * 83492791UL;
        long slot = (long)(h & (unsigned long)(size - 1));
        for (;;) {
            if (!used[slot]) {
                used[slot] = 1;
                table[3 * slot] = key0; table[3 * slot + 1] = key1; table[3 * slot + 2] = key2;
                ++k;
                break;
            }
            if (table[3 * slot] == key0 && table[3 * slot + 1] == key1 && table[3 * slot + 2] == key2) break;
            slot = (slot + 1) & (size - 1);
        }
        if ((double)(j + 1) > limit[k]) { kept = j + 1; break; }
    }
    free(table); free(used);
    return kept;
}

/* AMCL's estimate from clustered particles (label from twin_pf_clusters, 1..count): the heaviest
   cluster's weighted mean (x, y, and yaw as atan2 of the weighted sines and cosines; the first
   cluster of the largest weight), then the whole set's weighted x, y covariance and circular
   yaw variance -2 ln R. Sums run in particle order. out: x, y, yaw, var x, var y, cov xy, var yaw.
   Returns -1 when memory runs out. */
int twin_pf_estimate(const double *poses, const double *w, long n, const long *label, long count, double *out) {
    double *cw = calloc((size_t)(count + 1), sizeof(double));
    if (!cw) return -1;
    for (long i = 0; i < n; ++i) cw[label[i]] += w[i];
    long best = 0;
    for (long c = 1; c <= count; ++c) if (cw[c] > cw[best]) best = c;
    double tw = 0.0, tx = 0.0, ty = 0.0, tc = 0.0, ts = 0.0;
    double sw = 0.0, sx = 0.0, sy = 0.0, sxx = 0.0, syy = 0.0, sxy = 0.0, sc = 0.0, ss = 0.0;
    for (long i = 0; i < n; ++i) {
        double x = poses[3 * i], y = poses[3 * i + 1], c = cos(poses[3 * i + 2]), s = sin(poses[3 * i + 2]);
        double wi = w[i];
        if (label[i] == best) { tw += wi; tx += wi * x; ty += wi * y; tc += wi * c; ts += wi * s; }
        sw += wi; sx += wi * x; sy += wi * y; sxx += wi * x * x; syy += wi * y * y; sxy += wi * x * y;
        sc += wi * c; ss += wi * s;
    }
    free(cw);
    out[0] = tx / tw;
    out[1] = ty / tw;
    out[2] = atan2(ts, tc);
    double mx = sx / sw, my = sy / sw;
    out[3] = sxx / sw - mx * mx;
    out[4] = syy / sw - my * my;
    out[5] = sxy / sw - mx * my;
    double r = hypot(sc / sw, ss / sw);
    out[6] = -2.0 * log(r > 1e-300 ? r : 1e-300);
    return 0;
}

static int leaf_cmp(const void *a, const void *b) {
    const long *x = a, *y = b;   /* (x, y, yaw, leaf) */
    for (int d = 0; d < 3; ++d) if (x[d] != y[d]) return x[d] < y[d] ? -1 : 1;
    return 0;
}

/* pf_kdtree_cluster: the occupied histogram bins (keys, 3 per particle) joined when they touch
   (26-neighbourhood); label[i] is particle i's cluster, numbered from 1 in the order of each
   cluster's smallest bin (x, then y, then yaw). Returns the number of clusters, or -1 when memory
   runs out. */
long twin_pf_clusters(const long *keys, long n, long *label) {
    long size = 1;
    while (size < 2 * n + 2) size <<= 1;
    long cap = n > 0 ? n : 1;
    long *slots = malloc(sizeof(long) * (size_t)size);
    long *leaf_of = malloc(sizeof(long) * (size_t)cap);
    long *leaves = malloc(sizeof(long) * 4 * (size_t)cap);   /* key, then the leaf's first-seen index */
    long *leaf_label = calloc((size_t)cap, sizeof(long));
    long *stack = malloc(sizeof(long) * (size_t)cap);
    long *keyed = malloc(sizeof(long) * 3 * (size_t)cap);    /* leaf keys by first-seen index */
    if (!slots || !leaf_of || !leaves || !leaf_label || !stack || !keyed) {
        free(slots); free(leaf_of); free(leaves); free(leaf_label); free(stack); free(keyed);
        return -1;
    }
    for (long i = 0; i < size; ++i) slots[i] = -1;
#define TWIN_HASH(a, b, c) ((long)(((unsigned long)(a) * 73856093UL ^ (unsigned long)(b) * 19349663UL \
                                    ^ (unsigned long)(c) * 83492791UL) & (unsigned long)(size - 1)))
    long nl = 0;
    for (long i = 0; i < n; ++i) {
        const long *key = keys + 3 * i;
        long slot = TWIN_HASH(key[0], key[1], key[2]);
        for (;;) {
            long o = slots[slot];
            if (o < 0) {
                slots[slot] = nl;
                keyed[3 * nl] = key[0]; keyed[3 * nl + 1] = key[1]; keyed[3 * nl + 2] = key[2];
                leaf_of[i] = nl++;
                break;
            }
            if (keyed[3 * o] == key[0] && keyed[3 * o + 1] == key[1] && keyed[3 * o + 2] == key[2]) {
                leaf_of[i] = o;
                break;
            }
            slot = (slot + 1) & (size - 1);
        }
    }
    for (long l = 0; l < nl; ++l) {
        leaves[4 * l] = keyed[3 * l]; leaves[4 * l + 1] = keyed[3 * l + 1]; leaves[4 * l + 2] = keyed[3 * l + 2];
        leaves[4 * l + 3] = l;
    }
    qsort(leaves, (size_t)nl, 4 * sizeof(long), leaf_cmp);
    long clusters = 0;
    for (long r = 0; r < nl; ++r) {   /* leaves in raster order; leaf_label indexed by first-seen index */
        long l = leaves[4 * r + 3];
        if (leaf_label[l]) continue;
        leaf_label[l] = ++clusters;
        long top = 0;
        stack[top++] = l;
        while (top) {
            long q = stack[--top];
            for (long dx = -1; dx <= 1; ++dx)
                for (long dy = -1; dy <= 1; ++dy)
                    for (long da = -1; da <= 1; ++da) {
                        long a = keyed[3 * q] + dx, b = keyed[3 * q + 1] + dy, c = keyed[3 * q + 2] + da;
                        long slot = TWIN_HASH(a, b, c);
                        while (slots[slot] >= 0) {
                            long o = slots[slot];
                            if (keyed[3 * o] == a && keyed[3 * o + 1] == b && keyed[3 * o + 2] == c) {
                                if (!leaf_label[o]) { leaf_label[o] = clusters; stack[top++] = o; }
                                break;
                            }
                            slot = (slot + 1) & (size - 1);
                        }
                    }
        }
    }
#undef TWIN_HASH
    for (long i = 0; i < n; ++i) label[i] = leaf_label[leaf_of[i]];
    free(slots); free(leaf_of); free(leaves); free(leaf_label); free(stack); free(keyed);
    return clusters;
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
        /* the cells written form one run along the ray (a monotone line crosses the grid once), so
           its first and last cell bound them all */
        long fx = 0, fy = 0, lx = 0, ly = 0;
        int any = 0;
        for (long i = 0; i <= end; ++i) {
            if ((unsigned long)cy < (unsigned long)rows && (unsigned long)cx < (unsigned long)cols) {
                cost[cy * cols + cx] = value;
                if (!any) { fx = cx; fy = cy; any = 1; }
                lx = cx; ly = cy;
            }
            error += db;
            long step = error >= da;   /* the minor axis steps: no branch on it */
            cx += sa_x + (step ? sb_x : 0);
            cy += sa_y + (step ? sb_y : 0);
            error -= step ? da : 0;
        }
        if (any) {
            long rlo = fy < ly ? fy : ly, rhi = fy < ly ? ly : fy, clo = fx < lx ? fx : lx, chi = fx < lx ? lx : fx;
            if (rlo < bounds[0]) bounds[0] = rlo;
            if (rhi > bounds[1]) bounds[1] = rhi;
            if (clo < bounds[2]) bounds[2] = clo;
            if (chi > bounds[3]) bounds[3] = chi;
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

/* twin_obstacle_update for a LaserScan: beam i (range r, direction cos_a[i], sin_a[i] in the sensor
   frame) gives the point (sx + r (c cos_a - s sin_a), sy + r (s cos_a + c sin_a)) when
   range_min <= r < range_max, as scan_observation projects it (the same roundings); then the
   points are cleared and marked as twin_obstacle_update does. Returns -1 when memory runs out. */
int twin_scan_update(unsigned char *cost, long rows, long cols, double gx, double gy, double res,
                     const double *ranges, long n, const double *cos_a, const double *sin_a,
                     double range_min, double range_max, double sx, double sy, double c, double s,
                     int clearing, int marking, double ray_max_cells, double ray_min_cells,
                     double mark_max_m, double mark_min_m, long *bounds) {
    double *pts = malloc(2 * sizeof(double) * (size_t)(n > 0 ? n : 1));
    if (!pts) return -1;
    long m = 0;
    for (long i = 0; i < n; ++i) {
        double r = ranges[i];
        if (r >= range_min && r < range_max) {
            double ca = cos_a[i], sa = sin_a[i];
            pts[2 * m] = sx + r * (c * ca - s * sa);
            pts[2 * m + 1] = sy + r * (s * ca + c * sa);
            ++m;
        }
    }
    twin_obstacle_update(cost, rows, cols, gx, gy, res, sx, sy, pts, m, clearing, marking, ray_max_cells,
                         ray_min_cells, mark_max_m, mark_min_m, bounds);
    free(pts);
    return 0;
}

/* The inflation of twin_costmap_compose with squared distances of type T (`far`: no seed in reach).
   Loops are written without data-dependent branches, so the compiler can vectorise them. */
#define TWIN_INFLATE(T, far_value)                                                                   \
    do {                                                                                             \
        const T far = far_value;                                                                     \
        T *gt = (T *)g, *bt = (T *)best;                                                             \
        for (long r = 0; r < er; ++r) {                                                              \
            const unsigned char *row = pre + r * ec;                                                 \
            long last = -(radius + 1);                                                               \
            for (long c = 0; c < ec; ++c) { /* distance to the nearest seed at or left of c */       \
                last = seed(row[c], around_unknown) ? c : last;                                      \
                span[c] = c - last;                                                                  \
            }                                                                                        \
            last = ec + radius + 1;                                                                  \
            for (long c = ec - 1; c >= 0; --c) { /* or right of it */                                \
                last = seed(row[c], around_unknown) ? c : last;                                      \
                long d = last - c;                                                                   \
                span[c] = d < span[c] ? d : span[c];                                                 \
            }                                                                                        \
            T *gr = gt + r * wc;                                                                     \
            const long *sp = span + (v0 - f0);                                                       \
            for (long x = 0; x < wc; ++x) gr[x] = sp[x] <= radius ? (T)(sp[x] * sp[x]) : far;        \
        }                                                                                            \
        for (long r = w0; r < w1; ++r) {                                                             \
            for (long x = 0; x < wc; ++x) bt[x] = far;                                               \
            long lo = r - radius < e0 ? e0 : r - radius, hi = r + radius >= e1 ? e1 - 1 : r + radius; \
            for (long q = lo; q <= hi; ++q) {                                                        \
                T add = (T)((q - r) * (q - r));                                                      \
                const T *gq = gt + (q - e0) * wc;                                                    \
                for (long x = 0; x < wc; ++x) {                                                      \
                    T v = (T)(gq[x] + add);                                                          \
                    bt[x] = v < bt[x] ? v : bt[x];                                                   \
                }                                                                                    \
            }                                                                                        \
            const unsigned char *prow = pre + (r - e0) * ec + (v0 - f0);                             \
            unsigned char *out = master + r * cols + v0;                                             \
            for (long x = 0; x < wc; ++x) costs[x] = table[bt[x] <= r2 ? bt[x] : r2 + 1];            \
            for (long x = 0; x < wc; ++x) {                                                          \
                unsigned char cost = costs[x], old = prow[x];                                        \
                unsigned char raised = cost > old ? cost : old;                                      \
                unsigned char unknown = (inflate_unknown ? cost > 0 : cost >= 253) ? cost : old;     \
                out[x] = old == 255 ? unknown : raised;                                              \
            }                                                                                        \
        }                                                                                            \
    } while (0)

static inline int seed(unsigned char v, int around_unknown) {
    return (v == 254) | (around_unknown & (v == 255));
}

/* One costmap update's master cells over the window W = rows [w0, w1) x cols [v0, v1) of a
   rows x cols grid, from the cells of E = rows [e0, e1) x cols [f0, f1) (W grown by the inflation
   radius, so that every obstacle reaching W lies in E):
   - layers: `base` (the static layer; NULL: every cell `fill`) overlaid by each obstacle layer,
     whose known cells (not 255) replace an unknown master cell or raise a lower one;
   - inflation (when `inflate`): d2, the squared distance in cells from a cell of W to the nearest
     seed of E (a cell of 254, or also 255 with `around_unknown`), exact: per row the distance to the
     nearest seed in that row, then the minimum over rows within `radius` of (row distance^2 +
     row offset^2); the cost is table[d2] for d2 <= radius^2 (table holds radius^2 + 2 values, the
     last 0), else 0; an unknown cell takes it only when it is >= 253 (> 0 with
     `inflate_unknown`), any other cell the larger of the two.
   master is written in W only. Returns -1 when memory runs out. */
int twin_costmap_compose(const unsigned char *base, unsigned char fill, const unsigned char *const *layers,
                         long n_layers, long rows, long cols, long w0, long w1, long v0, long v1,
                         long e0, long e1, long f0, long f1, int inflate, long radius,
                         const unsigned char *table, int inflate_unknown, int around_unknown,
                         unsigned char *master) {
    (void)rows;
    long er = e1 - e0, ec = f1 - f0, wc = v1 - v0;
    if (er <= 0 || ec <= 0 || wc <= 0 || w1 <= w0) return 0;
    unsigned char *pre = malloc((size_t)(er * ec) + (size_t)wc);
    void *g = inflate ? malloc(sizeof(int) * (size_t)(er * wc)) : NULL;
    void *best = inflate ? malloc(sizeof(int) * (size_t)wc) : NULL;
    long *span = inflate ? malloc(sizeof(long) * (size_t)ec) : NULL;
    if (!pre || (inflate && (!g || !best || !span))) { free(pre); free(g); free(best); free(span); return -1; }
    unsigned char *costs = pre + er * ec;
    for (long r = 0; r < er; ++r) {
        unsigned char *row = pre + r * ec;
        if (base) {
            const unsigned char *b = base + (e0 + r) * cols + f0;
            for (long c = 0; c < ec; ++c) row[c] = b[c];
        } else {
            for (long c = 0; c < ec; ++c) row[c] = fill;
        }
        for (long l = 0; l < n_layers; ++l) {
            const unsigned char *o = layers[l] + (e0 + r) * cols + f0;
            for (long c = 0; c < ec; ++c) {
                unsigned char v = o[c], m = row[c];
                row[c] = (v != 255 && (m == 255 || m < v)) ? v : m;
            }
        }
    }
    if (!inflate) {
        for (long r = w0; r < w1; ++r)
            for (long c = v0; c < v1; ++c) master[r * cols + c] = pre[(r - e0) * ec + (c - f0)];
        free(pre);
        return 0;
    }
    /* squared distances as 16-bit integers (the vector minimum takes 8 at a time), or as 32-bit ones
       for radii over 127 cells; `far` (no seed within the radius) plus any row offset stays in range */
    long r2 = radius * radius;
    if (radius <= 127) {
        TWIN_INFLATE(short, (short)(32767 - r2));
    } else {
        TWIN_INFLATE(int, (int)(2147483647L - r2));
    }
    free(pre); free(g); free(best); free(span);
    return 0;
}

/* Set the cells whose centres lie inside a polygon (even-odd) to `value`; bounds grow as in raytrace.
   Returns -1 when memory runs out. */
int twin_fill_polygon(unsigned char *cost, long rows, long cols, double ox, double oy, double res,
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
    double *cross = malloc(sizeof(double) * (size_t)(n > 0 ? n : 1));
    if (!cross) return -1;
    for (long r = r0; r < r1; ++r) {
        double y = oy + (r + 0.5) * res;
        long m = 0;   /* where the row's centre line crosses the edges (once per row, not per cell) */
        for (long i = 0; i < n; ++i) {
            double x1 = poly[2 * i], y1 = poly[2 * i + 1];
            double x2 = poly[2 * ((i + 1) % n)], y2 = poly[2 * ((i + 1) % n) + 1];
            if ((y1 > y) != (y2 > y)) cross[m++] = x1 + (y - y1) * (x2 - x1) / (y2 - y1);
        }
        for (long c = c0; c < c1; ++c) {
            double x = ox + (c + 0.5) * res;
            int inside = 0;
            for (long i = 0; i < m; ++i) inside ^= x < cross[i];
            if (inside) {
                cost[r * cols + c] = value;
                if (r < bounds[0]) bounds[0] = r;
                if (r > bounds[1]) bounds[1] = r;
                if (c < bounds[2]) bounds[2] = c;
                if (c > bounds[3]) bounds[3] = c;
            }
        }
    }
    free(cross);
    return 0;
}


/* The footprint (fp: n points in the robot frame) placed at (x, y) with heading cos c, sin s
   (x + c fx - s fy, y + s fx + c fy), filled with `value` as twin_fill_polygon does. Returns -1
   when memory runs out. */
int twin_fill_footprint(unsigned char *cost, long rows, long cols, double ox, double oy, double res,
                        const double *fp, long n, double x, double y, double c, double s,
                        unsigned char value, long *bounds) {
    if (n < 1) return 0;
    double *poly = malloc(2 * sizeof(double) * (size_t)n);
    if (!poly) return -1;
    for (long i = 0; i < n; ++i) {
        poly[2 * i] = x + c * fp[2 * i] - s * fp[2 * i + 1];
        poly[2 * i + 1] = y + s * fp[2 * i] + c * fp[2 * i + 1];
    }
    int status = twin_fill_polygon(cost, rows, cols, ox, oy, res, poly, n, value, bounds);
    free(poly);
    return status;
}

/* One whole costmap update for the common case, in one call: a single obstacle layer fed a single
   LaserScan source that both clears and marks (twin_scan_update), then its footprint cleared
   (twin_fill_footprint), then the master composed (twin_costmap_compose) over everything when
   `full`, else over the cells written grown by `pad` (twice: the window, then its obstacles).
   d: gx, gy, res, range_min, range_max, sx, sy, c, s, ray_max_cells, ray_min_cells, mark_max_m,
      mark_min_m, robot x, robot y, robot cos, robot sin;
   k: rows, cols, ranges, footprint points, fill, full, inflate, radius, inflate_unknown,
      around_unknown, pad.
   bounds (4) receives the cells written. Returns -1 when memory runs out. */
int twin_costmap_scan_update(unsigned char *layer, const unsigned char *base, unsigned char *master,
                             const unsigned char *table, const double *ranges, const double *cos_a,
                             const double *sin_a, const double *footprint, const double *d, const long *k,
                             long *bounds) {
    long rows = k[0], cols = k[1];
    bounds[0] = rows; bounds[1] = -1; bounds[2] = cols; bounds[3] = -1;
    if (twin_scan_update(layer, rows, cols, d[0], d[1], d[2], ranges, k[2], cos_a, sin_a, d[3], d[4], d[5], d[6],
                         d[7], d[8], 1, 1, d[9], d[10], d[11], d[12], bounds))
        return -1;
    if (k[3] > 0 && twin_fill_footprint(layer, rows, cols, d[0], d[1], d[2], footprint, k[3], d[13], d[14], d[15],
                                        d[16], 0, bounds))
        return -1;
    long r0, r1, c0, c1;
    if (k[5]) { r0 = 0; r1 = rows; c0 = 0; c1 = cols; }
    else if (bounds[1] < 0) return 0;
    else { r0 = bounds[0]; r1 = bounds[1] + 1; c0 = bounds[2]; c1 = bounds[3] + 1; }
    long pad = k[10];
    long w0 = r0 - pad < 0 ? 0 : r0 - pad, w1 = r1 + pad > rows ? rows : r1 + pad;
    long v0 = c0 - pad < 0 ? 0 : c0 - pad, v1 = c1 + pad > cols ? cols : c1 + pad;
    long e0 = w0 - pad < 0 ? 0 : w0 - pad, e1 = w1 + pad > rows ? rows : w1 + pad;
    long f0 = v0 - pad < 0 ? 0 : v0 - pad, f1 = v1 + pad > cols ? cols : v1 + pad;
    const unsigned char *layers[1] = {layer};
    return twin_costmap_compose(base, (unsigned char)k[4], layers, 1, rows, cols, w0, w1, v0, v1, e0, e1, f0, f1,
                                (int)k[6], k[7], table, (int)k[8], (int)k[9], master);
}

/* The 4-connected region of cells not `blocked` holding cell `start` (row-major index): region[i] = 1.
   Returns the region's size, or -1 when memory runs out. */
long twin_flood_fill(const unsigned char *blocked, long rows, long cols, long start, unsigned char *region) {
    long n = rows * cols, size = 0, top = 0;
    for (long i = 0; i < n; ++i) region[i] = 0;
    if (start < 0 || start >= n || blocked[start]) return 0;
    long *stack = malloc(sizeof(long) * (size_t)n);
    if (!stack) return -1;
    region[start] = 1;
    stack[top++] = start;
    while (top > 0) {
        long c = stack[--top];
        size++;
        long r = c / cols, k = c % cols;
        long next[4] = {r > 0 ? c - cols : -1, r < rows - 1 ? c + cols : -1,
                        k > 0 ? c - 1 : -1, k < cols - 1 ? c + 1 : -1};
        for (int j = 0; j < 4; ++j) {
            long m = next[j];
            if (m >= 0 && !blocked[m] && !region[m]) {
                region[m] = 1;
                stack[top++] = m;
            }
        }
    }
    free(stack);
    return size;
}

/* Nav2's FootprintCollisionChecker::footprintCost: the highest cost (uint8 grid, row-major rows x cols)
   on the edges of the footprint (fx, fy: n points in the robot's frame) at pose (x, y, yaw), each
   edge walked as nav2_util's LineIterator (Bresenham) walks it: a line's cost is 254 (lethal) at its
   first lethal cell, and the walk stops when the running maximum is lethal (an unknown 255 seen on an
   earlier edge outranks it, as in Nav2); 254 for a footprint point off the grid. Same arithmetic as
   behaviors.footprint_cost_py. */
int twin_footprint_cost(const unsigned char *cost, long rows, long cols, double ox, double oy, double res,
                        const double *fx, const double *fy, long n, double x, double y, double yaw) {
    enum { LETHAL = 254 };
    double c = cos(yaw), s = sin(yaw);
    long mxs[64], mys[64];
    if (n <= 0 || n > 64) return -1;
    for (long i = 0; i < n; ++i) {
        double wx = x + c * fx[i] - s * fy[i];
        double wy = y + s * fx[i] + c * fy[i];
        if (wx < ox || wy < oy) return LETHAL;
        long mx = (long)((wx - ox) / res), my = (long)((wy - oy) / res);
        if (mx >= cols || my >= rows) return LETHAL;
        mxs[i] = mx;
        mys[i] = my;
    }
    int worst = 0;
    for (long i = 0; i < n; ++i) {
        long x0 = mxs[i], y0 = mys[i], x1 = mxs[(i + 1) % n], y1 = mys[(i + 1) % n];
        long dx = labs(x1 - x0), dy = labs(y1 - y0);
        long sx = x1 >= x0 ? 1 : -1, sy = y1 >= y0 ? 1 : -1;
        int straight = dx >= dy;
        long den = straight ? dx : dy, num = den / 2, add = straight ? dy : dx, pixels = den;
        long cx = x0, cy = y0;
        int line = 0;
        for (long k = 0; k <= pixels; ++k) {
            int v = cost[cy * cols + cx];
            if (v == LETHAL) { line = LETHAL; break; }  /* the line's cost; unknown (255) seen before stays */
            if (v > line) line = v;
            num += add;
            if (num >= den) {
                num -= den;
                if (straight) cy += sy; else cx += sx;
            }
            if (straight) cx += sx; else cy += sy;
        }
        if (line > worst) worst = line;
        if (worst == LETHAL) return LETHAL;
    }
    return worst;
}
"""


@functools.cache
def load_kernel() -> ctypes.CDLL | None:
    """Return the compiled kernels, building them on first use; None if unavailable."""
    lib = load_library(CLibrary(name="nav_loc", source=_SOURCE, flags=_FLAGS), keep_gil=True)
    if lib is None:
        return None
    ptr, long_, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    lib.twin_amcl_likelihood.restype = ctypes.c_int
    lib.twin_amcl_likelihood.argtypes = [ptr, long_, dbl, dbl, dbl, ptr, ptr, long_, ptr, long_, long_, dbl, ptr]
    lib.twin_amcl_motion.restype = None
    lib.twin_amcl_motion.argtypes = [ptr, long_, ptr, dbl, dbl, dbl, dbl, dbl, dbl]
    lib.twin_amcl_distances.restype = ctypes.c_int
    lib.twin_amcl_distances.argtypes = [ptr, long_, long_, dbl, dbl, ptr]
    lib.twin_kld_count.restype = long_
    lib.twin_kld_count.argtypes = [ptr, long_, ptr]
    lib.twin_pf_clusters.restype = long_
    lib.twin_pf_clusters.argtypes = [ptr, long_, ptr]
    lib.twin_pf_resample.restype = long_
    lib.twin_pf_resample.argtypes = [ptr, long_, ptr, ptr, long_, ptr, ptr, ptr]
    lib.twin_pf_estimate.restype = ctypes.c_int
    lib.twin_pf_estimate.argtypes = [ptr, ptr, long_, ptr, long_, ptr]
    lib.twin_raytrace.restype = None
    lib.twin_raytrace.argtypes = [
        ptr, long_, long_, long_, long_, ptr, ptr, long_, dbl, dbl, ctypes.c_ubyte, ptr,
    ]  # fmt: skip
    lib.twin_obstacle_update.restype = None
    lib.twin_obstacle_update.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, dbl, dbl, ptr, long_, ctypes.c_int, ctypes.c_int,
        dbl, dbl, dbl, dbl, ptr,
    ]  # fmt: skip
    lib.twin_costmap_compose.restype = ctypes.c_int
    lib.twin_costmap_compose.argtypes = [
        ptr, ctypes.c_ubyte, ptr, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_, long_,
        ctypes.c_int, long_, ptr, ctypes.c_int, ctypes.c_int, ptr,
    ]  # fmt: skip
    lib.twin_scan_update.restype = ctypes.c_int
    lib.twin_scan_update.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, ptr, long_, ptr, ptr, dbl, dbl, dbl, dbl, dbl, dbl,
        ctypes.c_int, ctypes.c_int, dbl, dbl, dbl, dbl, ptr,
    ]  # fmt: skip
    lib.twin_fill_footprint.restype = ctypes.c_int
    lib.twin_fill_footprint.argtypes = [
        ptr, long_, long_, dbl, dbl, dbl, ptr, long_, dbl, dbl, dbl, dbl, ctypes.c_ubyte, ptr,
    ]  # fmt: skip
    lib.twin_costmap_scan_update.restype = ctypes.c_int
    lib.twin_costmap_scan_update.argtypes = [ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr]
    lib.twin_flood_fill.restype = long_
    lib.twin_flood_fill.argtypes = [ptr, long_, long_, long_, ptr]
    lib.twin_footprint_cost.restype = ctypes.c_int
    lib.twin_footprint_cost.argtypes = [ptr, long_, long_, dbl, dbl, dbl, ptr, ptr, long_, dbl, dbl, dbl]
    lib.twin_fill_polygon.restype = ctypes.c_int
    lib.twin_fill_polygon.argtypes = [ptr, long_, long_, dbl, dbl, dbl, ptr, long_, ctypes.c_ubyte, ptr]
    return lib
