/* FMI 2.0 Model Exchange API over model.h and model_me.h (a copy of fmus/common/fmi2_layer.c
 * with the Model Exchange functions; doStep and the other Co-Simulation functions are not exported).
 *
 * Only Real variables exist; Integer/Boolean/String access with nvr > 0 is an error. FMU states,
 * directional derivatives and input derivatives are not supported (the modelDescription says so).
 * Build with -DMODEL_GUID="\"...\"" (the build writes it together with modelDescription.xml).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"
#include "model_me.h"

#ifndef MODEL_GUID
#error "MODEL_GUID must be defined by the build"
#endif

typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

typedef struct {
    void *model;
    char *name;
    fmi2CallbackFunctions cb;
    fmi2Boolean logging;
    Phase phase;
    int event_mode; /* after initialization: in event mode (1) or continuous-time mode (0) */
    double time_s;
    char msg[MODEL_MSG_LEN];
} Instance;

static void say(Instance *inst, fmi2Status status, const char *category, const char *text) {
    if (inst->cb.logger != NULL && (inst->logging || status > fmi2Warning)) {
        inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, category, "%s", text);
    }
}

static fmi2Status fail(Instance *inst, fmi2Status status, const char *fmt, ...) {
    char text[MODEL_MSG_LEN + 64];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    say(inst, status, "logStatusError", text);
    if (status >= fmi2Error) inst->phase = ST_ERROR;
    return status;
}

static fmi2Status from_model(Instance *inst, int code, const char *where) {
    if (code == MODEL_OK) return fmi2OK;
    if (code == MODEL_DISCARD) {
        say(inst, fmi2Discard, "logStatusDiscard", inst->msg);
        return fmi2Discard;
    }
    return fail(inst, fmi2Error, "%s: %s", where, inst->msg);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories;
    (void)categories;
    if (c == NULL) return fmi2Error;
    ((Instance *)c)->logging = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL) return NULL;
    const char *name = instanceName != NULL ? instanceName : "";
    if (fmuType != fmi2ModelExchange) {
        if (functions->logger) functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                                                 "this FMU supports Model Exchange only");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        if (functions->logger) functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                                                 "GUID %s does not match this binary (%s)", fmuGUID ? fmuGUID : "(null)",
                                                 MODEL_GUID);
        return NULL;
    }
    Instance *inst = calloc(1, sizeof *inst);
    if (inst == NULL) return NULL;
    inst->name = malloc(strlen(name) + 1);
    inst->model = model_new();
    if (inst->name == NULL || inst->model == NULL) {
        free(inst->name);
        model_free(inst->model);
        free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    inst->cb = *functions;
    inst->logging = loggingOn;
    inst->phase = ST_INSTANTIATED;
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return;
    model_free(inst->model);
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (inst->phase != ST_INSTANTIATED) return fail(inst, fmi2Error, "fmi2SetupExperiment: not allowed now");
    inst->time_s = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (inst->phase != ST_INSTANTIATED) return fail(inst, fmi2Error, "fmi2EnterInitializationMode: not allowed now");
    inst->phase = ST_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (inst->phase != ST_INIT) return fail(inst, fmi2Error, "fmi2ExitInitializationMode: not allowed now");
    fmi2Status status = from_model(inst, model_initialize(inst->model, inst->msg), "initialization");
    if (status == fmi2OK) {
        inst->phase = ST_STEP;
        inst->event_mode = 1; /* Model Exchange leaves initialization in event mode */
    }
    return status == fmi2Discard ? fail(inst, fmi2Error, "initialization: %s", inst->msg) : status;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    inst->phase = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    model_reset(inst->model);
    inst->time_s = 0.0;
    inst->phase = ST_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (inst->phase == ST_STEP) {
        double dx[8];
        model_derivatives(inst->model, dx); /* outputs and derivatives at the current states and inputs */
    }
    for (size_t k = 0; k < nvr; k++) {
        if (model_get(inst->model, vr[k], &value[k], inst->msg) != MODEL_OK) {
            return fail(inst, fmi2Error, "fmi2GetReal: %s", inst->msg);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (inst->phase == ST_ERROR || inst->phase == ST_TERMINATED) {
        return fail(inst, fmi2Error, "fmi2SetReal: not allowed after an error or termination");
    }
    int initializing = inst->phase == ST_INSTANTIATED || inst->phase == ST_INIT;
    for (size_t k = 0; k < nvr; k++) {
        if (!initializing && !inst->event_mode && model_is_discrete_input(vr[k])) {
            return fail(inst, fmi2Error, "fmi2SetReal: value reference %u is a discrete input; set it in "
                        "initialization or event mode, not in continuous-time mode", vr[k]);
        }
        if (model_set(inst->model, vr[k], value[k], initializing, inst->msg) != MODEL_OK) {
            return fail(inst, fmi2Error, "fmi2SetReal: %s", inst->msg);
        }
    }
    return fmi2OK;
}

#define NO_VARIABLES(fn, T)                                                                  \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, T value[]) {   \
        (void)vr;                                                                            \
        (void)value;                                                                         \
        if (c == NULL) return fmi2Error;                                                     \
        return nvr == 0 ? fmi2OK : fail(c, fmi2Error, #fn ": this FMU has no such variable"); \
    }
NO_VARIABLES(fmi2GetInteger, fmi2Integer)
NO_VARIABLES(fmi2GetBoolean, fmi2Boolean)
NO_VARIABLES(fmi2GetString, fmi2String)
NO_VARIABLES(fmi2SetInteger, const fmi2Integer)
NO_VARIABLES(fmi2SetBoolean, const fmi2Boolean)
NO_VARIABLES(fmi2SetString, const fmi2String)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s;
    return fail(c, fmi2Error, "fmi2GetFMUstate is not supported");
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    (void)s;
    return fail(c, fmi2Error, "fmi2SetFMUstate is not supported");
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)s;
    return fail(c, fmi2Error, "fmi2FreeFMUstate is not supported");
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    (void)s;
    (void)size;
    return fail(c, fmi2Error, "fmi2SerializedFMUstateSize is not supported");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size) {
    (void)s;
    (void)bytes;
    (void)size;
    return fail(c, fmi2Error, "fmi2SerializeFMUstate is not supported");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s) {
    (void)s;
    (void)bytes;
    (void)size;
    return fail(c, fmi2Error, "fmi2DeSerializeFMUstate is not supported");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown;
    (void)nUnknown;
    (void)vKnown;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return fail(c, fmi2Error, "fmi2GetDirectionalDerivative is not supported");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail(c, fmi2Error, "fmi2SetRealInputDerivatives is not supported");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail(c, fmi2Error, "fmi2GetRealOutputDerivatives is not supported");
}

/* --- Model Exchange -------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    inst->event_mode = 1;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    if (c == NULL || info == NULL) return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    inst->event_mode = 0;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    double x[8];
    model_get_states(inst->model, x);
    for (int k = 0; k < model_n_states(); k++) {
        if (!isfinite(x[k])) return fail(inst, fmi2Error, "fmi2CompletedIntegratorStep: the state is no longer finite");
    }
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    inst->time_s = time;
    return fmi2OK;
}

static fmi2Status check_n(Instance *inst, size_t n, const char *fn) {
    if (n != (size_t)model_n_states()) {
        return fail(inst, fmi2Error, "%s: %zu states given, the model has %d", fn, n, model_n_states());
    }
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (check_n(inst, nx, "fmi2SetContinuousStates") != fmi2OK) return fmi2Error;
    model_set_states(inst->model, x);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (check_n(inst, nx, "fmi2GetDerivatives") != fmi2OK) return fmi2Error;
    model_derivatives(inst->model, derivatives);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    if (c == NULL) return fmi2Error;
    return ni == 0 ? fmi2OK : fail(c, fmi2Error, "fmi2GetEventIndicators: the model has no event indicators");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (check_n(inst, nx, "fmi2GetContinuousStates") != fmi2OK) return fmi2Error;
    model_get_states(inst->model, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    Instance *inst = c;
    if (inst == NULL) return fmi2Error;
    if (check_n(inst, nx, "fmi2GetNominalsOfContinuousStates") != fmi2OK) return fmi2Error;
    for (size_t k = 0; k < nx; k++) x_nominal[k] = 1.0;
    return fmi2OK;
}
