/*
 * core.c - instance life cycle, variable access and the co-simulation
 * stepper shared by the FMI 2 and FMI 3 wrappers (see core.h).
 */
#include "core.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- strings */

bool fmu_copy_string(char **dst, const char *src)
{
    char *copy = NULL;
    if (src) {
        size_t n = strlen(src) + 1;
        copy = malloc(n);
        if (!copy) return false;
        memcpy(copy, src, n);
    }
    free(*dst);
    *dst = copy;
    return true;
}

bool fmu_copy_blob(Blob *dst, const uint8_t *data, size_t size)
{
    /* one spare byte so that an empty value still has a valid pointer */
    uint8_t *copy = malloc(size + 1);
    if (!copy) return false;
    if (size) memcpy(copy, data, size);
    free(dst->data);
    dst->data = copy;
    dst->size = size;
    return true;
}

void fmu_free_blob(Blob *b)
{
    free(b->data);
    b->data = NULL;
    b->size = 0;
}

/* ---------------------------------------------------------------- logging */

static void vlog(Instance *in, Status status, const char *category, const char *format, va_list args)
{
    char message[1024];
    if (!in->sink) return;
    vsnprintf(message, sizeof message, format, args);
    in->sink(in->sink_env, in->name, status, category, message);
}

void core_log(Instance *in, Status status, const char *category, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vlog(in, status, category, format, args);
    va_end(args);
}

void core_debug(Instance *in, const char *format, ...)
{
    va_list args;
    if (!in->logging_on) return;
    va_start(args, format);
    vlog(in, ST_OK, "logEvents", format, args);
    va_end(args);
}

Status core_fail(Instance *in, const char *fn, const char *format, ...)
{
    char message[900];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    core_log(in, ST_ERROR, "logStatusError", "%s: %s", fn, message);
    return ST_ERROR;
}

static const char *mode_name(Mode m)
{
    switch (m) {
    case M_INSTANTIATED: return "Instantiated";
    case M_CONFIGURATION: return "ConfigurationMode";
    case M_INITIALIZATION: return "InitializationMode";
    case M_EVENT: return "EventMode";
    case M_CONTINUOUS: return "ContinuousTimeMode";
    case M_STEP: return "StepMode";
    case M_STEP_FAILED: return "StepFailed";
    case M_TERMINATED: return "Terminated";
    default: return "Error";
    }
}

bool core_allowed(Instance *in, const char *fn, unsigned modes)
{
    if (in->mode & modes) return true;
    core_fail(in, fn, "must not be called in %s", mode_name(in->mode));
    return false;
}

/* ---------------------------------------------------------------- life cycle */

static void free_scratch(Instance *in)
{
    free(in->x);
    free(in->x_start);
    free(in->x_try);
    free(in->k);
    free(in->z_start);
    free(in->z_try);
    in->x = in->x_start = in->x_try = in->k = in->z_start = in->z_try = NULL;
}

/* Fix the numbers of states and event indicators and allocate the stepper's
   arrays (sizes can no longer change once initialisation is over). */
static bool alloc_scratch(Instance *in)
{
    size_t nx, nz;
    free_scratch(in);
    nx = core_n_states(in);
    nz = core_n_indicators(in);
    in->nx = nx;
    in->nz = nz;
    /* +1: valid pointers also for a model without states */
    in->x = calloc(nx + 1, sizeof(double));
    in->x_start = calloc(nx + 1, sizeof(double));
    in->x_try = calloc(nx + 1, sizeof(double));
    in->k = calloc(5 * nx + 1, sizeof(double));
    in->z_start = calloc(nz + 1, sizeof(double));
    in->z_try = calloc(nz + 1, sizeof(double));
    return in->x && in->x_start && in->x_try && in->k && in->z_start && in->z_try;
}

static void reset_data(Instance *in)
{
    if (MODEL.release) MODEL.release(in->data);
    memset(in->data, 0, MODEL.data_size);
    MODEL.defaults(in->data);
    in->time = 0.0;
    in->stop_defined = false;
    in->next_time_defined = false;
    in->terminate_requested = false;
    in->last_successful_time = 0.0;
    in->dirty = true;
    in->mode = M_INSTANTIATED;
}

Instance *core_new(int fmi_version, Interface iface, const char *name, LogSink sink, void *env, bool logging_on)
{
    Instance *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->fmi_version = fmi_version;
    in->iface = iface;
    in->sink = sink;
    in->sink_env = env;
    in->logging_on = logging_on;
    in->data = calloc(1, MODEL.data_size ? MODEL.data_size : 1);
    if (!in->data || !fmu_copy_string(&in->name, name ? name : "")) {
        free(in->data);
        free(in);
        return NULL;
    }
    reset_data(in);
    return in;
}

void core_free(Instance *in)
{
    if (!in) return;
    if (MODEL.release) MODEL.release(in->data);
    free_scratch(in);
    free(in->data);
    free(in->name);
    free(in);
}

Status core_reset(Instance *in)
{
    free_scratch(in);
    reset_data(in);
    return ST_OK;
}

Status core_enter_initialization(Instance *in, double start_time, bool stop_defined, double stop_time)
{
    in->time = start_time;
    in->last_successful_time = start_time;
    in->stop_defined = stop_defined;
    in->stop_time = stop_time;
    in->mode = M_INITIALIZATION;
    in->dirty = true;
    return ST_OK;
}

Status core_exit_initialization(Instance *in)
{
    const char *fn = "ExitInitializationMode";
    const char *why = MODEL.invalid ? MODEL.invalid(in->data) : NULL;
    if (why) return core_fail(in, fn, "%s", why);
    MODEL.initialize(in->data, in->time);
    in->dirty = true;
    if (!alloc_scratch(in)) return core_fail(in, fn, "out of memory");
    if (in->iface == IF_MODEL_EXCHANGE) {
        in->mode = M_EVENT;   /* the importer now calls the discrete update */
        return ST_OK;
    }
    /* co-simulation: the FMU settles the initial event itself */
    in->mode = M_STEP;
    {
        EventUpdate ev;
        int i = 0;
        do core_event_update(in, &ev); while (ev.more && ++i < 100);
        if (ev.more) return core_fail(in, fn, "the initial event iteration does not converge");
        if (ev.terminate)
            return core_fail(in, fn, "the model asks to terminate at the start time t = %.17g", in->time);
    }
    return ST_OK;
}

/* ---------------------------------------------------------------- variables */

static const char *type_name(VarType t)
{
    switch (t) {
    case T_FLOAT32: return "Float32";
    case T_FLOAT64: return "Float64";
    case T_INT8: return "Int8";
    case T_UINT8: return "UInt8";
    case T_INT16: return "Int16";
    case T_UINT16: return "UInt16";
    case T_INT32: return "Int32";
    case T_UINT32: return "UInt32";
    case T_INT64: return "Int64";
    case T_UINT64: return "UInt64";
    case T_BOOL: return "Boolean";
    case T_STRING: return "String";
    case T_BINARY: return "Binary";
    case T_ENUM: return "Enumeration";
    default: return "Clock";
    }
}

static const VarInfo *find(unsigned vr)
{
    for (size_t i = 0; i < MODEL_N_VARS; i++)
        if (MODEL_VARS[i].vr == vr) return &MODEL_VARS[i];
    return NULL;
}

const VarInfo *core_lookup(Instance *in, const char *fn, unsigned vr, unsigned accepted)
{
    const VarInfo *v = find(vr);
    if (!v) {
        core_fail(in, fn, "unknown value reference %u", vr);
        return NULL;
    }
    if (!(v->type & accepted)) {
        core_fail(in, fn, "variable \"%s\" (value reference %u) is of type %s", v->name, vr, type_name(v->type));
        return NULL;
    }
    return v;
}

size_t core_length(const Instance *in, const VarInfo *v)
{
    size_t n = 1;
    for (int i = 0; i < v->ndims; i++) {
        if (v->dims[i].size_vr >= 0) {
            const VarInfo *s = find((unsigned)v->dims[i].size_vr);
            n *= (size_t) * (const uint64_t *)((const char *)in->data + s->offset);
        } else {
            n *= v->dims[i].size;
        }
    }
    return n;
}

void *core_element(Instance *in, const VarInfo *v)
{
    char *field;
    if (v->causality == CAUS_INDEPENDENT) return &in->time;
    field = (char *)in->data + v->offset;
    return v->indirect ? *(void **)field : field;
}

void core_update(Instance *in)
{
    if (!in->dirty) return;
    if (in->mode == M_INITIALIZATION) MODEL.initialize(in->data, in->time);
    MODEL.outputs(in->data, in->time);
    in->dirty = false;
}

Status core_count_error(Instance *in, const char *fn, size_t given, size_t needed)
{
    return core_fail(in, fn, "nValues = %zu but the variables requested have %zu values", given, needed);
}

/* Whether v may be set in the current mode (FMI 2 section 3.2.3 / FMI 3
   section 2.3.x tables, for the combinations these models use). */
bool core_can_set(Instance *in, const char *fn, const VarInfo *v)
{
    unsigned modes = 0;
    bool me = in->iface == IF_MODEL_EXCHANGE;
    switch (v->causality) {
    case CAUS_STRUCTURAL:
        modes = M_INSTANTIATED | M_CONFIGURATION;
        break;
    case CAUS_PARAMETER:
        modes = M_INSTANTIATED | M_INITIALIZATION;
        if (v->variability == VAR_TUNABLE) modes |= me ? M_EVENT : M_STEP;
        break;
    case CAUS_INPUT:
        modes = M_INSTANTIATED | M_INITIALIZATION;
        if (!me) modes |= M_STEP;
        else if (v->variability == VAR_CONTINUOUS) modes |= M_EVENT | M_CONTINUOUS;
        else modes |= M_EVENT;   /* discrete inputs change only at events */
        if (v->type == T_CLOCK) modes = M_EVENT;
        break;
    default:
        if (v->initial == INIT_EXACT || v->initial == INIT_APPROX) modes = M_INSTANTIATED | M_INITIALIZATION;
        break;
    }
    if (in->mode & modes) return true;
    if (!modes) core_fail(in, fn, "variable \"%s\" cannot be set", v->name);
    else core_fail(in, fn, "variable \"%s\" cannot be set in %s", v->name, mode_name(in->mode));
    return false;
}

Status core_after_set(Instance *in, const char *fn, const VarInfo *v, const void *old_value)
{
    in->dirty = true;
    if (v->causality != CAUS_STRUCTURAL || !MODEL.resize) return ST_OK;
    if (MODEL.resize(in->data)) return ST_OK;
    memcpy(core_element(in, v), old_value, sizeof(uint64_t));
    MODEL.resize(in->data);
    return core_fail(in, fn, "invalid value for structural parameter \"%s\"", v->name);
}

/* ---------------------------------------------------------------- model exchange */

/* The current numbers (they follow structural parameters until initialisation ends). */
size_t core_n_states(const Instance *in)
{
    return MODEL.n_states ? MODEL.n_states(in->data) : MODEL.n_fixed_states;
}

/* The model's continuous states out of (get) or into (set) its data: its functions, else its fixed states. */
static void model_get_states(const Instance *in, double *x)
{
    if (MODEL.get_states) {
        MODEL.get_states(in->data, x);
        return;
    }
    for (size_t i = 0; i < MODEL.n_fixed_states; i++)
        memcpy(&x[i], (const char *)in->data + MODEL.state_offsets[i], sizeof(double));
}

static void model_set_states(Instance *in, const double *x)
{
    if (MODEL.set_states) {
        MODEL.set_states(in->data, x);
        return;
    }
    for (size_t i = 0; i < MODEL.n_fixed_states; i++)
        memcpy((char *)in->data + MODEL.state_offsets[i], &x[i], sizeof(double));
}

size_t core_n_indicators(const Instance *in)
{
    return MODEL.n_indicators ? MODEL.n_indicators(in->data) : 0;
}

Status core_set_time(Instance *in, double t)
{
    if (MODEL.strict_stop_time && in->stop_defined && t > in->stop_time)
        return core_fail(in, "SetTime", "Exceeded model finish time: time = %.17g > stopTime = %.17g", t,
                         in->stop_time);
    in->time = t;
    in->dirty = true;
    return ST_OK;
}

Status core_states(Instance *in, const char *fn, double *x, size_t n, bool set)
{
    size_t nx = core_n_states(in);
    if (n != nx) return core_fail(in, fn, "nx = %zu but the model has %zu continuous states", n, nx);
    if (n == 0) return ST_OK;
    if (set) {
        model_set_states(in, x);
        in->dirty = true;
    } else {
        core_update(in);
        model_get_states(in, x);
    }
    return ST_OK;
}

Status core_derivatives(Instance *in, const char *fn, double *dx, size_t n)
{
    size_t nx = core_n_states(in);
    if (n != nx) return core_fail(in, fn, "nx = %zu but the model has %zu continuous states", n, nx);
    if (n) MODEL.derivatives(in->data, in->time, dx);
    return ST_OK;
}

Status core_indicators(Instance *in, const char *fn, double *z, size_t n)
{
    size_t nz = core_n_indicators(in);
    if (n != nz) return core_fail(in, fn, "ni = %zu but the model has %zu event indicators", n, nz);
    if (n) MODEL.indicators(in->data, in->time, z);
    return ST_OK;
}

Status core_nominals(Instance *in, const char *fn, double *nominal, size_t n)
{
    size_t nx = core_n_states(in);
    if (n != nx) return core_fail(in, fn, "nx = %zu but the model has %zu continuous states", n, nx);
    if (n && MODEL.nominals)
        MODEL.nominals(in->data, nominal);
    else
        for (size_t i = 0; i < n; i++) nominal[i] = 1.0;
    return ST_OK;
}

void core_event_update(Instance *in, EventUpdate *ev)
{
    memset(ev, 0, sizeof *ev);
    if (MODEL.event) MODEL.event(in->data, in->time, ev);
    in->next_time_defined = ev->next_time_defined;
    in->next_time = ev->next_time;
    if (ev->terminate) in->terminate_requested = true;
    in->dirty = true;
}

/* ---------------------------------------------------------------- FMU state */

size_t core_state_size(void)
{
    return sizeof(Instance) + MODEL.data_size;
}

Status core_get_state(Instance *in, const char *fn, void **state)
{
    if (MODEL.release)  /* pointers into allocated arrays or strings: a byte copy would share them */
        return core_fail(in, fn, "the model's data holds allocated memory: its state cannot be copied");
    if (!*state) {  /* a state given back is overwritten, as FMI allows */
        *state = malloc(core_state_size());
        if (!*state) return core_fail(in, fn, "out of memory");
    }
    memcpy(*state, in, sizeof(Instance));
    memcpy((char *)*state + sizeof(Instance), in->data, MODEL.data_size);
    return ST_OK;
}

Status core_set_state(Instance *in, const char *fn, const void *state)
{
    Instance s;
    if (!state) return core_fail(in, fn, "the FMU state is NULL");
    memcpy(&s, state, sizeof s);
    in->mode = s.mode;
    in->dirty = s.dirty;
    in->time = s.time;
    in->stop_defined = s.stop_defined;
    in->stop_time = s.stop_time;
    in->next_time_defined = s.next_time_defined;
    in->next_time = s.next_time;
    in->terminate_requested = s.terminate_requested;
    in->last_successful_time = s.last_successful_time;
    in->early_return_allowed = s.early_return_allowed;
    memcpy(in->data, (const char *)state + sizeof(Instance), MODEL.data_size);
    return ST_OK;
}

void core_free_state(void **state)
{
    free(*state);
    *state = NULL;
}

Status core_serialize_state(Instance *in, const char *fn, const void *state, unsigned char *bytes, size_t size)
{
    if (!state) return core_fail(in, fn, "the FMU state is NULL");
    if (size != core_state_size())
        return core_fail(in, fn, "size = %zu but a serialized state of this FMU has %zu bytes", size,
                         core_state_size());
    memcpy(bytes, state, size);
    return ST_OK;
}

Status core_deserialize_state(Instance *in, const char *fn, const unsigned char *bytes, size_t size, void **state)
{
    if (size != core_state_size())
        return core_fail(in, fn, "size = %zu but a serialized state of this FMU has %zu bytes: not a state of this "
                         "FMU", size, core_state_size());
    if (!*state) {
        *state = malloc(size);
        if (!*state) return core_fail(in, fn, "out of memory");
    }
    memcpy(*state, bytes, size);
    return ST_OK;
}

/* ---------------------------------------------------------------- co-simulation */

/* One classical Runge-Kutta step of size dt from (t, x_start) into x_out. */
static void rk4(Instance *in, double t, double dt, double *x_out)
{
    size_t n = in->nx;
    double *k1 = in->k, *k2 = k1 + n, *k3 = k2 + n, *k4 = k3 + n, *tmp = k4 + n;
    const double *x0 = in->x_start;
    size_t i;

    model_set_states(in, x0);
    MODEL.derivatives(in->data, t, k1);
    for (i = 0; i < n; i++) tmp[i] = x0[i] + 0.5 * dt * k1[i];
    model_set_states(in, tmp);
    MODEL.derivatives(in->data, t + 0.5 * dt, k2);
    for (i = 0; i < n; i++) tmp[i] = x0[i] + 0.5 * dt * k2[i];
    model_set_states(in, tmp);
    MODEL.derivatives(in->data, t + 0.5 * dt, k3);
    for (i = 0; i < n; i++) tmp[i] = x0[i] + dt * k3[i];
    model_set_states(in, tmp);
    MODEL.derivatives(in->data, t + dt, k4);
    for (i = 0; i < n; i++) x_out[i] = x0[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    model_set_states(in, x_out);
}

/* Whether some event indicator changed sign (or reached zero) between
   z_start and the current indicators written to z_try. */
static bool crossed(Instance *in, double t)
{
    if (!in->nz) return false;
    MODEL.indicators(in->data, t, in->z_try);
    for (size_t i = 0; i < in->nz; i++) {
        double a = in->z_start[i], b = in->z_try[i];
        if ((a > 0.0 && b <= 0.0) || (a < 0.0 && b >= 0.0)) return true;
    }
    return false;
}

/* Advance the states by dt (one RK4 step). If an event indicator changes
   sign, bisect for the earliest crossing and stop just after it; returns
   true then, with in->time at the event. */
static bool advance(Instance *in, double dt)
{
    double t0 = in->time, lo = 0.0, hi = dt;

    if (in->nx == 0) {
        in->time = t0 + dt;
        return false;
    }
    model_get_states(in, in->x_start);
    if (in->nz) MODEL.indicators(in->data, t0, in->z_start);
    rk4(in, t0, dt, in->x);
    if (!crossed(in, t0 + dt)) {
        in->time = t0 + dt;
        return false;
    }
    /* bracket [lo, hi]: no crossing up to lo, a crossing by hi */
    while (hi - lo > 1e-13 * fmax(1.0, fabs(t0))) {
        double mid = 0.5 * (lo + hi);
        rk4(in, t0, mid, in->x_try);
        if (crossed(in, t0 + mid)) {
            hi = mid;
            memcpy(in->x, in->x_try, in->nx * sizeof(double));
        } else {
            lo = mid;
        }
    }
    model_set_states(in, in->x);
    in->time = t0 + hi;
    return true;
}

StepOutcome core_do_step(Instance *in, double t, double h, double *t_end, bool *event)
{
    const char *fn = "DoStep";
    double target = t + h, t_reject = 0.0;

    *event = false;
    *t_end = in->time;
    if (fabs(t - in->time) > 1e-9 * fmax(1.0, fabs(t))) {
        core_fail(in, fn, "currentCommunicationPoint = %.17g but the FMU is at t = %.17g", t, in->time);
        return STEP_FAILED;
    }
    if (in->terminate_requested) {
        core_fail(in, fn, "the model terminated the simulation at t = %.17g", in->time);
        return STEP_FAILED;
    }
    if (h < 0.0) {
        core_fail(in, fn, "communicationStepSize = %.17g < 0", h);
        return STEP_FAILED;
    }
    if (MODEL.strict_stop_time && in->stop_defined && target > in->stop_time) {
        core_fail(in, fn, "Exceeded model finish time: the step from t = %.17g by h = %.17g ends at %.17g > "
                  "stopTime = %.17g", t, h, target, in->stop_time);
        return STEP_FAILED;
    }
    if (MODEL.rejects_step && MODEL.rejects_step(in->data, t, target, &t_reject)) {
        core_log(in, ST_DISCARD, "logStatusDiscard",
                 "step rejected at t = %.17g (step from t = %.17g to %.17g crosses t_reject)", t_reject, t, target);
        return STEP_REJECTED;
    }
    in->time = t;
    while (!fmu_time_reached(in->time, target)) {
        double dt = fmin(CS_FIXED_STEP, target - in->time);
        bool time_event = false, state_event;

        if (in->next_time_defined && in->next_time <= in->time + dt) {
            dt = fmax(0.0, in->next_time - in->time);
            time_event = true;
        }
        state_event = advance(in, dt);
        if (time_event && !state_event) in->time = in->next_time;
        if (MODEL.step_event && MODEL.step_event(in->data, in->time)) state_event = true;  /* a step event */
        if (state_event || (in->next_time_defined && fmu_time_reached(in->time, in->next_time))) {
            EventUpdate ev;
            int i = 0;
            *event = true;
            do core_event_update(in, &ev); while (ev.more && ++i < 100);
            core_debug(in, "event at t = %.17g", in->time);
            if (ev.terminate) {
                in->dirty = true;
                in->last_successful_time = *t_end = in->time;
                return STEP_TERMINATED;
            }
        }
    }
    in->time = target;
    in->dirty = true;
    in->last_successful_time = *t_end = target;
    return STEP_DONE;
}
