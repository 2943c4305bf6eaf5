/* nav2_costmap_2d's hot loops in C (loaded by twin/nav/costmap_2d/_native.py): ray tracing,
   marking, footprint clearing, the layers' composition with inflation, and the footprint's cost. */

#include <math.h>
#include <stdlib.h>

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

/* One entry of the inflation's wavefront: a cell and the obstacle it came from (grid coordinates),
   and the next entry of its queue. */
typedef struct { int x, y, sx, sy, next; } twin_wave_entry;

/* Nav2's InflationLayer::updateCosts over the window W = rows [w0, w1) x cols [v0, v1) of a rows x cols
   grid whose values before inflation, `pre`, are given over a box P = rows [p0, p0 + pr) x cols
   [q0, q0 + pc) holding W grown by `radius` cells (clipped to the grid).
   The wavefront as Nav2 runs it: every cell of W grown by `radius` (clipped) that is 254, or 255 with
   `around_unknown`, is its own source, queued in row-major order at distance 0; queues are taken by
   increasing squared distance, each first-in first-out; a cell is settled the first time it is taken
   and gets the cost of the distance to the obstacle it was queued from (table[|dx| * (radius + 1) +
   |dy|], dx along columns); then its four neighbours (left, down, right, up) not yet settled are queued
   with that same obstacle when within `radius` of it. An entry whose squared distance is below the
   queue being taken is lost (Nav2 appends it to a bin its loop has passed). A settled cell of W is
   written to master: an unknown (255) one takes the cost only when it is >= 253 (> 0 with
   `inflate_unknown`), any other cell the larger of the two.
   Nav2 queues a cell once per neighbour that reaches it; here an entry is not queued when the cell
   already waits in a queue at the same or a smaller distance: that earlier entry is taken first and
   settles the cell, so the later one would only be skipped (same cells, same order, fewer entries).
   Returns -1 when memory runs out. */
int twin_inflate(const unsigned char *pre, long p0, long q0, long pr, long pc, long rows, long cols,
                 long w0, long w1, long v0, long v1, long radius, const unsigned char *table,
                 int inflate_unknown, int around_unknown, unsigned char *master) {
    (void)pr;
    if (radius <= 0 || w1 <= w0 || v1 <= v0) return 0;
    long e0 = w0 - radius < 0 ? 0 : w0 - radius, e1 = w1 + radius > rows ? rows : w1 + radius;
    long f0 = v0 - radius < 0 ? 0 : v0 - radius, f1 = v1 + radius > cols ? cols : v1 + radius;
    /* The search stays in E. A cell is queued from a neighbour settled strictly nearer the same
       source, one step further from it along x or y: the chain from a source to a cell it settles
       runs monotonically away from the source, inside the box of the two. For a cell of W and a
       source of E that box lies in E, and so does every chain that decides which source settles a
       cell of E first. What Nav2 settles outside E never reaches W. */
    long s0 = e0, t0 = f0, sr = e1 - e0, sc = f1 - f0, r2 = radius * radius, width = radius + 1;
    long seeds = 0;
    for (long r = e0; r < e1; ++r) {
        const unsigned char *row = pre + (r - p0) * pc + (f0 - q0);
        for (long c = 0; c < f1 - f0; ++c) seeds += (row[c] == 254) | (around_unknown & (row[c] == 255));
    }
    if (seeds == 0) return 0;
    /* queued[cell of E]: the smallest squared distance the cell waits at (r2 + 1: none), -1 once
       settled. Each settled cell queues at most four entries: the pool holds seeds + 4 |E|. */
    long capacity = seeds + 4 * sr * sc;
    int *queued = malloc(sizeof(int) * (size_t)(sr * sc));
    twin_wave_entry *pool = malloc(sizeof(twin_wave_entry) * (size_t)capacity);
    int *head = malloc(sizeof(int) * (size_t)(2 * (r2 + 1)));
    if (!queued || !pool || !head) { free(queued); free(pool); free(head); return -1; }
    for (long i = 0; i < sr * sc; ++i) queued[i] = (int)(r2 + 1);
    int *tail = head + r2 + 1;
    for (long b = 0; b <= r2; ++b) head[b] = tail[b] = -1;
    long used = 0;
    for (long r = e0; r < e1; ++r) {
        const unsigned char *row = pre + (r - p0) * pc + (f0 - q0);
        for (long c = f0; c < f1; ++c) {
            unsigned char v = row[c - f0];
            if (!((v == 254) | (around_unknown & (v == 255)))) continue;
            twin_wave_entry *e = pool + used;
            e->x = (int)c; e->y = (int)r; e->sx = (int)c; e->sy = (int)r; e->next = -1;
            queued[(r - s0) * sc + (c - t0)] = 0;
            if (tail[0] < 0) head[0] = (int)used; else pool[tail[0]].next = (int)used;
            tail[0] = (int)used++;
        }
    }
    for (long b = 0; b <= r2; ++b) {
        for (int k = head[b]; k >= 0; k = pool[k].next) {
            long mx = pool[k].x, my = pool[k].y, sx = pool[k].sx, sy = pool[k].sy;
            int *state = queued + (my - s0) * sc + (mx - t0);
            if (*state < 0) continue;
            *state = -1;
            if (my >= w0 && my < w1 && mx >= v0 && mx < v1) {
                long dx = mx > sx ? mx - sx : sx - mx, dy = my > sy ? my - sy : sy - my;
                unsigned char cost = table[dx * width + dy];
                unsigned char old = pre[(my - p0) * pc + (mx - q0)];
                unsigned char *out = master + my * cols + mx;
                if (old == 255 && (inflate_unknown ? cost > 0 : cost >= 253)) *out = cost;
                else *out = cost > old ? cost : old;
            }
            /* the neighbours in Nav2's order: left, down, right, up */
            long nx[4] = {mx - 1, mx, mx + 1, mx}, ny[4] = {my, my - 1, my, my + 1};
            for (int n = 0; n < 4; ++n) {
                long x = nx[n], y = ny[n];
                if (x < f0 || y < e0 || x >= f1 || y >= e1) continue;
                long ddx = x - sx, ddy = y - sy, d2 = ddx * ddx + ddy * ddy;
                if (d2 > r2 || d2 < b) continue;   /* beyond the radius, or into a bin already passed */
                int *nstate = queued + (y - s0) * sc + (x - t0);
                if (d2 >= *nstate) continue;       /* settled (-1), or waiting at this distance or less */
                *nstate = (int)d2;
                twin_wave_entry *e = pool + used;
                e->x = (int)x; e->y = (int)y; e->sx = (int)sx; e->sy = (int)sy; e->next = -1;
                if (tail[d2] < 0) head[d2] = (int)used; else pool[tail[d2]].next = (int)used;
                tail[d2] = (int)used++;
            }
        }
    }
    free(queued); free(pool); free(head);
    return 0;
}

/* One costmap update's master cells over the window W = rows [w0, w1) x cols [v0, v1) of a
   rows x cols grid, from the cells of E = rows [e0, e1) x cols [f0, f1) (W grown by the inflation
   radius, clipped to the grid):
   - layers: `base` (the static layer; NULL: every cell `fill`) overlaid by each obstacle layer,
     whose known cells (not 255) replace an unknown master cell or raise a lower one;
   - inflation (when `inflate`): twin_inflate over W with those cells (table: (radius + 1)^2 costs by
     |dx|, |dy|).
   master is written in W only. Returns -1 when memory runs out. */
int twin_costmap_compose(const unsigned char *base, unsigned char fill, const unsigned char *const *layers,
                         long n_layers, long rows, long cols, long w0, long w1, long v0, long v1,
                         long e0, long e1, long f0, long f1, int inflate, long radius,
                         const unsigned char *table, int inflate_unknown, int around_unknown,
                         unsigned char *master) {
    long er = e1 - e0, ec = f1 - f0;
    if (er <= 0 || ec <= 0 || v1 <= v0 || w1 <= w0) return 0;
    unsigned char *pre = malloc((size_t)(er * ec));
    if (!pre) return -1;
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
    for (long r = w0; r < w1; ++r)
        for (long c = v0; c < v1; ++c) master[r * cols + c] = pre[(r - e0) * ec + (c - f0)];
    int status = 0;
    if (inflate)
        status = twin_inflate(pre, e0, f0, er, ec, rows, cols, w0, w1, v0, v1, radius, table, inflate_unknown,
                              around_unknown, master);
    free(pre);
    return status;
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
   `full`, else over the cells written grown by `pad` (the window), whose inflation sources lie within
   `radius` of it.
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
    long pad = k[10], reach = k[7];
    long w0 = r0 - pad < 0 ? 0 : r0 - pad, w1 = r1 + pad > rows ? rows : r1 + pad;
    long v0 = c0 - pad < 0 ? 0 : c0 - pad, v1 = c1 + pad > cols ? cols : c1 + pad;
    if (!k[6]) reach = 0;
    long e0 = w0 - reach < 0 ? 0 : w0 - reach, e1 = w1 + reach > rows ? rows : w1 + reach;
    long f0 = v0 - reach < 0 ? 0 : v0 - reach, f1 = v1 + reach > cols ? cols : v1 + reach;
    const unsigned char *layers[1] = {layer};
    return twin_costmap_compose(base, (unsigned char)k[4], layers, 1, rows, cols, w0, w1, v0, v1, e0, e1, f0, f1,
                                (int)k[6], k[7], table, (int)k[8], (int)k[9], master);
}

/* Nav2's FootprintCollisionChecker::footprintCost: the highest cost (uint8 grid, row-major rows x cols)
   on the edges of the footprint (fx, fy: n points in the robot's frame) at pose (x, y, yaw), each
   edge walked as nav2_util's LineIterator (Bresenham) walks it: a line's cost is 254 (lethal) at its
   first lethal cell, and the walk stops when the running maximum is lethal (an unknown 255 seen on an
   earlier edge outranks it, as in Nav2); 254 for a footprint point off the grid. Same arithmetic as
   footprint.footprint_cost_py. */
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
