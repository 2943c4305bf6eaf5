/* What a Model Exchange model adds to model.h: its continuous states and their derivatives. */
#ifndef TWIN_MODEL_ME_H
#define TWIN_MODEL_ME_H

int model_n_states(void);
void model_get_states(void *m, double *x);
void model_set_states(void *m, const double *x);
/* Derivatives at the current states and inputs; also updates the outputs. */
void model_derivatives(void *m, double *dx);
/* Whether vr is a discrete input: settable only in initialization and event mode. */
int model_is_discrete_input(unsigned vr);

#endif
