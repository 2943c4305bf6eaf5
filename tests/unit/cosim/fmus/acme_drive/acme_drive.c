/* A stand-in for a vendor's motor FMU, to test that twin maps FMUs it did not write.
 *
 * Everything differs from fmus/dc_motor on purpose: names, units (rpm, deg, mA, mN.m, degC),
 * parameters given at the wheel, no inductance (current follows the voltage at once), an extra
 * winding-temperature output, and explicit midpoint substeps instead of an exact discretisation.
 * `fault_time` >= 0 makes doStep fail once the step would pass that time (to test error handling).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "model.h"
#include "model_vars.h"
#include "var_table.h"

#define PI 3.14159265358979323846
#define RPM_PER_RADPS (60.0 / (2.0 * PI))
#define DEG_PER_RAD (180.0 / PI)

typedef struct {
    double v[MODEL_NVR];
    double w_radps, angle_rad, current_a, temp_c;
} Acme;

void *model_new(void) {
    Acme *m = calloc(1, sizeof *m);
    if (m != NULL) vt_reset(m->v);
    return m;
}
void model_free(void *m) { free(m); }
void model_reset(void *p) { vt_reset(((Acme *)p)->v); }
int model_set(void *p, unsigned vr, double value, int initializing, char *msg) {
    return vt_set(((Acme *)p)->v, vr, value, initializing, msg);
}
int model_get(void *p, unsigned vr, double *value, char *msg) { return vt_get(((Acme *)p)->v, vr, value, msg); }

static double supply(const Acme *m) {
    const double u = m->v[VR_U_motor], limit = m->v[VR_U_max];
    return u > limit ? limit : (u < -limit ? -limit : u);
}

static void publish(Acme *m) {
    double *v = m->v;
#ifndef BARE
    v[VR_n_out] = m->w_radps * RPM_PER_RADPS;
#endif
    v[VR_pos] = m->angle_rad * DEG_PER_RAD;
    v[VR_I_mA] = m->current_a * 1000.0;
    v[VR_T_drive] = v[VR_k_m] * m->current_a * 1000.0;
    v[VR_temp_winding] = m->temp_c;
}

int model_initialize(void *p, char *msg) {
    Acme *m = p;
    if (!(m->v[VR_Rw] > 0.0) || !(m->v[VR_J_total] > 0.0) || !(m->v[VR_k_m] > 0.0)) {
        snprintf(msg, MODEL_MSG_LEN, "Rw, J_total and k_m must be positive");
        return MODEL_ERROR;
    }
    m->w_radps = 0.0;
    m->angle_rad = 0.0;
    m->current_a = 0.0;
    m->temp_c = m->v[VR_T_ambient];
    publish(m);
    return MODEL_OK;
}

static void derivatives(const Acme *m, double w, double temp, double *dw, double *dtemp, double *current) {
    const double *v = m->v;
#ifdef BARE
    const double load = 0.0;
#else
    const double load = v[VR_T_ext] * 1e-3;
#endif
    *current = (supply(m) - v[VR_k_m] * w) / v[VR_Rw];
    *dw = (v[VR_k_m] * *current - v[VR_d_visc] * w - load) / v[VR_J_total];
    *dtemp = (*current * *current * v[VR_Rw] - (temp - v[VR_T_ambient]) / v[VR_R_th]) / v[VR_C_th];
}

int model_do_step(void *p, double t_s, double h_s, char *msg) {
    Acme *m = p;
    const double fault = m->v[VR_fault_time];
    if (fault >= 0.0 && t_s + h_s > fault) {
        snprintf(msg, MODEL_MSG_LEN, "simulated drive fault at t = %.6f s", t_s);
        return MODEL_ERROR;
    }
    const int n = (int)ceil(h_s / 5e-4 - 1e-9) > 0 ? (int)ceil(h_s / 5e-4 - 1e-9) : 1;
    const double dt = h_s / n;
    for (int k = 0; k < n; k++) {
        double dw, dtemp, i;
        derivatives(m, m->w_radps, m->temp_c, &dw, &dtemp, &i);
        const double w_mid = m->w_radps + 0.5 * dt * dw, temp_mid = m->temp_c + 0.5 * dt * dtemp;
        derivatives(m, w_mid, temp_mid, &dw, &dtemp, &i);
        m->angle_rad += dt * w_mid;
        m->w_radps += dt * dw;
        m->temp_c += dt * dtemp;
    }
    double dw, dtemp;
    derivatives(m, m->w_radps, m->temp_c, &dw, &dtemp, &m->current_a);
    publish(m);
    return MODEL_OK;
}
