/*
 * fmi2_wrapper.c - the FMI 2.0 C API (Model Exchange and Co-Simulation in one
 * binary) on top of core.c. Functions the test models do not support
 * (directional derivatives, input derivatives, asynchronous steps; FMU state
 * unless the model declares it) are present and return fmi2Error with a
 * message, as their capability flags in modelDescription.xml announce.
 */
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "fmi2Functions.h"

#ifndef INSTANTIATION_TOKEN
#error "compile with -DINSTANTIATION_TOKEN=\"...\" (the guid of modelDescription.xml)"
#endif

/* The importer's callbacks are kept next to the core instance. */
typedef struct {
    Instance *core;
    fmi2CallbackFunctions callbacks;
} Component;

#define CORE(c) (((Component *)(c))->core)

/* Guard used at the top of every function taking an fmi2Component. */
#define BEGIN(c, modes)                                                \
    Instance *in;                                                      \
    if (!(c)) return fmi2Error;                                        \
    in = CORE(c);                                                      \
    if (!core_allowed(in, __func__, (modes))) return fmi2Error

static void sink(void *env, const char *name, Status status, const char *category, const char *message)
{
    const fmi2CallbackFunctions *cb = env;
    char escaped[2048];
    size_t j = 0;
    if (!cb || !cb->logger) return;
    /* the logger formats its message like printf: escape '%' */
    for (size_t i = 0; message[i] && j + 2 < sizeof escaped; i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    cb->logger(MODEL.null_log_environment ? NULL : cb->componentEnvironment, name, (fmi2Status)status,
               category, escaped);
}

/* ---------------------------------------------------------------- common */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    BEGIN(c, ~0u);
    (void)nCategories;
    (void)categories;
    in->logging_on = loggingOn != fmi2False;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Component *comp;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions) return NULL;
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                          "fmi2Instantiate: the GUID does not match this binary");
        return NULL;
    }
    comp = calloc(1, sizeof *comp);
    if (!comp) return NULL;
    comp->callbacks = *functions;
    comp->core = core_new(2, fmuType == fmi2CoSimulation ? IF_CO_SIMULATION : IF_MODEL_EXCHANGE, instanceName,
                          sink, &comp->callbacks, loggingOn != fmi2False);
    if (!comp->core) {
        free(comp);
        return NULL;
    }
    return comp;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (!c) return;
    core_free(CORE(c));
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    BEGIN(c, M_INSTANTIATED);
    (void)toleranceDefined;
    (void)tolerance;
    if (MODEL.fmi2_setup_resets) core_reset(in);
    in->time = startTime;
    in->stop_defined = stopTimeDefined != fmi2False;
    in->stop_time = stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    BEGIN(c, M_INSTANTIATED);
    return (fmi2Status)core_enter_initialization(in, in->time, in->stop_defined, in->stop_time);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    BEGIN(c, M_INITIALIZATION);
    return (fmi2Status)core_exit_initialization(in);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    BEGIN(c, M_EVENT | M_CONTINUOUS | M_STEP | M_STEP_FAILED);
    in->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    BEGIN(c, ~0u);
    return (fmi2Status)core_reset(in);
}

/* ---------------------------------------------------------------- getters */

#define GET_MODES (M_INITIALIZATION | M_AFTER_INIT)

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_FLOAT64);
        if (!v) return fmi2Error;
        value[i] = *(const double *)core_element(in, v);
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_INT32 | T_ENUM);
        if (!v) return fmi2Error;
        if (v->type == T_ENUM) value[i] = (fmi2Integer) * (const int64_t *)core_element(in, v);
        else value[i] = *(const int32_t *)core_element(in, v);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BOOL);
        if (!v) return fmi2Error;
        value[i] = *(const bool *)core_element(in, v) ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

/* The pointers stay valid until the variable is set again (or the instance freed). */
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        const char *s;
        if (!v) return fmi2Error;
        s = *(char *const *)core_element(in, v);
        value[i] = s ? s : "";
    }
    return fmi2OK;
}

/* ---------------------------------------------------------------- setters */

#define SET_MODES (M_INSTANTIATED | M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_STEP)

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_FLOAT64);
        if (!v || !core_can_set(in, __func__, v)) return fmi2Error;
        *(double *)core_element(in, v) = value[i];
        core_after_set(in, __func__, v, NULL);
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_INT32 | T_ENUM);
        if (!v || !core_can_set(in, __func__, v)) return fmi2Error;
        if (v->type == T_ENUM) *(int64_t *)core_element(in, v) = value[i];
        else *(int32_t *)core_element(in, v) = value[i];
        core_after_set(in, __func__, v, NULL);
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BOOL);
        if (!v || !core_can_set(in, __func__, v)) return fmi2Error;
        *(bool *)core_element(in, v) = value[i] != fmi2False;
        core_after_set(in, __func__, v, NULL);
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        if (!v || !core_can_set(in, __func__, v)) return fmi2Error;
        if (!fmu_copy_string((char **)core_element(in, v), value[i] ? value[i] : ""))
            return (fmi2Status)core_fail(in, __func__, "out of memory");
        core_after_set(in, __func__, v, NULL);
    }
    return fmi2OK;
}

/* ---------------------------------------------------------------- unsupported optional features */

static fmi2Status unsupported(fmi2Component c, const char *fn, const char *what)
{
    if (c) core_fail(CORE(c), fn, "%s is not supported by this FMU", what);
    return fmi2Error;
}

/* ---------------------------------------------------------------- FMU state (core.h; models that declare it) */

#define BEGIN_STATE(c, what)                                                           \
    BEGIN(c, ~0u);                                                                     \
    if (!CFMU_FMU_STATE) return unsupported(c, __func__, what)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    BEGIN_STATE(c, "getting the FMU state");
    return (fmi2Status)core_get_state(in, __func__, s);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    BEGIN_STATE(c, "setting the FMU state");
    return (fmi2Status)core_set_state(in, __func__, s);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    BEGIN_STATE(c, "freeing an FMU state");
    if (s) core_free_state(s);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    BEGIN_STATE(c, "serializing the FMU state");
    (void)s;
    *size = core_state_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size)
{
    BEGIN_STATE(c, "serializing the FMU state");
    return (fmi2Status)core_serialize_state(in, __func__, s, (unsigned char *)bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s)
{
    BEGIN_STATE(c, "de-serializing the FMU state");
    return (fmi2Status)core_deserialize_state(in, __func__, (const unsigned char *)bytes, size, s);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown;
    (void)nUnknown;
    (void)vKnown;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return unsupported(c, __func__, "computing directional derivatives");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, __func__, "interpolating inputs");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, __func__, "providing output derivatives");
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return unsupported(c, __func__, "cancelling an asynchronous step");
}

/* ---------------------------------------------------------------- model exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    BEGIN(c, M_EVENT | M_CONTINUOUS);
    in->mode = M_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    EventUpdate ev;
    BEGIN(c, M_EVENT);
    core_event_update(in, &ev);
    info->newDiscreteStatesNeeded = ev.more;
    info->terminateSimulation = ev.terminate;
    info->nominalsOfContinuousStatesChanged = ev.nominals_changed;
    info->valuesOfContinuousStatesChanged = ev.states_changed;
    info->nextEventTimeDefined = ev.next_time_defined;
    info->nextEventTime = ev.next_time;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    BEGIN(c, M_EVENT);
    in->mode = M_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    BEGIN(c, M_CONTINUOUS);
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = MODEL.step_event && MODEL.step_event(in->data, in->time) ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    BEGIN(c, M_EVENT | M_CONTINUOUS);
    return (fmi2Status)core_set_time(in, time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS);
    return (fmi2Status)core_states(in, __func__, (double *)x, nx, true);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    BEGIN(c, M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_TERMINATED);
    core_update(in);
    return (fmi2Status)core_derivatives(in, __func__, derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    BEGIN(c, M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_TERMINATED);
    core_update(in);
    return (fmi2Status)core_indicators(in, __func__, eventIndicators, ni);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    BEGIN(c, M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_TERMINATED);
    return (fmi2Status)core_states(in, __func__, x, nx, false);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    BEGIN(c, M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_TERMINATED);
    return (fmi2Status)core_nominals(in, __func__, x_nominal, nx);
}

/* ---------------------------------------------------------------- co-simulation */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    double t_end;
    bool event;
    BEGIN(c, M_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    switch (core_do_step(in, currentCommunicationPoint, communicationStepSize, &t_end, &event)) {
    case STEP_DONE:
        return fmi2OK;
    case STEP_TERMINATED:
        /* fmi2Discard + fmi2Terminated: the simulation ends at fmi2LastSuccessfulTime */
        core_log(in, ST_DISCARD, "logStatusDiscard", "the model terminates the simulation at t = %.17g", t_end);
        in->mode = M_STEP_FAILED;
        return fmi2Discard;
    case STEP_REJECTED:
        in->mode = M_STEP_FAILED;
        return fmi2Discard;
    default:
        in->mode = M_ERROR;
        return fmi2Error;
    }
}

#define STATUS_MODES (M_STEP | M_STEP_FAILED | M_TERMINATED)

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi2Status)core_fail(in, __func__, "status kind %d is not available (no asynchronous steps)", (int)s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    BEGIN(c, STATUS_MODES);
    if (s != fmi2LastSuccessfulTime)
        return (fmi2Status)core_fail(in, __func__, "status kind %d is not a Real status", (int)s);
    *value = in->last_successful_time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi2Status)core_fail(in, __func__, "status kind %d is not an Integer status", (int)s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    BEGIN(c, STATUS_MODES);
    if (s != fmi2Terminated)
        return (fmi2Status)core_fail(in, __func__, "status kind %d is not a Boolean status", (int)s);
    *value = in->terminate_requested ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi2Status)core_fail(in, __func__, "status kind %d is not available (no asynchronous steps)", (int)s);
}
