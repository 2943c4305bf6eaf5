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

/* Costmap2D::worldToMap: the cell holding (wx, wy), false off the grid. */
static inline int twin_world_to_map(double wx, double wy, double gx, double gy, double res, long rows, long cols,
                                    long *mx, long *my) {
    if (wx < gx || wy < gy) return 0;
    double fx = (wx - gx) / res, fy = (wy - gy) / res;
    if (!(fx < (double)cols) || !(fy < (double)rows)) return 0;
    *mx = (long)(int)fx;
    *my = (long)(int)fy;
    return *mx < cols && *my < rows;
}

static inline void twin_grow(long *bounds, long r, long c) {
    if (r < bounds[0]) bounds[0] = r;
    if (r > bounds[1]) bounds[1] = r;
    if (c < bounds[2]) bounds[2] = c;
    if (c > bounds[3]) bounds[3] = c;
}

/* ObstacleLayer for one observation (pts: n points x, y, z in the grid's frame; sensor at (ox, oy)).
   Clearing as raytraceFreespace: nothing when the sensor is off the grid; each endpoint clipped to the
   grid (the far edges less 1 mm), a ray whose clipped end is off the grid skipped, the rest traced
   FREE (twin_raytrace). Marking as updateBounds: nothing when the sensor is off the grid; a point
   below min_h or above max_h, or off the grid, is skipped, and so is one whose distance in cells from
   the sensor's cell, (unsigned) hypot(dx, dy), is above mark_max_cells or below mark_min_cells
   (cellDistance of obstacle_max_range / obstacle_min_range); the rest become LETHAL (254).
   bounds as in twin_raytrace. */
void twin_obstacle_update(unsigned char *cost, long rows, long cols, double gx, double gy, double res,
                          double ox, double oy, const double *pts, long n, int clearing, int marking,
                          double ray_max_cells, double ray_min_cells, double mark_max_cells,
                          double mark_min_cells, double min_h, double max_h, long *bounds) {
    long x0, y0;
    if (!twin_world_to_map(ox, oy, gx, gy, res, rows, cols, &x0, &y0)) return;
    double map_end_x = gx + cols * res, map_end_y = gy + rows * res;
    if (clearing) {
        for (long k = 0; k < n; ++k) {
            double wx = pts[3 * k], wy = pts[3 * k + 1];
            double a = wx - ox, b = wy - oy, t;
            if (wx < gx) { t = (gx - ox) / a; wx = gx; wy = oy + b * t; }
            if (wy < gy) { t = (gy - oy) / b; wx = ox + a * t; wy = gy; }
            if (wx > map_end_x) { t = (map_end_x - ox) / a; wx = map_end_x - 0.001; wy = oy + b * t; }
            if (wy > map_end_y) { t = (map_end_y - oy) / b; wx = ox + a * t; wy = map_end_y - 0.001; }
            long x1, y1;
            if (!twin_world_to_map(wx, wy, gx, gy, res, rows, cols, &x1, &y1)) continue;
            twin_raytrace(cost, rows, cols, x0, y0, &x1, &y1, 1, ray_max_cells, ray_min_cells, 0, bounds);
        }
    }
    if (!marking) return;
    for (long k = 0; k < n; ++k) {
        double pz = pts[3 * k + 2];
        if (pz < min_h || pz > max_h) continue;
        long mx, my;
        if (!twin_world_to_map(pts[3 * k], pts[3 * k + 1], gx, gy, res, rows, cols, &mx, &my)) continue;
        double dist = (double)(unsigned int)hypot((double)(mx - x0), (double)(my - y0));
        if (dist > mark_max_cells || dist < mark_min_cells) continue;
        cost[my * cols + mx] = 254;
        twin_grow(bounds, my, mx);
    }
}

static inline int twin_bits_below(unsigned int n, unsigned int threshold) {  /* VoxelGrid::bitsBelowThreshold */
    /* n holds 16 bits here: the thresholds TB3 uses (0 and 15) need no count */
    if (threshold == 0) return n == 0;
    if (threshold >= 16) return 1;
    if (threshold == 15) return n != 0xffffu;
    return (unsigned int)__builtin_popcount(n) <= threshold;
}

static inline double twin_min(double a, double b) { return b < a ? b : a; }  /* std::min */
static inline double twin_max(double a, double b) { return a < b ? b : a; }  /* std::max */

/* VoxelLayer for one observation: the layer's 2-D cells `cost` and its voxel columns `vox` (bit z and
   bit z + 16 of a column: both set marked, one unknown, none free; a fresh column is 0xffff).
   vz: origin_z, z_resolution, max_obstacle_height; vk: z_voxels, unknown threshold (the parameter
   plus 16 - z_voxels), mark_threshold.
   Clearing as VoxelLayer::raytraceFreespace: nothing when the sensor is off the voxel grid; each
   endpoint pulled 2 cells towards the sensor, clipped to the grid (whose extent is (size - 0.5)
   cells), and traced in 3-D from the sensor's fractional voxel to it (VoxelGrid::raytraceLine,
   ClearVoxelInMap): each voxel visited is cleared, and its 2-D cell becomes FREE when the column's
   marked bits are within mark_threshold and its unknown bits within the unknown threshold, unknown
   (255) when only the marked bits are. Marking as VoxelLayer::updateBounds: a point above
   max_obstacle_height, or at a squared 3-D distance from the sensor at or beyond mark_max_m^2 or
   below mark_min_m^2, or off the grid (a point below origin_z counts at origin_z), is skipped; the
   rest mark their voxel, and the 2-D cell becomes LETHAL when the column's marked bits exceed
   mark_threshold. bounds as in twin_raytrace. */
void twin_voxel_update(unsigned char *cost, unsigned int *vox, long rows, long cols, double gx, double gy, double res,
                       double ox, double oy, double oz, const double *pts, long n, int clearing, int marking,
                       double ray_max_cells, double ray_min_cells, double mark_max_m, double mark_min_m,
                       const double *vz, const long *vk, long *bounds) {
    double z0 = vz[0], zr = vz[1], max_h = vz[2];
    long size_z = vk[0];
    unsigned int unknown_thr = (unsigned int)vk[1], mark_thr = (unsigned int)vk[2];
    if (clearing && n > 0) {
        double sx = 0, sy = 0, sz = 0;
        int inside = !(ox < gx || oy < gy || oz < z0);
        if (inside) {
            sx = (ox - gx) / res; sy = (oy - gy) / res; sz = (oz - z0) / zr;
            inside = sx < cols && sy < rows && sz < size_z;
        }
        double map_end_x = gx + (cols - 1 + 0.5) * res, map_end_y = gy + (rows - 1 + 0.5) * res;
        double map_end_z = z0 + (size_z - 1 + 0.5) * zr;
        unsigned int max_length = (unsigned int)ray_max_cells, min_length = (unsigned int)ray_min_cells;
        for (long k = 0; inside && k < n; ++k) {
            double wpx = pts[3 * k], wpy = pts[3 * k + 1], wpz = pts[3 * k + 2];
            double distance = sqrt((wpx - ox) * (wpx - ox) + (wpy - oy) * (wpy - oy) + (wpz - oz) * (wpz - oz));
            double scaling = twin_max(twin_min(1.0, (distance - 2 * res) / distance), 0.0);
            wpx = scaling * (wpx - ox) + ox;
            wpy = scaling * (wpy - oy) + oy;
            wpz = scaling * (wpz - oz) + oz;
            double a = wpx - ox, b = wpy - oy, c = wpz - oz, t = 1.0;
            if (wpz > map_end_z) t = twin_max(0.0, twin_min(t, (map_end_z - 0.01 - oz) / c));
            else if (wpz < z0) t = twin_min(t, (z0 - oz) / c);
            if (wpx < gx) t = twin_min(t, (gx - ox) / a);
            if (wpy < gy) t = twin_min(t, (gy - oy) / b);
            if (wpx > map_end_x) t = twin_min(t, (map_end_x - ox) / a);
            if (wpy > map_end_y) t = twin_min(t, (map_end_y - oy) / b);
            wpx = ox + a * t; wpy = oy + b * t; wpz = oz + c * t;
            if (wpx < gx || wpy < gy || wpz < z0) continue;
            double px = (wpx - gx) / res, py = (wpy - gy) / res, pz = (wpz - z0) / zr;
            if (!(px < cols && py < rows && pz < size_z)) continue;
            /* VoxelGrid::raytraceLine (clearVoxelLineInMap's bounds check passes: both ends are inside) */
            double dist = sqrt((sx - px) * (sx - px) + (sy - py) * (sy - py) + (sz - pz) * (sz - pz));
            if ((unsigned int)dist < min_length) continue;
            double scale = 1.0, mx0 = sx, my0 = sy, mz0 = sz;
            if (dist > 0.0) {
                scale = twin_min(1.0, max_length / dist);
                mx0 = sx + (px - sx) / dist * min_length;
                my0 = sy + (py - sy) / dist * min_length;
                mz0 = sz + (pz - sz) / dist * min_length;
            }
            int dx = (int)px - (int)mx0, dy = (int)py - (int)my0, dz = (int)pz - (int)mz0;
            unsigned int adx = (unsigned int)abs(dx), ady = (unsigned int)abs(dy), adz = (unsigned int)abs(dz);
            int odx = dx > 0 ? 1 : -1, ody = (dy > 0 ? 1 : -1) * (int)cols, odz = dz > 0 ? 1 : -1;
            unsigned int z_mask = ((1u << 16) | 1u) << (unsigned int)mz0;
            unsigned int offset = (unsigned int)my0 * (unsigned int)cols + (unsigned int)mx0;
            /* the dominant axis a and the two others b, c: each an xy offset step or a z mask shift */
            unsigned int da, db, dc;
            int oa, ob, oc, a_is_z = 0, b_is_z = 0, c_is_z = 0;
            if (adx >= (ady > adz ? ady : adz)) { da = adx; db = ady; dc = adz; oa = odx; ob = ody; oc = odz; c_is_z = 1; }
            else if (ady >= adz) { da = ady; db = adx; dc = adz; oa = ody; ob = odx; oc = odz; c_is_z = 1; }
            else { da = adz; db = adx; dc = ady; oa = odz; ob = odx; oc = ody; a_is_z = 1; }
            int error_b = (int)(da / 2), error_c = (int)(da / 2);
            unsigned int cap = (unsigned int)(scale * da), end = cap < da ? cap : da;
            /* the ray is monotone along x and y: its first and last cell written bound the others */
            long first = -1, last = -1;
            for (unsigned int i = 0;; ++i) {
                /* ClearVoxelInMap */
                unsigned int column = vox[offset] & ~z_mask;
                vox[offset] = column;
                unsigned int unknown_bits = (unsigned int)((unsigned short)(column >> 16) ^ (unsigned short)column);
                if (twin_bits_below(column >> 16, mark_thr)) {
                    cost[offset] = twin_bits_below(unknown_bits, unknown_thr) ? 0 : 255;
                    if (first < 0) first = (long)offset;
                    last = (long)offset;
                }
                if (i >= end) break;
                if (a_is_z) z_mask = oa > 0 ? z_mask << 1 : z_mask >> 1; else offset += (unsigned int)oa;
                error_b += (int)db;
                error_c += (int)dc;
                if ((unsigned int)error_b >= da) {
                    if (b_is_z) z_mask = ob > 0 ? z_mask << 1 : z_mask >> 1; else offset += (unsigned int)ob;
                    error_b -= (int)da;
                }
                if ((unsigned int)error_c >= da) {
                    if (c_is_z) z_mask = oc > 0 ? z_mask << 1 : z_mask >> 1; else offset += (unsigned int)oc;
                    error_c -= (int)da;
                }
            }
            if (first >= 0) {
                twin_grow(bounds, first / cols, first % cols);
                twin_grow(bounds, last / cols, last % cols);
            }
        }
    }
    if (!marking) return;
    double sq_max = mark_max_m * mark_max_m, sq_min = mark_min_m * mark_min_m;
    for (long k = 0; k < n; ++k) {
        double x = pts[3 * k], y = pts[3 * k + 1], z = pts[3 * k + 2];
        if (z > max_h) continue;
        double sq = (x - ox) * (x - ox) + (y - oy) * (y - oy) + (z - oz) * (z - oz);
        if (sq >= sq_max || sq < sq_min) continue;
        double wz = z < z0 ? z0 : z;
        if (x < gx || y < gy || wz < z0) continue;
        unsigned int mx = (unsigned int)((x - gx) / res), my = (unsigned int)((y - gy) / res);
        unsigned int mz = (unsigned int)((wz - z0) / zr);
        if (!(mx < (unsigned long)cols && my < (unsigned long)rows && mz < (unsigned long)size_z)) continue;
        unsigned int *col = vox + my * cols + mx;
        *col |= (1u << mz << 16) | (1u << mz);
        if (!twin_bits_below(*col >> 16, mark_thr)) {
            cost[my * cols + mx] = 254;
            twin_grow(bounds, (long)my, (long)mx);
        }
    }
}

/* A LaserScan's points for the layers: beam i (range r, direction cos_a[i], sin_a[i] in the sensor
   frame) gives (sx + r (c cos_a - s sin_a), sy + r (s cos_a + c sin_a), sz) when range_min <= r <
   range_max (laser_geometry's projection keeps those), as scan_observation projects it. pts holds 3 n
   doubles; returns how many points. */
long twin_scan_points(const double *ranges, long n, const double *cos_a, const double *sin_a, double range_min,
                      double range_max, double sx, double sy, double sz, double c, double s, double *pts) {
    long m = 0;
    for (long i = 0; i < n; ++i) {
        double r = ranges[i];
        if (r >= range_min && r < range_max) {
            double ca = cos_a[i], sa = sin_a[i];
            pts[3 * m] = sx + r * (c * ca - s * sa);
            pts[3 * m + 1] = sy + r * (s * ca + c * sa);
            pts[3 * m + 2] = sz;
            ++m;
        }
    }
    return m;
}

/* One layer's update from a LaserScan: its points (twin_scan_points), then twin_obstacle_update (vox
   NULL) or twin_voxel_update. d: gx, gy, res, range_min, range_max, sx, sy, sz, c, s, ray_max_cells,
   ray_min_cells, mark_max (cells, or m for a voxel layer), mark_min (likewise), min_h, max_h,
   origin_z, z_resolution; k: ranges, clearing, marking, z_voxels, unknown threshold, mark_threshold;
   rows, cols. Returns -1 when memory runs out. */
int twin_scan_update(unsigned char *cost, unsigned int *vox, long rows, long cols, const double *d, const long *k,
                     const double *ranges, const double *cos_a, const double *sin_a, long *bounds) {
    double *pts = malloc(3 * sizeof(double) * (size_t)(k[0] > 0 ? k[0] : 1));
    if (!pts) return -1;
    long m = twin_scan_points(ranges, k[0], cos_a, sin_a, d[3], d[4], d[5], d[6], d[7], d[8], d[9], pts);
    if (vox) {
        double vz[3] = {d[16], d[17], d[15]};
        long vk[3] = {k[3], k[4], k[5]};
        twin_voxel_update(cost, vox, rows, cols, d[0], d[1], d[2], d[5], d[6], d[7], pts, m, (int)k[1], (int)k[2],
                          d[10], d[11], d[12], d[13], vz, vk, bounds);
    } else {
        twin_obstacle_update(cost, rows, cols, d[0], d[1], d[2], d[5], d[6], pts, m, (int)k[1], (int)k[2], d[10], d[11],
                             d[12], d[13], d[14], d[15], bounds);
    }
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

/* A growing list of cells (x, y) for twin_fill_footprint. */
typedef struct { long *xy; long n, cap; } twin_cells;

static int twin_cells_push(twin_cells *l, long x, long y) {
    if (l->n == l->cap) {
        long cap = l->cap ? 2 * l->cap : 64;
        long *xy = realloc(l->xy, 2 * sizeof(long) * (size_t)cap);
        if (!xy) return -1;
        l->xy = xy; l->cap = cap;
    }
    l->xy[2 * l->n] = x; l->xy[2 * l->n + 1] = y; ++l->n;
    return 0;
}

/* Costmap2D::raytraceLine from (x0, y0) to (x1, y1) at full length, each cell appended (PolygonOutlineCells). */
static int twin_outline(twin_cells *l, long x0, long y0, long x1, long y1) {
    long dx = x1 - x0, dy = y1 - y0, adx = labs(dx), ady = labs(dy);
    long sx = dx > 0 ? 1 : -1, sy = dy > 0 ? 1 : -1;
    int x_major = adx >= ady;
    long da = x_major ? adx : ady, db = x_major ? ady : adx, error = da / 2, x = x0, y = y0;
    for (long i = 0; i < da; ++i) {
        if (twin_cells_push(l, x, y)) return -1;
        if (x_major) x += sx; else y += sy;
        error += db;
        if (error >= da) {
            if (x_major) y += sy; else x += sx;
            error -= da;
        }
    }
    return twin_cells_push(l, x, y);
}

/* Costmap2D::setConvexPolygonCost for the footprint (fp: n points in the robot frame) at (x, y) with
   heading cos c, sin s, placed as transformFootprint does (x + (fx c - fy s), y + (fx s + fy c)):
   nothing when a corner is off the grid; else convexFillCells: the outline's cells (raytraceLine
   along each edge, the last back to the first) sorted by x (Nav2's exchange sort, stable), then
   for each x from the first to the last, the column between the lowest and highest outline cell
   of it (taken two at a time as Nav2 takes them, the filled cells appended to the same list), all
   set to `value`. bounds grow as in twin_raytrace. Returns -1 when memory runs out. */
int twin_fill_footprint(unsigned char *cost, long rows, long cols, double ox, double oy, double res,
                        const double *fp, long n, double x, double y, double c, double s,
                        unsigned char value, long *bounds) {
    if (n < 1) return 0;
    long *corner = malloc(2 * sizeof(long) * (size_t)n);
    if (!corner) return -1;
    for (long i = 0; i < n; ++i) {
        double wx = x + (fp[2 * i] * c - fp[2 * i + 1] * s);
        double wy = y + (fp[2 * i] * s + fp[2 * i + 1] * c);
        if (!twin_world_to_map(wx, wy, ox, oy, res, rows, cols, corner + 2 * i, corner + 2 * i + 1)) {
            free(corner);
            return 0;
        }
    }
    if (n < 3) { free(corner); return 0; }
    twin_cells l = {NULL, 0, 0};
    int status = 0;
    for (long i = 0; i < n && !status; ++i) {
        long j = i + 1 < n ? i + 1 : 0;
        status = twin_outline(&l, corner[2 * i], corner[2 * i + 1], corner[2 * j], corner[2 * j + 1]);
    }
    free(corner);
    if (status) { free(l.xy); return -1; }
    long i = 0;
    while (i < l.n - 1) {
        if (l.xy[2 * i] > l.xy[2 * i + 2]) {
            long tx = l.xy[2 * i], ty = l.xy[2 * i + 1];
            l.xy[2 * i] = l.xy[2 * i + 2]; l.xy[2 * i + 1] = l.xy[2 * i + 3];
            l.xy[2 * i + 2] = tx; l.xy[2 * i + 3] = ty;
            if (i > 0) --i;
        } else {
            ++i;
        }
    }
    i = 0;
    long min_x = l.xy[0], max_x = l.xy[2 * (l.n - 1)];
    for (long cx = min_x; cx <= max_x && !status; ++cx) {
        if (i >= l.n - 1) break;
        long lo_y, hi_y;
        if (l.xy[2 * i + 1] < l.xy[2 * i + 3]) { lo_y = l.xy[2 * i + 1]; hi_y = l.xy[2 * i + 3]; }
        else { lo_y = l.xy[2 * i + 3]; hi_y = l.xy[2 * i + 1]; }
        i += 2;
        while (i < l.n && l.xy[2 * i] == cx) {
            if (l.xy[2 * i + 1] < lo_y) lo_y = l.xy[2 * i + 1];
            else if (l.xy[2 * i + 1] > hi_y) hi_y = l.xy[2 * i + 1];
            ++i;
        }
        for (long cy = lo_y; cy <= hi_y && !status; ++cy) status = twin_cells_push(&l, cx, cy);
    }
    if (!status) {
        for (long k = 0; k < l.n; ++k) {
            long cx = l.xy[2 * k], cy = l.xy[2 * k + 1];
            cost[cy * cols + cx] = value;
            twin_grow(bounds, cy, cx);
        }
    }
    free(l.xy);
    return status ? -1 : 0;
}

/* Nav2's FootprintCollisionChecker::footprintCost: the highest cost (uint8 grid, row-major rows x cols)
   on the edges of the footprint (fx, fy: n points in the robot's frame) at pose (x, y, yaw), each
   edge walked as nav2_util's LineIterator (Bresenham) walks it (the closing edge from the first point to
   the last, the points placed as x + (fx cos - fy sin), y + (fx sin + fy cos)): a line's cost is 254 (lethal) at its
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
        double wx = x + (fx[i] * c - fy[i] * s);   /* footprintCostAtPose's rounding */
        double wy = y + (fx[i] * s + fy[i] * c);
        if (wx < ox || wy < oy) return LETHAL;
        long mx = (long)((wx - ox) / res), my = (long)((wy - oy) / res);
        if (mx >= cols || my >= rows) return LETHAL;
        mxs[i] = mx;
        mys[i] = my;
    }
    int worst = 0;
    for (long i = 0; i < n; ++i) {
        /* edges 0-1, 1-2, ..., then the closing one walked from the first point to the last */
        long x0 = mxs[i + 1 < n ? i : 0], y0 = mys[i + 1 < n ? i : 0];
        long x1 = mxs[i + 1 < n ? i + 1 : i], y1 = mys[i + 1 < n ? i + 1 : i];
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

/* One whole costmap update in one call, for the common case: every obstacle/voxel layer fed one LaserScan
   source that clears and marks (TB3's costmaps). For each layer l: twin_scan_update with its own
   doubles ld + 18 l and longs lk + 6 l (see twin_scan_update), then its footprint cleared when
   fp_clear[l] (twin_fill_footprint at the robot pose d: x, y, cos, sin); then the master composed
   (twin_costmap_compose) over everything when `full`, else over the cells written grown by `pad`.
   k: rows, cols, footprint points, fill, full, inflate, radius, inflate_unknown, around_unknown, pad.
   bounds (4) receives the cells written. Returns -1 when memory runs out. */
int twin_costmap_scan_update(unsigned char *const *layers, unsigned int *const *voxels, long n_layers,
                             const long *fp_clear, const double *ld, const long *lk, const unsigned char *base,
                             unsigned char *master, const unsigned char *table, const double *ranges,
                             const double *cos_a, const double *sin_a, const double *footprint, const double *d,
                             const long *k, long *bounds) {
    long rows = k[0], cols = k[1];
    bounds[0] = rows; bounds[1] = -1; bounds[2] = cols; bounds[3] = -1;
    for (long l = 0; l < n_layers; ++l) {
        const double *g = ld + 18 * l;
        if (twin_scan_update(layers[l], voxels[l], rows, cols, g, lk + 6 * l, ranges, cos_a, sin_a, bounds)) return -1;
        if (fp_clear[l] && k[2] > 0 &&
            twin_fill_footprint(layers[l], rows, cols, g[0], g[1], g[2], footprint, k[2], d[0], d[1], d[2], d[3], 0,
                                bounds))
            return -1;
    }
    long r0, r1, c0, c1;
    if (k[4]) { r0 = 0; r1 = rows; c0 = 0; c1 = cols; }
    else if (bounds[1] < 0) return 0;
    else { r0 = bounds[0]; r1 = bounds[1] + 1; c0 = bounds[2]; c1 = bounds[3] + 1; }
    long pad = k[9], reach = k[5] ? k[6] : 0;
    long w0 = r0 - pad < 0 ? 0 : r0 - pad, w1 = r1 + pad > rows ? rows : r1 + pad;
    long v0 = c0 - pad < 0 ? 0 : c0 - pad, v1 = c1 + pad > cols ? cols : c1 + pad;
    long e0 = w0 - reach < 0 ? 0 : w0 - reach, e1 = w1 + reach > rows ? rows : w1 + reach;
    long f0 = v0 - reach < 0 ? 0 : v0 - reach, f1 = v1 + reach > cols ? cols : v1 + reach;
    return twin_costmap_compose(base, (unsigned char)k[3], (const unsigned char *const *)layers, n_layers, rows, cols,
                                w0, w1, v0, v1, e0, e1, f0, f1, (int)k[5], k[6], table, (int)k[7], (int)k[8], master);
}
