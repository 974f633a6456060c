/* FMI 2.0 entry points (model exchange and co-simulation in one binary) on top of runtime.c. */
#include <string.h>

#include "fmi2Functions.h"
#include "runtime.h"

typedef struct {
    Instance rt;                 /* first member: an Fmi2Instance * is an Instance * */
    fmi2CallbackFunctions cb;
} Fmi2Instance;

static const char *const TYPE_NAMES[] = { "Real", "Boolean", "Integer", "String" };

static void forward_log(Instance *inst, RtStatus status, const char *category, const char *message)
{
    const Fmi2Instance *f = (const Fmi2Instance *)inst;
    if (f->cb.logger)
        f->cb.logger(f->cb.componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

/* Instance of `c`, or return fmi2Error (logged) when c is NULL or the mode does not allow F. */
#define BEGIN(F, MODES) \
    Instance *inst = (Instance *)c; \
    if (!rt_allowed(inst, (MODES), #F)) return fmi2Error
#define BEGIN_ME(F, MODES) BEGIN(F, MODES); if (!rt_kind(inst, 1, #F)) return fmi2Error
#define BEGIN_CS(F, MODES) BEGIN(F, MODES); if (!rt_kind(inst, 0, #F)) return fmi2Error

#define GET_MODES (MODE_INITIALIZATION | MODE_STEP | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
#define ME_GET_MODES (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
#define SET_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_EVENT)

/* ------------------------------------------------------------------ common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    BEGIN(fmi2SetDebugLogging, MODES_ANY);
    (void)nCategories;
    (void)categories;
    inst->logging_on = loggingOn != fmi2False;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Fmi2Instance *f;
    const char *name = instanceName ? instanceName : "";
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) {
        if (functions && functions->logger)
            functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                              "fmi2Instantiate: allocateMemory and freeMemory are required");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL_TOKEN) != 0) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                              "fmi2Instantiate: GUID %s does not match %s of model %s",
                              fmuGUID ? fmuGUID : "(null)", MODEL_TOKEN, MODEL_IDENTIFIER);
        return NULL;
    }
    if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                              "fmi2Instantiate: unknown fmuType %d", (int)fmuType);
        return NULL;
    }
    f = (Fmi2Instance *)rt_new(sizeof(Fmi2Instance), name, fmuType == fmi2ModelExchange, 2, TYPE_NAMES,
                               functions->allocateMemory, functions->freeMemory, forward_log);
    if (!f) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, name, fmi2Error, "logStatusError",
                              "fmi2Instantiate: out of memory");
        return NULL;
    }
    f->cb = *functions;
    f->rt.logging_on = loggingOn != fmi2False;
    return f;
}

void fmi2FreeInstance(fmi2Component c)
{
    rt_free((Instance *)c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    BEGIN(fmi2SetupExperiment, MODE_INSTANTIATED);
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    rt_set_time(inst, startTime);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    BEGIN(fmi2EnterInitializationMode, MODE_INSTANTIATED);
    inst->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    BEGIN(fmi2ExitInitializationMode, MODE_INITIALIZATION);
    return (fmi2Status)rt_exit_initialization(inst);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    BEGIN(fmi2Terminate, MODE_STEP | MODE_EVENT | MODE_CONTINUOUS);
    inst->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    BEGIN(fmi2Reset, MODES_ANY);
    rt_reset(inst);
    return fmi2OK;
}

/* ------------------------------------------------------------------ getting and setting values */

/* Every vr checked before the first value is read or stored; one of the output arrays is not NULL. */
static fmi2Status get(Instance *inst, const fmi2ValueReference vr[], size_t nvr, VarType type, const char *function,
                      fmi2Real *reals, fmi2Integer *integers, fmi2Boolean *booleans)
{
    size_t i;
    double v;
    for (i = 0; i < nvr; i++)
        if (!rt_check_var(inst, vr[i], type, 0, function)) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (rt_get(inst, vr[i], &v) != RT_OK) return fmi2Error;
        if (reals) reals[i] = v;
        else if (integers) integers[i] = (fmi2Integer)v;
        else booleans[i] = v != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

static fmi2Status set(Instance *inst, const fmi2ValueReference vr[], size_t nvr, VarType type, const char *function,
                      const fmi2Real *reals, const fmi2Integer *integers, const fmi2Boolean *booleans)
{
    size_t i;
    for (i = 0; i < nvr; i++)
        if (!rt_check_var(inst, vr[i], type, 1, function)) return fmi2Error;
    for (i = 0; i < nvr; i++)
        rt_set(inst, vr[i], reals ? reals[i] : integers ? (double)integers[i] : booleans[i] ? 1.0 : 0.0);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    BEGIN(fmi2GetReal, GET_MODES);
    return get(inst, vr, nvr, TYPE_REAL, "fmi2GetReal", value, NULL, NULL);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    BEGIN(fmi2GetInteger, GET_MODES);
    return get(inst, vr, nvr, TYPE_INTEGER, "fmi2GetInteger", NULL, value, NULL);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    BEGIN(fmi2GetBoolean, GET_MODES);
    return get(inst, vr, nvr, TYPE_BOOLEAN, "fmi2GetBoolean", NULL, NULL, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    size_t i;
    BEGIN(fmi2GetString, GET_MODES);
    for (i = 0; i < nvr; i++)
        if (rt_get_string(inst, vr[i], &value[i], "fmi2GetString") != RT_OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    BEGIN(fmi2SetReal, SET_MODES | MODE_CONTINUOUS);
    return set(inst, vr, nvr, TYPE_REAL, "fmi2SetReal", value, NULL, NULL);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    BEGIN(fmi2SetInteger, SET_MODES);
    return set(inst, vr, nvr, TYPE_INTEGER, "fmi2SetInteger", NULL, value, NULL);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    BEGIN(fmi2SetBoolean, SET_MODES);
    return set(inst, vr, nvr, TYPE_BOOLEAN, "fmi2SetBoolean", NULL, NULL, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    size_t i;
    BEGIN(fmi2SetString, SET_MODES);
    for (i = 0; i < nvr; i++)
        if (rt_set_string(inst, vr[i], value[i], "fmi2SetString") != RT_OK) return fmi2Error;
    return fmi2OK;
}

/* ------------------------------------------------------------------ FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2GetFMUstate, MODES_ANY);
    return (fmi2Status)rt_get_snapshot(inst, (Snapshot **)FMUstate, "fmi2GetFMUstate");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    BEGIN(fmi2SetFMUstate, MODES_ANY);
    return (fmi2Status)rt_set_snapshot(inst, (const Snapshot *)FMUstate, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2FreeFMUstate, MODES_ANY);
    return (fmi2Status)rt_free_snapshot(inst, (Snapshot **)FMUstate, "fmi2FreeFMUstate");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    BEGIN(fmi2SerializedFMUstateSize, MODES_ANY);
    (void)FMUstate;
    *size = rt_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    BEGIN(fmi2SerializeFMUstate, MODES_ANY);
    return (fmi2Status)rt_serialize(inst, (const Snapshot *)FMUstate, (unsigned char *)serializedState, size,
                                    "fmi2SerializeFMUstate");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2DeSerializeFMUstate, MODES_ANY);
    return (fmi2Status)rt_deserialize(inst, (const unsigned char *)serializedState, size, (Snapshot **)FMUstate,
                                      "fmi2DeSerializeFMUstate");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return (fmi2Status)rt_not_supported((Instance *)c, "fmi2GetDirectionalDerivative");
}

/* ------------------------------------------------------------------ model exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    BEGIN_ME(fmi2EnterEventMode, MODE_EVENT | MODE_CONTINUOUS);
    if (rt_me_commit(inst) != RT_OK) return fmi2Error;
    inst->mode = MODE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    BEGIN_ME(fmi2NewDiscreteStates, MODE_EVENT);
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    BEGIN_ME(fmi2EnterContinuousTimeMode, MODE_EVENT);
    inst->mode = MODE_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    BEGIN_ME(fmi2CompletedIntegratorStep, MODE_CONTINUOUS);
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return (fmi2Status)rt_me_commit(inst);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    BEGIN_ME(fmi2SetTime, MODE_EVENT | MODE_CONTINUOUS);
    rt_set_time(inst, time);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    BEGIN_ME(fmi2SetContinuousStates, MODE_CONTINUOUS);
    return (fmi2Status)rt_set_states(inst, x, nx, "fmi2SetContinuousStates");
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    BEGIN_ME(fmi2GetDerivatives, ME_GET_MODES);
    return (fmi2Status)rt_get_derivatives(inst, derivatives, nx, "fmi2GetDerivatives");
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    BEGIN_ME(fmi2GetEventIndicators, ME_GET_MODES);
    (void)eventIndicators;
    return (fmi2Status)rt_check_event_indicators(inst, ni, "fmi2GetEventIndicators");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    BEGIN_ME(fmi2GetContinuousStates, ME_GET_MODES);
    return (fmi2Status)rt_get_states(inst, x, nx, "fmi2GetContinuousStates");
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    BEGIN_ME(fmi2GetNominalsOfContinuousStates, MODES_ANY);
    return (fmi2Status)rt_get_nominals(inst, x_nominal, nx, "fmi2GetNominalsOfContinuousStates");
}

/* ------------------------------------------------------------------ co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)rt_not_supported((Instance *)c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)rt_not_supported((Instance *)c, "fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    BEGIN_CS(fmi2DoStep, MODE_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)rt_do_step(inst, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return (fmi2Status)rt_not_supported((Instance *)c, "fmi2CancelStep (doStep never returns fmi2Pending)");
}

/* Status kinds this FMU cannot report return fmi2Discard, as the standard says. */
static fmi2Status no_status(Instance *inst, const char *function, fmi2StatusKind s)
{
    rt_log(inst, RT_DISCARD, "%s: status kind %d is not available (doStep never returns fmi2Pending)", function,
           (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    BEGIN_CS(fmi2GetStatus, MODE_STEP | MODE_TERMINATED);
    (void)value;
    return no_status(inst, "fmi2GetStatus", s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    BEGIN_CS(fmi2GetRealStatus, MODE_STEP | MODE_TERMINATED);
    if (s != fmi2LastSuccessfulTime) return no_status(inst, "fmi2GetRealStatus", s);
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    BEGIN_CS(fmi2GetIntegerStatus, MODE_STEP | MODE_TERMINATED);
    (void)value;
    return no_status(inst, "fmi2GetIntegerStatus", s);
}

/* fmi2Terminated: true once a step failed, since this instance cannot continue. */
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    BEGIN_CS(fmi2GetBooleanStatus, MODE_STEP | MODE_TERMINATED);
    if (s != fmi2Terminated) return no_status(inst, "fmi2GetBooleanStatus", s);
    *value = inst->failed ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    BEGIN_CS(fmi2GetStringStatus, MODE_STEP | MODE_TERMINATED);
    (void)value;
    return no_status(inst, "fmi2GetStringStatus", s);
}
