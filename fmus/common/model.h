/* The interface between a model and the FMI layers (fmi2_layer.c, fmi3_layer.c).
 *
 * A model implements these functions for its Float64 (FMI 2: Real) variables only; the layers
 * translate the FMI calls and states. Status codes: MODEL_OK, MODEL_DISCARD (the step was not
 * taken), MODEL_ERROR (the instance is unusable until reset), MODEL_WARNING (done, with a warning
 * the layers pass to the FMU's logger). A failing or warning function writes a one-line reason to
 * `msg` (at most MODEL_MSG_LEN bytes, NUL-terminated).
 */
#ifndef TWIN_MODEL_H
#define TWIN_MODEL_H

#include <stddef.h>

#define MODEL_OK 0
#define MODEL_DISCARD 1
#define MODEL_ERROR 2
#define MODEL_WARNING 3
#define MODEL_MSG_LEN 256
/* Value reference of the independent variable `time` that FMI 3 model descriptions declare. */
#define MODEL_TIME_VR 4096u

/* Allocate an instance with every variable at its start value; NULL if out of memory. */
void *model_new(void);
void model_free(void *m);
/* Put every variable back to its start value. */
void model_reset(void *m);
/* Set or get one variable; MODEL_ERROR for an unknown value reference or a variable that may not be set. */
int model_set(void *m, unsigned vr, double value, int initializing, char *msg);
int model_get(void *m, unsigned vr, double *value, char *msg);
/* Called when initialisation ends: check the parameters, set the states from their start values. */
int model_initialize(void *m, char *msg);
/* Advance from t_s by h_s with the inputs held constant. */
int model_do_step(void *m, double t_s, double h_s, char *msg);

#endif
