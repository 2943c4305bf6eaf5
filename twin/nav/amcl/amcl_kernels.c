/* nav2_amcl's hot loops in C (loaded by twin/nav/amcl/_native.py): the laser model, motion
   sampling, the likelihood field's distances, KLD-sampling, resampling, clusters and the estimate. */

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* Nav2's map lookup for one beam of one particle, as LikelihoodFieldModel::sensorFunction does it: the
   laser's pose in the map (pf_vector_coord_add of the laser's (lx, ly, 0) onto the particle), the
   endpoint lp + range (cos, sin)(lp yaw + bearing), and MAP_GXWX / MAP_GYWY with the map's origin at
   its centre cell (amcl_node's convertMap): floor((x - centre) / scale + 0.5) + size / 2. */
static void nav2_cell(const double *pose, double lx, double ly, double range, double bearing, double ox, double oy,
                      double scale, long rows, long cols, long *col, long *row) {
    double px = pose[0] + lx * cos(pose[2]) - ly * sin(pose[2]);
    double py = pose[1] + lx * sin(pose[2]) + ly * cos(pose[2]);
    double yaw = pose[2] + 0.0;
    yaw = atan2(sin(yaw), cos(yaw));
    double hx = px + range * cos(yaw + bearing), hy = py + range * sin(yaw + bearing);
    double cx = ox + (double)(cols / 2) * scale, cy = oy + (double)(rows / 2) * scale;
    *col = (long)(floor((hx - cx) / scale + 0.5) + (double)(cols / 2));
    *row = (long)(floor((hy - cy) / scale + 0.5) + (double)(rows / 2));
}

/* AMCL likelihood field: out[j] = 1 + pz^3 + pz^3 + ... over the beams' endpoints, in beam order, as Nav2
   adds them; cube[k] is map cell k's pz * pz * pz (taken once per cell in that order, the same bits as per
   beam), row-major, and cube[rows * cols] an endpoint's off the map. Particle j at poses[j] = (x, y, yaw) has
   the grid position gx = (x - ox) * inv_res + 0.5 (likewise gy) and heading cos, sin; beam i's endpoint in
   the base frame in cells is (ex, ey). The endpoint's cell is (floor(gx + c ex - s ey), floor(gy + s ex +
   c ey)), AMCL's rounding lookup; this differs from Nav2's arithmetic (nav2_cell) only in the last bits, so
   where it lands within 1e-6 of a cell edge the cell is taken Nav2's way from the beam's range and bearing
   and the laser's (lx, ly). Beam by beam over all particles: one beam's endpoints from a cluster of
   particles fall in a few neighbouring cells, which keeps the lookups in cache. On x86-64 each beam's cells
   are found four particles at a time with AVX2 (two with SSE2 where the CPU lacks it; no fused
   multiply-adds), the same operations in the same order, so the same bits, then looked up one by one.
   Returns -1 when memory runs out. */
#define TWIN_EDGE 1e-6

static long endpoint_cell(const double *pose, double gx, double gy, double c, double s, double bx, double by,
                          double lx, double ly, double range, double bearing, double ox, double oy, double scale,
                          long rows, long cols) {
    double fc = gx + c * bx - s * by;
    double fr = gy + s * bx + c * by;
    long col = (long)fc, row = (long)fr;   /* floor without a libm call: truncate, step down below 0 */
    col -= (double)col > fc;
    row -= (double)row > fr;
    double dc = fc - (double)col, dr = fr - (double)row;
    if (dc < TWIN_EDGE || dc > 1.0 - TWIN_EDGE || dr < TWIN_EDGE || dr > 1.0 - TWIN_EDGE)
        nav2_cell(pose, lx, ly, range, bearing, ox, oy, scale, rows, cols, &col, &row);
    return (col >= 0 && col < cols && row >= 0 && row < rows) ? row * cols + col : rows * cols;
}

#if defined(__SSE2__)
/* Each particle's endpoint cell for one beam (bx, by in cells), m particles (a multiple of 4): cell[j] is
   row * cols + col, rows * cols off the map, -1 within 1e-6 of a cell edge (or beyond an int, where
   the conversion gives INT_MIN and the fraction is far outside [0, 1)): there the caller takes Nav2's
   arithmetic. Two particles at a time; the AVX2 twin below four. The same operations in the same
   order as endpoint_cell, so the same bits. */
static void beam_cells_sse2(const double *gx, const double *gy, const double *c, const double *s, long m, double ex,
                            double ey, long rows, long cols, int *cell) {
    const __m128d one = _mm_set1_pd(1.0), lo = _mm_set1_pd(TWIN_EDGE), hi = _mm_set1_pd(1.0 - TWIN_EDGE);
    const __m128d zero = _mm_setzero_pd(), ncols = _mm_set1_pd((double)cols), nrows = _mm_set1_pd((double)rows);
    const __m128d outside = _mm_set1_pd((double)(rows * cols)), near_edge = _mm_set1_pd(-1.0);
    const __m128d bx = _mm_set1_pd(ex), by = _mm_set1_pd(ey);
    for (long j = 0; j < m; j += 2) {
        __m128d cj = _mm_loadu_pd(c + j), sj = _mm_loadu_pd(s + j);
        __m128d fc = _mm_sub_pd(_mm_add_pd(_mm_loadu_pd(gx + j), _mm_mul_pd(cj, bx)), _mm_mul_pd(sj, by));
        __m128d fr = _mm_add_pd(_mm_add_pd(_mm_loadu_pd(gy + j), _mm_mul_pd(sj, bx)), _mm_mul_pd(cj, by));
        __m128d tc = _mm_cvtepi32_pd(_mm_cvttpd_epi32(fc)), tr = _mm_cvtepi32_pd(_mm_cvttpd_epi32(fr));
        tc = _mm_sub_pd(tc, _mm_and_pd(_mm_cmpgt_pd(tc, fc), one));   /* floor */
        tr = _mm_sub_pd(tr, _mm_and_pd(_mm_cmpgt_pd(tr, fr), one));
        __m128d dc = _mm_sub_pd(fc, tc), dr = _mm_sub_pd(fr, tr);
        __m128d edge = _mm_or_pd(_mm_or_pd(_mm_cmplt_pd(dc, lo), _mm_cmpgt_pd(dc, hi)),
                                 _mm_or_pd(_mm_cmplt_pd(dr, lo), _mm_cmpgt_pd(dr, hi)));
        __m128d in = _mm_and_pd(_mm_and_pd(_mm_cmpge_pd(tc, zero), _mm_cmplt_pd(tc, ncols)),
                                _mm_and_pd(_mm_cmpge_pd(tr, zero), _mm_cmplt_pd(tr, nrows)));
        __m128d k = _mm_add_pd(_mm_mul_pd(tr, ncols), tc);
        k = _mm_or_pd(_mm_and_pd(in, k), _mm_andnot_pd(in, outside));
        k = _mm_or_pd(_mm_andnot_pd(edge, k), _mm_and_pd(edge, near_edge));
        _mm_storel_epi64((__m128i *)(cell + j), _mm_cvttpd_epi32(k));
    }
}
#endif

#if defined(__x86_64__) && defined(__GNUC__)
#define TWIN_AVX2 1
__attribute__((target("avx2"))) static void beam_cells_avx2(const double *gx, const double *gy, const double *c,
                                                           const double *s, long m, double ex, double ey, long rows,
                                                           long cols, int *cell) {
    const __m256d one = _mm256_set1_pd(1.0), lo = _mm256_set1_pd(TWIN_EDGE), hi = _mm256_set1_pd(1.0 - TWIN_EDGE);
    const __m256d zero = _mm256_setzero_pd(), ncols = _mm256_set1_pd((double)cols);
    const __m256d nrows = _mm256_set1_pd((double)rows);
    const __m256d outside = _mm256_set1_pd((double)(rows * cols)), near_edge = _mm256_set1_pd(-1.0);
    const __m256d bx = _mm256_set1_pd(ex), by = _mm256_set1_pd(ey);
    for (long j = 0; j < m; j += 4) {
        __m256d cj = _mm256_loadu_pd(c + j), sj = _mm256_loadu_pd(s + j);
        __m256d fc = _mm256_sub_pd(_mm256_add_pd(_mm256_loadu_pd(gx + j), _mm256_mul_pd(cj, bx)),
                                   _mm256_mul_pd(sj, by));
        __m256d fr = _mm256_add_pd(_mm256_add_pd(_mm256_loadu_pd(gy + j), _mm256_mul_pd(sj, bx)),
                                   _mm256_mul_pd(cj, by));
        __m256d tc = _mm256_cvtepi32_pd(_mm256_cvttpd_epi32(fc)), tr = _mm256_cvtepi32_pd(_mm256_cvttpd_epi32(fr));
        tc = _mm256_sub_pd(tc, _mm256_and_pd(_mm256_cmp_pd(tc, fc, _CMP_GT_OQ), one));   /* floor */
        tr = _mm256_sub_pd(tr, _mm256_and_pd(_mm256_cmp_pd(tr, fr, _CMP_GT_OQ), one));
        __m256d dc = _mm256_sub_pd(fc, tc), dr = _mm256_sub_pd(fr, tr);
        __m256d edge = _mm256_or_pd(_mm256_or_pd(_mm256_cmp_pd(dc, lo, _CMP_LT_OQ), _mm256_cmp_pd(dc, hi, _CMP_GT_OQ)),
                                    _mm256_or_pd(_mm256_cmp_pd(dr, lo, _CMP_LT_OQ), _mm256_cmp_pd(dr, hi, _CMP_GT_OQ)));
        __m256d in = _mm256_and_pd(
            _mm256_and_pd(_mm256_cmp_pd(tc, zero, _CMP_GE_OQ), _mm256_cmp_pd(tc, ncols, _CMP_LT_OQ)),
            _mm256_and_pd(_mm256_cmp_pd(tr, zero, _CMP_GE_OQ), _mm256_cmp_pd(tr, nrows, _CMP_LT_OQ)));
        __m256d k = _mm256_add_pd(_mm256_mul_pd(tr, ncols), tc);
        k = _mm256_blendv_pd(outside, k, in);
        k = _mm256_blendv_pd(k, near_edge, edge);
        _mm_storeu_si128((__m128i *)(cell + j), _mm256_cvttpd_epi32(k));
    }
}
#endif

int twin_amcl_likelihood(const double *poses, long n, double ox, double oy, double inv_res,
                         const double *ex, const double *ey, const double *range, const double *bearing, long nb,
                         double lx, double ly, double scale, const double *cube, long rows, long cols, double *out) {
    long m = (n + 3) & ~3L;   /* padded to fours */
    double *buf = malloc(4 * sizeof(double) * (size_t)(m > 0 ? m : 4));
    int *cell = malloc(sizeof(int) * (size_t)(m > 0 ? m : 4));
    if (!buf || !cell) { free(buf); free(cell); return -1; }
    double *gx = buf, *gy = buf + m, *c = buf + 2 * m, *s = buf + 3 * m;
    for (long j = 0; j < n; ++j) {
        gx[j] = (poses[3 * j] - ox) * inv_res + 0.5;
        gy[j] = (poses[3 * j + 1] - oy) * inv_res + 0.5;
        c[j] = cos(poses[3 * j + 2]);
        s[j] = sin(poses[3 * j + 2]);
        out[j] = 1.0;
    }
    for (long j = n; j < m; ++j) { gx[j] = gy[j] = -1.0; c[j] = 1.0; s[j] = 0.0; }   /* the pad (never read) */
#if defined(__SSE2__)
    if (rows * cols < 1073741824L) {   /* cell numbers fit an int */
#if defined(TWIN_AVX2)
        int avx2 = __builtin_cpu_supports("avx2");
#endif
        for (long i = 0; i < nb; ++i) {
#if defined(TWIN_AVX2)
            if (avx2)
                beam_cells_avx2(gx, gy, c, s, m, ex[i], ey[i], rows, cols, cell);
            else
#endif
                beam_cells_sse2(gx, gy, c, s, m, ex[i], ey[i], rows, cols, cell);
            for (long j = 0; j < n; ++j) {
                long k = cell[j];
                if (k < 0)   /* near a cell edge: Nav2's arithmetic decides */
                    k = endpoint_cell(poses + 3 * j, gx[j], gy[j], c[j], s[j], ex[i], ey[i], lx, ly, range[i],
                                      bearing[i], ox, oy, scale, rows, cols);
                out[j] += cube[k];
            }
        }
        free(buf); free(cell);
        return 0;
    }
#endif
    for (long i = 0; i < nb; ++i)
        for (long j = 0; j < n; ++j)
            out[j] += cube[endpoint_cell(poses + 3 * j, gx[j], gy[j], c[j], s[j], ex[i], ey[i], lx, ly, range[i],
                                         bearing[i], ox, oy, scale, rows, cols)];
    free(buf); free(cell);
    return 0;
}

/* Nav2's angleutils::angle_diff(a, b) given a already folded (atan2(sin a, cos a), which does not
   change per particle): b folded the same way, then a - b the shorter way round. */
static double angle_diff_folded(double a, double b) {
    b = atan2(sin(b), cos(b));
    double d1 = a - b;
    double d2 = 2 * M_PI - fabs(d1);
    if (d1 > 0) d2 *= -1.0;
    return fabs(d1) < fabs(d2) ? d1 : d2;
}

/* The differential motion model's sampling (DifferentialMotionModel::odometryUpdate) given the
   standard normal draws (3 per particle): the rotations angle_diff(rot, sd z) (folded into [-pi, pi]),
   the translation trans - sd z, applied to each pose as Nav2 applies them; headings are not folded. */
void twin_amcl_motion(double *poses, long n, const double *noise, double rot1, double trans, double rot2,
                      double sd_rot1, double sd_trans, double sd_rot2) {
    double a1 = atan2(sin(rot1), cos(rot1)), a2 = atan2(sin(rot2), cos(rot2));
    for (long j = 0; j < n; ++j) {
        double r1 = angle_diff_folded(a1, sd_rot1 * noise[3 * j]);
        double t = trans - sd_trans * noise[3 * j + 1];
        double r2 = angle_diff_folded(a2, sd_rot2 * noise[3 * j + 2]);
        poses[3 * j] += t * cos(poses[3 * j + 2] + r1);
        poses[3 * j + 1] += t * sin(poses[3 * j + 2] + r1);
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

/* (long)floor(x) without a libm call (LONG_MIN where x is NaN or beyond a long, as the conversion gives). */
static inline long floor_long(double x) {
    long t = (long)x;
    return (t != LONG_MIN && (double)t > x) ? t - 1 : t;
}

/* Each particle's (x, y, yaw) histogram bin as pf_kdtree keys it: floor(pose / bin_size), 3 per particle. */
void twin_pf_keys(const double *poses, long n, const double *bin_size, long *keys) {
    for (long i = 0; i < 3 * n; i += 3) {
        keys[i] = floor_long(poses[i] / bin_size[0]);
        keys[i + 1] = floor_long(poses[i + 1] / bin_size[1]);
        keys[i + 2] = floor_long(poses[i + 2] / bin_size[2]);
    }
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
        long key0 = floor_long(p[0] / bin_size[0]), key1 = floor_long(p[1] / bin_size[1]);
        long key2 = floor_long(p[2] / bin_size[2]);
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

/* AMCL's estimate from clustered particles (label from twin_pf_clusters, 1..count), as pf_cluster_stats
   and amcl_node give it: the heaviest cluster's weighted mean (x, y, and yaw as atan2 of the weighted
   sines and cosines; the first cluster of the largest weight), then the whole set's weighted x, y
   covariance (sum w x x / sum w - mean x mean x, ...) and yaw variance -2 ln sqrt(C^2 + S^2), C and S
   the weighted sums of cosines and sines (not divided by the total weight, as Nav2). Sums run in
   particle order. out: x, y, yaw, var x, var y, cov xy (sum (w x) y), var yaw, cov yx (sum (w y) x).
   Returns -1 when memory runs out. */
int twin_pf_estimate(const double *poses, const double *w, long n, const long *label, long count, double *out) {
    double *cw = calloc((size_t)(count + 1), sizeof(double));
    if (!cw) return -1;
    for (long i = 0; i < n; ++i) cw[label[i]] += w[i];
    long best = 0;
    for (long c = 1; c <= count; ++c) if (cw[c] > cw[best]) best = c;
    double tw = 0.0, tx = 0.0, ty = 0.0, tc = 0.0, ts = 0.0;
    double sw = 0.0, sx = 0.0, sy = 0.0, sxx = 0.0, syy = 0.0, sxy = 0.0, syx = 0.0, sc = 0.0, ss = 0.0;
    for (long i = 0; i < n; ++i) {
        double x = poses[3 * i], y = poses[3 * i + 1], c = cos(poses[3 * i + 2]), s = sin(poses[3 * i + 2]);
        double wi = w[i];
        if (label[i] == best) { tw += wi; tx += wi * x; ty += wi * y; tc += wi * c; ts += wi * s; }
        sw += wi; sx += wi * x; sy += wi * y; sxx += wi * x * x; syy += wi * y * y; sxy += wi * x * y;
        syx += wi * y * x; sc += wi * c; ss += wi * s;
    }
    free(cw);
    out[0] = tx / tw;
    out[1] = ty / tw;
    out[2] = atan2(ts, tc);
    double mx = sx / sw, my = sy / sw;
    out[3] = sxx / sw - mx * mx;
    out[4] = syy / sw - my * my;
    out[5] = sxy / sw - mx * my;
    out[6] = -2 * log(sqrt(sc * sc + ss * ss));
    out[7] = syx / sw - my * mx;
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
