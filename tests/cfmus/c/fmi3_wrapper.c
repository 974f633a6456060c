/*
 * fmi3_wrapper.c - the FMI 3.0 C API (Model Exchange and Co-Simulation in one
 * binary; Scheduled Execution refuses to instantiate) on top of core.c.
 *
 * Array variables are read and written with nValues = the total number of
 * elements of the variables requested; any other count is an error that is
 * logged. Optional features the models do not declare (FMU state unless
 * the model declares it, directional/adjoint derivatives, output derivatives,
 * clock intervals, event mode in co-simulation, dependencies at run time)
 * return fmi3Error with a message.
 */
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "fmi3Functions.h"

#ifndef INSTANTIATION_TOKEN
#error "compile with -DINSTANTIATION_TOKEN=\"...\" (the instantiationToken of modelDescription.xml)"
#endif

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Logger;

typedef struct {
    Instance *core;
    Logger logger;
} Component;

#define BEGIN(c, modes)                                                \
    Instance *in;                                                      \
    if (!(c)) return fmi3Error;                                        \
    in = ((Component *)(c))->core;                                     \
    if (!core_allowed(in, __func__, (modes))) return fmi3Error

static void sink(void *env, const char *name, Status status, const char *category, const char *message)
{
    const Logger *logger = env;
    (void)name;
    if (logger && logger->log) logger->log(logger->env, (fmi3Status)status, category, message);
}

/* ---------------------------------------------------------------- life cycle */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    BEGIN(instance, ~0u);
    (void)nCategories;
    (void)categories;
    in->logging_on = loggingOn;
    return fmi3OK;
}

static fmi3Instance instantiate(Interface iface, fmi3String name, fmi3String token, fmi3Boolean loggingOn,
                                fmi3InstanceEnvironment env, fmi3LogMessageCallback log)
{
    Component *comp;
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        if (log)
            log(env, fmi3Error, "logStatusError", "instantiate: the instantiationToken does not match this binary");
        return NULL;
    }
    comp = calloc(1, sizeof *comp);
    if (!comp) return NULL;
    comp->logger.env = env;
    comp->logger.log = log;
    comp->core = core_new(3, iface, name, sink, &comp->logger, loggingOn);
    if (!comp->core) {
        free(comp);
        return NULL;
    }
    return comp;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath;
    (void)visible;
    return instantiate(IF_MODEL_EXCHANGE, instanceName, instantiationToken, loggingOn, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Component *comp;
    (void)resourcePath;
    (void)visible;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (eventModeUsed) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: event mode is not supported (hasEventMode=\"false\")");
        return NULL;
    }
    comp = instantiate(IF_CO_SIMULATION, instanceName, instantiationToken, loggingOn, instanceEnvironment,
                       logMessage);
    if (comp) comp->core->early_return_allowed = earlyReturnAllowed;
    return comp;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU has no ScheduledExecution interface");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    if (!instance) return;
    core_free(((Component *)instance)->core);
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    BEGIN(instance, M_INSTANTIATED);
    (void)toleranceDefined;
    (void)tolerance;
    return (fmi3Status)core_enter_initialization(in, startTime, stopTimeDefined, stopTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    BEGIN(instance, M_INITIALIZATION);
    return (fmi3Status)core_exit_initialization(in);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    BEGIN(instance, M_EVENT | M_CONTINUOUS);
    if (in->iface != IF_MODEL_EXCHANGE)
        return (fmi3Status)core_fail(in, __func__, "event mode is not supported in co-simulation");
    in->mode = M_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    BEGIN(instance, M_EVENT | M_CONTINUOUS | M_STEP);
    in->mode = M_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    BEGIN(instance, ~0u);
    return (fmi3Status)core_reset(in);
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    BEGIN(instance, M_INSTANTIATED);
    if (!MODEL.resize) return (fmi3Status)core_fail(in, __func__, "the model has no structural parameters");
    in->mode = M_CONFIGURATION;
    return fmi3OK;
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    BEGIN(instance, M_CONFIGURATION);
    in->mode = M_INSTANTIATED;
    return fmi3OK;
}

/* ---------------------------------------------------------------- getters and setters */

#define GET_MODES (M_CONFIGURATION | M_INITIALIZATION | M_AFTER_INIT)
#define SET_MODES (M_INSTANTIATED | M_CONFIGURATION | M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_STEP)

/* Check every variable of a get/set call before touching any value: the
   value references, their types, (for set) the mode, and that nValues is
   the total number of their elements. */
static bool check_call(Instance *in, const char *fn, const fmi3ValueReference vr[], size_t nvr, unsigned accepted,
                       size_t nValues, bool set)
{
    size_t needed = 0;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, fn, vr[i], accepted);
        if (!v || (set && !core_can_set(in, fn, v))) return false;
        needed += core_length(in, v);
    }
    if (needed != nValues) {
        core_count_error(in, fn, nValues, needed);
        return false;
    }
    if (!set) core_update(in);
    return true;
}

/* Values stored exactly as the API type (numbers, Boolean, Clock) are
   copied element-wise as bytes. */
static fmi3Status get_plain(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr,
                            unsigned accepted, size_t size, void *values, size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, GET_MODES);
    if (!check_call(in, fn, vr, nvr, accepted, nValues, false)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, fn, vr[i], accepted);
        size_t n = core_length(in, v);
        memcpy((char *)values + k * size, core_element(in, v), n * size);
        k += n;
    }
    return fmi3OK;
}

static fmi3Status set_plain(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr,
                            unsigned accepted, size_t size, const void *values, size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, SET_MODES);
    if (!check_call(in, fn, vr, nvr, accepted, nValues, true)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, fn, vr[i], accepted);
        size_t n = core_length(in, v);
        uint64_t old = 0;
        void *dst = core_element(in, v);
        if (n == 1) memcpy(&old, dst, size < sizeof old ? size : sizeof old);
        memcpy(dst, (const char *)values + k * size, n * size);
        k += n;
        if (core_after_set(in, fn, v, &old) != ST_OK) return fmi3Error;
    }
    return fmi3OK;
}

#define PLAIN_ACCESSORS(NAME, CTYPE, ACCEPTED)                                                                     \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, CTYPE values[],     \
                             size_t nValues)                                                                       \
    {                                                                                                              \
        return get_plain(instance, "fmi3Get" #NAME, vr, nvr, ACCEPTED, sizeof(CTYPE), values, nValues);           \
    }                                                                                                              \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                     \
                             const CTYPE values[], size_t nValues)                                                 \
    {                                                                                                              \
        return set_plain(instance, "fmi3Set" #NAME, vr, nvr, ACCEPTED, sizeof(CTYPE), values, nValues);           \
    }

PLAIN_ACCESSORS(Float32, fmi3Float32, T_FLOAT32)
PLAIN_ACCESSORS(Float64, fmi3Float64, T_FLOAT64)
PLAIN_ACCESSORS(Int8, fmi3Int8, T_INT8)
PLAIN_ACCESSORS(UInt8, fmi3UInt8, T_UINT8)
PLAIN_ACCESSORS(Int16, fmi3Int16, T_INT16)
PLAIN_ACCESSORS(UInt16, fmi3UInt16, T_UINT16)
PLAIN_ACCESSORS(Int32, fmi3Int32, T_INT32)
PLAIN_ACCESSORS(UInt32, fmi3UInt32, T_UINT32)
PLAIN_ACCESSORS(Int64, fmi3Int64, T_INT64 | T_ENUM)
PLAIN_ACCESSORS(UInt64, fmi3UInt64, T_UINT64)
PLAIN_ACCESSORS(Boolean, fmi3Boolean, T_BOOL)

/* Strings: the pointers returned stay valid until the variable is set again. */
fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, GET_MODES);
    if (!check_call(in, __func__, vr, nvr, T_STRING, nValues, false)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        char *const *s = core_element(in, v);
        for (size_t j = 0; j < core_length(in, v); j++) values[k++] = s[j] ? s[j] : "";
    }
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[],
                         size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, SET_MODES);
    if (!check_call(in, __func__, vr, nvr, T_STRING, nValues, true)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        char **s = core_element(in, v);
        for (size_t j = 0; j < core_length(in, v); j++, k++)
            if (!fmu_copy_string(&s[j], values[k] ? values[k] : ""))
                return (fmi3Status)core_fail(in, __func__, "out of memory");
        core_after_set(in, __func__, v, NULL);
    }
    return fmi3OK;
}

/* Binary values: the pointers returned stay valid until the variable is set again. */
fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, GET_MODES);
    if (!check_call(in, __func__, vr, nvr, T_BINARY, nValues, false)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BINARY);
        const Blob *b = core_element(in, v);
        for (size_t j = 0; j < core_length(in, v); j++, k++) {
            valueSizes[k] = b[j].size;
            values[k] = b[j].data;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    size_t k = 0;
    BEGIN(instance, SET_MODES);
    if (!check_call(in, __func__, vr, nvr, T_BINARY, nValues, true)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BINARY);
        Blob *b = core_element(in, v);
        for (size_t j = 0; j < core_length(in, v); j++, k++)
            if (!fmu_copy_blob(&b[j], values[k], values[k] ? valueSizes[k] : 0))
                return (fmi3Status)core_fail(in, __func__, "out of memory");
        core_after_set(in, __func__, v, NULL);
    }
    return fmi3OK;
}

/* Clocks are scalars: one value per value reference. */
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    return get_plain(instance, "fmi3GetClock", vr, nvr, T_CLOCK, sizeof(fmi3Clock), values, nvr);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    return set_plain(instance, "fmi3SetClock", vr, nvr, T_CLOCK, sizeof(fmi3Clock), values, nvr);
}

/* ---------------------------------------------------------------- unsupported optional features */

static fmi3Status unsupported(fmi3Instance instance, const char *fn, const char *what)
{
    if (instance) core_fail(((Component *)instance)->core, fn, "%s is not supported by this FMU", what);
    return fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference;
    (void)nDependencies;
    return unsupported(instance, __func__, "querying dependencies at run time (see ModelStructure)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    (void)nDependencies;
    return unsupported(instance, __func__, "querying dependencies at run time (see ModelStructure)");
}

/* FMU state (core.h; models that declare it) */

#define BEGIN_STATE(c, what)                                                           \
    BEGIN(c, ~0u);                                                                     \
    if (!CFMU_FMU_STATE) return unsupported(c, __func__, what)

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    BEGIN_STATE(instance, "getting the FMU state");
    return (fmi3Status)core_get_state(in, __func__, FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    BEGIN_STATE(instance, "setting the FMU state");
    return (fmi3Status)core_set_state(in, __func__, FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    BEGIN_STATE(instance, "freeing an FMU state");
    if (FMUState) core_free_state(FMUState);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    BEGIN_STATE(instance, "serializing the FMU state");
    (void)FMUState;
    *size = core_state_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    BEGIN_STATE(instance, "serializing the FMU state");
    return (fmi3Status)core_serialize_state(in, __func__, FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    BEGIN_STATE(instance, "de-serializing the FMU state");
    return (fmi3Status)core_deserialize_state(in, __func__, serializedState, size, FMUState);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity)
{
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, __func__, "computing directional derivatives");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, __func__, "computing adjoint derivatives");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr;
    (void)nvr;
    (void)intervals;
    (void)qualifiers;
    return unsupported(instance, __func__, "clock intervals (the clocks are triggered)");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    (void)qualifiers;
    return unsupported(instance, __func__, "clock intervals (the clocks are triggered)");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[])
{
    (void)vr;
    (void)nvr;
    (void)shifts;
    return unsupported(instance, __func__, "clock shifts (the clocks are triggered)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    return unsupported(instance, __func__, "clock shifts (the clocks are triggered)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr;
    (void)nvr;
    (void)intervals;
    return unsupported(instance, __func__, "clock intervals (the clocks are triggered)");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    return unsupported(instance, __func__, "clock intervals (the clocks are triggered)");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr;
    (void)nvr;
    (void)shifts;
    return unsupported(instance, __func__, "clock shifts (the clocks are triggered)");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr;
    (void)nvr;
    (void)counters;
    (void)resolutions;
    return unsupported(instance, __func__, "clock shifts (the clocks are triggered)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr;
    (void)nvr;
    (void)orders;
    (void)values;
    (void)nValues;
    return unsupported(instance, __func__, "providing output derivatives");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference;
    (void)activationTime;
    return unsupported(instance, __func__, "scheduled execution");
}

/* ---------------------------------------------------------------- model exchange */

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    BEGIN(instance, M_EVENT | M_CONTINUOUS);
    return fmi3OK;   /* no clocked partitions to evaluate ahead of the update */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    EventUpdate ev;
    BEGIN(instance, M_EVENT);
    core_event_update(in, &ev);
    *discreteStatesNeedUpdate = ev.more;
    *terminateSimulation = ev.terminate;
    *nominalsOfContinuousStatesChanged = ev.nominals_changed;
    *valuesOfContinuousStatesChanged = ev.states_changed;
    *nextEventTimeDefined = ev.next_time_defined;
    *nextEventTime = ev.next_time_defined ? ev.next_time : 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    BEGIN(instance, M_EVENT);
    if (in->iface != IF_MODEL_EXCHANGE) return (fmi3Status)core_fail(in, __func__, "only for model exchange");
    in->mode = M_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    BEGIN(instance, M_CONTINUOUS);
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = MODEL.step_event && MODEL.step_event(in->data, in->time);
    *terminateSimulation = false;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    BEGIN(instance, M_CONTINUOUS);
    return (fmi3Status)core_set_time(in, time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    BEGIN(instance, M_CONTINUOUS | M_EVENT);
    return (fmi3Status)core_states(in, __func__, (double *)continuousStates, nContinuousStates, true);
}

#define ME_GET_MODES (M_INITIALIZATION | M_EVENT | M_CONTINUOUS | M_TERMINATED)

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    BEGIN(instance, ME_GET_MODES);
    core_update(in);
    return (fmi3Status)core_derivatives(in, __func__, derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    BEGIN(instance, ME_GET_MODES);
    core_update(in);
    return (fmi3Status)core_indicators(in, __func__, eventIndicators, nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    BEGIN(instance, ME_GET_MODES);
    return (fmi3Status)core_states(in, __func__, continuousStates, nContinuousStates, false);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    BEGIN(instance, ME_GET_MODES);
    return (fmi3Status)core_nominals(in, __func__, nominals, nContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    BEGIN(instance, ~0u);
    *nEventIndicators = core_n_indicators(in);
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    BEGIN(instance, ~0u);
    *nContinuousStates = core_n_states(in);
    return fmi3OK;
}

/* ---------------------------------------------------------------- co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    BEGIN(instance, M_EVENT);
    return (fmi3Status)core_fail(in, __func__, "event mode is not supported in co-simulation");
}

/*
 * When the model asks to terminate at the end of the step, fmi3DoStep returns
 * fmi3OK with terminateSimulation. When it asks inside the step, the FMU
 * stops there: with early return allowed it returns fmi3OK, terminateSimulation,
 * earlyReturn and lastSuccessfulTime = the termination time; without, it
 * cannot return early and reports fmi3Discard with terminateSimulation and
 * lastSuccessfulTime (the FMI 3 form of FMI 2's fmi2Terminated). A rejected
 * step (the model's t_reject) is fmi3Discard without termination, with
 * nothing changed: lastSuccessfulTime = currentCommunicationPoint.
 */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    double t_end;
    bool event;
    BEGIN(instance, M_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    switch (core_do_step(in, currentCommunicationPoint, communicationStepSize, &t_end, &event)) {
    case STEP_DONE:
        *lastSuccessfulTime = t_end;
        return fmi3OK;
    case STEP_TERMINATED:
        *terminateSimulation = true;
        *lastSuccessfulTime = t_end;
        if (fmu_time_reached(t_end, currentCommunicationPoint + communicationStepSize)) return fmi3OK;
        if (in->early_return_allowed) {
            *earlyReturn = true;
            core_debug(in, "the model terminates the simulation at t = %.17g (early return)", t_end);
            return fmi3OK;
        }
        core_log(in, ST_DISCARD, "logStatusDiscard",
                 "the model terminates the simulation at t = %.17g, inside the step (early return not allowed)",
                 t_end);
        return fmi3Discard;
    case STEP_REJECTED:
        *lastSuccessfulTime = currentCommunicationPoint;
        return fmi3Discard;
    default:
        in->mode = M_ERROR;
        *lastSuccessfulTime = in->time;
        return fmi3Error;
    }
}
