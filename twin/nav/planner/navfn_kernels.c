/* NavFn's two hot loops as Nav2 Humble runs them (loaded by twin/nav/planner/_native.py; signatures in its
   docstring). Potentials are float32, as NavFn's potarr; every expression keeps NavFn's operand types, so a
   double literal times a float is a double rounded once to float where NavFn assigns it to a float.
   Built with -ffp-contract=off: a fused multiply-add would round differently from NavFn's build. */

#include <math.h>

#define POT_HIGH 1.0e10f
#define COST_OBS 254
#define COST_NEUTRAL 50
#define BLOCK_CAP 10000 /* NavFn's PRIORITYBUFSIZE: a push to a full block is dropped */
#define HALF_DIAGONAL 0.707106781

typedef struct {
    const unsigned char *cost;
    float *pot;
    unsigned char *queued;
    int nx, ns, astar, tx, ty;
    float threshold;
    int *block[3]; /* 0: this batch, 1: the next batch under the threshold, 2: past the threshold */
    int fill[3];
} Wave;

static void enqueue(Wave *w, int which, int n) {
    if (n < 0 || n >= w->ns || w->queued[n] || w->cost[n] >= COST_OBS || w->fill[which] >= BLOCK_CAP) return;
    w->block[which][w->fill[which]++] = n;
    w->queued[n] = 1;
}

static void swap_blocks(Wave *w, int a, int b) {
    int *p = w->block[a], f = w->fill[a];
    w->block[a] = w->block[b]; w->fill[a] = w->fill[b];
    w->block[b] = p; w->fill[b] = f;
}

/* NavFn::updateCell / updateCellAstar: the interpolated update from the lower horizontal and vertical
   neighbours; an improved cell hands each neighbour on whose potential lies past it by 0.707 x that
   neighbour's cost, into the next batch below the threshold or the overflow block above it. */
static void relax(Wave *w, int n) {
    const int nx = w->nx;
    float *pot = w->pot;
    float left = pot[n - 1], right = pot[n + 1], below = pot[n - nx], above = pot[n + nx];
    float horizontal = left < right ? left : right;
    float vertical = below < above ? below : above;
    if (w->cost[n] >= COST_OBS) return;
    float hf = (float)w->cost[n];
    float low = vertical, gap = horizontal - vertical;
    if (gap < 0) { gap = -gap; low = horizontal; }
    float p;
    if (gap >= hf) {
        p = low + hf;
    } else {
        float q = gap / hf;
        float weight = -0.2301 * q * q + 0.5307 * q + 0.7040;
        p = low + hf * weight;
    }
    if (!(p < pot[n])) return;
    float margin_l = HALF_DIAGONAL * (float)w->cost[n - 1];
    float margin_r = HALF_DIAGONAL * (float)w->cost[n + 1];
    float margin_b = HALF_DIAGONAL * (float)w->cost[n - nx];
    float margin_a = HALF_DIAGONAL * (float)w->cost[n + nx];
    pot[n] = p;
    if (w->astar) {
        float to_go = hypot(n % nx - w->tx, n / nx - w->ty) * (float)COST_NEUTRAL;
        p += to_go;
    }
    int which = p < w->threshold ? 1 : 2;
    if (left > p + margin_l) enqueue(w, which, n - 1);
    if (right > p + margin_r) enqueue(w, which, n + 1);
    if (below > p + margin_b) enqueue(w, which, n - nx);
    if (above > p + margin_a) enqueue(w, which, n + nx);
}

int twin_navfn_potential(const unsigned char *cost, int nx, int ny, int source, int target, int astar,
                         float *pot, int *blocks, unsigned char *queued) {
    Wave w;
    w.cost = cost; w.pot = pot; w.queued = queued;
    w.nx = nx; w.ns = nx * ny; w.astar = astar;
    w.tx = target % nx; w.ty = target / nx;
    for (int k = 0; k < 3; ++k) { w.block[k] = blocks + k * BLOCK_CAP; w.fill[k] = 0; }
    for (int i = 0; i < w.ns; ++i) pot[i] = POT_HIGH;
    w.threshold = (float)COST_OBS;
    const float step = 2 * COST_NEUTRAL;
    /* NavFn::initCost: the source at 0, its four neighbours make the first batch */
    pot[source] = 0;
    enqueue(&w, 0, source + 1);
    enqueue(&w, 0, source - 1);
    enqueue(&w, 0, source - nx);
    enqueue(&w, 0, source + nx);
    if (astar) {
        float span = hypot(source % nx - w.tx, source / nx - w.ty) * (float)COST_NEUTRAL;
        w.threshold = span + w.threshold;
    }
    int cycles = nx * ny / 20 > nx + ny ? nx * ny / 20 : nx + ny;
    int cycle = 0;
    for (; cycle < cycles; ++cycle) {
        if (w.fill[0] == 0 && w.fill[1] == 0) break;
        int *batch = w.block[0], size = w.fill[0];
        for (int i = 0; i < size; ++i) queued[batch[i]] = 0;
        for (int i = 0; i < size; ++i) relax(&w, batch[i]);
        swap_blocks(&w, 0, 1);
        w.fill[1] = 0;
        if (w.fill[0] == 0) {
            w.threshold += step;
            swap_blocks(&w, 0, 2);
            w.fill[2] = 0;
        }
        if (pot[target] < POT_HIGH) break;
    }
    return cycle;
}

/* NavFn::gradCell: the normalised descent direction at a cell; 0 outside rows 1 .. ny-2 */
static void gradient(const float *pot, int ns, int nx, int n, float *gx, float *gy) {
    *gx = 0; *gy = 0;
    if (n < nx || n > ns - nx) return;
    float cv = pot[n], dx = 0, dy = 0;
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
    float norm = hypotf(dx, dy);
    if (norm > 0) {
        norm = 1.0 / norm;
        *gx = norm * dx;
        *gy = norm * dy;
    }
}

/* float -> int as x86-64's cvttss2si does it (NavFn's `int minp = potarr[stc]`): INT_MIN when out of range */
static int truncate_potential(float p) {
    return (p >= 2147483648.0f || p < -2147483648.0f || p != p) ? (int)(-2147483647 - 1) : (int)p;
}

int twin_navfn_trace(const float *pot, int nx, int ny, int start, int goal, int max_cycles, float *out_xy) {
    /* NavFn::calcPath: from cell `start` (the plan's end) down the potential to `goal` (the potential's
       source); `out_xy` takes up to max_cycles (x, y) points in cells, the last one `goal` itself. */
    const int ns = nx * ny;
    int stc = start, count = 0;
    float dx = 0, dy = 0;
    for (int cycle = 0; cycle < max_cycles; ++cycle) {
        int near = stc + (int)roundf(dx) + (int)(nx * roundf(dy));
        if (near < 0) near = 0;
        if (near > ns - 1) near = ns - 1;
        if (pot[near] < COST_NEUTRAL) {
            out_xy[2 * count] = (float)(goal % nx);
            out_xy[2 * count + 1] = (float)(goal / nx);
            return count + 1;
        }
        if (stc < nx || stc > ns - nx) return -1;
        out_xy[2 * count] = stc % nx + dx;
        out_xy[2 * count + 1] = stc / nx + dy;
        ++count;
        int oscillating = count > 2 && out_xy[2 * (count - 1)] == out_xy[2 * (count - 3)]
                          && out_xy[2 * (count - 1) + 1] == out_xy[2 * (count - 3) + 1];
        const int ring[8] = {-nx - 1, -nx, -nx + 1, -1, 1, nx - 1, nx, nx + 1};
        int boundary = pot[stc] >= POT_HIGH;
        for (int j = 0; j < 8 && !boundary; ++j) boundary = pot[stc + ring[j]] >= POT_HIGH;
        if (boundary || oscillating) {
            /* follow the grid: the lowest of the eight neighbours, the running minimum kept in an int */
            int best = stc, best_p = truncate_potential(pot[stc]);
            for (int j = 0; j < 8; ++j) {
                int m = stc + ring[j];
                if (pot[m] < (float)best_p) { best_p = truncate_potential(pot[m]); best = m; }
            }
            stc = best; dx = 0; dy = 0;
            if (pot[stc] >= POT_HIGH) return -1;
            continue;
        }
        float g[4][2];
        gradient(pot, ns, nx, stc, &g[0][0], &g[0][1]);
        gradient(pot, ns, nx, stc + 1, &g[1][0], &g[1][1]);
        gradient(pot, ns, nx, stc + nx, &g[2][0], &g[2][1]);
        gradient(pot, ns, nx, stc + nx + 1, &g[3][0], &g[3][1]);
        float x1 = (1.0 - dx) * g[0][0] + dx * g[1][0];
        float x2 = (1.0 - dx) * g[2][0] + dx * g[3][0];
        float x = (1.0 - dy) * x1 + dy * x2;
        float y1 = (1.0 - dx) * g[0][1] + dx * g[1][1];
        float y2 = (1.0 - dx) * g[2][1] + dx * g[3][1];
        float y = (1.0 - dy) * y1 + dy * y2;
        if (x == 0.0 && y == 0.0) return -1;
        float ss = 0.5f / hypotf(x, y);
        dx += x * ss;
        dy += y * ss;
        if (dx > 1.0) { ++stc; dx -= 1.0; }
        if (dx < -1.0) { --stc; dx += 1.0; }
        if (dy > 1.0) { stc += nx; dy -= 1.0; }
        if (dy < -1.0) { stc -= nx; dy += 1.0; }
    }
    return -1;
}
