/* One DWB controller cycle (Nav2 Humble's dwb_core::DWBLocalPlanner::computeVelocityCommands) in C.

   What Python would do with numpy in milliseconds, done here in tens of microseconds: cut the global
   plan around the robot (transformGlobalPlan), prepare the critics (the map-grid critics' Manhattan
   distance maps over the local costmap, RotateToGoal's window), iterate the velocity samples as
   XYThetaIterator does, roll every sample out as StandardTrajectoryGenerator does (or
   LimitedAccelGenerator), score it with the configured critics in their order, and keep the first
   lowest total among the legal ones. Python keeps the critics' state between cycles (local_planner.py, critics.py)
   and has a numpy implementation of the same cycle for machines without a C compiler.

   Where this differs from a literal transcription, it gives the same answers, bit for bit, faster:
   - the samples of one theta velocity share their headings (the heading after each step does not
     depend on the x velocity);
   - every sample is first placed with a fast table of headings (their cos and sin by rotation, the
     positions in closed form: within ~1e-13 m of Nav2's step-by-step doubles); only a point that falls
     within 1e-7 cell of a cell edge, where that could change the cell looked up, is recomputed exactly
     as Nav2 integrates it (libm's cos and sin of each step's heading, x + (v cos th) dt step by step).
     The chosen trajectory (`/local_plan`) is always integrated exactly;
   - every sample is scored from its end pose first; the poses in between (off the costmap, or on a
     lethal, inscribed or unknown cell, make a trajectory illegal) are checked only for the samples
     that would win, best first, until one is legal: that is the sample Humble keeps. Poses closer to
     a checked one than any illegal cell (a chessboard distance map around the robot) are not looked
     up: they cannot be illegal;
   - PathDist's Manhattan distance map comes from a two-pass distance transform, which equals the
     propagation Humble runs (costmap_queue, 4-neighbour, unobstructed grid); GoalDist and GoalAlign
     seed one cell, so their distance is |dx| + |dy|.
   `tests/unit/nav/controller/dwb_cases` holds it to Nav2's own code. */

#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* static parameters: par[] */
enum {
    P_MIN_VX, P_MAX_VX, P_MIN_VTH, P_MAX_VTH,
    P_ACC_X, P_DEC_X, P_ACC_TH, P_DEC_TH,
    P_MIN_SPEED_XY, P_MAX_SPEED_XY, P_MIN_SPEED_TH,
    P_VX_SAMPLES, P_VTH_SAMPLES,
    P_SIM_TIME, P_LIN_GRAN, P_ANG_GRAN,
    P_WINDOW_TIME, P_LIMITED,
    P_PRUNE_PLAN, P_PRUNE_DIST, P_FWD_PRUNE, P_SHORTEN,
    P_XY_GOAL_TOL, P_STOPPED_VEL, P_SLOWING,
    P_PATH_ALIGN_FPD, P_GOAL_ALIGN_FPD,
    P_INCLUDE_LAST,
    P_N_CRITICS, P_CRITICS /* then (code, scale) pairs */
};

/* critic codes, as dwb_params.py numbers them */
enum { C_ROTATE = 1, C_OSCILLATION, C_BASE_OBSTACLE, C_GOAL_ALIGN, C_PATH_ALIGN, C_PATH_DIST, C_GOAL_DIST };

/* per-cycle state: st[] (ROT_* are read and written back) */
enum {
    S_X, S_Y, S_YAW, S_VX, S_VTH, S_TX, S_TY, S_TYAW,
    S_ROT_IN_WINDOW, S_ROT_ROTATING,
    S_OSC_X_POS, S_OSC_X_NEG, S_OSC_TH_POS, S_OSC_TH_NEG
};

/* outputs: out[] */
enum {
    O_STATUS, O_VX, O_VTH, O_TOTAL, O_N_SAMPLES,
    O_N_LEGAL, /* samples found legal: all of them only when every sample had to be checked */
    O_BEGIN, O_END, O_N_TRAJ
};

#define STATUS_OK 0
#define STATUS_NO_LEGAL 1
#define STATUS_EMPTY_TRANSFORMED 2
#define STATUS_EMPTY_PLAN 3
#define STATUS_NO_MEMORY 4

#define CHECK_NONE 0
#define CHECK_GRID 1   /* every pose on the costmap (the map-grid critics) */
#define CHECK_COST 2   /* and on a cell below 253 (BaseObstacle) */

#define EPS 1e-5
#define BIG 0x3fffffff

typedef struct {
    const unsigned char *cost;
    long rows, cols;
    double ox, oy, res;
} Grid;

/* Costmap2D::worldToMap: false left of or below the origin, or past the far edges. */
static int world_to_map(const Grid *g, double wx, double wy, long *mx, long *my) {
    if (wx < g->ox || wy < g->oy) return 0;
    double fx = (wx - g->ox) / g->res, fy = (wy - g->oy) / g->res;
    if (fx >= (double)g->cols || fy >= (double)g->rows) return 0;
    *mx = (long)fx;
    *my = (long)fy;
    return *mx < g->cols && *my < g->rows;
}

static double project_velocity(double v0, double accel, double decel, double dt, double target) {
    if (v0 < target) {
        double v1 = v0 + accel * dt;
        return target < v1 ? target : v1;
    }
    double v1 = v0 + decel * dt;
    return target > v1 ? target : v1;
}

/* dwb_plugins::OneDVelocityIterator */
typedef struct {
    double min_vel, max_vel, current, increment;
    int return_zero, return_zero_now;
} Iter1D;

static void iter_reset(Iter1D *it) {
    it->current = it->min_vel;
    it->return_zero = 1;
    it->return_zero_now = 0;
}

static void iter_init(Iter1D *it, double current, double lo, double hi, double acc, double dec, double t, int n) {
    if (current < lo) current = lo;
    else if (current > hi) current = hi;
    it->max_vel = project_velocity(current, acc, dec, t, hi);
    it->min_vel = project_velocity(current, acc, dec, t, lo);
    iter_reset(it);
    if (fabs(it->min_vel - it->max_vel) < EPS) {
        it->increment = 1.0;
        return;
    }
    if (n < 2) n = 2;
    it->increment = (it->max_vel - it->min_vel) / (double)(n - 1 > 1 ? n - 1 : 1);
}

static double iter_velocity(const Iter1D *it) { return it->return_zero_now ? 0.0 : it->current; }

static void iter_next(Iter1D *it) {
    if (it->return_zero && it->current < 0.0 && it->current + it->increment > 0.0 &&
        it->current + it->increment <= it->max_vel + EPS) {
        it->return_zero_now = 1;
        it->return_zero = 0;
    } else {
        it->current += it->increment;
        it->return_zero_now = 0;
    }
}

static int iter_finished(const Iter1D *it) { return it->current > it->max_vel + EPS; }

/* XYThetaIterator::isValidSpeed with y = 0 (differential drive). */
static int valid_speed(const double *par, double x, double th) {
    double vmag_sq = x * x;
    double max_xy = par[P_MAX_SPEED_XY], min_xy = par[P_MIN_SPEED_XY], min_th = par[P_MIN_SPEED_TH];
    if (max_xy >= 0.0 && vmag_sq > max_xy * max_xy + EPS) return 0;
    if (min_xy >= 0.0 && vmag_sq + EPS < min_xy * min_xy && min_th >= 0.0 && fabs(th) + EPS < min_th) return 0;
    if (vmag_sq == 0.0 && th == 0.0) return 0;
    return 1;
}

/* The samples in XYThetaIterator's order (x outer, theta inner); returns their count. */
static long sample_twists(const double *par, double vx0, double vth0, double *cmd, int *th_index, long cap) {
    Iter1D xi, ti;
    int tpos = 0;
    double t = par[P_WINDOW_TIME];
    iter_init(&xi, vx0, par[P_MIN_VX], par[P_MAX_VX], par[P_ACC_X], par[P_DEC_X], t, (int)par[P_VX_SAMPLES]);
    iter_init(&ti, vth0, par[P_MIN_VTH], par[P_MAX_VTH], par[P_ACC_TH], par[P_DEC_TH], t, (int)par[P_VTH_SAMPLES]);
    long n = 0;
    int valid = valid_speed(par, iter_velocity(&xi), iter_velocity(&ti));
    for (;;) {
        if (!valid) { /* iterateToValidVelocity */
            while (!valid && !iter_finished(&xi)) {
                iter_next(&ti);
                tpos++;
                if (iter_finished(&ti)) {
                    iter_reset(&ti);
                    tpos = 0;
                    iter_next(&xi); /* the y iterator has one value: it finishes at once */
                }
                valid = valid_speed(par, iter_velocity(&xi), iter_velocity(&ti));
            }
        }
        if (iter_finished(&xi)) break;
        if (n < cap) {
            cmd[2 * n] = iter_velocity(&xi);
            cmd[2 * n + 1] = iter_velocity(&ti);
            th_index[n] = tpos;
        }
        n++;
        valid = 0;
    }
    return n;
}

/* StandardTrajectoryGenerator::getTimeSteps (discretised by distance). */
static long time_steps(const double *par, double vx, double vth) {
    double lin = fabs(vx) * par[P_SIM_TIME], ang = fabs(vth) * par[P_SIM_TIME];
    double a = lin / par[P_LIN_GRAN], b = ang / par[P_ANG_GRAN];
    long n = (long)ceil(a > b ? a : b);
    return n < 1 ? 1 : n;
}

/* The plan's poses at the costmap's resolution (nav_2d_utils::adjustPlanResolution), visited one by
   one as the map-grid critics' prepare() visits them. */
typedef struct {
    const Grid *g;
    int mode;             /* 0: seed every pose on the costmap (PathDist); 1: find the last one (GoalDist) */
    int started, stopped;
    long last_mx, last_my;
    int *dist;            /* mode 0: seeds set to 0 */
    long seeds;
} Walk;

static void walk_visit(Walk *w, double x, double y) {
    if (w->stopped) return;
    long mx, my;
    const Grid *g = w->g;
    if (world_to_map(g, x, y, &mx, &my) && g->cost[my * g->cols + mx] != 255) {
        if (w->mode == 0) {
            w->dist[my * g->cols + mx] = 0;
            w->seeds++;
        }
        w->last_mx = mx;
        w->last_my = my;
        w->started = 1;
    } else if (w->started) {
        w->stopped = 1;
    }
}

static void walk_plan(Walk *w, const double *xs, const double *ys, long n) {
    if (n <= 0) return;
    double res = w->g->res;
    double min_sq = res * res * 4.0;
    double lx = xs[0], ly = ys[0];
    walk_visit(w, lx, ly);
    for (long i = 1; i < n && !w->stopped; ++i) {
        double x = xs[i], y = ys[i];
        double sq = (x - lx) * (x - lx) + (y - ly) * (y - ly);
        if (sq > min_sq) {
            double diff = sqrt(sq) - sqrt(min_sq);
            int steps = (int)(diff / res) - 1;
            double sd = (double)steps;
            double dx = (x - lx) / sd, dy = (y - ly) / sd;
            for (int j = 1; j < steps; ++j) walk_visit(w, lx + j * dx, ly + j * dy);
        }
        walk_visit(w, x, y);
        lx = x;
        ly = y;
    }
}

/* Manhattan distance of every cell to the nearest seed (cells holding 0), in place: two passes. */
static void manhattan(int *d, long rows, long cols) {
    for (long r = 0; r < rows; ++r) {
        int *row = d + r * cols;
        for (long c = 0; c < cols; ++c) {
            int v = row[c];
            if (r > 0 && row[c - cols] + 1 < v) v = row[c - cols] + 1;
            if (c > 0 && row[c - 1] + 1 < v) v = row[c - 1] + 1;
            row[c] = v;
        }
    }
    for (long r = rows - 1; r >= 0; --r) {
        int *row = d + r * cols;
        for (long c = cols - 1; c >= 0; --c) {
            int v = row[c];
            if (r < rows - 1 && row[c + cols] + 1 < v) v = row[c + cols] + 1;
            if (c < cols - 1 && row[c + 1] + 1 < v) v = row[c + 1] + 1;
            row[c] = v;
        }
    }
}

/* Chessboard distance (cells) of every cell of a window [r0, r1) x [c0, c1) to the nearest illegal cell,
   counting the ring of cells just outside the window as illegal (the true distance is never smaller,
   so a pose's safe radius from it is never too large). `cost_limit` 256 makes only the outside illegal. */
static void clearance(int *d, const Grid *g, int cost_limit, long r0, long r1, long c0, long c1) {
    long cols = g->cols;
    for (long r = r0; r < r1; ++r) {
        for (long c = c0; c < c1; ++c) {
            long edge = r - r0 + 1;
            if (c - c0 + 1 < edge) edge = c - c0 + 1;
            if (r1 - r < edge) edge = r1 - r;
            if (c1 - c < edge) edge = c1 - c;
            d[r * cols + c] = g->cost[r * cols + c] >= cost_limit ? 0 : (int)edge;
        }
    }
    for (long r = r0; r < r1; ++r) {
        for (long c = c0; c < c1; ++c) {
            int v = d[r * cols + c];
            if (r > r0) {
                const int *up = d + (r - 1) * cols;
                if (up[c] + 1 < v) v = up[c] + 1;
                if (c > c0 && up[c - 1] + 1 < v) v = up[c - 1] + 1;
                if (c < c1 - 1 && up[c + 1] + 1 < v) v = up[c + 1] + 1;
            }
            if (c > c0 && d[r * cols + c - 1] + 1 < v) v = d[r * cols + c - 1] + 1;
            d[r * cols + c] = v;
        }
    }
    for (long r = r1 - 1; r >= r0; --r) {
        for (long c = c1 - 1; c >= c0; --c) {
            int v = d[r * cols + c];
            if (r < r1 - 1) {
                const int *dn = d + (r + 1) * cols;
                if (dn[c] + 1 < v) v = dn[c] + 1;
                if (c > c0 && dn[c - 1] + 1 < v) v = dn[c - 1] + 1;
                if (c < c1 - 1 && dn[c + 1] + 1 < v) v = dn[c + 1] + 1;
            }
            if (c < c1 - 1 && d[r * cols + c + 1] + 1 < v) v = d[r * cols + c + 1] + 1;
            d[r * cols + c] = v;
        }
    }
}

/* The window the clearance map covers; poses outside it are checked one by one. */
typedef struct {
    const int *d;
    long r0, r1, c0, c1;
} Clearance;

typedef struct {
    double x, y, th;   /* end pose */
    double c, s;       /* cos and sin of th */
} End;

/* The poses of one sample, step by step as StandardTrajectoryGenerator writes them (the start, each
   step's end, with include_last_point the end again), for `/local_plan`; returns how many. */
static long rollout(const double *par, const double *st, double cmd_x, double cmd_th, double *traj, long cap) {
    long n = time_steps(par, cmd_x, cmd_th);
    double dt = par[P_SIM_TIME] / (double)n;
    int limited = par[P_LIMITED] != 0.0;
    double x = st[S_X], y = st[S_Y], th = st[S_YAW];
    double v = st[S_VX], w = st[S_VTH];
    long k_out = 0;
    for (long k = 0; k <= n; ++k) {
        if (k > 0) { /* computeNewVelocity, then computeNewPosition from the heading before the step */
            v = limited ? cmd_x : project_velocity(v, par[P_ACC_X], par[P_DEC_X], dt, cmd_x);
            w = limited ? cmd_th : project_velocity(w, par[P_ACC_TH], par[P_DEC_TH], dt, cmd_th);
            double c = cos(th), s = sin(th);
            x = x + (v * c) * dt;
            y = y + (v * s) * dt;
            th = th + w * dt;
        }
        if (k_out < cap) {
            traj[3 * k_out] = x;
            traj[3 * k_out + 1] = y;
            traj[3 * k_out + 2] = th;
            k_out++;
        }
    }
    if (par[P_INCLUDE_LAST] != 0.0 && k_out < cap && k_out > 0) {
        traj[3 * k_out] = x;
        traj[3 * k_out + 1] = y;
        traj[3 * k_out + 2] = th;
        k_out++;
    }
    return k_out;
}

/* The headings of every trajectory turning towards one theta sample in n steps: they do not depend on
   the x sample, so the x samples of a theta sample share them. th[k] after step k (th + w * dt, w
   ramping as computeNewVelocity ramps it: exact in both tables). In the exact table c[k] and s[k] are
   libm's cos and sin of th[k], as Nav2 calls them; in the fast table they come from rotating (cos, sin)
   by each step's angle (within ~1e-14 of libm's), with C[k], S[k] the sums of c[0..k-1], s[0..k-1]
   (positions in closed form once the x velocity holds). */
typedef struct {
    long n;
    double dt, w;
    double *c, *s, *th, *C, *S;
} Heading;

static void heading_exact(Heading *h, const double *par, const double *st, double cmd_th, long n) {
    double dt = par[P_SIM_TIME] / (double)n;
    int limited = par[P_LIMITED] != 0.0;
    double w = st[S_VTH], th = st[S_YAW];
    h->n = n;
    h->dt = dt;
    h->w = cmd_th;
    h->th[0] = th;
    h->c[0] = cos(th);
    h->s[0] = sin(th);
    for (long k = 1; k <= n; ++k) {
        w = limited ? cmd_th : project_velocity(w, par[P_ACC_TH], par[P_DEC_TH], dt, cmd_th);
        th = th + w * dt;
        h->th[k] = th;
        h->c[k] = cos(th);
        h->s[k] = sin(th);
    }
}

/* sin and cos of a small angle (|a| <= 0.2, a Taylor polynomial exact to double precision), else libm. */
static void small_sincos(double a, double *s, double *c) {
    if (fabs(a) > 0.2) {
        *s = sin(a);
        *c = cos(a);
        return;
    }
    double a2 = a * a;
    *s = a * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0 * (1.0 - a2 / 72.0 * (1.0 - a2 / 110.0)))));
    *c = 1.0 - a2 / 2.0 * (1.0 - a2 / 12.0 * (1.0 - a2 / 30.0 * (1.0 - a2 / 56.0 * (1.0 - a2 / 90.0 * (1.0 - a2 / 132.0)))));
}

static void heading_fast(Heading *h, const double *par, const double *st, double cmd_th, long n) {
    double dt = par[P_SIM_TIME] / (double)n;
    int limited = par[P_LIMITED] != 0.0;
    double w = st[S_VTH], th = st[S_YAW], c = cos(th), s = sin(th);
    double w_rot = NAN, ca = 1.0, sa = 0.0;
    h->n = n;
    h->dt = dt;
    h->w = cmd_th;
    h->c[0] = c;
    h->s[0] = s;
    h->th[0] = th;
    h->C[0] = 0.0;
    h->S[0] = 0.0;
    for (long k = 1; k <= n; ++k) {
        w = limited ? cmd_th : project_velocity(w, par[P_ACC_TH], par[P_DEC_TH], dt, cmd_th);
        th = th + w * dt;
        if (w != w_rot) {
            w_rot = w;
            small_sincos(w * dt, &sa, &ca);
        }
        double c2 = c * ca - s * sa;
        s = s * ca + c * sa;
        c = c2;
        h->C[k] = h->C[k - 1] + h->c[k - 1];
        h->S[k] = h->S[k - 1] + h->s[k - 1];
        h->c[k] = c;
        h->s[k] = s;
        h->th[k] = th;
    }
}

/* Steps while the x velocity ramps towards the sample (none with LimitedAccelGenerator: it is the
   sample from the first step); returns that step count and the pose after it. */
static long ramp(const Heading *h, const double *par, const double *st, double vx, double *xr, double *yr) {
    long k = 0;
    double dt = h->dt, x = st[S_X], y = st[S_Y], v = st[S_VX];
    if (par[P_LIMITED] == 0.0) {
        while (k < h->n && v != vx) {
            k++;
            v = project_velocity(v, par[P_ACC_X], par[P_DEC_X], dt, vx);
            x = x + (v * h->c[k - 1]) * dt;
            y = y + (v * h->s[k - 1]) * dt;
        }
    }
    *xr = x;
    *yr = y;
    return k;
}

/* The end pose of one x sample from the fast table (closed form after the ramp; within ~1e-13 m). */
static void end_pose_fast(const Heading *h, const double *par, const double *st, double vx, End *e) {
    double xr, yr;
    long r = ramp(h, par, st, vx, &xr, &yr), n = h->n;
    double step = vx * h->dt;
    e->x = xr + step * (h->C[n] - h->C[r]);
    e->y = yr + step * (h->S[n] - h->S[r]);
    e->th = h->th[n];
    e->c = h->c[n];
    e->s = h->s[n];
}

/* The end pose of one x sample, step by step as StandardTrajectoryGenerator integrates it (exact table). */
static void end_pose_exact(const Heading *h, const double *par, const double *st, double vx, End *e) {
    long n = h->n;
    double dt = h->dt, x = st[S_X], y = st[S_Y], v = st[S_VX];
    long k = 1;
    if (par[P_LIMITED] != 0.0) v = vx;
    for (; k <= n && v != vx; ++k) { /* the ramp; then the velocity holds at the sample */
        v = project_velocity(v, par[P_ACC_X], par[P_DEC_X], dt, vx);
        x = x + (v * h->c[k - 1]) * dt;
        y = y + (v * h->s[k - 1]) * dt;
    }
    for (; k <= n; ++k) {
        x = x + (vx * h->c[k - 1]) * dt;
        y = y + (vx * h->s[k - 1]) * dt;
    }
    e->x = x;
    e->y = y;
    e->th = h->th[n];
    e->c = h->c[n];
    e->s = h->s[n];
}

/* True when a point lies within 1e-7 cell of a cell edge (or the costmap's): there a fast-table
   position (within ~1e-12 cell of the exact one) might fall in another cell than Nav2's. */
static int near_edge(const Grid *g, double wx, double wy) {
    double fx = (wx - g->ox) / g->res, fy = (wy - g->oy) / g->res;
    double rx = fx - floor(fx), ry = fy - floor(fy);
    return rx < 1e-7 || rx > 1.0 - 1e-7 || ry < 1e-7 || ry > 1.0 - 1e-7;
}

/* Check a pose; on success set *safe to the distance within which no other pose needs checking. */
static int check_pose(const Grid *g, const Clearance *clear, int checks, double x, double y, double *safe) {
    long mx, my;
    if (!world_to_map(g, x, y, &mx, &my)) return 0;
    long idx = my * g->cols + mx;
    if (checks == CHECK_COST && g->cost[idx] >= 253) return 0;
    if (my >= clear->r0 && my < clear->r1 && mx >= clear->c0 && mx < clear->c1)
        *safe = (double)(clear->d[idx] - 1) * g->res - 1e-9;
    else
        *safe = -1.0;
    return 1;
}

/* Every pose of one sample's trajectory on the costmap (and, CHECK_COST, on a cell below 253), from
   the exact table, step by step as for the end pose; poses closer to a checked one than any illegal
   cell are not looked up: they cannot be illegal. */
static int poses_legal_exact(const Heading *h, const double *par, const double *st, const Grid *g,
                             const Clearance *clear, int checks, double vx) {
    long n = h->n;
    double dt = h->dt, x = st[S_X], y = st[S_Y], v = st[S_VX];
    int limited = par[P_LIMITED] != 0.0;
    double budget = 0.0; /* distance left before a pose must be checked */
    if (!check_pose(g, clear, checks, x, y, &budget)) return 0;
    for (long k = 1; k <= n; ++k) {
        v = limited ? vx : project_velocity(v, par[P_ACC_X], par[P_DEC_X], dt, vx);
        x = x + (v * h->c[k - 1]) * dt;
        y = y + (v * h->s[k - 1]) * dt;
        budget -= fabs(v) * dt;
        if ((budget <= 0.0 || k == n) && !check_pose(g, clear, checks, x, y, &budget)) return 0;
    }
    return 1;
}

/* The same from the fast table, in closed form once the velocity holds: 1 legal, 0 illegal, -1 when a
   checked pose lies on a cell edge (then only the exact table decides). */
static int poses_legal_fast(const Heading *h, const double *par, const double *st, const Grid *g,
                            const Clearance *clear, int checks, double vx) {
    long n = h->n, k = 0;
    double dt = h->dt, x = st[S_X], y = st[S_Y], v = st[S_VX];
    double budget = 0.0;
    if (!check_pose(g, clear, checks, x, y, &budget)) return 0;
    if (par[P_LIMITED] == 0.0) {
        while (k < n && v != vx) {
            k++;
            v = project_velocity(v, par[P_ACC_X], par[P_DEC_X], dt, vx);
            x = x + (v * h->c[k - 1]) * dt;
            y = y + (v * h->s[k - 1]) * dt;
            budget -= fabs(v) * dt;
            if (budget <= 0.0 || k == n) {
                if (near_edge(g, x, y)) return -1;
                if (!check_pose(g, clear, checks, x, y, &budget)) return 0;
            }
        }
    }
    long r = k;
    double xr = x, yr = y, step = vx * dt, len = fabs(step);
    while (k < n) {
        long j;
        if (len == 0.0) j = n;
        else if (budget <= 0.0) j = k + 1;
        else {
            double m = ceil(budget / len);
            j = m >= (double)(n - k) ? n : k + (long)m;
            if (j <= k) j = k + 1;
        }
        x = xr + step * (h->C[j] - h->C[r]);
        y = yr + step * (h->S[j] - h->S[r]);
        if (near_edge(g, x, y)) return -1;
        if (!check_pose(g, clear, checks, x, y, &budget)) return 0;
        k = j;
    }
    return 1;
}

/* One sample's legality: the fast table, and the exact one where the fast one cannot tell. */
static int poses_legal(Heading *h, Heading *hx, const double *par, const double *st, const Grid *g,
                       const Clearance *clear, int checks, double vx, double vth, long steps) {
    if (h->n != steps || h->w != vth) heading_fast(h, par, st, vth, steps);
    int r = poses_legal_fast(h, par, st, g, clear, checks, vx);
    if (r >= 0) return r;
    if (hx->n != steps || hx->w != vth) heading_exact(hx, par, st, vth, steps);
    return poses_legal_exact(hx, par, st, g, clear, checks, vx);
}

/* angles::shortest_angular_distance (angles 1.15, Humble): normalize_angle(to - from) */
static double shortest_angle(double from, double to) {
    double r = fmod((to - from) + M_PI, 2.0 * M_PI);
    return r <= 0.0 ? r + M_PI : r - M_PI;
}

static int has_critic(const double *par, int code, double *scale) {
    int n = (int)par[P_N_CRITICS];
    for (int i = 0; i < n; ++i) {
        if ((int)par[P_CRITICS + 2 * i] == code && par[P_CRITICS + 2 * i + 1] != 0.0) {
            if (scale) *scale = par[P_CRITICS + 2 * i + 1];
            return 1;
        }
    }
    return 0;
}

#define UNCHECKED 1   /* scored; the poses between the start and the end not yet checked */
#define LEGAL 2
#define LAZY_LIMIT 24 /* illegal best candidates tolerated before every sample is checked */

/* One cycle; see the top of this file. `plan` holds the global plan (n_plan x 3) in its own frame,
   `st` the robot and the critics' state, `cost` the local costmap (rows x cols, row-major, y rows).
   Writes out[] and, for the best sample, its poses (traj_cap x 3). Returns out[O_STATUS]. */
int twin_dwb_cycle(const double *par, double *st, const double *plan, long n_plan, const unsigned char *cost,
                   long rows, long cols, double ox, double oy, double res, double *out, double *traj,
                   long traj_cap) {
    Grid g = {cost, rows, cols, ox, oy, res};
    for (int i = 0; i <= O_N_TRAJ; ++i) out[i] = 0.0;
    if (n_plan <= 0) return (int)(out[O_STATUS] = STATUS_EMPTY_PLAN);

    /* transformGlobalPlan: the robot in the plan's frame, the plan cut around it */
    double tx = st[S_TX], ty = st[S_TY], tyaw = st[S_TYAW];
    double tc = cos(tyaw), ts = sin(tyaw);
    double rx = tc * (st[S_X] - tx) + ts * (st[S_Y] - ty);
    double ry = -ts * (st[S_X] - tx) + tc * (st[S_Y] - ty);
    double dist_threshold = (double)(cols > rows ? cols : rows) * res / 2.0;
    double prune_dist = par[P_PRUNE_DIST];
    double start_thr = par[P_PRUNE_PLAN] != 0.0 ? fmin(dist_threshold, prune_dist) : dist_threshold;
    double end_thr = par[P_SHORTEN] != 0.0 ? fmin(dist_threshold, par[P_FWD_PRUNE]) : dist_threshold;
    long prune_point = n_plan;
    double along = 0.0;
    for (long i = 0; i + 1 < n_plan; ++i) {
        along += hypot(plan[3 * i] - plan[3 * (i + 1)], plan[3 * i + 1] - plan[3 * (i + 1) + 1]);
        if (along > prune_dist) {
            prune_point = i + 1;
            break;
        }
    }
    long begin = prune_point;
    for (long i = 0; i < prune_point; ++i) {
        if (hypot(rx - plan[3 * i], ry - plan[3 * i + 1]) < start_thr) {
            begin = i;
            break;
        }
    }
    long end = n_plan;
    for (long i = begin; i < n_plan; ++i) {
        if (hypot(plan[3 * i] - rx, plan[3 * i + 1] - ry) > end_thr) {
            end = i;
            break;
        }
    }
    out[O_BEGIN] = (double)begin;
    out[O_END] = (double)end;
    long m = end - begin;
    if (m <= 0) return (int)(out[O_STATUS] = STATUS_EMPTY_TRANSFORMED);

    /* memory: the cut plan, the samples and their scores, the heading tables, two cell maps */
    long cells = rows * cols;
    double nx = par[P_VX_SAMPLES] > 2 ? par[P_VX_SAMPLES] : 2, nt = par[P_VTH_SAMPLES] > 2 ? par[P_VTH_SAMPLES] : 2;
    long cap = (long)((nx + 2) * (nt + 2));
    double vmax = fmax(fabs(par[P_MIN_VX]), fabs(par[P_MAX_VX]));
    long max_steps = (long)ceil(fmax(vmax * par[P_SIM_TIME] / par[P_LIN_GRAN],
                                     fabs(par[P_MAX_VTH]) * par[P_SIM_TIME] / par[P_ANG_GRAN])) + 2;
    double *dbl = malloc(sizeof(double) * (size_t)(2 * m + 3 * cap + 8 * (max_steps + 1)));
    int *ints = malloc(sizeof(int) * (size_t)(2 * cells + 2 * cap + (long)nt + 4));
    long *order = malloc(sizeof(long) * (size_t)cap);
    unsigned char *state = malloc((size_t)cap);
    if (dbl == NULL || ints == NULL || order == NULL || state == NULL) {
        free(dbl);
        free(ints);
        free(order);
        free(state);
        return (int)(out[O_STATUS] = STATUS_NO_MEMORY);
    }
    double *xs = dbl, *ys = dbl + m, *cmd = dbl + 2 * m, *totals = dbl + 2 * m + 2 * cap;
    double *tab = dbl + 2 * m + 3 * cap;
    long stride = max_steps + 1;
    Heading h = {-1, 0.0, 0.0, tab, tab + stride, tab + 2 * stride, tab + 3 * stride, tab + 4 * stride};
    Heading hx = {-1, 0.0, 0.0, tab + 5 * stride, tab + 6 * stride, tab + 7 * stride, NULL, NULL};
    int *path_map = ints, *th_index = ints + 2 * cells, *first = th_index + cap;
    Clearance clear = {ints + cells, 0, 0, 0, 0};
    for (long i = 0; i < m; ++i) {
        const double *p = plan + 3 * (begin + i);
        xs[i] = tx + tc * p[0] - ts * p[1];
        ys[i] = ty + ts * p[0] + tc * p[1];
    }
    const double *last = plan + 3 * (n_plan - 1);
    double gx = tx + tc * last[0] - ts * last[1], gy = ty + ts * last[0] + tc * last[1];
    double gyaw = last[2] + tyaw;
    double px = st[S_X], py = st[S_Y];

    /* prepare(): RotateToGoal's window, the map-grid critics' seeds */
    double dxy_sq = (px - gx) * (px - gx) + (py - gy) * (py - gy);
    double tol = par[P_XY_GOAL_TOL], stopped = par[P_STOPPED_VEL];
    double cur_sq = st[S_VX] * st[S_VX];
    if (dxy_sq <= tol * tol) st[S_ROT_IN_WINDOW] = 1.0;
    if (st[S_ROT_IN_WINDOW] != 0.0 && cur_sq <= stopped * stopped) st[S_ROT_ROTATING] = 1.0;
    int in_window = st[S_ROT_IN_WINDOW] != 0.0, rotating = st[S_ROT_ROTATING] != 0.0;

    double s_rot = 0, s_base = 0, s_galign = 0, s_palign = 0, s_pdist = 0, s_gdist = 0;
    int use_rot = has_critic(par, C_ROTATE, &s_rot);
    int use_osc = has_critic(par, C_OSCILLATION, NULL);
    int use_base = has_critic(par, C_BASE_OBSTACLE, &s_base);
    int use_galign = has_critic(par, C_GOAL_ALIGN, &s_galign);
    int use_palign = has_critic(par, C_PATH_ALIGN, &s_palign);
    int use_pdist = has_critic(par, C_PATH_DIST, &s_pdist);
    int use_gdist = has_critic(par, C_GOAL_DIST, &s_gdist);
    double fpd_path = par[P_PATH_ALIGN_FPD], fpd_goal = par[P_GOAL_ALIGN_FPD];
    if (use_palign && dxy_sq <= fpd_path * fpd_path) use_palign = 0; /* PathAlign's zero scale near the goal */
    double unit = res * 0.5; /* MapGridCritic::getScale: the scale counts per half cell */
    int active[16], n_active = 0; /* the critics that score, in their order (Oscillation scores 0) */
    for (int k = 0; k < (int)par[P_N_CRITICS] && n_active < 16; ++k) {
        int code = (int)par[P_CRITICS + 2 * k];
        if (par[P_CRITICS + 2 * k + 1] == 0.0 || code == C_OSCILLATION || (code == C_PATH_ALIGN && !use_palign)) continue;
        active[n_active++] = code;
    }
    double unreachable = (double)cells + 1.0;

    int path_ok = 0, goal_ok = 0, align_ok = 0;
    if (use_pdist || use_palign) {
        for (long i = 0; i < cells; ++i) path_map[i] = BIG;
        Walk w = {&g, 0, 0, 0, 0, 0, path_map, 0};
        walk_plan(&w, xs, ys, m);
        path_ok = w.seeds > 0;
        if (path_ok) manhattan(path_map, rows, cols);
    }
    /* GoalDist and GoalAlign seed one cell each: their distance is |dx| + |dy| to it, no map needed */
    long goal_mx = 0, goal_my = 0, align_mx = 0, align_my = 0;
    if (use_gdist) {
        Walk w = {&g, 1, 0, 0, 0, 0, NULL, 0};
        walk_plan(&w, xs, ys, m);
        goal_ok = w.started;
        goal_mx = w.last_mx;
        goal_my = w.last_my;
    }
    if (use_galign) {
        double angle = atan2(gy - py, gx - px);
        double keep_x = xs[m - 1], keep_y = ys[m - 1];
        xs[m - 1] += fpd_goal * cos(angle);
        ys[m - 1] += fpd_goal * sin(angle);
        Walk w = {&g, 1, 0, 0, 0, 0, NULL, 0};
        walk_plan(&w, xs, ys, m);
        xs[m - 1] = keep_x;
        ys[m - 1] = keep_y;
        align_ok = w.started;
        align_mx = w.last_mx;
        align_my = w.last_my;
    }
    int checks = use_base ? CHECK_COST : (use_pdist || use_gdist) ? CHECK_GRID : CHECK_NONE;
    int clear_ready = 0;
    /* PathDist or GoalDist without seeds makes every pose unreachable; an illegal start pose, every trajectory */
    int all_illegal = (use_pdist && !path_ok) || (use_gdist && !goal_ok);
    if (checks != CHECK_NONE && !all_illegal) {
        long mx, my;
        if (!world_to_map(&g, px, py, &mx, &my) || (checks == CHECK_COST && cost[my * cols + mx] >= 253))
            all_illegal = 1;
    }

    /* the samples, grouped by theta sample so that each group shares its heading table */
    long n = sample_twists(par, st[S_VX], st[S_VTH], cmd, th_index, cap);
    if (n > cap) n = cap;
    out[O_N_SAMPLES] = (double)n;
    int groups = 0;
    for (long i = 0; i < n; ++i) groups = th_index[i] + 1 > groups ? th_index[i] + 1 : groups;
    for (int j = 0; j <= groups; ++j) first[j] = 0;
    for (long i = 0; i < n; ++i) first[th_index[i] + 1]++;
    for (int j = 0; j < groups; ++j) first[j + 1] += first[j];
    for (long i = 0; i < n; ++i) order[first[th_index[i]]++] = i;

    /* score every sample from its end pose; what needs the poses in between is checked lazily below */
    for (long q = 0; q < n; ++q) {
        long i = order[q];
        double vx = cmd[2 * i], vth = cmd[2 * i + 1];
        double speed_sq = vx * vx;
        state[i] = 0;
        if (all_illegal) continue;
        if (use_osc && (((st[S_OSC_X_POS] != 0.0) && vx < 0.0) || ((st[S_OSC_X_NEG] != 0.0) && vx > 0.0) ||
                        ((st[S_OSC_TH_POS] != 0.0) && vth < 0.0) || ((st[S_OSC_TH_NEG] != 0.0) && vth > 0.0)))
            continue;
        if (use_rot && in_window) {
            if (!rotating && speed_sq >= cur_sq) continue;
            if (rotating && fabs(vx) > 0.0) continue;
        }
        long steps = time_steps(par, vx, vth);
        if (steps > max_steps) steps = max_steps;
        if (h.n != steps || h.w != vth) heading_fast(&h, par, st, vth, steps);
        End e;
        end_pose_fast(&h, par, st, vx, &e);
        if (near_edge(&g, e.x, e.y) || (use_galign && near_edge(&g, e.x + fpd_goal * e.c, e.y + fpd_goal * e.s)) ||
            (use_palign && near_edge(&g, e.x + fpd_path * e.c, e.y + fpd_path * e.s))) {
            /* a looked-up point on a cell edge: Nav2's exact doubles decide its cell */
            if (hx.n != steps || hx.w != vth) heading_exact(&hx, par, st, vth, steps);
            end_pose_exact(&hx, par, st, vx, &e);
        }
        long emx = 0, emy = 0;
        int end_on = world_to_map(&g, e.x, e.y, &emx, &emy);
        int end_cost = end_on ? cost[emy * cols + emx] : 255;
        if (checks != CHECK_NONE && (!end_on || (checks == CHECK_COST && end_cost >= 253))) continue;
        /* each active critic's weighted score, summed in the configured order */
        double part[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        int ok = 1;
        long mx, my;
        if (use_rot && in_window) {
            double rot = fabs(shortest_angle(e.th, gyaw));
            part[C_ROTATE] = (rotating ? rot : speed_sq * par[P_SLOWING] + rot) * s_rot;
        }
        if (use_base) part[C_BASE_OBSTACLE] = (double)end_cost * s_base;
        if (use_galign) {
            if (!world_to_map(&g, e.x + fpd_goal * e.c, e.y + fpd_goal * e.s, &mx, &my)) continue;
            part[C_GOAL_ALIGN] = (align_ok ? (double)(labs(mx - align_mx) + labs(my - align_my)) : unreachable) * (unit * s_galign);
        }
        if (use_palign) {
            if (!world_to_map(&g, e.x + fpd_path * e.c, e.y + fpd_path * e.s, &mx, &my)) continue;
            part[C_PATH_ALIGN] = (path_ok ? (double)path_map[my * cols + mx] : unreachable) * (unit * s_palign);
        }
        if ((use_pdist || use_gdist) && !end_on) continue;
        if (use_pdist) part[C_PATH_DIST] = (double)path_map[emy * cols + emx] * (unit * s_pdist);
        if (use_gdist) part[C_GOAL_DIST] = (double)(labs(emx - goal_mx) + labs(emy - goal_my)) * (unit * s_gdist);
        double total = 0.0;
        for (int k = 0; k < n_active; ++k) total += part[active[k]];
        if (!ok) continue;
        state[i] = checks == CHECK_NONE ? LEGAL : UNCHECKED;
        totals[i] = total;
    }

    /* the first lowest total in the iterator's order among the legal samples (coreScoringAlgorithm):
       candidates in order of (total, index), their poses checked until one is legal */
    long best = -1, failures = 0;
    for (;;) {
        long cand = -1;
        for (long i = 0; i < n; ++i) {
            if (state[i] && (cand < 0 || totals[i] < totals[cand])) cand = i;
        }
        if (cand < 0) break;
        if (state[cand] == LEGAL) {
            best = cand;
            break;
        }
        if (!clear_ready) { /* around the robot, as far as a trajectory can go */
            long rmx = 0, rmy = 0;
            world_to_map(&g, px, py, &rmx, &rmy);
            long reach = (long)ceil(fmax(vmax, fabs(st[S_VX])) * par[P_SIM_TIME] / res) + 3;
            clear.r0 = rmy - reach > 0 ? rmy - reach : 0;
            clear.r1 = rmy + reach + 1 < rows ? rmy + reach + 1 : rows;
            clear.c0 = rmx - reach > 0 ? rmx - reach : 0;
            clear.c1 = rmx + reach + 1 < cols ? rmx + reach + 1 : cols;
            clearance(ints + cells, &g, checks == CHECK_COST ? 253 : 256, clear.r0, clear.r1, clear.c0, clear.c1);
            clear_ready = 1;
        }
        if (failures >= LAZY_LIMIT) { /* many illegal leaders: check the rest in one pass */
            for (long i = 0; i < n; ++i) {
                if (state[i] != UNCHECKED) continue;
                double vx = cmd[2 * i], vth = cmd[2 * i + 1];
                long steps = time_steps(par, vx, vth);
                if (steps > max_steps) steps = max_steps;
                state[i] = poses_legal(&h, &hx, par, st, &g, &clear, checks, vx, vth, steps) ? LEGAL : 0;
            }
            continue;
        }
        double vx = cmd[2 * cand], vth = cmd[2 * cand + 1];
        long steps = time_steps(par, vx, vth);
        if (steps > max_steps) steps = max_steps;
        if (poses_legal(&h, &hx, par, st, &g, &clear, checks, vx, vth, steps)) {
            state[cand] = LEGAL;
            best = cand;
            break;
        }
        state[cand] = 0;
        failures++;
    }
    long n_legal = 0;
    for (long i = 0; i < n; ++i) n_legal += state[i] == LEGAL;
    out[O_N_LEGAL] = (double)n_legal;
    if (best >= 0) {
        out[O_VX] = cmd[2 * best];
        out[O_VTH] = cmd[2 * best + 1];
        out[O_TOTAL] = totals[best];
        out[O_N_TRAJ] = (double)rollout(par, st, cmd[2 * best], cmd[2 * best + 1], traj, traj_cap);
    }
    free(dbl);
    free(ints);
    free(order);
    free(state);
    return (int)(out[O_STATUS] = best >= 0 ? STATUS_OK : STATUS_NO_LEGAL);
}
