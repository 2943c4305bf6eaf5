/* NavFn's two hot loops (loaded by twin/nav/planner/_native.py; signatures in its docstring). */

#include <math.h>

#define POT_HIGH 1.0e10
#define COST_OBS 254
#define COST_NEUTRAL 50

static void sift_up(int *cells, double *keys, int i) {
    int c = cells[i]; double k = keys[i];
    while (i > 0) {
        int p = (i - 1) >> 1;
        if (keys[p] < k || (keys[p] == k && cells[p] <= c)) break;
        cells[i] = cells[p]; keys[i] = keys[p]; i = p;
    }
    cells[i] = c; keys[i] = k;
}

static void sift_down(int *cells, double *keys, int n, int i) {
    int c = cells[i]; double k = keys[i];
    for (;;) {
        int l = 2 * i + 1, r = l + 1, m = i;
        int mc = c; double mk = k;
        if (l < n && (keys[l] < mk || (keys[l] == mk && cells[l] < mc))) { m = l; mc = cells[l]; mk = keys[l]; }
        if (r < n && (keys[r] < mk || (keys[r] == mk && cells[r] < mc))) { m = r; mc = cells[r]; mk = keys[r]; }
        if (m == i) break;
        cells[i] = mc; keys[i] = mk; i = m;
    }
    cells[i] = c; keys[i] = k;
}

static double heuristic(int astar, int n, int nx, int tx, int ty) {
    if (!astar) return 0.0;
    double dx = (double)(n % nx - tx), dy = (double)(n / nx - ty);
    return COST_NEUTRAL * sqrt(dx * dx + dy * dy);
}

static double cell_update(const unsigned char *cost, const double *pot, int nx, int n) {
    double l = pot[n - 1], r = pot[n + 1], u = pot[n - nx], d = pot[n + nx];
    double ta = l < r ? l : r, tc = u < d ? u : d;
    double hf = (double)cost[n];
    if (tc < ta) { double t = ta; ta = tc; tc = t; }
    double dc = tc - ta;
    if (dc >= hf) return ta + hf;
    double q = dc / hf;
    double v = -0.2301 * q * q + 0.5307 * q + 0.7040;
    return ta + hf * v;
}

int twin_navfn_potential(const unsigned char *cost, int nx, int ny, int source, int target, int astar,
                         double *pot, int *heap_cells, double *heap_keys, unsigned char *done) {
    int size = 0, settled = 0, cap = 4 * nx * ny;
    int tx = target >= 0 ? target % nx : 0, ty = target >= 0 ? target / nx : 0;
    pot[source] = 0.0;
    heap_cells[0] = source; heap_keys[0] = 0.0; size = 1;
    const int offs[4] = {1, -1, nx, -nx};
    while (size > 0) {
        int n = heap_cells[0]; double key = heap_keys[0];
        --size;
        if (size > 0) {
            heap_cells[0] = heap_cells[size]; heap_keys[0] = heap_keys[size];
            sift_down(heap_cells, heap_keys, size, 0);
        }
        double h = heuristic(astar, n, nx, tx, ty);
        if (done[n] || key > pot[n] + h) continue; /* settled already, or a stale entry */
        done[n] = 1;
        ++settled;
        if (n == target) break;
        for (int j = 0; j < 4; ++j) {
            int m = n + offs[j];
            if (cost[m] >= COST_OBS || done[m]) continue;
            double p = cell_update(cost, pot, nx, m);
            if (p < pot[m]) {
                pot[m] = p;
                if (size >= cap) return -1;
                double hm = heuristic(astar, m, nx, tx, ty);
                heap_cells[size] = m; heap_keys[size] = p + hm;
                sift_up(heap_cells, heap_keys, size); ++size;
            }
        }
    }
    return settled;
}

static void gradient(const double *pot, int ns, int nx, int n, double *gx, double *gy) {
    /* NavFn::gradCell: the normalised descent direction at a cell (0 at the grid's first and last rows) */
    double cv, dx = 0.0, dy = 0.0;
    *gx = 0.0; *gy = 0.0;
    if (n < nx || n > ns - nx) return;
    cv = pot[n];
    if (cv >= POT_HIGH) {
        if (pot[n - 1] < POT_HIGH) dx = -COST_OBS;
        else if (pot[n + 1] < POT_HIGH) dx = COST_OBS;
        if (pot[n - nx] < POT_HIGH) dy = -COST_OBS;
        else if (pot[n + nx] < POT_HIGH) dy = COST_OBS;
    } else {
        if (pot[n - 1] < POT_HIGH) dx += pot[n - 1] - cv;
        if (pot[n + 1] < POT_HIGH) dx += cv - pot[n + 1];
        if (pot[n - nx] < POT_HIGH) dy += pot[n - nx] - cv;
        if (pot[n + nx] < POT_HIGH) dy += cv - pot[n + nx];
    }
    double norm = sqrt(dx * dx + dy * dy);
    if (norm > 0.0) { norm = 1.0 / norm; dx *= norm; dy *= norm; }
    *gx = dx; *gy = dy;
}

int twin_navfn_trace(const double *pot, const unsigned char *cost, int nx, int ny, int start, int goal,
                     int max_cycles, double *out_xy, int max_points) {
    /* NavFn::calcPath: from `start` (the plan's end) down the potential to `goal` (the robot's node, where
       the potential is 0); the last point written is `goal` itself. */
    int ns = nx * ny, stc = start, count = 0;
    double dx = 0.0, dy = 0.0;
    const int ring[8] = {-nx - 1, -nx, -nx + 1, -1, 1, nx - 1, nx, nx + 1};
    for (int cycle = 0; cycle < max_cycles; ++cycle) {
        if (count >= max_points) return -1;
        long near = (long)stc + (long)round(dx) + (long)(nx * round(dy));
        if (near < 0) near = 0;
        if (near > ns - 1) near = ns - 1;
        if (pot[near] < COST_NEUTRAL) {
            out_xy[2 * count] = goal % nx; out_xy[2 * count + 1] = goal / nx; ++count;
            return count;
        }
        if (stc < nx || stc > ns - nx) return -1;
        out_xy[2 * count] = stc % nx + dx; out_xy[2 * count + 1] = stc / nx + dy; ++count;
        int oscillating = count > 2 && out_xy[2 * (count - 1)] == out_xy[2 * (count - 3)]
                          && out_xy[2 * (count - 1) + 1] == out_xy[2 * (count - 3) + 1];
        int high = pot[stc] >= POT_HIGH;
        for (int j = 0; j < 8 && !high; ++j) if (pot[stc + ring[j]] >= POT_HIGH) high = 1;
        if (high || oscillating) {
            /* the lowest of the eight neighbours; NavFn keeps the running minimum in an int */
            int best = stc;
            double bp = (double)(int)pot[stc];
            for (int j = 0; j < 8; ++j) {
                int m = stc + ring[j];
                if (pot[m] < bp) { bp = (double)(int)pot[m]; best = m; }
            }
            stc = best; dx = 0.0; dy = 0.0;
            if (pot[stc] >= POT_HIGH) return -1;
            continue;
        }
        double g[4][2];
        gradient(pot, ns, nx, stc, &g[0][0], &g[0][1]);
        gradient(pot, ns, nx, stc + 1, &g[1][0], &g[1][1]);
        gradient(pot, ns, nx, stc + nx, &g[2][0], &g[2][1]);
        gradient(pot, ns, nx, stc + nx + 1, &g[3][0], &g[3][1]);
        double x1 = (1.0 - dx) * g[0][0] + dx * g[1][0], x2 = (1.0 - dx) * g[2][0] + dx * g[3][0];
        double x = (1.0 - dy) * x1 + dy * x2;
        double y1 = (1.0 - dx) * g[0][1] + dx * g[1][1], y2 = (1.0 - dx) * g[2][1] + dx * g[3][1];
        double y = (1.0 - dy) * y1 + dy * y2;
        if (x == 0.0 && y == 0.0) return -1;
        double ss = 0.5 / sqrt(x * x + y * y);
        dx += x * ss; dy += y * ss;
        if (dx > 1.0) { stc += 1; dx -= 1.0; }
        if (dx < -1.0) { stc -= 1; dx += 1.0; }
        if (dy > 1.0) { stc += nx; dy -= 1.0; }
        if (dy < -1.0) { stc -= nx; dy += 1.0; }
    }
    return -1;
}
