/* The project's DC motor (fmus/dc_motor/dc_motor.c) with a fault injected at a set sim time, for
 * the tests of how twin survives a vendor FMU that misbehaves.
 *
 * fault_mode: 0 none, 1 segfault (a write through a NULL pointer), 2 abort(), 3 hang (doStep never
 * returns), 4 NaN (doStep returns OK with wheel_speed, current and motor_torque NaN), 5 warn (the
 * motor, but every doStep that reaches a whole second of sim time logs a warning through the FMU's
 * logger and returns Warning).
 * The fault happens in the first doStep that starts at or after fault_time (s); before that the
 * model is the motor itself, to the bit.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

/* The motor's own step under another name; this file's model_do_step wraps it. */
#define model_do_step motor_do_step
#include "dc_motor.c"
#undef model_do_step

enum { FAULT_NONE = 0, FAULT_SEGFAULT = 1, FAULT_ABORT = 2, FAULT_HANG = 3, FAULT_NAN = 4, FAULT_WARN = 5 };

int model_do_step(void *p, double t_s, double h_s, char *msg);

int model_do_step(void *p, double t_s, double h_s, char *msg) {
    Motor *m = p;
    double *v = m->v;
    const int mode = (int)v[VR_fault_mode];
    if (mode == FAULT_NONE || t_s < v[VR_fault_time] - 1e-12) return motor_do_step(p, t_s, h_s, msg);
    switch (mode) {
    case FAULT_SEGFAULT: {
        volatile int *nowhere = NULL;
        *nowhere = 1;
        raise(SIGSEGV); /* in case the write did not fault */
        break;
    }
    case FAULT_ABORT:
        abort();
    case FAULT_HANG:
        for (;;) pause();
    case FAULT_NAN:
        v[VR_wheel_speed] = NAN;
        v[VR_current] = NAN;
        v[VR_motor_torque] = NAN;
        return MODEL_OK;
    case FAULT_WARN: {
        const int code = motor_do_step(p, t_s, h_s, msg);
        const double second = floor(t_s + h_s + 1e-9);
        if (code != MODEL_OK || second <= floor(t_s + 1e-9)) return code;
        snprintf(msg, MODEL_MSG_LEN, "winding temperature check at t = %.0f s: current %.3f A", second,
                 v[VR_current]);
        return MODEL_WARNING;
    }
    default:
        break;
    }
    snprintf(msg, MODEL_MSG_LEN, "fault_mode %d is not one of 0 to 5", mode);
    return MODEL_ERROR;
}
