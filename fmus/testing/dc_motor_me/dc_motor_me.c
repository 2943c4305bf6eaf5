/* The project's DC motor (fmus/dc_motor/dc_motor.c) as a Model Exchange model: the same variables,
 * parameters and initialisation, with the right-hand side of its ODE exposed instead of a step.
 *
 * States: current, wheel_speed, wheel_angle and, with SERVO, pi_integral (the velocity PI's
 * integral of the speed error, run here in continuous time with the same gains, saturation at
 * V_max and conditional integration as the Co-Simulation build's 0.1 ms discrete PI).
 */
#include "dc_motor.c"
#include "model_me.h"

int model_is_discrete_input(unsigned vr) { return vr < MODEL_NVR && MODEL_KIND[vr] == KIND_DISCRETE_INPUT; }

int model_n_states(void) {
#ifdef SERVO
    return 4;
#else
    return 3;
#endif
}

void model_get_states(void *p, double *x) {
    Motor *m = p;
    x[0] = m->v[VR_current];
    x[1] = m->v[VR_wheel_speed];
    x[2] = m->v[VR_wheel_angle];
#ifdef SERVO
    x[3] = m->integral;
#endif
}

void model_set_states(void *p, const double *x) {
    Motor *m = p;
    m->v[VR_current] = x[0];
    m->v[VR_wheel_speed] = x[1];
    m->v[VR_wheel_angle] = x[2];
#ifdef SERVO
    m->integral = x[3];
#endif
}

void model_derivatives(void *p, double *dx) {
    Motor *m = p;
    double *v = m->v;
    const double i = v[VR_current], w = v[VR_wheel_speed], N = v[VR_N];
#ifdef SERVO
    const double error = v[VR_speed_setpoint] - w;
    const double demand = m->kp * error + m->ki * m->integral;
    const double volts = clamp(demand, v[VR_V_max]);
    dx[3] = (volts == demand || (demand > 0.0) != (error > 0.0)) ? error : 0.0;
    v[VR_pi_integral] = m->integral;
    v[VR_der_pi_integral] = dx[3];
#else
    const double volts = clamp(v[VR_voltage], v[VR_V_max]);
#endif
    dx[0] = (volts - v[VR_R] * i - v[VR_Ke] * N * w) / v[VR_L];
    dx[1] = (N * v[VR_Kt] * i - friction(v) * w - v[VR_load_torque]) / inertia(v);
    dx[2] = w;
    v[VR_der_current] = dx[0];
    v[VR_der_wheel_speed] = dx[1];
    v[VR_der_wheel_angle] = dx[2];
    outputs(m, volts);
}
