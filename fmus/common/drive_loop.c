/* twin's compiled drive loop: the FMU drivetrain's per-step path for two wheels, in C.
 *
 * Not part of any FMU. It does, step for step and operation for operation, what the Python reference
 * does (FmuDrivetrain._run_voltage / _run_servo in twin/robot/drivetrain.py and Chassis.update in
 * twin/robot/chassis.py): the setpoints' acceleration ramp, the wheel-speed PI with conditional
 * integration (profile voltage) or the speed setpoint (profile velocity-servo), the unit conversions, one step of both FMUs through the
 * shim's slots, then the chassis: slip, midpoint integration, the drive-torque estimate, rolling
 * resistance and the load torques of the coupled modes, with the holding torque of a blocked mode.
 * Keep the two in step: the tests compare them to the last bits. Build without -ffast-math and
 * without FMA contraction (twin.cosim.build does) so the arithmetic is the same as Python's.
 *
 * Contact is the one thing not done here: the world is Python's. The caller gives a travel budget
 * (how far the robot may move with no contact possible) and the loop counts the chassis' motion
 * bound, translation plus |rotation| x reach_m, over the steps it takes; it stops before the chassis
 * update of a step that would reach the budget, so the caller can do that update with the contact
 * checks. A step that leaves the pose where it is needs no contact check and is always taken: one
 * with no motion, and one whose motion is below the pose's float resolution (a stopped wheel's speed
 * decays for ever; a robot pressed against another creeps so in the mode its contact does not
 * block). Chassis.update never refuses such a step either.
 */
#include <math.h>
#include <stdbool.h>

#include "step_shim.h"

/* Budget kept back for the rounding in the caller's distances. */
#define TWIN_BUDGET_MARGIN_M 1e-9

typedef struct {
    /* Setup. */
    TwinSlot *slots;             /* left, right */
    long long *step_index;       /* communication steps taken (the StepGroup's counter) */
    const double *slip_regions;  /* n_slip_regions x (x_min, x_max, y_min, y_max, slip), world frame */
    int n_slip_regions;
    int servo;                   /* 1: the FMU takes the speed setpoint; 0: the PI gives the voltage */
    int has_slip;                /* 0: no slip anywhere (then slip and the regions are unused) */
    int failed;                  /* out: the slot that failed, else -1 */
    int stopped_on_budget;       /* out: the last run stopped before a chassis update on the budget */
    double budget_m;             /* in: motion known free of contact for the next run (INFINITY: no world) */
    double step_s;               /* communication step */
    double kp, ki, v_max;        /* PI: V per rad/s, V per rad, output clamp V */
    double cmd_scale, cmd_offset, load_scale, load_offset, speed_scale, speed_offset; /* twin <-> FMU units */
    double half_r, r_over_b;     /* chassis kinematics: r / 2, r / b */
    double m_common, m_diff;     /* per-wheel chassis inertia of the common and differential modes */
    double j, j_over_h;          /* the drive's own inertia at the wheel, and over the step */
    double k_common, k_diff;     /* share of a mode's drive torque the chassis takes, without slip */
    double roll_nm, roll_gain;   /* rolling resistance at the rim, and its ramp gain per rad/s */
    double hold_damping;         /* fraction of a blocked mode's speed removed per step */
    double slip;                 /* outside the regions */
    double reach_m;              /* bounding radius for the motion bound */
    double ramp_radps;           /* largest change of a speed setpoint per step, rad/s (INFINITY: none) */
    /* Wheels. */
    double target_left, target_right; /* commanded wheel speeds, rad/s, after the limits */
    double ref_left, ref_right;  /* speed setpoints, rad/s: the targets reached under the ramp */
    double w_left, w_right;      /* FMU wheel speeds, rad/s */
    double int_left, int_right;  /* PI integrators, rad */
    double volt_left, volt_right;
    /* Chassis (twin.robot.chassis.ChassisDynamics). */
    double x_m, y_m, yaw_rad, v_mps, yaw_rate_radps, ax_mps2, ay_mps2, yaw_accel_radps2;
    double block_common, block_diff; /* sign of a blocked mode's motion, 0 when free */
    double w_left_prev_radps, w_right_prev_radps;
    double wheel_angle_left_rad, wheel_angle_right_rad;
    double load_left_nm, load_right_nm;
    bool blocked;
} TwinDrive;

static double pi_volts(const TwinDrive *d, double ref, double w, double *integral) {
    const double e = ref - w;
    const double u = d->kp * e + d->ki * *integral;
    const double v = u > d->v_max ? d->v_max : (u < -d->v_max ? -d->v_max : u);
    if (v == u || (u > 0.0) != (e > 0.0)) *integral += e * d->step_s; /* no wind-up while saturated */
    return v;
}

/* One step of the setpoint towards the target, at most `step` (gazebo_ros_diff_drive's
 * max_wheel_acceleration, and the TB3 firmware's profile acceleration). */
static double ramp_to(double ref, double target, double step) {
    const double err = target - ref;
    return fabs(err) <= step ? target : ref + copysign(step, err);
}

static double slip_at(const TwinDrive *d, double x, double y) {
    for (int k = 0; k < d->n_slip_regions; k++) {
        const double *r = d->slip_regions + 5 * k;
        if (r[0] <= x && x <= r[1] && r[2] <= y && y <= r[3]) return r[4];
    }
    return d->slip;
}

static double unit_ramp(double a) { return a > 1.0 ? 1.0 : (a < -1.0 ? -1.0 : a); }

/* Whether a step at body speeds v, w leaves the pose exactly where it is (the same arithmetic as
 * chassis_step's update, so "the same" is bit for bit). */
static bool stays_in_place(const TwinDrive *d, double v, double w) {
    const double h = d->step_s, yaw = d->yaw_rad, vh = v * h, mid = yaw + 0.5 * w * h;
    return d->x_m + vh * cos(mid) == d->x_m && d->y_m + vh * sin(mid) == d->y_m && yaw + w * h == yaw;
}

/* The chassis update for the wheel speeds in d->w_left, d->w_right; false (and nothing changed) if
 * its motion would use up the budget. */
static bool chassis_step(TwinDrive *d, double *used_m, double usable_m) {
    const double h = d->step_s, wl = d->w_left, wr = d->w_right;
    double scale = 1.0, k_common = d->k_common, k_diff = d->k_diff;
    if (d->has_slip) {
        scale = 1.0 - slip_at(d, d->x_m, d->y_m);
        const double m_common = d->m_common * scale * scale, m_diff = d->m_diff * scale * scale;
        k_common = m_common / (d->j + m_common);
        k_diff = m_diff / (d->j + m_diff);
    }
    const double v = d->block_common != 0.0 ? 0.0 : scale * d->half_r * (wl + wr);
    const double w = d->block_diff != 0.0 ? 0.0 : scale * d->r_over_b * (wr - wl);
    if (v != 0.0 || w != 0.0) {
        const double travel = fabs(v * h) + d->reach_m * fabs(w * h);
        if (*used_m + travel < usable_m) {
            *used_m += travel;
        } else if (!stays_in_place(d, v, w)) {
            return false;
        }
    }
    d->wheel_angle_left_rad += wl * h;
    d->wheel_angle_right_rad += wr * h;
    const double yaw = d->yaw_rad, vh = v * h, mid = yaw + 0.5 * w * h;
    d->x_m = d->x_m + vh * cos(mid);
    d->y_m = d->y_m + vh * sin(mid);
    d->yaw_rad = yaw + w * h;
    d->ax_mps2 = (v - d->v_mps) / h;
    d->yaw_accel_radps2 = (w - d->yaw_rate_radps) / h;
    d->ay_mps2 = v * w;
    d->v_mps = v;
    d->yaw_rate_radps = w;

    /* Load torques for the next step, from the drive torques estimated over this one. */
    const double j_h = d->j_over_h;
    const double d_left = j_h * (wl - d->w_left_prev_radps) + d->load_left_nm;
    const double d_right = j_h * (wr - d->w_right_prev_radps) + d->load_right_nm;
    d->w_left_prev_radps = wl;
    d->w_right_prev_radps = wr;
    const double ext_left = d->roll_nm * unit_ramp(wl * d->roll_gain);
    const double ext_right = d->roll_nm * unit_ramp(wr * d->roll_gain);
    const double d_common = 0.5 * (d_left + d_right - ext_left - ext_right);
    const double d_diff = 0.5 * (d_right - d_left - ext_right + ext_left);
    if (d->block_common != 0.0 && d_common * d->block_common < 0.0) d->block_common = 0.0; /* pulls away */
    const double t_common = d->block_common != 0.0 ? d_common + d->hold_damping * j_h * 0.5 * (wl + wr)
                                                   : k_common * d_common;
    if (d->block_diff != 0.0 && d_diff * d->block_diff < 0.0) d->block_diff = 0.0;
    const double t_diff = d->block_diff != 0.0 ? d_diff + d->hold_damping * j_h * 0.5 * (wr - wl)
                                               : k_diff * d_diff;
    d->load_left_nm = t_common - t_diff + ext_left;
    d->load_right_nm = t_common + t_diff + ext_right;
    d->blocked = d->block_common != 0.0 || d->block_diff != 0.0;
    return true;
}

/* Run up to `count` communication steps within d->budget_m of motion. Returns the steps fully taken.
 * A shorter run either failed in an FMU (d->failed is its slot; the FMUs did not advance, the PI
 * did) or stopped on the budget (d->stopped_on_budget: the FMUs of the next step were stepped and
 * d->w_left, d->w_right hold their speeds; its chassis update is left to the caller). The arguments
 * are an int and a pointer so that ctypes passes them without declared types (the cheapest call). */
int twin_drive_run(TwinDrive *d, int count) {
    double *in_left = d->slots[0].in, *in_right = d->slots[1].in;
    const double *out_left = d->slots[0].out, *out_right = d->slots[1].out;
    const double usable_m = d->budget_m - TWIN_BUDGET_MARGIN_M;
    double used_m = 0.0;
    d->failed = -1;
    d->stopped_on_budget = 0;
    for (int k = 0; k < count; k++) {
        d->ref_left = ramp_to(d->ref_left, d->target_left, d->ramp_radps);
        d->ref_right = ramp_to(d->ref_right, d->target_right, d->ramp_radps);
        if (d->servo) {
            in_left[0] = (d->ref_left - d->cmd_offset) * d->cmd_scale;
            in_right[0] = (d->ref_right - d->cmd_offset) * d->cmd_scale;
        } else {
            d->volt_left = pi_volts(d, d->ref_left, d->w_left, &d->int_left);
            d->volt_right = pi_volts(d, d->ref_right, d->w_right, &d->int_right);
            in_left[0] = (d->volt_left - d->cmd_offset) * d->cmd_scale;
            in_right[0] = (d->volt_right - d->cmd_offset) * d->cmd_scale;
        }
        in_left[1] = (d->load_left_nm - d->load_offset) * d->load_scale;
        in_right[1] = (d->load_right_nm - d->load_offset) * d->load_scale;
        const int failed = twin_step_next(d->slots, 2, d->step_index, &d->step_s);
        if (failed >= 0) {
            d->failed = failed;
            return k;
        }
        d->w_left = d->speed_scale * out_left[0] + d->speed_offset;
        d->w_right = d->speed_scale * out_right[0] + d->speed_offset;
        if (!chassis_step(d, &used_m, usable_m)) {
            d->stopped_on_budget = 1;
            return k;
        }
    }
    return count;
}
