/* FMI 3.0 entry points (model exchange and co-simulation, no scheduled execution) on top of runtime.c. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "runtime.h"

typedef struct {
    Instance rt;                 /* first member: an Fmi3Instance * is an Instance * */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
} Fmi3Instance;

static const char *const TYPE_NAMES[] = { "Float64", "Boolean", "Int32", "String" };

static void forward_log(Instance *inst, RtStatus status, const char *category, const char *message)
{
    const Fmi3Instance *f = (const Fmi3Instance *)inst;
    if (f->logMessage) f->logMessage(f->env, (fmi3Status)status, category, message);
}

/* Instance of `instance`, or return fmi3Error (logged) when it is NULL or the mode does not allow F. */
#define BEGIN(F, MODES) \
    Instance *inst = (Instance *)instance; \
    if (!rt_allowed(inst, (MODES), #F)) return fmi3Error
#define BEGIN_ME(F, MODES) BEGIN(F, MODES); if (!rt_kind(inst, 1, #F)) return fmi3Error
#define BEGIN_CS(F, MODES) BEGIN(F, MODES); if (!rt_kind(inst, 0, #F)) return fmi3Error

#define SET_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_EVENT)
#define ME_GET_MODES (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

/* ------------------------------------------------------------------ common functions */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    BEGIN(fmi3SetDebugLogging, MODES_ANY);
    (void)nCategories;
    (void)categories;
    inst->logging_on = loggingOn;
    return fmi3OK;
}

static fmi3Instance instantiate(fmi3String instanceName, fmi3String instantiationToken, int is_me,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback logMessage,
                                const char *function)
{
    Fmi3Instance *f;
    const char *name = instanceName ? instanceName : "";
    if (!instantiationToken || strcmp(instantiationToken, MODEL_TOKEN) != 0) {
        if (logMessage) {
            char message[512];
            snprintf(message, sizeof message, "%s: instantiationToken %s does not match %s of model %s", function,
                     instantiationToken ? instantiationToken : "(null)", MODEL_TOKEN, MODEL_IDENTIFIER);
            logMessage(env, fmi3Error, "logStatusError", message);
        }
        return NULL;
    }
    f = (Fmi3Instance *)rt_new(sizeof(Fmi3Instance), name, is_me, 3, TYPE_NAMES, calloc, free, forward_log);
    if (!f) {
        if (logMessage) logMessage(env, fmi3Error, "logStatusError", "out of memory");
        return NULL;
    }
    f->env = env;
    f->logMessage = logMessage;
    f->rt.logging_on = loggingOn;
    return f;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath;
    (void)visible;
    return instantiate(instanceName, instantiationToken, 1, loggingOn, instanceEnvironment, logMessage,
                       "fmi3InstantiateModelExchange");
}

/* earlyReturnAllowed and the intermediate update callback are accepted and never used (no early return);
 * eventModeUsed makes exitInitializationMode enter event mode, where nothing ever happens. */
fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Instance *inst;
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    inst = (Instance *)instantiate(instanceName, instantiationToken, 0, loggingOn, instanceEnvironment, logMessage,
                                   "fmi3InstantiateCoSimulation");
    if (inst) inst->event_mode_used = eventModeUsed;
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    rt_free((Instance *)instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    BEGIN(fmi3EnterInitializationMode, MODE_INSTANTIATED);
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    rt_set_time(inst, startTime);
    inst->mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    BEGIN(fmi3ExitInitializationMode, MODE_INITIALIZATION);
    return (fmi3Status)rt_exit_initialization(inst);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    BEGIN(fmi3EnterEventMode, MODE_CONTINUOUS | MODE_STEP);
    if (!inst->is_me && !inst->event_mode_used) {
        rt_log(inst, RT_ERROR, "fmi3EnterEventMode: the instance was created with eventModeUsed = false");
        return fmi3Error;
    }
    if (inst->is_me && rt_me_commit(inst) != RT_OK) return fmi3Error;
    inst->mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    BEGIN(fmi3Terminate, MODE_STEP | MODE_EVENT | MODE_CONTINUOUS);
    inst->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    BEGIN(fmi3Reset, MODES_ANY);
    rt_reset(inst);
    return fmi3OK;
}

/* ------------------------------------------------------------------ getting and setting values */

static int check_sizes(Instance *inst, size_t nValueReferences, size_t nValues, const char *function)
{
    if (nValues == nValueReferences) return 1;
    rt_log(inst, RT_ERROR, "%s: nValues = %lu must equal nValueReferences = %lu (no array variables)", function,
           (unsigned long)nValues, (unsigned long)nValueReferences);
    return 0;
}

/* Every vr checked before the first value is read or stored; one of the value arrays is not NULL. */
static fmi3Status get(Instance *inst, const fmi3ValueReference vr[], size_t nvr, size_t nValues, VarType type,
                      const char *function, fmi3Float64 *reals, fmi3Int32 *integers, fmi3Boolean *booleans)
{
    size_t i;
    double v;
    if (!check_sizes(inst, nvr, nValues, function)) return fmi3Error;
    for (i = 0; i < nvr; i++)
        if (!rt_check_var(inst, vr[i], type, 0, function)) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        if (rt_get(inst, vr[i], &v) != RT_OK) return fmi3Error;
        if (reals) reals[i] = v;
        else if (integers) integers[i] = (fmi3Int32)v;
        else booleans[i] = v != 0.0;
    }
    return fmi3OK;
}

static fmi3Status set(Instance *inst, const fmi3ValueReference vr[], size_t nvr, size_t nValues, VarType type,
                      const char *function, const fmi3Float64 *reals, const fmi3Int32 *integers,
                      const fmi3Boolean *booleans)
{
    size_t i;
    if (!check_sizes(inst, nvr, nValues, function)) return fmi3Error;
    for (i = 0; i < nvr; i++)
        if (!rt_check_var(inst, vr[i], type, 1, function)) return fmi3Error;
    for (i = 0; i < nvr; i++)
        rt_set(inst, vr[i], reals ? reals[i] : integers ? (double)integers[i] : booleans[i] ? 1.0 : 0.0);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues)
{
    BEGIN(fmi3GetFloat64, MODES_ANY);
    return get(inst, valueReferences, nValueReferences, nValues, TYPE_REAL, "fmi3GetFloat64", values, NULL, NULL);
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues)
{
    BEGIN(fmi3GetInt32, MODES_ANY);
    return get(inst, valueReferences, nValueReferences, nValues, TYPE_INTEGER, "fmi3GetInt32", NULL, values, NULL);
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Boolean values[], size_t nValues)
{
    BEGIN(fmi3GetBoolean, MODES_ANY);
    return get(inst, valueReferences, nValueReferences, nValues, TYPE_BOOLEAN, "fmi3GetBoolean", NULL, NULL, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues)
{
    BEGIN(fmi3SetFloat64, SET_MODES | MODE_CONTINUOUS);
    return set(inst, valueReferences, nValueReferences, nValues, TYPE_REAL, "fmi3SetFloat64", values, NULL, NULL);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues)
{
    BEGIN(fmi3SetInt32, SET_MODES);
    return set(inst, valueReferences, nValueReferences, nValues, TYPE_INTEGER, "fmi3SetInt32", NULL, values, NULL);
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Boolean values[], size_t nValues)
{
    BEGIN(fmi3SetBoolean, SET_MODES);
    return set(inst, valueReferences, nValueReferences, nValues, TYPE_BOOLEAN, "fmi3SetBoolean", NULL, NULL, values);
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         fmi3String values[], size_t nValues)
{
    size_t i;
    BEGIN(fmi3GetString, MODES_ANY);
    if (nValues != nValueReferences) {
        rt_log(inst, RT_ERROR, "fmi3GetString: nValues (%lu) must equal nValueReferences (%lu): no arrays",
               (unsigned long)nValues, (unsigned long)nValueReferences);
        return fmi3Error;
    }
    for (i = 0; i < nValueReferences; i++)
        if (rt_get_string(inst, valueReferences[i], &values[i], "fmi3GetString") != RT_OK) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues)
{
    size_t i;
    BEGIN(fmi3SetString, SET_MODES);
    if (nValues != nValueReferences) {
        rt_log(inst, RT_ERROR, "fmi3SetString: nValues (%lu) must equal nValueReferences (%lu): no arrays",
               (unsigned long)nValues, (unsigned long)nValueReferences);
        return fmi3Error;
    }
    for (i = 0; i < nValueReferences; i++)
        if (rt_set_string(inst, valueReferences[i], values[i], "fmi3SetString") != RT_OK) return fmi3Error;
    return fmi3OK;
}

/* Types no variable has: an error naming the first value reference (nothing to do for none). */
static fmi3Status no_type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const char *type,
                          const char *function)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    return nvr == 0 ? fmi3OK : (fmi3Status)rt_type_error(inst, vr[0], type, function);
}

#define NO_GETTER(T) \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, fmi3##T values[], size_t nValues) \
    { \
        (void)values; (void)nValues; \
        return no_type(instance, valueReferences, nValueReferences, #T, "fmi3Get" #T); \
    }
#define NO_SETTER(T) \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, const fmi3##T values[], size_t nValues) \
    { \
        (void)values; (void)nValues; \
        return no_type(instance, valueReferences, nValueReferences, #T, "fmi3Set" #T); \
    }

NO_GETTER(Float32)
NO_GETTER(Int8)
NO_GETTER(UInt8)
NO_GETTER(Int16)
NO_GETTER(UInt16)
NO_GETTER(UInt32)
NO_GETTER(Int64)
NO_GETTER(UInt64)
NO_SETTER(Float32)
NO_SETTER(Int8)
NO_SETTER(UInt8)
NO_SETTER(Int16)
NO_SETTER(UInt16)
NO_SETTER(UInt32)
NO_SETTER(Int64)
NO_SETTER(UInt64)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_type(instance, valueReferences, nValueReferences, "Binary", "fmi3GetBinary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_type(instance, valueReferences, nValueReferences, "Binary", "fmi3SetBinary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    (void)values;
    return no_type(instance, valueReferences, nValueReferences, "Clock", "fmi3GetClock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    (void)values;
    return no_type(instance, valueReferences, nValueReferences, "Clock", "fmi3SetClock");
}

/* ------------------------------------------------------------------ not supported */

#define NOT_SUPPORTED(F) return (fmi3Status)rt_not_supported((Instance *)instance, #F)

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    NOT_SUPPORTED(fmi3GetNumberOfVariableDependencies);
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    NOT_SUPPORTED(fmi3GetVariableDependencies);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    NOT_SUPPORTED(fmi3GetDirectionalDerivative);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    NOT_SUPPORTED(fmi3GetAdjointDerivative);
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED(fmi3EnterConfigurationMode); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED(fmi3ExitConfigurationMode); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    NOT_SUPPORTED(fmi3GetIntervalDecimal);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    NOT_SUPPORTED(fmi3GetIntervalFraction);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    NOT_SUPPORTED(fmi3GetShiftDecimal);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3GetShiftFraction);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    NOT_SUPPORTED(fmi3SetIntervalDecimal);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3SetIntervalFraction);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    NOT_SUPPORTED(fmi3SetShiftDecimal);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3SetShiftFraction);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { NOT_SUPPORTED(fmi3EvaluateDiscreteStates); }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    NOT_SUPPORTED(fmi3GetOutputDerivatives);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    NOT_SUPPORTED(fmi3ActivateModelPartition);
}

/* ------------------------------------------------------------------ FMU state */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    BEGIN(fmi3GetFMUState, MODES_ANY);
    return (fmi3Status)rt_get_snapshot(inst, (Snapshot **)FMUState, "fmi3GetFMUState");
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    BEGIN(fmi3SetFMUState, MODES_ANY);
    return (fmi3Status)rt_set_snapshot(inst, (const Snapshot *)FMUState, "fmi3SetFMUState");
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    BEGIN(fmi3FreeFMUState, MODES_ANY);
    return (fmi3Status)rt_free_snapshot(inst, (Snapshot **)FMUState, "fmi3FreeFMUState");
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    BEGIN(fmi3SerializedFMUStateSize, MODES_ANY);
    (void)FMUState;
    *size = rt_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    BEGIN(fmi3SerializeFMUState, MODES_ANY);
    return (fmi3Status)rt_serialize(inst, (const Snapshot *)FMUState, serializedState, size, "fmi3SerializeFMUState");
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    BEGIN(fmi3DeserializeFMUState, MODES_ANY);
    return (fmi3Status)rt_deserialize(inst, serializedState, size, (Snapshot **)FMUState, "fmi3DeserializeFMUState");
}

/* ------------------------------------------------------------------ event mode (model exchange, and
 * co-simulation with eventModeUsed): no events, no discrete states, no clocks */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    BEGIN(fmi3UpdateDiscreteStates, MODE_EVENT);
    *discreteStatesNeedUpdate = false;
    *terminateSimulation = false;
    *nominalsOfContinuousStatesChanged = false;
    *valuesOfContinuousStatesChanged = false;
    *nextEventTimeDefined = false;
    *nextEventTime = 0.0;
    return fmi3OK;
}

/* ------------------------------------------------------------------ model exchange */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    BEGIN_ME(fmi3EnterContinuousTimeMode, MODE_EVENT);
    inst->mode = MODE_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    BEGIN_ME(fmi3CompletedIntegratorStep, MODE_CONTINUOUS);
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = false;
    *terminateSimulation = false;
    return (fmi3Status)rt_me_commit(inst);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    BEGIN_ME(fmi3SetTime, MODE_EVENT | MODE_CONTINUOUS);
    rt_set_time(inst, time);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    BEGIN_ME(fmi3SetContinuousStates, MODE_CONTINUOUS);
    return (fmi3Status)rt_set_states(inst, continuousStates, nContinuousStates, "fmi3SetContinuousStates");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    BEGIN_ME(fmi3GetContinuousStateDerivatives, ME_GET_MODES);
    return (fmi3Status)rt_get_derivatives(inst, derivatives, nContinuousStates, "fmi3GetContinuousStateDerivatives");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    BEGIN_ME(fmi3GetEventIndicators, ME_GET_MODES);
    (void)eventIndicators;
    return (fmi3Status)rt_check_event_indicators(inst, nEventIndicators, "fmi3GetEventIndicators");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    BEGIN_ME(fmi3GetContinuousStates, ME_GET_MODES);
    return (fmi3Status)rt_get_states(inst, continuousStates, nContinuousStates, "fmi3GetContinuousStates");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    BEGIN_ME(fmi3GetNominalsOfContinuousStates, ME_GET_MODES | MODE_INSTANTIATED);
    return (fmi3Status)rt_get_nominals(inst, nominals, nContinuousStates, "fmi3GetNominalsOfContinuousStates");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    BEGIN(fmi3GetNumberOfEventIndicators, MODES_ANY);
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    BEGIN(fmi3GetNumberOfContinuousStates, MODES_ANY);
    *nContinuousStates = MODEL_N_CONTINUOUS;
    return fmi3OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    BEGIN_CS(fmi3EnterStepMode, MODE_EVENT);
    inst->mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    fmi3Status status;
    BEGIN_CS(fmi3DoStep, MODE_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    status = (fmi3Status)rt_do_step(inst, currentCommunicationPoint, communicationStepSize);
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    *lastSuccessfulTime = inst->time;
    return status;
}
