/* twin's stepping shim: FMU instances stepped from C (see step_shim.c and drive_loop.c).
 *
 * Not part of any FMU. twin.cosim compiles step_shim.c and drive_loop.c into one shared library in
 * its cache and fills these structures through ctypes (twin/cosim/fmu.py, twin/cosim/drive_loop.py:
 * keep the field order in step with them).
 */
#ifndef TWIN_STEP_SHIM_H
#define TWIN_STEP_SHIM_H

#include <stddef.h>

/* Reported in status[2] (the get call) when the FMU returned OK but an output is NaN or infinite. */
#define TWIN_STATUS_NONFINITE 6

/* One FMU instance with its FMI 2 or FMI 3 function pointers and its input/output buffers. */
typedef struct {
    int fmi_version;
    void *instance;
    void *set;
    void *get;
    void *step;
    const unsigned *in_vr;
    size_t n_in;
    double *in;
    const unsigned *out_vr;
    size_t n_out;
    double *out;
    int status[3]; /* of the set, doStep and get calls */
    int terminate; /* FMI 3: the FMU asked to end the simulation */
} TwinSlot;

/* Step every slot from t by h. Returns -1 when all calls succeeded (status OK or Warning), else the
 * index of the first slot with a worse status, a non-finite output (TWIN_STATUS_NONFINITE) or a
 * termination request; later slots are not stepped. */
int twin_step_slots(TwinSlot *slots, int n, double t, double h);

/* Step every slot from t = *step_index * h by h and count the step. Returns as twin_step_slots;
 * *step_index is not advanced on a failure, so the failing step's start time is *step_index * h. */
int twin_step_next(TwinSlot *slots, int n, long long *step_index, const double *h);

#endif
