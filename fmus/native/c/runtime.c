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
    for (i = 0; i < MODEL_N_STATES; i++) inst->state[i] = 0.0;
    set_time(inst, 0.0);
    inst->t_last = 0.0;
    inst->mode = MODE_INSTANTIATED;
    inst->dirty = 1;
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
    } else {
        k = model_refresh(inst->time, inst->values, inst->state, inst->detail);
        if (check(inst, CALL_REFRESH, k, inst->time) != RT_OK) return RT_ERROR;
    }
    inst->dirty = 0;
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
    if (MODEL_ME_ACCEPTS && inst->started &&
        check(inst, CALL_ACCEPT, model_accept(inst->time, inst->values, inst->state, inst->detail), inst->time) != RT_OK)
        return RT_ERROR;
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
    if ((c == CAUSALITY_OUTPUT || c == CAUSALITY_LOCAL) && (inst->dirty || !inst->started) && !inst->failed &&
        rt_update(inst) != RT_OK)
        return RT_ERROR;
    *value = inst->values[vr];
    return RT_OK;
}

void rt_set(Instance *inst, size_t vr, double value)
{
    inst->values[vr] = value;
    inst->dirty = 1;
    if (MODEL_VARIABLES[vr].causality == CAUSALITY_PARAMETER &&
        (inst->mode & (MODE_INSTANTIATED | MODE_INITIALIZATION)))
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

/* ------------------------------------------------------------------ FMU state */

/* What determines the future outputs: the values (every variable: parameters, inputs, the outputs of the last
 * update, the continuous states of model exchange), the internal state, time, t_last and the flags. Not saved: the
 * scratch after values[MODEL_N_VARIABLES] (the parameter-only constants, which model.c computes again whenever the
 * parameters differ, bit for bit from the bits of the parameters the snapshot restores: a cache, not a state), the
 * detail of the last failed check (written before it is printed), and the instance's settings (name, logger,
 * logging, eventModeUsed). */
struct Snapshot {
    uint64_t magic;             /* SNAPSHOT_MAGIC while the snapshot lives, 0 once freed */
    char token[RT_TOKEN_SIZE];  /* of the model it was taken from (MODEL_TOKEN, NUL-padded) */
    int fmi_version, is_me;     /* of the instance it was taken from */
    double time, t_last;
    int dirty, started, failed;
    int last_check[N_CALLS];
    double data[];              /* values[MODEL_N_VARIABLES], then state[MODEL_N_STATES] */
};

#define N_DATA (MODEL_N_VARIABLES + MODEL_N_STATES)
#define SNAPSHOT_MAGIC 0x50414E53544C4544ull   /* "DELTSNAP" in little-endian byte order */

static const char *kind_name(int is_me) { return is_me ? "model exchange" : "co-simulation"; }

/* 1 when `s` is a live snapshot of this model and build (the token) and, with `same_kind`, was taken from an
 * instance of this FMI version and interface; otherwise 0, logged naming what differs. */
static int snapshot_ok(Instance *inst, const Snapshot *s, int same_kind, const char *function)
{
    if (!s) {
        rt_log(inst, RT_ERROR, "%s: the FMU state is NULL", function);
        return 0;
    }
    if (s->magic != SNAPSHOT_MAGIC) {
        rt_log(inst, RT_ERROR, "%s: %p is not an FMU state of a native delta FMU (or it was freed)", function,
               (const void *)s);
        return 0;
    }
    if (memcmp(s->token, inst->token, RT_TOKEN_SIZE) != 0) {
        rt_log(inst, RT_ERROR, "%s: the FMU state is of another model or build: token %.*s, model %s expects %s",
               function, RT_TOKEN_SIZE - 1, s->token, MODEL_IDENTIFIER, inst->token);
        return 0;
    }
    if (same_kind && s->fmi_version != inst->fmi_version) {
        rt_log(inst, RT_ERROR, "%s: the FMU state was taken by the FMI %d build of %s, this is the FMI %d build",
               function, s->fmi_version, MODEL_IDENTIFIER, inst->fmi_version);
        return 0;
    }
    if (same_kind && s->is_me != inst->is_me) {
        rt_log(inst, RT_ERROR, "%s: the FMU state was taken from a %s instance, this is a %s instance", function,
               kind_name(s->is_me), kind_name(inst->is_me));
        return 0;
    }
    return 1;
}

RtStatus rt_get_snapshot(Instance *inst, Snapshot **snapshot, const char *function)
{
    Snapshot *s;
    size_t i;
    if (!snapshot) {
        rt_log(inst, RT_ERROR, "%s: FMUstate is NULL, no place to return the state in", function);
        return RT_ERROR;
    }
    s = *snapshot;
    if (s && !snapshot_ok(inst, s, 0, function)) return RT_ERROR;   /* reused: one of this model's */
    if (!s) {
        s = (Snapshot *)inst->alloc(1, sizeof(Snapshot) + N_DATA * sizeof(double));
        if (!s) {
            rt_log(inst, RT_ERROR, "%s: out of memory for an FMU state", function);
            return RT_ERROR;
        }
        s->magic = SNAPSHOT_MAGIC;
        memcpy(s->token, inst->token, RT_TOKEN_SIZE);
    }
    s->fmi_version = inst->fmi_version;
    s->is_me = inst->is_me;
    s->time = inst->time;
    s->t_last = inst->t_last;
    s->dirty = inst->dirty;
    s->started = inst->started;
    s->failed = inst->failed;
    for (i = 0; i < N_CALLS; i++) s->last_check[i] = inst->last_check[i];
    memcpy(s->data, inst->values, MODEL_N_VARIABLES * sizeof(double));
    if (MODEL_N_STATES) memcpy(s->data + MODEL_N_VARIABLES, inst->state, MODEL_N_STATES * sizeof(double));
    *snapshot = s;
    return RT_OK;
}

/* The mode stays the instance's (FMI 2.0 section 2.1.8 allows get and set in every state after instantiation; the
 * importer's calling sequence keeps its mode, e.g. a master rolling back in step mode). A state taken before the
 * model started (before initialization ended) set into an instance past initialization starts from its values
 * now, as exitInitializationMode would have; a state taken after set into an instance in initialization keeps its
 * motion through exitInitializationMode (a parameter set there afterwards starts the model again from its start
 * values, as any change of a parameter in initialization does). Model exchange: time and continuous states are the
 * state's until the importer sets its own (setTime, setContinuousStates). */
RtStatus rt_set_snapshot(Instance *inst, const Snapshot *s, const char *function)
{
    size_t i;
    if (!snapshot_ok(inst, s, 1, function)) return RT_ERROR;
    inst->time = s->time;
    inst->t_last = s->t_last;
    inst->dirty = s->dirty;
    inst->started = s->started;
    inst->failed = s->failed;
    for (i = 0; i < N_CALLS; i++) inst->last_check[i] = s->last_check[i];
    memcpy(inst->values, s->data, MODEL_N_VARIABLES * sizeof(double));
    if (MODEL_N_STATES) memcpy(inst->state, s->data + MODEL_N_VARIABLES, MODEL_N_STATES * sizeof(double));
    if (!inst->started && !(inst->mode & (MODE_INSTANTIATED | MODE_INITIALIZATION))) {
        if (rt_update(inst) != RT_OK) {
            inst->failed = 1;
            return RT_ERROR;
        }
        inst->t_last = inst->time;
    }
    return RT_OK;
}

RtStatus rt_free_snapshot(Instance *inst, Snapshot **snapshot, const char *function)
{
    if (!snapshot || !*snapshot) return RT_OK;   /* FMI: a NULL state is ignored */
    if (!snapshot_ok(inst, *snapshot, 0, function)) return RT_ERROR;   /* not ours to free */
    (*snapshot)->magic = 0;
    inst->free(*snapshot);
    *snapshot = NULL;
    return RT_OK;
}

/* Serialized layout (format 2; integers and doubles in the machine's byte order, which the byte-order mark tells):
 *
 *   offset  bytes              field
 *        0  8                  magic "DLTSTATE"
 *        8  4   uint32         format version (FORMAT_VERSION)
 *       12  4   uint32         byte-order mark 0x01020304
 *       16  8   uint64         size of the whole record in bytes (this layout, checksum included)
 *       24  64  char[64]       the model's token (MODEL_TOKEN: FMI 2 guid / FMI 3 instantiationToken), NUL-padded
 *       88  4   uint32         FMI version of the instance it was taken from (2 or 3)
 *       92  4   uint32         its interface: 0 co-simulation, 1 model exchange
 *       96  4   uint32         MODEL_N_VARIABLES
 *      100  4   uint32         MODEL_N_STATES
 *      104  12  int32[3]       dirty, started, failed
 *      116  20  int32[N_CALLS] last result of each model function
 *      136  8   double         time
 *      144  8   double         t_last
 *      152  8 n double         values[MODEL_N_VARIABLES], then state[MODEL_N_STATES]  (n = their sum)
 * 152 + 8n  8   uint64         FNV-1a 64 of every byte before it
 */
#define FORMAT_VERSION 2u
#define BYTE_ORDER_MARK 0x01020304u
#define AT_VERSION 8
#define AT_ORDER 12
#define AT_SIZE 16
#define AT_TOKEN 24
#define AT_FMI (AT_TOKEN + RT_TOKEN_SIZE)
#define AT_KIND (AT_FMI + 4)
#define AT_N_VARIABLES (AT_KIND + 4)
#define AT_N_STATES (AT_N_VARIABLES + 4)
#define AT_FLAGS (AT_N_STATES + 4)
#define AT_CHECKS (AT_FLAGS + 3 * 4)
#define AT_TIME (AT_CHECKS + N_CALLS * 4)
#define AT_T_LAST (AT_TIME + 8)
#define AT_DATA (AT_T_LAST + 8)
static const char FORMAT_MAGIC[8] = { 'D', 'L', 'T', 'S', 'T', 'A', 'T', 'E' };

size_t rt_serialized_size(void)
{
    return AT_DATA + N_DATA * sizeof(double) + sizeof(uint64_t);
}

static uint64_t fnv1a(const unsigned char *bytes, size_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= bytes[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

static void put_u32(unsigned char *bytes, size_t at, uint32_t v) { memcpy(bytes + at, &v, sizeof v); }
static void put_i32(unsigned char *bytes, size_t at, int v) { int32_t w = (int32_t)v; memcpy(bytes + at, &w, sizeof w); }
static uint32_t get_u32(const unsigned char *bytes, size_t at) { uint32_t v; memcpy(&v, bytes + at, sizeof v); return v; }
static int get_i32(const unsigned char *bytes, size_t at) { int32_t v; memcpy(&v, bytes + at, sizeof v); return (int)v; }

RtStatus rt_serialize(Instance *inst, const Snapshot *s, unsigned char *bytes, size_t size, const char *function)
{
    const size_t n = rt_serialized_size();
    uint64_t total = n, sum;
    size_t i;
    if (!snapshot_ok(inst, s, 0, function)) return RT_ERROR;
    if (!bytes || size != n) {
        rt_log(inst, RT_ERROR, "%s: a serialized FMU state of %s takes %lu bytes, got %s%lu", function,
               MODEL_IDENTIFIER, (unsigned long)n, bytes ? "" : "no buffer, size ", (unsigned long)size);
        return RT_ERROR;
    }
    memset(bytes, 0, n);
    memcpy(bytes, FORMAT_MAGIC, sizeof FORMAT_MAGIC);
    put_u32(bytes, AT_VERSION, FORMAT_VERSION);
    put_u32(bytes, AT_ORDER, BYTE_ORDER_MARK);
    memcpy(bytes + AT_SIZE, &total, sizeof total);
    memcpy(bytes + AT_TOKEN, s->token, RT_TOKEN_SIZE);
    put_u32(bytes, AT_FMI, (uint32_t)s->fmi_version);
    put_u32(bytes, AT_KIND, (uint32_t)s->is_me);
    put_u32(bytes, AT_N_VARIABLES, (uint32_t)MODEL_N_VARIABLES);
    put_u32(bytes, AT_N_STATES, (uint32_t)MODEL_N_STATES);
    put_i32(bytes, AT_FLAGS, s->dirty);
    put_i32(bytes, AT_FLAGS + 4, s->started);
    put_i32(bytes, AT_FLAGS + 8, s->failed);
    for (i = 0; i < N_CALLS; i++) put_i32(bytes, AT_CHECKS + 4 * i, s->last_check[i]);
    memcpy(bytes + AT_TIME, &s->time, sizeof(double));
    memcpy(bytes + AT_T_LAST, &s->t_last, sizeof(double));
    memcpy(bytes + AT_DATA, s->data, N_DATA * sizeof(double));
    sum = fnv1a(bytes, n - sizeof sum);
    memcpy(bytes + n - sizeof sum, &sum, sizeof sum);
    return RT_OK;
}

RtStatus rt_deserialize(Instance *inst, const unsigned char *bytes, size_t size, Snapshot **snapshot,
                        const char *function)
{
    const size_t n = rt_serialized_size();
    uint64_t total, stored, computed;
    char token[RT_TOKEN_SIZE];
    Snapshot *s;
    size_t i;
    if (!snapshot) {
        rt_log(inst, RT_ERROR, "%s: FMUstate is NULL, no place to return the state in", function);
        return RT_ERROR;
    }
    if (!bytes || size < AT_DATA + sizeof(uint64_t)) {
        rt_log(inst, RT_ERROR, "%s: %lu bytes%s are too few for a serialized FMU state (one of %s takes %lu bytes)",
               function, (unsigned long)size, bytes ? "" : " (NULL)", MODEL_IDENTIFIER, (unsigned long)n);
        return RT_ERROR;
    }
    if (memcmp(bytes, FORMAT_MAGIC, sizeof FORMAT_MAGIC) != 0) {
        rt_log(inst, RT_ERROR, "%s: the bytes are not a serialized FMU state of a native delta FMU (no \"DLTSTATE\" "
               "magic)", function);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_VERSION) != FORMAT_VERSION) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state has format version %lu, this FMU reads version %u",
               function, (unsigned long)get_u32(bytes, AT_VERSION), FORMAT_VERSION);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_ORDER) != BYTE_ORDER_MARK) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state was written on a machine of another byte order",
               function);
        return RT_ERROR;
    }
    memcpy(token, bytes + AT_TOKEN, RT_TOKEN_SIZE);
    token[RT_TOKEN_SIZE - 1] = '\0';
    if (memcmp(bytes + AT_TOKEN, inst->token, RT_TOKEN_SIZE) != 0) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is of another model or build: token %s (%lu bytes), "
               "model %s expects %s (%lu bytes)", function, token, (unsigned long)size, MODEL_IDENTIFIER,
               inst->token, (unsigned long)n);
        return RT_ERROR;
    }
    memcpy(&total, bytes + AT_SIZE, sizeof total);
    if (size != n || total != n) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is %lu bytes and its header says %llu, a state of %s "
               "takes %lu bytes (truncated or corrupted)", function, (unsigned long)size, (unsigned long long)total,
               MODEL_IDENTIFIER, (unsigned long)n);
        return RT_ERROR;
    }
    memcpy(&stored, bytes + n - sizeof stored, sizeof stored);
    computed = fnv1a(bytes, n - sizeof stored);
    if (stored != computed) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is corrupted: checksum %016llx, its bytes give %016llx",
               function, (unsigned long long)stored, (unsigned long long)computed);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_N_VARIABLES) != MODEL_N_VARIABLES || get_u32(bytes, AT_N_STATES) != MODEL_N_STATES) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state has %lu variables and %lu states, %s has %lu and %lu",
               function, (unsigned long)get_u32(bytes, AT_N_VARIABLES), (unsigned long)get_u32(bytes, AT_N_STATES),
               MODEL_IDENTIFIER, (unsigned long)MODEL_N_VARIABLES, (unsigned long)MODEL_N_STATES);
        return RT_ERROR;
    }
    s = (Snapshot *)inst->alloc(1, sizeof(Snapshot) + N_DATA * sizeof(double));   /* always a new one */
    if (!s) {
        rt_log(inst, RT_ERROR, "%s: out of memory for an FMU state", function);
        return RT_ERROR;
    }
    s->magic = SNAPSHOT_MAGIC;
    memcpy(s->token, bytes + AT_TOKEN, RT_TOKEN_SIZE);
    s->fmi_version = (int)get_u32(bytes, AT_FMI);
    s->is_me = (int)get_u32(bytes, AT_KIND);
    s->dirty = get_i32(bytes, AT_FLAGS);
    s->started = get_i32(bytes, AT_FLAGS + 4);
    s->failed = get_i32(bytes, AT_FLAGS + 8);
    for (i = 0; i < N_CALLS; i++) s->last_check[i] = get_i32(bytes, AT_CHECKS + 4 * i);
    memcpy(&s->time, bytes + AT_TIME, sizeof(double));
    memcpy(&s->t_last, bytes + AT_T_LAST, sizeof(double));
    memcpy(s->data, bytes + AT_DATA, N_DATA * sizeof(double));
    if (!snapshot_ok(inst, s, 1, function)) {   /* another FMI version or interface */
        s->magic = 0;
        inst->free(s);
        return RT_ERROR;
    }
    *snapshot = s;
    return RT_OK;
}
