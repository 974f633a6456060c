/*
 * fmi1_wrapper.c - the FMI 1.0 C APIs (Model Exchange and Co-Simulation) on
 * top of core.c. FMI 1.0 prefixes every function with the model identifier
 * (Stair_fmiDoStep): compile with -DMODEL_IDENTIFIER=<identifier>. One binary
 * exports both APIs; an FMI 1.0 FMU is either model exchange or
 * co-simulation, so modelDescription.xml announces one of them (an
 * <Implementation> element for co-simulation).
 *
 * FMI 1.0 differs from 2.0 where the core's mode machine shows it: no
 * initialization mode (fmiInitialize / fmiInitializeSlave do it all, model
 * exchange's returning the result of the first event update), no event mode
 * (fmiEventUpdate is called in continuous time, and a discrete input may be
 * set there: the next fmiEventUpdate takes it), and no way for a
 * co-simulation slave to ask to end the simulation: a step the model ends
 * early is fmiDiscard with fmiLastSuccessfulTime, as any partial step.
 */
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "fmi1Functions.h"

#ifndef INSTANTIATION_TOKEN
#error "compile with -DINSTANTIATION_TOKEN=\"...\" (the guid of modelDescription.xml)"
#endif
#ifndef MODEL_IDENTIFIER
#error "compile with -DMODEL_IDENTIFIER=<modelIdentifier> (the prefix of every FMI 1.0 function)"
#endif

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define FMI1(name) CAT(MODEL_IDENTIFIER, CAT(_fmi, name))
#define EXPORT __attribute__((visibility("default")))

typedef struct {
    Instance *core;
    fmi1CallbackFunctions callbacks;
} Component;

#define CORE(c) (((Component *)(c))->core)

#define BEGIN(c, modes)                                                \
    Instance *in;                                                      \
    if (!(c)) return fmi1Error;                                        \
    in = CORE(c);                                                      \
    if (!core_allowed(in, __func__, (modes))) return fmi1Error

/* FMI 1.0 loggers get the component itself (there is no componentEnvironment); some exporters' send NULL */
static void sink(void *env, const char *name, Status status, const char *category, const char *message)
{
    Component *comp = env;
    char escaped[2048];
    size_t j = 0;
    if (!comp || !comp->callbacks.logger) return;
    for (size_t i = 0; message[i] && j + 2 < sizeof escaped; i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    comp->callbacks.logger(MODEL.null_log_environment ? NULL : comp, name, (fmi1Status)status, category, escaped);
}

static Component *instantiate(const char *fn, fmi1String instanceName, fmi1String guid,
                              fmi1CallbackFunctions functions, fmi1Boolean loggingOn, Interface iface)
{
    Component *comp;
    if (!guid || strcmp(guid, INSTANTIATION_TOKEN) != 0) {
        if (functions.logger)
            functions.logger(NULL, instanceName, fmi1Error, "logStatusError",
                             "%s: the GUID does not match this binary", fn);
        return NULL;
    }
    comp = calloc(1, sizeof *comp);
    if (!comp) return NULL;
    comp->callbacks = functions;
    comp->core = core_new(1, iface, instanceName, sink, comp, loggingOn != fmi1False);
    if (!comp->core) {
        free(comp);
        return NULL;
    }
    return comp;
}

static void free_instance(fmi1Component c)
{
    if (!c) return;
    core_free(CORE(c));
    free(c);
}

/* ---------------------------------------------------------------- common */

EXPORT const char *FMI1(GetVersion)(void) { return "1.0"; }

EXPORT fmi1Status FMI1(SetDebugLogging)(fmi1Component c, fmi1Boolean loggingOn)
{
    BEGIN(c, ~0u);
    in->logging_on = loggingOn != fmi1False;
    return fmi1OK;
}

#define GET_MODES (M_INITIALIZATION | M_AFTER_INIT)

EXPORT fmi1Status FMI1(GetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Real value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_FLOAT64);
        if (!v) return fmi1Error;
        value[i] = *(const double *)core_element(in, v);
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Integer value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_INT32 | T_ENUM);
        if (!v) return fmi1Error;
        if (v->type == T_ENUM) value[i] = (fmi1Integer) * (const int64_t *)core_element(in, v);
        else value[i] = *(const int32_t *)core_element(in, v);
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Boolean value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BOOL);
        if (!v) return fmi1Error;
        value[i] = *(const bool *)core_element(in, v) ? fmi1True : fmi1False;
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1String value[])
{
    BEGIN(c, GET_MODES);
    core_update(in);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        const char *s;
        if (!v) return fmi1Error;
        s = *(char *const *)core_element(in, v);
        value[i] = s ? s : "";
    }
    return fmi1OK;
}

/* FMI 1.0 model exchange has no event mode: a discrete input set in continuous time is taken at the next
   fmiEventUpdate, so the core (whose FMI 2/3 rules allow that in event mode only) is asked as in event mode. */
static bool can_set(Instance *in, const char *fn, const VarInfo *v)
{
    Mode mode = in->mode;
    bool ok;
    if (in->iface == IF_MODEL_EXCHANGE && mode == M_CONTINUOUS) in->mode = M_EVENT;
    ok = core_can_set(in, fn, v);
    in->mode = mode;
    return ok;
}

#define SET_MODES (M_INSTANTIATED | M_EVENT | M_CONTINUOUS | M_STEP)

EXPORT fmi1Status FMI1(SetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1Real value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_FLOAT64);
        if (!v || !can_set(in, __func__, v)) return fmi1Error;
        *(double *)core_element(in, v) = value[i];
        core_after_set(in, __func__, v, NULL);
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(SetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                   const fmi1Integer value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_INT32 | T_ENUM);
        if (!v || !can_set(in, __func__, v)) return fmi1Error;
        if (v->type == T_ENUM) *(int64_t *)core_element(in, v) = value[i];
        else *(int32_t *)core_element(in, v) = value[i];
        core_after_set(in, __func__, v, NULL);
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(SetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                   const fmi1Boolean value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_BOOL);
        if (!v || !can_set(in, __func__, v)) return fmi1Error;
        *(bool *)core_element(in, v) = value[i] != fmi1False;
        core_after_set(in, __func__, v, NULL);
    }
    return fmi1OK;
}

EXPORT fmi1Status FMI1(SetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                  const fmi1String value[])
{
    BEGIN(c, SET_MODES);
    for (size_t i = 0; i < nvr; i++) {
        const VarInfo *v = core_lookup(in, __func__, vr[i], T_STRING);
        if (!v || !can_set(in, __func__, v)) return fmi1Error;
        if (!fmu_copy_string((char **)core_element(in, v), value[i] ? value[i] : ""))
            return (fmi1Status)core_fail(in, __func__, "out of memory");
        core_after_set(in, __func__, v, NULL);
    }
    return fmi1OK;
}

/* ---------------------------------------------------------------- model exchange */

EXPORT const char *FMI1(GetModelTypesPlatform)(void) { return "standard32"; }

EXPORT fmi1Component FMI1(InstantiateModel)(fmi1String instanceName, fmi1String GUID,
                                            fmi1CallbackFunctions functions, fmi1Boolean loggingOn)
{
    return instantiate(__func__, instanceName, GUID, functions, loggingOn, IF_MODEL_EXCHANGE);
}

EXPORT void FMI1(FreeModelInstance)(fmi1Component c) { free_instance(c); }

EXPORT fmi1Status FMI1(SetTime)(fmi1Component c, fmi1Real time)
{
    BEGIN(c, M_INSTANTIATED | M_CONTINUOUS);
    if (in->mode == M_INSTANTIATED) {  /* before fmiInitialize: the start time */
        in->time = time;
        return fmi1OK;
    }
    return (fmi1Status)core_set_time(in, time);
}

EXPORT fmi1Status FMI1(SetContinuousStates)(fmi1Component c, const fmi1Real x[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS);
    return (fmi1Status)core_states(in, __func__, (double *)x, nx, true);
}

EXPORT fmi1Status FMI1(CompletedIntegratorStep)(fmi1Component c, fmi1Boolean *callEventUpdate)
{
    BEGIN(c, M_CONTINUOUS);
    *callEventUpdate = MODEL.step_event && MODEL.step_event(in->data, in->time) ? fmi1True : fmi1False;
    return fmi1OK;
}

/* one discrete update in continuous time, reported in the FMI 1.0 terms */
static void event_update(Instance *in, fmi1EventInfo *info)
{
    EventUpdate ev;
    in->mode = M_EVENT;
    core_event_update(in, &ev);
    in->mode = M_CONTINUOUS;
    info->iterationConverged = ev.more ? fmi1False : fmi1True;
    info->stateValueReferencesChanged = fmi1False;
    info->stateValuesChanged = ev.states_changed ? fmi1True : fmi1False;
    info->terminateSimulation = ev.terminate ? fmi1True : fmi1False;
    info->upcomingTimeEvent = ev.next_time_defined ? fmi1True : fmi1False;
    info->nextEventTime = ev.next_time;
}

EXPORT fmi1Status FMI1(Initialize)(fmi1Component c, fmi1Boolean toleranceControlled, fmi1Real relativeTolerance,
                                   fmi1EventInfo *eventInfo)
{
    Status s;
    BEGIN(c, M_INSTANTIATED);
    (void)toleranceControlled;
    (void)relativeTolerance;
    core_enter_initialization(in, in->time, false, 0.0);
    s = core_exit_initialization(in);
    if (s > ST_WARNING) return (fmi1Status)s;
    event_update(in, eventInfo);  /* fmiInitialize includes the first event update */
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetDerivatives)(fmi1Component c, fmi1Real derivatives[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS | M_TERMINATED);
    core_update(in);
    return (fmi1Status)core_derivatives(in, __func__, derivatives, nx);
}

EXPORT fmi1Status FMI1(GetEventIndicators)(fmi1Component c, fmi1Real eventIndicators[], size_t ni)
{
    BEGIN(c, M_CONTINUOUS | M_TERMINATED);
    core_update(in);
    return (fmi1Status)core_indicators(in, __func__, eventIndicators, ni);
}

EXPORT fmi1Status FMI1(EventUpdate)(fmi1Component c, fmi1Boolean intermediateResults, fmi1EventInfo *eventInfo)
{
    BEGIN(c, M_CONTINUOUS);
    (void)intermediateResults;
    event_update(in, eventInfo);
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetContinuousStates)(fmi1Component c, fmi1Real states[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS | M_TERMINATED);
    return (fmi1Status)core_states(in, __func__, states, nx, false);
}

EXPORT fmi1Status FMI1(GetNominalContinuousStates)(fmi1Component c, fmi1Real x_nominal[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS | M_TERMINATED);
    return (fmi1Status)core_nominals(in, __func__, x_nominal, nx);
}

EXPORT fmi1Status FMI1(GetStateValueReferences)(fmi1Component c, fmi1ValueReference vrx[], size_t nx)
{
    BEGIN(c, M_CONTINUOUS | M_TERMINATED);
    for (size_t i = 0; i < nx; i++) vrx[i] = fmi1UndefinedValueReference;
    return fmi1OK;
}

EXPORT fmi1Status FMI1(Terminate)(fmi1Component c)
{
    BEGIN(c, M_CONTINUOUS);
    in->mode = M_TERMINATED;
    return fmi1OK;
}

/* ---------------------------------------------------------------- co-simulation */

EXPORT const char *FMI1(GetTypesPlatform)(void) { return "standard32"; }

EXPORT fmi1Component FMI1(InstantiateSlave)(fmi1String instanceName, fmi1String fmuGUID, fmi1String fmuLocation,
                                            fmi1String mimeType, fmi1Real timeout, fmi1Boolean visible,
                                            fmi1Boolean interactive, fmi1CallbackFunctions functions,
                                            fmi1Boolean loggingOn)
{
    (void)fmuLocation;
    (void)mimeType;
    (void)timeout;
    (void)visible;
    (void)interactive;
    return instantiate(__func__, instanceName, fmuGUID, functions, loggingOn, IF_CO_SIMULATION);
}

EXPORT fmi1Status FMI1(InitializeSlave)(fmi1Component c, fmi1Real tStart, fmi1Boolean StopTimeDefined, fmi1Real tStop)
{
    Status s;
    BEGIN(c, M_INSTANTIATED);
    core_enter_initialization(in, tStart, StopTimeDefined != fmi1False, tStop);
    s = core_exit_initialization(in);
    return (fmi1Status)s;
}

EXPORT fmi1Status FMI1(TerminateSlave)(fmi1Component c)
{
    BEGIN(c, M_STEP | M_STEP_FAILED);
    in->mode = M_TERMINATED;
    return fmi1OK;
}

EXPORT fmi1Status FMI1(ResetSlave)(fmi1Component c)
{
    BEGIN(c, ~0u);
    return (fmi1Status)core_reset(in);
}

EXPORT void FMI1(FreeSlaveInstance)(fmi1Component c) { free_instance(c); }

static fmi1Status unsupported(fmi1Component c, const char *fn, const char *what)
{
    if (c) core_fail(CORE(c), fn, "%s is not supported by this FMU", what);
    return fmi1Error;
}

EXPORT fmi1Status FMI1(SetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                                const fmi1Integer order[], const fmi1Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, __func__, "interpolating inputs");
}

EXPORT fmi1Status FMI1(GetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                                 const fmi1Integer order[], fmi1Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, __func__, "providing output derivatives");
}

EXPORT fmi1Status FMI1(CancelStep)(fmi1Component c) { return unsupported(c, __func__, "cancelling a step"); }

EXPORT fmi1Status FMI1(DoStep)(fmi1Component c, fmi1Real currentCommunicationPoint, fmi1Real communicationStepSize,
                               fmi1Boolean newStep)
{
    double t_end;
    bool event;
    BEGIN(c, M_STEP);
    (void)newStep;
    switch (core_do_step(in, currentCommunicationPoint, communicationStepSize, &t_end, &event)) {
    case STEP_DONE:
        return fmi1OK;
    case STEP_TERMINATED:
        /* FMI 1.0 cannot say "terminated": a partial step, fmiLastSuccessfulTime = t_end */
        core_log(in, ST_DISCARD, "logStatusDiscard",
                 "the model terminates the simulation at t = %.17g", t_end);
        in->mode = M_STEP_FAILED;
        return fmi1Discard;
    case STEP_REJECTED:
        in->mode = M_STEP_FAILED;
        return fmi1Discard;
    default:
        in->mode = M_ERROR;
        return fmi1Error;
    }
}

#define STATUS_MODES (M_STEP | M_STEP_FAILED | M_TERMINATED)

EXPORT fmi1Status FMI1(GetStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Status *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi1Status)core_fail(in, __func__, "status kind %d is not available (no asynchronous steps)", (int)s);
}

EXPORT fmi1Status FMI1(GetRealStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Real *value)
{
    BEGIN(c, STATUS_MODES);
    if (s != fmi1LastSuccessfulTime)
        return (fmi1Status)core_fail(in, __func__, "status kind %d is not a Real status", (int)s);
    *value = in->last_successful_time;
    return fmi1OK;
}

EXPORT fmi1Status FMI1(GetIntegerStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Integer *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi1Status)core_fail(in, __func__, "status kind %d is not an Integer status", (int)s);
}

EXPORT fmi1Status FMI1(GetBooleanStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi1Status)core_fail(in, __func__, "status kind %d is not a Boolean status", (int)s);
}

EXPORT fmi1Status FMI1(GetStringStatus)(fmi1Component c, const fmi1StatusKind s, fmi1String *value)
{
    BEGIN(c, STATUS_MODES);
    (void)value;
    return (fmi1Status)core_fail(in, __func__, "status kind %d is not available (no asynchronous steps)", (int)s);
}
