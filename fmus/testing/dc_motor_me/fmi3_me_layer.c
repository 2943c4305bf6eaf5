/* FMI 3.0 Model Exchange API over model.h and model_me.h (a copy of fmus/common/fmi3_layer.c with
 * the Model Exchange functions implemented and Co-Simulation instantiation refused).
 *
 * Only Float64 scalar variables exist; other types with nValueReferences > 0 are an error.
 * Co-Simulation, Scheduled Execution, FMU states, clocks, events and derivatives are not supported.
 * Build with -DMODEL_GUID="\"...\"" (the instantiation token written into modelDescription.xml).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"
#include "model_me.h"

#ifndef MODEL_GUID
#error "MODEL_GUID must be defined by the build"
#endif

typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

typedef struct {
    void *model;
    char *name;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    fmi3Boolean logging;
    Phase phase;
    int event_mode; /* after initialization: in event mode (1) or continuous-time mode (0) */
    double time_s;
    char msg[MODEL_MSG_LEN];
} Instance;

static void say(Instance *inst, fmi3Status status, const char *category, const char *text) {
    if (inst->log != NULL && (inst->logging || status > fmi3Warning)) inst->log(inst->env, status, category, text);
}

static fmi3Status fail(Instance *inst, fmi3Status status, const char *fmt, ...) {
    char text[MODEL_MSG_LEN + 64];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    if (inst == NULL) return fmi3Error;
    say(inst, status, "logStatusError", text);
    if (status >= fmi3Error) inst->phase = ST_ERROR;
    return status;
}

static fmi3Status from_model(Instance *inst, int code, const char *where) {
    if (code == MODEL_OK) return fmi3OK;
    if (code == MODEL_DISCARD) {
        say(inst, fmi3Discard, "logStatusDiscard", inst->msg);
        return fmi3Discard;
    }
    return fail(inst, fmi3Error, "%s: %s", where, inst->msg);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    if (instance == NULL) return fmi3Error;
    ((Instance *)instance)->logging = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    if (instantiationToken == NULL || strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "instantiation token does not match this binary");
        return NULL;
    }
    const char *name = instanceName != NULL ? instanceName : "";
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
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    inst->logging = loggingOn;
    inst->phase = ST_INSTANTIATED;
    return inst;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)eventModeUsed;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports Model Exchange only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports Co-Simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return;
    model_free(inst->model);
    free(inst->name);
    free(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (inst->phase != ST_INSTANTIATED) return fail(inst, fmi3Error, "fmi3EnterInitializationMode: not allowed now");
    inst->time_s = startTime;
    inst->phase = ST_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (inst->phase != ST_INIT) return fail(inst, fmi3Error, "fmi3ExitInitializationMode: not allowed now");
    fmi3Status status = from_model(inst, model_initialize(inst->model, inst->msg), "initialization");
    if (status == fmi3OK) {
        inst->phase = ST_STEP;
        inst->event_mode = 1; /* Model Exchange leaves initialization in event mode */
    }
    return status == fmi3Discard ? fail(inst, fmi3Error, "initialization: %s", inst->msg) : status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (inst->phase != ST_STEP) return fail(inst, fmi3Error, "fmi3EnterEventMode: not allowed now");
    inst->event_mode = 1;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    inst->phase = ST_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    model_reset(inst->model);
    inst->time_s = 0.0;
    inst->phase = ST_INSTANTIATED;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (nValues != nValueReferences) return fail(inst, fmi3Error, "fmi3GetFloat64: nValues != nValueReferences");
    if (inst->phase == ST_STEP) {
        double dx[8];
        model_derivatives(inst->model, dx); /* outputs and derivatives at the current states and inputs */
    }
    for (size_t k = 0; k < nValueReferences; k++) {
        if (valueReferences[k] == MODEL_TIME_VR) {
            values[k] = inst->time_s;
            continue;
        }
        if (model_get(inst->model, valueReferences[k], &values[k], inst->msg) != MODEL_OK) {
            return fail(inst, fmi3Error, "fmi3GetFloat64: %s", inst->msg);
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (inst->phase == ST_ERROR || inst->phase == ST_TERMINATED) {
        return fail(inst, fmi3Error, "fmi3SetFloat64: not allowed after an error or termination");
    }
    if (nValues != nValueReferences) return fail(inst, fmi3Error, "fmi3SetFloat64: nValues != nValueReferences");
    int initializing = inst->phase == ST_INSTANTIATED || inst->phase == ST_INIT;
    for (size_t k = 0; k < nValueReferences; k++) {
        if (!initializing && !inst->event_mode && model_is_discrete_input(valueReferences[k])) {
            return fail(inst, fmi3Error, "fmi3SetFloat64: value reference %u is a discrete input; set it in "
                        "initialization or event mode, not in continuous-time mode", valueReferences[k]);
        }
        if (model_set(inst->model, valueReferences[k], values[k], initializing, inst->msg) != MODEL_OK) {
            return fail(inst, fmi3Error, "fmi3SetFloat64: %s", inst->msg);
        }
    }
    return fmi3OK;
}

#define NO_GET(fn, T)                                                                                   \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, T values[], size_t n) { \
        (void)vr;                                                                                       \
        (void)values;                                                                                   \
        (void)n;                                                                                        \
        return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, #fn ": this FMU has no such variable");     \
    }
#define NO_SET(fn, T)                                                                                        \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const T values[], size_t n) { \
        (void)vr;                                                                                            \
        (void)values;                                                                                        \
        (void)n;                                                                                             \
        return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, #fn ": this FMU has no such variable");          \
    }
NO_GET(fmi3GetFloat32, fmi3Float32)
NO_GET(fmi3GetInt8, fmi3Int8)
NO_GET(fmi3GetUInt8, fmi3UInt8)
NO_GET(fmi3GetInt16, fmi3Int16)
NO_GET(fmi3GetUInt16, fmi3UInt16)
NO_GET(fmi3GetInt32, fmi3Int32)
NO_GET(fmi3GetUInt32, fmi3UInt32)
NO_GET(fmi3GetInt64, fmi3Int64)
NO_GET(fmi3GetUInt64, fmi3UInt64)
NO_GET(fmi3GetBoolean, fmi3Boolean)
NO_GET(fmi3GetString, fmi3String)
NO_SET(fmi3SetFloat32, fmi3Float32)
NO_SET(fmi3SetInt8, fmi3Int8)
NO_SET(fmi3SetUInt8, fmi3UInt8)
NO_SET(fmi3SetInt16, fmi3Int16)
NO_SET(fmi3SetUInt16, fmi3UInt16)
NO_SET(fmi3SetInt32, fmi3Int32)
NO_SET(fmi3SetUInt32, fmi3UInt32)
NO_SET(fmi3SetInt64, fmi3Int64)
NO_SET(fmi3SetUInt64, fmi3UInt64)
NO_SET(fmi3SetBoolean, fmi3Boolean)
NO_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t n) {
    (void)vr;
    (void)valueSizes;
    (void)values;
    (void)n;
    return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, "fmi3GetBinary: this FMU has no such variable");
}
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t n) {
    (void)vr;
    (void)valueSizes;
    (void)values;
    (void)n;
    return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, "fmi3SetBinary: this FMU has no such variable");
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr;
    (void)values;
    return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, "fmi3GetClock: this FMU has no clocks");
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr;
    (void)values;
    return nvr == 0 ? fmi3OK : fail(instance, fmi3Error, "fmi3SetClock: this FMU has no clocks");
}

/* Everything below is outside this FMU's capabilities, as its modelDescription declares. */
#define UNSUPPORTED(name) return fail(instance, fmi3Error, name " is not supported")

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference;
    (void)nDependencies;
    UNSUPPORTED("fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    (void)nDependencies;
    UNSUPPORTED("fmi3GetVariableDependencies");
}
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)FMUState;
    UNSUPPORTED("fmi3GetFMUState");
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    (void)FMUState;
    UNSUPPORTED("fmi3SetFMUState");
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)FMUState;
    UNSUPPORTED("fmi3FreeFMUState");
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    (void)size;
    UNSUPPORTED("fmi3SerializedFMUStateSize");
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    (void)FMUState;
    (void)serializedState;
    (void)size;
    UNSUPPORTED("fmi3SerializeFMUState");
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    (void)serializedState;
    (void)size;
    (void)FMUState;
    UNSUPPORTED("fmi3DeserializeFMUState");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED("fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED("fmi3GetAdjointDerivative");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { UNSUPPORTED("fmi3EnterConfigurationMode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { UNSUPPORTED("fmi3ExitConfigurationMode"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr;
    (void)nvr;
    (void)intervals;
    (void)qualifiers;
    UNSUPPORTED("fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    (void)qualifiers;
    UNSUPPORTED("fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr;
    (void)nvr;
    (void)shifts;
    UNSUPPORTED("fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    UNSUPPORTED("fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr;
    (void)nvr;
    (void)intervals;
    UNSUPPORTED("fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    UNSUPPORTED("fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr;
    (void)nvr;
    (void)shifts;
    UNSUPPORTED("fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    UNSUPPORTED("fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { UNSUPPORTED("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    if (instance == NULL) return fmi3Error;
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    inst->event_mode = 0;
    return fmi3OK;
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    double x[8];
    model_get_states(inst->model, x);
    for (int k = 0; k < model_n_states(); k++) {
        if (!isfinite(x[k])) return fail(inst, fmi3Error, "fmi3CompletedIntegratorStep: the state is no longer finite");
    }
    return fmi3OK;
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    inst->time_s = time;
    return fmi3OK;
}
static fmi3Status check_n(Instance *inst, size_t n, const char *fn) {
    if (n != (size_t)model_n_states()) {
        return fail(inst, fmi3Error, "%s: %zu states given, the model has %d", fn, n, model_n_states());
    }
    return fmi3OK;
}
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (check_n(inst, nContinuousStates, "fmi3SetContinuousStates") != fmi3OK) return fmi3Error;
    model_set_states(inst->model, continuousStates);
    return fmi3OK;
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (check_n(inst, nContinuousStates, "fmi3GetContinuousStateDerivatives") != fmi3OK) return fmi3Error;
    model_derivatives(inst->model, derivatives);
    return fmi3OK;
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    (void)eventIndicators;
    if (instance == NULL) return fmi3Error;
    return nEventIndicators == 0 ? fmi3OK
                                 : fail(instance, fmi3Error, "fmi3GetEventIndicators: the model has no event indicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (check_n(inst, nContinuousStates, "fmi3GetContinuousStates") != fmi3OK) return fmi3Error;
    model_get_states(inst->model, continuousStates);
    return fmi3OK;
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (check_n(inst, nContinuousStates, "fmi3GetNominalsOfContinuousStates") != fmi3OK) return fmi3Error;
    for (size_t k = 0; k < nContinuousStates; k++) nominals[k] = 1.0;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    if (instance == NULL) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    if (instance == NULL) return fmi3Error;
    *nContinuousStates = (size_t)model_n_states();
    return fmi3OK;
}
fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    return inst->phase == ST_STEP ? fmi3OK : fail(inst, fmi3Error, "fmi3EnterStepMode: not allowed now");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)valueReferences;
    (void)nValueReferences;
    (void)orders;
    (void)values;
    (void)nValues;
    UNSUPPORTED("fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    Instance *inst = instance;
    if (inst == NULL) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (inst->phase != ST_STEP) return fail(inst, fmi3Error, "fmi3DoStep: not allowed now");
    if (!(communicationStepSize > 0.0)) {
        return fail(inst, fmi3Error, "fmi3DoStep: communication step %g s is not positive", communicationStepSize);
    }
    fmi3Status status = from_model(inst, model_do_step(inst->model, currentCommunicationPoint,
                                                       communicationStepSize, inst->msg), "fmi3DoStep");
    if (status == fmi3OK) inst->time_s = currentCommunicationPoint + communicationStepSize;
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->time_s;
    return status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference;
    (void)activationTime;
    UNSUPPORTED("fmi3ActivateModelPartition");
}
