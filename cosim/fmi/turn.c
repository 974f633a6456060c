/* The master's per-step FMI calls in one call from Python each (see cosim/fmi/turn.py):
 * - cosim_turn: one co-simulation component's turn of a Gauss-Seidel macro step: set its inputs,
 *   doStep, get its outputs, check its real outputs for NaN and infinity;
 * - cosim_steps: macro steps of a whole system of such components (cosim/engine/cloop.py): per step the
 *   link copies and every component's turn in the algorithm's order, the record the watchdog and the
 *   supervisor read, each component's wall time, the tracked errors' sums, the log's row of each step;
 * - cosim_rhs: one right-hand side of a model-exchange FMU for the master's integrator: set the time,
 *   set the continuous states, get their derivatives, check the derivatives for NaN and infinity;
 *
 * The same FMI calls in the same order as the master makes them through ctypes one by one; each
 * crossing from Python into C costs about 0.6 us in the master's loop, so one crossing instead of
 * three saves over a microsecond per call. The first call returning a status worse than fmiWarning
 * ends the sequence; the caller reads which call it was and raises from Python.
 */
#define _POSIX_C_SOURCE 199309L  /* clock_gettime */
#include <math.h>
#include <stdint.h>
#include <time.h>
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

/* a link's values: an output's bytes into an input's (the same C type on both ends) */
typedef struct {
    void *dst;
    const void *src;
    size_t bytes;
} Move;

typedef struct {
    size_t n;              /* turns per macro step, in the algorithm's order */
    Turn *const *turns;
    const size_t *comp;    /* each turn's component index (the record, the wall times) */
    const size_t *first;   /* turn i's link copies: moves[first[i]] .. moves[first[i + 1] - 1] */
    const Move *moves;
    int jacobi;            /* 1: every turn's links copied before the first turn; 0: each before its turn */
    double *wall;          /* per component index: wall seconds in its turns (its link copies included) */
    double *record;        /* the shared record: [0] component with the turn, [1] the macro step's time, s,
                              [3] macro steps done */
    double master;         /* the record's value for "no component has the turn" */
    const double *times;   /* per macro step of the call: its time and step size, s; its end, ns */
    const double *steps;
    const int64_t *ends;
    size_t n_pairs;        /* tracked errors: actual - reference, their sum of squares, the largest |e| */
    const double *const *actual;
    const double *const *reference;
    double *sq;
    double *mx;
    int64_t *t_mx;         /* when the largest |e| was seen (the macro step's end, ns) */
    double budget;         /* wall s after which the call returns at the end of a macro step */
    size_t failed;         /* out: the turn that ended a macro step */
    int ended;             /* out: its cosim_turn result */
    size_t n_copies;       /* the log's row of a macro step (0: none): copies[c].dst is the byte offset in the row */
    const Move *copies;
    int64_t *row_count;    /* rows held, written after the row (a counted row is complete) */
    int64_t *row_stamps;   /* per row the macro step's end, ns */
    char *rows;            /* row_cap rows of row_width bytes; the call returns when they are full */
    size_t row_width;
    size_t row_cap;
} Steps;

static double wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* After a completed macro step: its row of the log's values (each copy from an FMU buffer into the row) and its end
 * as the row's stamp, then the count; true when the rows are full. */
static bool copy_row(Steps *s, size_t j)
{
    int64_t i = *s->row_count;
    char *row = s->rows + (size_t)i * s->row_width;
    for (size_t c = 0; c < s->n_copies; c++)
        memcpy(row + (size_t)s->copies[c].dst, s->copies[c].src, s->copies[c].bytes);
    s->row_stamps[i] = s->ends[j];
    __atomic_store_n(s->row_count, i + 1, __ATOMIC_RELEASE);
    return (size_t)(i + 1) >= s->row_cap;
}

static void copy_links(const Steps *s, size_t i)
{
    for (size_t j = s->first[i]; j < s->first[i + 1]; j++)
        memcpy(s->moves[j].dst, s->moves[j].src, s->moves[j].bytes);
}

/* Macro steps k0 .. k0 + n - 1 (times[j0 + j], steps[j0 + j], ends[j0 + j] of step k0 + j): the macro steps
 * completed. Fewer than n: a turn ended step k0 + returned early (failed and ended say which and how; the turns
 * before it in that step completed), or the wall budget was spent or the log's rows are full (ended is 0). The same
 * arithmetic as the master's Python loop. The caller starts a call with room for a row (row_count < row_cap). */
size_t cosim_steps(Steps *s, size_t k0, size_t j0, size_t n)
{
    double start = wall_now(), prev = start;
    for (size_t j = 0; j < n; j++) {
        const double t = s->times[j0 + j], h = s->steps[j0 + j];
        s->record[1] = t;
        if (s->jacobi)
            for (size_t i = 0; i < s->n; i++)
                copy_links(s, i);
        if (j > 0 || s->jacobi)  /* the step's first reading: before its first copy (Jacobi: after them all) */
            prev = wall_now();
        for (size_t i = 0; i < s->n; i++) {
            Turn *u = s->turns[i];
            s->record[0] = (double)s->comp[i];
            if (!s->jacobi)
                copy_links(s, i);
            *(double *)u->t = t;
            *(double *)u->h = h;
            int ended = cosim_turn(u);
            if (ended) {
                s->failed = i;
                s->ended = ended;
                s->record[0] = s->master;
                return j;
            }
            double now = wall_now();
            s->wall[s->comp[i]] += now - prev;
            prev = now;
        }
        s->record[0] = s->master;
        s->record[3] = (double)(k0 + j + 1);
        for (size_t p = 0; p < s->n_pairs; p++) {
            double e = *s->actual[p] - *s->reference[p];
            s->sq[p] += e * e;
            if (fabs(e) > s->mx[p]) {
                s->mx[p] = fabs(e);
                s->t_mx[p] = s->ends[j0 + j];
            }
        }
        if (s->n_copies && copy_row(s, j0 + j)) {
            s->ended = 0;
            return j + 1;
        }
        if (prev - start > s->budget) {
            s->ended = 0;
            return j + 1;
        }
    }
    s->ended = 0;
    return n;
}
