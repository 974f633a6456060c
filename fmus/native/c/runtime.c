/* The FMU instance shared by the FMI 2.0 and FMI 3.0 entry points: see runtime.h. */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "runtime.h"

/* ------------------------------------------------------------------ logging */

static const char *category(RtStatus status)
{
    switch (status) {
    case RT_OK: return "logAll";
    case RT_WARNING: return "logStatusWarning";
    case RT_DISCARD: return "logStatusDiscard";
    default: return "logStatusError";
    }
}

static void vlog_at(Instance *inst, double t, RtStatus status, const char *fmt, va_list args)
{
    char message[1024];
    int n;
    if (!inst->log || (status == RT_OK && !inst->logging_on)) return;
    n = snprintf(message, sizeof message, "t = %.9g s: ", t);
    if (n > 0 && (size_t)n < sizeof message) vsnprintf(message + n, sizeof message - (size_t)n, fmt, args);
    inst->log(inst, status, category(status), message);
}

static void log_at(Instance *inst, double t, RtStatus status, const char *fmt, ...)
#ifdef __GNUC__
    __attribute__((format(printf, 4, 5)))
#endif
    ;
static void log_at(Instance *inst, double t, RtStatus status, const char *fmt, ...)
{
    va_list args;
    va_start(args, fmt);
    vlog_at(inst, t, status, fmt, args);
    va_end(args);
}

void rt_log(Instance *inst, RtStatus status, const char *fmt, ...)
{
    va_list args;
    va_start(args, fmt);
    vlog_at(inst, inst->time, status, fmt, args);
    va_end(args);
}

static const char *mode_name(Mode mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "instantiated";
    case MODE_INITIALIZATION: return "initialization";
    case MODE_STEP: return "step";
    case MODE_EVENT: return "event";
    case MODE_CONTINUOUS: return "continuous-time";
    default: return "terminated";
    }
}

int rt_allowed(Instance *inst, int modes, const char *function)
{
    if (!inst) return 0;
    if (inst->mode & modes) return 1;
    rt_log(inst, RT_ERROR, "%s must not be called in %s mode", function, mode_name(inst->mode));
    return 0;
}

int rt_kind(Instance *inst, int me, const char *function)
{
    if (inst->is_me == me) return 1;
    rt_log(inst, RT_ERROR, "%s is a %s function, this is a %s instance", function,
           me ? "model exchange" : "co-simulation", inst->is_me ? "model exchange" : "co-simulation");
    return 0;
}

RtStatus rt_not_supported(Instance *inst, const char *function)
{
    if (inst) rt_log(inst, RT_ERROR, "%s is not supported", function);
    return RT_ERROR;
}

/* ------------------------------------------------------------------ life cycle */

static void set_time(Instance *inst, double t)
{
    inst->time = t;
    inst->values[0] = t;
}

Instance *rt_new(size_t size, const char *name, int is_me, int fmi_version, const char *const *type_names,
                 AllocFn alloc, FreeFn free_fn, LogFn log)
{
    Instance *inst = (Instance *)alloc(1, size);
    if (!inst) return NULL;
    inst->values = inst->state = NULL;
    inst->name = NULL;
    inst->event_mode_used = inst->logging_on = 0;
    inst->alloc = alloc;
    inst->free = free_fn;
    inst->log = log;
    inst->is_me = is_me;
    inst->fmi_version = fmi_version;
    strncpy(inst->token, MODEL_TOKEN, RT_TOKEN_SIZE - 1);  /* NUL-padded */
    inst->token[RT_TOKEN_SIZE - 1] = '\0';
    inst->type_names = type_names;
    inst->values = (double *)alloc(MODEL_N_VARIABLES + 1 + MODEL_N_SCRATCH, sizeof(double));
    inst->state = (double *)alloc(MODEL_N_STATES + 1, sizeof(double));
    inst->name = (char *)alloc(strlen(name) + 1, 1);
    if (!inst->values || !inst->state || !inst->name) {
        rt_free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    memset(inst->values + MODEL_N_VARIABLES, 0, (1 + MODEL_N_SCRATCH) * sizeof(double));  /* no constants yet */
    rt_reset(inst);
    return inst;
}

void rt_free(Instance *inst)
{
    if (!inst) return;
    if (inst->values) inst->free(inst->values);
    if (inst->state) inst->free(inst->state);
    if (inst->name) inst->free(inst->name);
    inst->free(inst);
}

void rt_reset(Instance *inst)
{
    size_t i;
    for (i = 0; i < MODEL_N_VARIABLES; i++) inst->values[i] = MODEL_VARIABLES[i].start;
    rt_constants_stale(inst);
    for (i = 0; i < MODEL_N_STATES; i++) inst->state[i] = 0.0;
    set_time(inst, 0.0);
    inst->t_last = 0.0;
    inst->mode = MODE_INSTANTIATED;
    inst->dirty = 1;
    inst->outputs_stale = 0;
    inst->started = 0;
    inst->failed = 0;
    for (i = 0; i < N_CALLS; i++) inst->last_check[i] = 0;
}

/* ------------------------------------------------------------------ model calls */

/* Result k of a model function called at time t: 0 ok; an error check is logged and fails the call;
 * a warning is logged when no model function reported it on its last call, and the call succeeds. */
static RtStatus check(Instance *inst, ModelCall call, int k, double t)
{
    char reason[768];
    int i, reported = 0;
    for (i = 0; i < N_CALLS; i++) reported |= inst->last_check[i] == k;
    inst->last_check[call] = k;
    if (k == 0) return RT_OK;
    if (k < 0 || (size_t)k > MODEL_N_CHECKS) {
        log_at(inst, t, RT_ERROR, "the model returned the unknown check %d", k);
        return RT_ERROR;
    }
    if (MODEL_CHECK_N_VALUES[k - 1] > 0) {  /* a format of our generator's, the values the model wrote */
        const double *d = inst->detail;
        snprintf(reason, sizeof reason, MODEL_CHECKS[k - 1], d[0], d[1], d[2], d[3]);
    } else {
        snprintf(reason, sizeof reason, "%s", MODEL_CHECKS[k - 1]);
    }
    if (MODEL_CHECK_IS_ERROR[k - 1]) {
        log_at(inst, t, RT_ERROR, "%s", reason);
        return RT_ERROR;
    }
    if (!reported) log_at(inst, t, RT_WARNING, "%s", reason);
    return RT_OK;
}

RtStatus rt_update(Instance *inst)
{
    int k;
    if (!inst->started) {
        if (check(inst, CALL_START, model_start(inst->time, inst->values, inst->state, inst->detail), inst->time) != RT_OK)
            return RT_ERROR;
        inst->started = 1;
    }
    if (inst->is_me && MODEL_N_CONTINUOUS > 0) {
        k = model_derivatives(inst->time, inst->values, inst->state, inst->detail);
        if (check(inst, CALL_DERIVATIVES, k, inst->time) != RT_OK) return RT_ERROR;
        inst->outputs_stale = MODEL_ME_OUTPUTS;
    } else {
        k = model_refresh(inst->time, inst->values, inst->state, inst->detail);
        if (check(inst, CALL_REFRESH, k, inst->time) != RT_OK) return RT_ERROR;
    }
    inst->dirty = 0;
    return RT_OK;
}

/* model exchange: the checks of the state where the instance stands, accepted by the importer, and with
 * MODEL_ME_OUTPUTS its outputs (model_accept) */
static RtStatus me_accept(Instance *inst)
{
    if (check(inst, CALL_ACCEPT, model_accept(inst->time, inst->values, inst->state, inst->detail), inst->time) !=
        RT_OK)
        return RT_ERROR;
    inst->outputs_stale = 0;
    return RT_OK;
}

RtStatus rt_exit_initialization(Instance *inst)
{
    if (rt_update(inst) != RT_OK) return RT_ERROR;   /* model_start if needed, then always refresh */
    inst->t_last = inst->time;
    inst->mode = (inst->is_me || inst->event_mode_used) ? MODE_EVENT : MODE_STEP;
    return RT_OK;
}

/* CPython's float_floor_div (Objects/floatobject.c, _float_div_mod), wx != 0 */
static double py_floor_div(double vx, double wx)
{
    double mod = fmod(vx, wx), div = (vx - mod) / wx, floordiv;
    if (mod && (wx < 0) != (mod < 0)) div -= 1.0;
    if (div) {
        floordiv = floor(div);
        if (div - floordiv > 0.5) floordiv += 1.0;
    } else {
        floordiv = copysign(0.0, vx / wx);
    }
    return floordiv;
}

unsigned long long rt_substeps(Instance *inst, double h)
{
    double max_step, n;
    if (MODEL_MAX_STEP_VR == 0) return 1;
    max_step = inst->values[MODEL_MAX_STEP_VR];
    if (!(max_step > 0.0 && isfinite(max_step))) {
        rt_log(inst, RT_ERROR, "%s must be a time > 0 s, got %.17g", MODEL_VARIABLES[MODEL_MAX_STEP_VR].name, max_step);
        return 0;
    }
    n = -py_floor_div(-h, max_step);   /* integral: -int(q) == -q */
    if (n < 1.0) return 1;
    if (!(n <= 9007199254740992.0)) {
        rt_log(inst, RT_ERROR, "a step of %.17g s in substeps of %s = %.17g s is too many substeps", h,
               MODEL_VARIABLES[MODEL_MAX_STEP_VR].name, max_step);
        return 0;
    }
    return (unsigned long long)n;
}

RtStatus rt_do_step(Instance *inst, double t, double h)
{
    unsigned long long n, k;
    double dt;
    if (inst->failed) {
        rt_log(inst, RT_ERROR, "doStep refused: an earlier step failed, this instance cannot continue");
        return RT_ERROR;
    }
    if (!(h > 0.0 && isfinite(h))) {
        rt_log(inst, RT_ERROR, "the communication step must be a finite h > 0, got %.17g", h);
        return RT_ERROR;
    }
    set_time(inst, t);
    n = rt_substeps(inst, h);
    if (n == 0) {
        inst->failed = 1;
        return RT_DISCARD;
    }
    dt = h / (double)n;
    for (k = 0; k < n; k++) {
        double tk = t + (double)k * dt;
        if (check(inst, CALL_ADVANCE, model_advance(tk, dt, inst->values, inst->state, inst->detail), tk) != RT_OK) {
            inst->failed = 1;
            return RT_DISCARD;
        }
    }
    set_time(inst, t + h);
    if (rt_update(inst) != RT_OK) {
        inst->failed = 1;
        return RT_DISCARD;
    }
    return RT_OK;
}

RtStatus rt_me_commit(Instance *inst)
{
    if (MODEL_ME_ADVANCES && inst->time > inst->t_last) {
        int k = model_advance(inst->t_last, inst->time - inst->t_last, inst->values, inst->state, inst->detail);
        if (check(inst, CALL_ADVANCE, k, inst->t_last) != RT_OK) return RT_ERROR;
        inst->dirty = 1;
    }
    inst->t_last = inst->time;
    if (MODEL_ME_ACCEPTS && inst->started && me_accept(inst) != RT_OK) return RT_ERROR;
    return RT_OK;
}

void rt_set_time(Instance *inst, double time)
{
    set_time(inst, time);
    inst->dirty = 1;
}

/* ------------------------------------------------------------------ variables */

static const char *causality_name(Causality c)
{
    switch (c) {
    case CAUSALITY_PARAMETER: return "parameter";
    case CAUSALITY_INPUT: return "input";
    case CAUSALITY_OUTPUT: return "output";
    case CAUSALITY_LOCAL: return "local variable";
    default: return "independent variable";
    }
}

int rt_check_var(Instance *inst, size_t vr, VarType type, int for_set, const char *function)
{
    const ModelVariable *v;
    if (vr >= MODEL_N_VARIABLES) {
        rt_log(inst, RT_ERROR, "%s: no variable has the value reference %lu", function, (unsigned long)vr);
        return 0;
    }
    v = &MODEL_VARIABLES[vr];
    if (v->type != type) {
        rt_log(inst, RT_ERROR, "%s: variable \"%s\" (vr %lu) is a %s, not a %s", function, v->name,
               (unsigned long)vr, inst->type_names[v->type], inst->type_names[type]);
        return 0;
    }
    if (!for_set || v->causality == CAUSALITY_INPUT) return 1;
    if (v->causality == CAUSALITY_PARAMETER) {
        if (v->variability == VARIABILITY_TUNABLE) return 1;
        if (v->variability == VARIABILITY_FIXED && (inst->mode & (MODE_INSTANTIATED | MODE_INITIALIZATION))) return 1;
        rt_log(inst, RT_ERROR, "%s: parameter \"%s\" (vr %lu) is fixed: it can only be set before "
               "exitInitializationMode", function, v->name, (unsigned long)vr);
        return 0;
    }
    rt_log(inst, RT_ERROR, "%s: variable \"%s\" (vr %lu) is an %s and cannot be set", function, v->name,
           (unsigned long)vr, causality_name(v->causality));
    return 0;
}

RtStatus rt_get_string(Instance *inst, size_t vr, const char **text, const char *function)
{
    const ModelVariable *v;
    double value;
    if (!rt_check_var(inst, vr, TYPE_STRING, 0, function)) return RT_ERROR;
    if (rt_get(inst, vr, &value) != RT_OK) return RT_ERROR;
    v = &MODEL_VARIABLES[vr];
    *text = (value >= 0.0 && value < (double)v->n_choices) ? v->choices[(size_t)value] : "";
    return RT_OK;
}

RtStatus rt_set_string(Instance *inst, size_t vr, const char *text, const char *function)
{
    const ModelVariable *v;
    size_t k;
    char valid[256];
    size_t used = 0;
    if (!rt_check_var(inst, vr, TYPE_STRING, 1, function)) return RT_ERROR;
    v = &MODEL_VARIABLES[vr];
    for (k = 0; text && k < v->n_choices; k++) {
        if (strcmp(text, v->choices[k]) == 0) {
            rt_set(inst, vr, (double)k);
            return RT_OK;
        }
    }
    valid[0] = '\0';
    for (k = 0; k < v->n_choices && used + 1 < sizeof valid; k++) {
        int n = snprintf(valid + used, sizeof valid - used, "%s\"%s\"", k ? ", " : "", v->choices[k]);
        if (n < 0) break;
        used += (size_t)n;
    }
    rt_log(inst, RT_ERROR, "%s: \"%s\" is not a value of \"%s\" (vr %lu); valid values: %s", function,
           text ? text : "(null)", v->name, (unsigned long)vr, valid);
    return RT_ERROR;
}

RtStatus rt_get(Instance *inst, size_t vr, double *value)
{
    Causality c = MODEL_VARIABLES[vr].causality;
    if (c == CAUSALITY_INDEPENDENT) {
        *value = inst->time;
        return RT_OK;
    }
    /* after a failed step the outputs stay those of the last successful one */
    if ((c == CAUSALITY_OUTPUT || c == CAUSALITY_LOCAL) && !inst->failed) {
        if ((inst->dirty || !inst->started) && rt_update(inst) != RT_OK) return RT_ERROR;
        if (inst->outputs_stale && me_accept(inst) != RT_OK) return RT_ERROR;
    }
    *value = inst->values[vr];
    return RT_OK;
}

void rt_constants_stale(Instance *inst)
{
    inst->values[MODEL_N_VARIABLES + 1] = 0.0;  /* MODEL_N_SCRATCH >= 1: the flag always exists */
}

void rt_set(Instance *inst, size_t vr, double value)
{
    inst->values[vr] = value;
    inst->dirty = 1;
    if (MODEL_VARIABLES[vr].causality != CAUSALITY_PARAMETER) return;
    rt_constants_stale(inst);
    if (inst->mode & (MODE_INSTANTIATED | MODE_INITIALIZATION))
        inst->started = 0;
}

RtStatus rt_type_error(Instance *inst, size_t vr, const char *type, const char *function)
{
    if (vr < MODEL_N_VARIABLES)
        rt_log(inst, RT_ERROR, "%s: variable \"%s\" (vr %lu) is a %s, no variable of type %s exists", function,
               MODEL_VARIABLES[vr].name, (unsigned long)vr, inst->type_names[MODEL_VARIABLES[vr].type], type);
    else
        rt_log(inst, RT_ERROR, "%s: no variable has the value reference %lu (no variable of type %s exists)",
               function, (unsigned long)vr, type);
    return RT_ERROR;
}

/* ------------------------------------------------------------------ model exchange */

static int check_nx(Instance *inst, size_t nx, const char *function)
{
    if (nx == MODEL_N_CONTINUOUS) return 1;
    rt_log(inst, RT_ERROR, "%s: nx = %lu, the model has %lu continuous states", function, (unsigned long)nx,
           (unsigned long)MODEL_N_CONTINUOUS);
    return 0;
}

RtStatus rt_get_states(Instance *inst, double *x, size_t nx, const char *function)
{
    size_t i;
    if (!check_nx(inst, nx, function)) return RT_ERROR;
    if ((inst->dirty || !inst->started) && rt_update(inst) != RT_OK) return RT_ERROR;
    for (i = 0; i < nx; i++) x[i] = inst->values[MODEL_STATE_VRS[i]];
    return RT_OK;
}

RtStatus rt_set_states(Instance *inst, const double *x, size_t nx, const char *function)
{
    size_t i;
    if (!check_nx(inst, nx, function)) return RT_ERROR;
    for (i = 0; i < nx; i++) inst->values[MODEL_STATE_VRS[i]] = x[i];
    inst->dirty = 1;
    return RT_OK;
}

RtStatus rt_get_derivatives(Instance *inst, double *dx, size_t nx, const char *function)
{
    size_t i;
    if (!check_nx(inst, nx, function)) return RT_ERROR;
    if ((inst->dirty || !inst->started) && rt_update(inst) != RT_OK) return RT_ERROR;
    for (i = 0; i < nx; i++) dx[i] = inst->values[MODEL_DERIVATIVE_VRS[i]];
    return RT_OK;
}

RtStatus rt_get_nominals(Instance *inst, double *nominals, size_t nx, const char *function)
{
    size_t i;
    if (!check_nx(inst, nx, function)) return RT_ERROR;
    for (i = 0; i < nx; i++) nominals[i] = 1.0;
    return RT_OK;
}

RtStatus rt_check_event_indicators(Instance *inst, size_t ni, const char *function)
{
    if (ni == 0) return RT_OK;
    rt_log(inst, RT_ERROR, "%s: ni = %lu, the model has no event indicators", function, (unsigned long)ni);
    return RT_ERROR;
}
