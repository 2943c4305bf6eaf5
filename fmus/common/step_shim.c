/* twin's stepping shim: one call steps several FMU instances (set inputs, doStep, get outputs).
 *
 * Not part of any FMU. twin.cosim compiles it next to the FMUs and calls `twin_step_slots` once per
 * communication step instead of three FMI calls per instance from Python, which is what the per-step
 * cost is made of. Each slot holds an instance and its FMI 2 or FMI 3 function pointers.
 */
#include <math.h>
#include <stdbool.h>

#include "step_shim.h"

typedef int (*set2_fn)(void *, const unsigned *, size_t, const double *);
typedef int (*get2_fn)(void *, const unsigned *, size_t, double *);
typedef int (*do2_fn)(void *, double, double, int);
typedef int (*set3_fn)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*get3_fn)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*do3_fn)(void *, double, double, bool, bool *, bool *, bool *, double *);

int twin_step_slots(TwinSlot *slots, int n, double t, double h) {
    for (int k = 0; k < n; k++) {
        TwinSlot *s = &slots[k];
        if (s->fmi_version == 2) {
            s->status[0] = ((set2_fn)s->set)(s->instance, s->in_vr, s->n_in, s->in);
            s->status[1] = ((do2_fn)s->step)(s->instance, t, h, 1);
            s->status[2] = ((get2_fn)s->get)(s->instance, s->out_vr, s->n_out, s->out);
            s->terminate = 0;
        } else {
            bool event = false, terminate = false, early = false;
            double last = t;
            s->status[0] = ((set3_fn)s->set)(s->instance, s->in_vr, s->n_in, s->in, s->n_in);
            s->status[1] = ((do3_fn)s->step)(s->instance, t, h, true, &event, &terminate, &early, &last);
            s->status[2] = ((get3_fn)s->get)(s->instance, s->out_vr, s->n_out, s->out, s->n_out);
            s->terminate = terminate;
        }
        if ((s->status[0] | s->status[1] | s->status[2]) > 1 || s->terminate) return k;
        for (size_t j = 0; j < s->n_out; j++) {
            if (!isfinite(s->out[j])) {
                s->status[2] = TWIN_STATUS_NONFINITE;
                return k;
            }
        }
    }
    return -1;
}

/* The hot path of the Python step loop, called with prebuilt arguments only. */
int twin_step_next(TwinSlot *slots, int n, long long *step_index, const double *h) {
    const int failed = twin_step_slots(slots, n, (double)*step_index * *h, *h);
    if (failed < 0) ++*step_index;
    return failed;
}
