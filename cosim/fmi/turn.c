/* The master's per-step FMI calls in one call from Python each (see cosim/fmi/turn.py):
 * - cosim_turn: one co-simulation component's turn of a Gauss-Seidel macro step: set its inputs,
 *   doStep, get its outputs, check its real outputs for NaN and infinity;
 * - cosim_rhs: one right-hand side of a model-exchange FMU for the master's integrator: set the time,
 *   set the continuous states, get their derivatives, check the derivatives for NaN and infinity;
 * - cosim_samples: not the master's but the log writer's: the JSON messages of a block of samples,
 *   one per sample, from the numbers orjson wrote (see its comment below).
 *
 * The same FMI calls in the same order as the master makes them through ctypes one by one; each
 * crossing from Python into C costs about 0.6 us in the master's loop, so one crossing instead of
 * three saves over a microsecond per call. The first call returning a status worse than fmiWarning
 * ends the sequence; the caller reads which call it was and raises from Python.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>

typedef int (*Exchange2)(void *, const unsigned int *, size_t, void *);
typedef int (*Exchange3)(void *, const unsigned int *, size_t, void *, size_t);
typedef int (*DoStep1)(void *, double, double, char);  /* FMI 1: fmiBoolean newStep is a char */
typedef int (*DoStep2)(void *, double, double, int);
typedef int (*DoStep3)(void *, double, double, bool, bool *, bool *, bool *, double *);

/* one fmiXSet<Type> or fmiXGet<Type> call of a whole buffer */
typedef struct {
    void *function;
    const unsigned int *vrs;
    size_t n;            /* value references */
    void *values;
    size_t size;         /* values (FMI 3 nValues) */
} Exchange;

/* a real output buffer to check */
typedef struct {
    const void *values;
    size_t size;
    int single;          /* 1: float (Float32), 0: double */
} Finite;

typedef struct {
    int fmi;             /* 1, 2 or 3 */
    void *instance;
    void *do_step;
    const double *t;     /* communication point and step size, written by the caller before each turn */
    const double *h;
    bool *event;         /* FMI 3 doStep outputs: eventHandlingNeeded, terminateSimulation, earlyReturn, */
    bool *terminate;     /* lastSuccessfulTime */
    bool *early;
    double *last;
    size_t n_set, n_get, n_finite;
    const Exchange *sets;
    const Exchange *gets;
    const Finite *finite;
    int status;          /* out: the status of the call that ended the turn */
    size_t index;        /* out: which set, get or finite buffer */
} Turn;

enum { TURN_OK = 0, TURN_SET = 1, TURN_STEP = 2, TURN_GET = 3, TURN_NONFINITE = 4 };

static int exchange(const Turn *u, const Exchange *e)
{
    if (u->fmi < 3)  /* FMI 1 and 2: the same signature */
        return ((Exchange2)e->function)(u->instance, e->vrs, e->n, e->values);
    return ((Exchange3)e->function)(u->instance, e->vrs, e->n, e->values, e->size);
}

static bool finite(const Finite *f)
{
    if (f->single) {
        const float *x = f->values;
        for (size_t j = 0; j < f->size; j++)
            if (!isfinite(x[j])) return false;
    } else {
        const double *x = f->values;
        for (size_t j = 0; j < f->size; j++)
            if (!isfinite(x[j])) return false;
    }
    return true;
}

/* TURN_OK, or the phase that ended the turn (status and index say which call and how). FMI 3: a
 * doStep that sets terminateSimulation ends the turn as TURN_STEP whatever its status. */
int cosim_turn(Turn *u)
{
    int s;
    for (size_t i = 0; i < u->n_set; i++) {
        s = exchange(u, &u->sets[i]);
        if (s > 1) { u->status = s; u->index = i; return TURN_SET; }
    }
    if (u->fmi < 3) {
        if (u->fmi == 1)
            s = ((DoStep1)u->do_step)(u->instance, *u->t, *u->h, 1);  /* newStep */
        else
            s = ((DoStep2)u->do_step)(u->instance, *u->t, *u->h, 1);  /* noSetFMUStatePriorToCurrentPoint */
        if (s > 1) { u->status = s; u->index = 0; return TURN_STEP; }
    } else {
        s = ((DoStep3)u->do_step)(u->instance, *u->t, *u->h, true, u->event, u->terminate, u->early, u->last);
        if (s > 1 || *u->terminate) { u->status = s; u->index = 0; return TURN_STEP; }
    }
    for (size_t i = 0; i < u->n_get; i++) {
        s = exchange(u, &u->gets[i]);
        if (s > 1) { u->status = s; u->index = i; return TURN_GET; }
    }
    for (size_t i = 0; i < u->n_finite; i++)
        if (!finite(&u->finite[i])) { u->status = 0; u->index = i; return TURN_NONFINITE; }
    return TURN_OK;
}

/* fmiSetTime / fmi2SetTime / fmi3SetTime; fmiSetContinuousStates / fmi2SetContinuousStates /
 * fmi3SetContinuousStates; fmiGetDerivatives / fmi2GetDerivatives / fmi3GetContinuousStateDerivatives: the
 * same C signatures in all three versions */
typedef int (*SetTime)(void *, double);
typedef int (*SetStates)(void *, const double *, size_t);
typedef int (*GetDerivatives)(void *, double *, size_t);

typedef struct {
    void *instance;
    void *set_time;
    void *set_states;
    void *get_derivatives;
    size_t nx;           /* continuous states */
    const double *t;     /* the time, written by the caller before each call (cheaper than an argument) */
    int status;          /* out: the status of the call that ended the evaluation */
} Rhs;

enum { RHS_OK = 0, RHS_TIME = 1, RHS_STATES = 2, RHS_DERIVATIVES = 3, RHS_NONFINITE = 4 };

/* dx = f(*t, x): RHS_OK, or the call that ended the evaluation (status says how). */
int cosim_rhs(Rhs *r, const double *x, double *dx)
{
    int s = ((SetTime)r->set_time)(r->instance, *r->t);
    if (s > 1) { r->status = s; return RHS_TIME; }
    s = ((SetStates)r->set_states)(r->instance, x, r->nx);
    if (s > 1) { r->status = s; return RHS_STATES; }
    s = ((GetDerivatives)r->get_derivatives)(r->instance, dx, r->nx);
    if (s > 1) { r->status = s; return RHS_DERIVATIVES; }
    for (size_t j = 0; j < r->nx; j++)
        if (!isfinite(dx[j])) { r->status = 0; return RHS_NONFINITE; }
    return RHS_OK;
}

/* The log writer's messages of a block of samples in the samples layout (cosim/observers/log_writer.py,
 * encode_samples): the block's times and values as orjson wrote them, two JSON arrays (times: n
 * elements; values: n * width, sample after sample) whose elements are numbers, true, false or null,
 * none holding a comma, joined with the channel's joints (the bytes before the time, between the
 * values, after the last value: width + 2 of them, back to back in joints, joint j ending at
 * ends[j]). An element e of a sample whose fmi2[e] is set is an FMI 2 Boolean (a C int): 0 is written
 * false, anything else true. The messages go to out one after the other, '\n' between them (orjson
 * writes none: a JSON string escapes it); out holds at least times_len + values_len + n * (ends[width
 * + 1] + 1 + 4 * width) bytes. Returns the bytes written, or -1 when the arrays do not hold n and
 * n * width elements. */
ptrdiff_t cosim_samples(const char *times, size_t times_len, const char *values, size_t values_len, size_t n,
                        size_t width, const char *joints, const size_t *ends, const unsigned char *fmi2, char *out)
{
    if (times_len < 2 || values_len < 2)
        return -1;
    const char *t = times + 1, *t_end = times + times_len - 1;  /* inside the brackets */
    const char *v = values + 1, *v_end = values + values_len - 1;
    char *o = out;
    for (size_t k = 0; k < n; k++) {
        if (k > 0)
            *o++ = '\n';
        if (t >= t_end)
            return -1;
        memcpy(o, joints, ends[0]);
        o += ends[0];
        const char *comma = memchr(t, ',', (size_t)(t_end - t));
        const char *end = comma ? comma : t_end;
        memcpy(o, t, (size_t)(end - t));
        o += end - t;
        t = comma ? comma + 1 : t_end;
        for (size_t e = 0; e < width; e++) {
            if (v >= v_end)
                return -1;
            memcpy(o, joints + ends[e], ends[e + 1] - ends[e]);
            o += ends[e + 1] - ends[e];
            comma = memchr(v, ',', (size_t)(v_end - v));
            end = comma ? comma : v_end;
            if (fmi2[e]) {
                int zero = end - v == 1 && *v == '0';
                memcpy(o, zero ? "false" : "true", zero ? 5 : 4);
                o += zero ? 5 : 4;
            } else {
                memcpy(o, v, (size_t)(end - v));
                o += end - v;
            }
            v = comma ? comma + 1 : v_end;
        }
        memcpy(o, joints + ends[width], ends[width + 1] - ends[width]);
        o += ends[width + 1] - ends[width];
    }
    if (t < t_end || v < v_end)
        return -1;
    return o - out;
}
