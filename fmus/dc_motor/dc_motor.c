/* DC motor + gearbox + wheel, for FMI 2.0 and 3.0 Co-Simulation.
 *
 * States (wheel side): armature current i [A], wheel speed w [rad/s], wheel angle phi [rad].
 *   L di/dt   = V - R i - Ke N w
 *   J dw/dt   = N Kt i - b w - tau_load,     J = J_rotor N^2 + J_wheel,  b = b_rotor N^2
 *   dphi/dt   = w
 * V is the input voltage clamped to +-V_max. The ODE is linear, so each step uses its exact
 * zero-order-hold discretisation (matrix exponential, fmus/common/linsys.c): stable and exact at
 * any communication step, however small L/R is.
 *
 * With SERVO defined the input is a wheel-speed setpoint and a PI controller inside the FMU sets
 * the voltage, like a Dynamixel in velocity mode: it runs every servo_period (the step is cut into
 * equal substeps no longer than that), is tuned for a first-order closed loop with time constant
 * servo_time_constant, saturates at V_max and stops integrating while saturated.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "linsys.h"
#include "model.h"
#include "model_vars.h"
#include "var_table.h"

typedef struct {
    double v[MODEL_NVR];
    double h_sub_s;  /* substep the matrices below were computed for; 0 = none */
    int n_sub;
    double Phi[9];   /* 3 x 3 */
    double Gam[6];   /* 3 x 2, inputs (V, tau_load) */
    double kp, ki, integral;
} Motor;

void *model_new(void) {
    Motor *m = calloc(1, sizeof *m);
    if (m != NULL) vt_reset(m->v);
    return m;
}

void model_free(void *m) { free(m); }

void model_reset(void *p) {
    Motor *m = p;
    vt_reset(m->v);
    m->h_sub_s = 0.0;
    m->integral = 0.0;
}

int model_set(void *p, unsigned vr, double value, int initializing, char *msg) {
    return vt_set(((Motor *)p)->v, vr, value, initializing, msg);
}

int model_get(void *p, unsigned vr, double *value, char *msg) { return vt_get(((Motor *)p)->v, vr, value, msg); }

static double inertia(const double *v) { return v[VR_J_rotor] * v[VR_N] * v[VR_N] + v[VR_J_wheel]; }
static double friction(const double *v) { return v[VR_b_rotor] * v[VR_N] * v[VR_N]; }

static void outputs(Motor *m, double volts) {
    double *v = m->v;
    v[VR_motor_torque] = v[VR_N] * v[VR_Kt] * v[VR_current];
    v[VR_applied_voltage] = volts;
}

int model_initialize(void *p, char *msg) {
    Motor *m = p;
    double *v = m->v;
    const char *positive[] = {"R", "L", "Kt", "Ke", "J_rotor", "N", "V_max"};
    const unsigned vrs[] = {VR_R, VR_L, VR_Kt, VR_Ke, VR_J_rotor, VR_N, VR_V_max};
    for (int k = 0; k < 7; k++) {
        if (!(v[vrs[k]] > 0.0)) {
            snprintf(msg, MODEL_MSG_LEN, "parameter %s = %g must be positive", positive[k], v[vrs[k]]);
            return MODEL_ERROR;
        }
    }
    if (v[VR_b_rotor] < 0.0 || v[VR_J_wheel] < 0.0) {
        snprintf(msg, MODEL_MSG_LEN, "parameters b_rotor and J_wheel must not be negative");
        return MODEL_ERROR;
    }
    v[VR_current] = v[VR_i_start];
    v[VR_wheel_speed] = v[VR_w_start];
    v[VR_wheel_angle] = v[VR_phi_start];
    m->h_sub_s = 0.0;
    m->integral = 0.0;
#ifdef SERVO
    if (!(v[VR_servo_time_constant] > 0.0) || !(v[VR_servo_period] > 0.0)) {
        snprintf(msg, MODEL_MSG_LEN, "servo_time_constant and servo_period must be positive");
        return MODEL_ERROR;
    }
    /* Steady-state gain and mechanical time constant of w(s)/V(s), L neglected. */
    const double N = v[VR_N], R = v[VR_R], Kt = v[VR_Kt], Ke = v[VR_Ke];
    const double damping = R * friction(v) + N * N * Kt * Ke;
    const double gain = N * Kt / damping;
    const double tau_mech = R * inertia(v) / damping;
    m->kp = tau_mech / (gain * v[VR_servo_time_constant]);
    m->ki = 1.0 / (gain * v[VR_servo_time_constant]);
    /* Start in equilibrium with the initial speed, so a held setpoint keeps it. */
    m->integral = v[VR_w_start] / (gain * m->ki);
#endif
    outputs(m, 0.0);
    return MODEL_OK;
}

static int discretise(Motor *m, double h_sub_s, char *msg) {
    const double *v = m->v;
    const double J = inertia(v), b = friction(v), N = v[VR_N], L = v[VR_L];
    const double A[9] = {
        -v[VR_R] / L, -v[VR_Ke] * N / L, 0.0,
        N * v[VR_Kt] / J, -b / J, 0.0,
        0.0, 1.0, 0.0,
    };
    const double B[6] = {1.0 / L, 0.0, 0.0, -1.0 / J, 0.0, 0.0};
    if (linsys_zoh(3, 2, A, B, h_sub_s, m->Phi, m->Gam) != 0) {
        snprintf(msg, MODEL_MSG_LEN, "cannot discretise the motor for a %g s step", h_sub_s);
        return MODEL_ERROR;
    }
    m->h_sub_s = h_sub_s;
    return MODEL_OK;
}

static void advance(Motor *m, double volts, double tau) {
    double *v = m->v;
    const double x0 = v[VR_current], x1 = v[VR_wheel_speed], x2 = v[VR_wheel_angle];
    const double *P = m->Phi, *G = m->Gam;
    v[VR_current] = P[0] * x0 + P[1] * x1 + P[2] * x2 + G[0] * volts + G[1] * tau;
    v[VR_wheel_speed] = P[3] * x0 + P[4] * x1 + P[5] * x2 + G[2] * volts + G[3] * tau;
    v[VR_wheel_angle] = P[6] * x0 + P[7] * x1 + P[8] * x2 + G[4] * volts + G[5] * tau;
}

static double clamp(double x, double limit) { return x > limit ? limit : (x < -limit ? -limit : x); }

int model_do_step(void *p, double t_s, double h_s, char *msg) {
    (void)t_s;
    Motor *m = p;
    double *v = m->v;
    const double tau = v[VR_load_torque];
    const double v_max = v[VR_V_max];
#ifdef SERVO
    int n_sub = (int)ceil(h_s / v[VR_servo_period] - 1e-9);
    if (n_sub < 1) n_sub = 1;
#else
    const int n_sub = 1;
#endif
    const double h_sub = h_s / n_sub;
    if (h_sub != m->h_sub_s && discretise(m, h_sub, msg) != MODEL_OK) return MODEL_ERROR;
    double volts = 0.0;
    for (int k = 0; k < n_sub; k++) {
#ifdef SERVO
        const double error = v[VR_speed_setpoint] - v[VR_wheel_speed];
        const double demand = m->kp * error + m->ki * m->integral;
        volts = clamp(demand, v_max);
        /* Conditional integration: no wind-up while the voltage is saturated in the error's direction. */
        if (volts == demand || (demand > 0.0) != (error > 0.0)) m->integral += error * h_sub;
#else
        volts = clamp(v[VR_voltage], v_max);
#endif
        advance(m, volts, tau);
    }
    if (!isfinite(v[VR_current]) || !isfinite(v[VR_wheel_speed])) {
        snprintf(msg, MODEL_MSG_LEN, "the state is no longer finite");
        return MODEL_ERROR;
    }
    outputs(m, volts);
    return MODEL_OK;
}
