/* Variable storage shared by the project's models: one double per value reference.
 *
 * Include after the generated "model_vars.h", which defines MODEL_NVR, MODEL_START[], MODEL_KIND[]
 * and MODEL_NAME[] from the model's fmu.yaml.
 */
#ifndef TWIN_VAR_TABLE_H
#define TWIN_VAR_TABLE_H

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"

#define KIND_NONE 0
#define KIND_PARAMETER 1
#define KIND_INPUT 2
#define KIND_OUTPUT 3
#define KIND_DISCRETE_INPUT 4 /* an input that changes only at events */

static inline void vt_reset(double *v) { memcpy(v, MODEL_START, sizeof(double) * MODEL_NVR); }

static inline int vt_set(double *v, unsigned vr, double value, int initializing, char *msg) {
    if (vr >= MODEL_NVR || MODEL_KIND[vr] == KIND_NONE) {
        snprintf(msg, MODEL_MSG_LEN, "no variable has value reference %u", vr);
        return MODEL_ERROR;
    }
    const unsigned char kind = MODEL_KIND[vr];
    if (kind == KIND_OUTPUT || (kind == KIND_PARAMETER && !initializing)) {
        snprintf(msg, MODEL_MSG_LEN, "%s may not be set %s", MODEL_NAME[vr],
                 kind == KIND_OUTPUT ? "(it is an output)" : "after initialization (it is a fixed parameter)");
        return MODEL_ERROR;
    }
    if (!isfinite(value)) {
        snprintf(msg, MODEL_MSG_LEN, "%s = %g is not finite", MODEL_NAME[vr], value);
        return MODEL_ERROR;
    }
    v[vr] = value;
    return MODEL_OK;
}

static inline int vt_get(const double *v, unsigned vr, double *value, char *msg) {
    if (vr >= MODEL_NVR || MODEL_KIND[vr] == KIND_NONE) {
        snprintf(msg, MODEL_MSG_LEN, "no variable has value reference %u", vr);
        return MODEL_ERROR;
    }
    *value = v[vr];
    return MODEL_OK;
}

#endif
