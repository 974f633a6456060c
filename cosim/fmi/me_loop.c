/* A model-exchange FMU's integration between communication points, in C (see cosim/fmi/me_c.py).
 *
 * The master's Python loop (cosim/fmi/model_exchange.py) owns the FMI protocol: event mode, event
 * iteration, time events, termination. What runs many times per communication step runs here: the
 * right-hand side (fmiXSetTime, fmiXSetContinuousStates, fmiXGetDerivatives), the event indicators
 * (fmiXGetEventIndicators) and, once per advance, fmiXCompletedIntegratorStep, called on the FMU's C
 * functions directly. Two integrators:
 *
 * - cosim_dopri5_advance: the explicit Dormand-Prince 5(4) pair with its 4th-order dense output, an
 *   adaptive step (error per component against atol + rtol * |x|, a PI step-size controller), state events
 *   located on the dense output by bisection to 100 * eps * (|t| + |h|), as CVode does;
 * - cosim_cv_advance: SUNDIALS CVode, whose right-hand side and root function are cosim_cv_rhs and
 *   cosim_cv_roots below. The SUNDIALS functions are the ones fmpy's library already loaded, handed in as
 *   pointers by the Python side (no SUNDIALS header is needed to compile this file).
 *
 * The FMI calls have the same C signatures in FMI 1.0, 2.0 and 3.0 but for completedIntegratorStep.
 * The first call returning a status worse than fmiWarning ends the advance: the Fmu struct then says
 * which call, its status and the time, and the Python side raises as the same call made from Python does.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>

typedef int (*SetTime)(void *, double);
typedef int (*SetStates)(void *, const double *, size_t);
typedef int (*GetReals)(void *, double *, size_t);  /* states, derivatives, indicators, nominals */
typedef int (*Completed1)(void *, char *);
typedef int (*Completed2)(void *, int, int *, int *);
typedef int (*Completed3)(void *, bool, bool *, bool *);

/* which call ended an advance (Fmu.call); the values are cosim/fmi/me_c.py's */
enum { CALL_NONE = 0, CALL_SET_TIME, CALL_SET_X, CALL_GET_DX, CALL_NONFINITE, CALL_GET_Z, CALL_GET_X,
       CALL_GET_NOMINALS, CALL_COMPLETED, CALL_TOO_MANY_STEPS, CALL_STEP_TOO_SMALL, CALL_SOLVER };
/* what an advance returns */
enum { ADV_REACHED = 0, ADV_STATE_EVENT = 1, ADV_FAILED = 2 };

typedef struct {
    int fmi;                 /* 1, 2 or 3 */
    void *instance;
    void *set_time, *get_x, *set_x, *get_dx, *get_z, *get_nominals, *completed;
    int needs_completed;     /* call completedIntegratorStep at the end of each advance */
    size_t nx, nz;
    double *bad;             /* nx values: the derivatives that were not finite */
    /* out */
    int call;                /* CALL_*: what ended the advance */
    int status;              /* the FMI status of that call */
    double t_fail;           /* the FMU's time then */
    int step_event, terminate;  /* completedIntegratorStep's enterEventMode, terminateSimulation */
    long evaluations;        /* right-hand sides evaluated (statistics) */
    double t_set;            /* the time rhs last set (NAN: set it again) */
    double t_now;            /* the time last set, whoever set it here */
} Fmu;

/* fmiXSetTime, the time kept where the FMU's log messages are stamped from (t_now) */
static int set_time(Fmu *m, double t)
{
    m->t_now = t;
    return ((SetTime)m->set_time)(m->instance, t);
}

static int fail(Fmu *m, int call, int status, double t)
{
    m->call = call; m->status = status; m->t_fail = t;
    return -1;
}

/* dx: the derivatives where the FMU stands (time t); 0 or -1 (m says why) */
static int derivatives(Fmu *m, double t, double *dx)
{
    int s = ((GetReals)m->get_dx)(m->instance, dx, m->nx);
    if (s > 1) return fail(m, CALL_GET_DX, s, t);
    m->evaluations++;
    for (size_t j = 0; j < m->nx; j++)
        if (!isfinite(dx[j])) {
            memcpy(m->bad, dx, m->nx * sizeof(double));
            return fail(m, CALL_NONFINITE, 0, t);
        }
    return 0;
}

/* dx = f(t, x); 0 or -1 (m says why). The time is set only where it changed since the last call here
 * (m->t_set: NAN after any other call that sets it) */
static int rhs(Fmu *m, double t, const double *x, double *dx)
{
    int s = t == m->t_set ? 0 : set_time(m, t);
    if (s > 1) return fail(m, CALL_SET_TIME, s, t);
    m->t_set = t;
    if (m->nx == 0) return 0;
    s = ((SetStates)m->set_x)(m->instance, x, m->nx);
    if (s > 1) return fail(m, CALL_SET_X, s, t);
    return derivatives(m, t, dx);
}

/* the event indicators z at (t, x); 0 or -1 */
static int indicators(Fmu *m, double t, const double *x, double *z)
{
    m->t_set = NAN;
    int s = set_time(m, t);
    if (s > 1) return fail(m, CALL_SET_TIME, s, t);
    if (m->nx) {
        s = ((SetStates)m->set_x)(m->instance, x, m->nx);
        if (s > 1) return fail(m, CALL_SET_X, s, t);
    }
    s = ((GetReals)m->get_z)(m->instance, z, m->nz);
    if (s > 1) return fail(m, CALL_GET_Z, s, t);
    return 0;
}

/* the FMU at (t, x) (unless it is there: `there`, its last evaluation was at them; setting them again would make
 * it compute again what it holds), then completedIntegratorStep if it needs it; 0 or -1 */
static int finish(Fmu *m, double t, const double *x, bool there)
{
    m->t_set = NAN;
    int s = there ? 0 : set_time(m, t);
    if (s > 1) return fail(m, CALL_SET_TIME, s, t);
    if (m->nx && !there) {
        s = ((SetStates)m->set_x)(m->instance, x, m->nx);
        if (s > 1) return fail(m, CALL_SET_X, s, t);
    }
    m->step_event = m->terminate = 0;
    if (!m->needs_completed) return 0;
    if (m->fmi == 1) {
        char update = 0;
        s = ((Completed1)m->completed)(m->instance, &update);
        m->step_event = update != 0;
    } else if (m->fmi == 2) {
        int enter = 0, terminate = 0;
        s = ((Completed2)m->completed)(m->instance, 1, &enter, &terminate);  /* noSetFMUStatePriorToCurrentPoint */
        m->step_event = enter != 0; m->terminate = terminate != 0;
    } else {
        bool enter = false, terminate = false;
        s = ((Completed3)m->completed)(m->instance, true, &enter, &terminate);
        m->step_event = enter; m->terminate = terminate;
    }
    if (s > 1) return fail(m, CALL_COMPLETED, s, t);
    return 0;
}

/* FMI: an indicator crossed from > 0 to <= 0 or from < 0 to >= 0 */
static bool crossed(double z0, double z1)
{
    return (z0 > 0 && z1 <= 0) || (z0 < 0 && z1 >= 0);
}

static bool any_crossed(const double *z0, const double *z1, const char *hit, size_t nz)
{
    for (size_t i = 0; i < nz; i++)
        if ((hit == NULL || hit[i]) && crossed(z0[i], z1[i])) return true;
    return false;
}

static double root_tolerance(double t, double h)
{
    return 100.0 * 2.220446049250313e-16 * (fabs(t) + fabs(h));
}

/* --------------------------------------------------------------------------------------- DOPRI5 */

/* Dormand & Prince (1980), the 5(4) pair; the dense output's coefficients are Hairer's (Solving ODEs I) */
static const double C2 = 1.0 / 5, C3 = 3.0 / 10, C4 = 4.0 / 5, C5 = 8.0 / 9;
static const double A21 = 1.0 / 5;
static const double A31 = 3.0 / 40, A32 = 9.0 / 40;
static const double A41 = 44.0 / 45, A42 = -56.0 / 15, A43 = 32.0 / 9;
static const double A51 = 19372.0 / 6561, A52 = -25360.0 / 2187, A53 = 64448.0 / 6561, A54 = -212.0 / 729;
static const double A61 = 9017.0 / 3168, A62 = -355.0 / 33, A63 = 46732.0 / 5247, A64 = 49.0 / 176,
                    A65 = -5103.0 / 18656;
static const double A71 = 35.0 / 384, A73 = 500.0 / 1113, A74 = 125.0 / 192, A75 = -2187.0 / 6784,
                    A76 = 11.0 / 84;
static const double E1 = 71.0 / 57600, E3 = -71.0 / 16695, E4 = 71.0 / 1920, E5 = -17253.0 / 339200,
                    E6 = 22.0 / 525, E7 = -1.0 / 40;
static const double D1 = -12715105075.0 / 11282082432, D3 = 87487479700.0 / 32700410799,
                    D4 = -10690763975.0 / 1880347072, D5 = 701980252875.0 / 199316789632,
                    D6 = -1453857185.0 / 822651844, D7 = 69997945.0 / 29380423;

typedef struct {
    Fmu *fmu;
    double rtol, max_step;
    long max_steps;          /* steps per advance before it gives up */
    int restart;             /* set by reset: read the FMU's states at the next advance */
    double t;                /* where the integration stands */
    double h;                /* the step size proposed next (0: none yet) */
    double facold;           /* the step-size controller's previous error */
    double t_reached;        /* out */
    int inputs;              /* set by the macro step: inputs changed, the FMU still at (t, x) (a light restart) */
    /* work arrays of nx values each (k: 7 * nx, dense: 5 * nx) and nz values each (z*) */
    double *x, *xnew, *xs, *atol, *k, *dense, *z_prev, *z, *z_mid;
    char *hit;               /* nz flags */
} Dopri;

#define K(i) (d->k + (size_t)(i) * n)
#define R(i) (d->dense + (size_t)(i) * n)

/* the dense output at theta in [0, 1] of the last step, into y */
static void dense_at(const Dopri *d, double theta, double *y)
{
    size_t n = d->fmu->nx;
    double theta1 = 1.0 - theta;
    for (size_t j = 0; j < n; j++)
        y[j] = R(0)[j] + theta * (R(1)[j] + theta1 * (R(2)[j] + theta * (R(3)[j] + theta1 * R(4)[j])));
}

static double scale(const Dopri *d, size_t j, double a, double b)
{
    return d->atol[j] + d->rtol * fmax(fabs(a), fabs(b));
}

/* Hairer's starting step: h with h * |f| and h^5 * |f'| about 0.01 of the tolerance; k(0) = f(t, x) */
static int initial_step(Dopri *d, double hmax, double *h)
{
    Fmu *m = d->fmu;
    size_t n = m->nx;
    double dnf = 0, dny = 0, der2 = 0;
    for (size_t j = 0; j < n; j++) {
        double sk = scale(d, j, d->x[j], d->x[j]);
        dnf += (K(0)[j] / sk) * (K(0)[j] / sk);
        dny += (d->x[j] / sk) * (d->x[j] / sk);
    }
    double h0 = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : 0.01 * sqrt(dny / dnf);
    h0 = fmin(h0, hmax);
    for (size_t j = 0; j < n; j++) d->xs[j] = d->x[j] + h0 * K(0)[j];
    if (rhs(m, d->t + h0, d->xs, K(1))) return -1;
    for (size_t j = 0; j < n; j++) {
        double q = (K(1)[j] - K(0)[j]) / scale(d, j, d->x[j], d->x[j]);
        der2 += q * q;
    }
    der2 = sqrt(der2) / h0;
    double der12 = fmax(der2, sqrt(dnf));
    double h1 = der12 <= 1e-15 ? fmax(1e-6, h0 * 1e-3) : pow(0.01 / der12, 0.2);
    *h = fmin(fmin(100 * h0, h1), hmax);
    return 0;
}

/* one trial step of size h from (t, x) to t1 (t + h, or the stop time it rounds to) with k(0) = f(t, x): xnew,
 * k(1..6) (k(6) = f(t1, xnew), the FMU left there) and the scaled error norm in *err; 0 or -1 */
static int trial(Dopri *d, double h, double t1, double *err)
{
    Fmu *m = d->fmu;
    size_t n = m->nx;
    double t = d->t, *x = d->x, *xs = d->xs, e = 0;
    for (size_t j = 0; j < n; j++) xs[j] = x[j] + h * A21 * K(0)[j];
    if (rhs(m, t + C2 * h, xs, K(1))) return -1;
    for (size_t j = 0; j < n; j++) xs[j] = x[j] + h * (A31 * K(0)[j] + A32 * K(1)[j]);
    if (rhs(m, t + C3 * h, xs, K(2))) return -1;
    for (size_t j = 0; j < n; j++) xs[j] = x[j] + h * (A41 * K(0)[j] + A42 * K(1)[j] + A43 * K(2)[j]);
    if (rhs(m, t + C4 * h, xs, K(3))) return -1;
    for (size_t j = 0; j < n; j++)
        xs[j] = x[j] + h * (A51 * K(0)[j] + A52 * K(1)[j] + A53 * K(2)[j] + A54 * K(3)[j]);
    if (rhs(m, t + C5 * h, xs, K(4))) return -1;
    for (size_t j = 0; j < n; j++)
        xs[j] = x[j] + h * (A61 * K(0)[j] + A62 * K(1)[j] + A63 * K(2)[j] + A64 * K(3)[j] + A65 * K(4)[j]);
    if (rhs(m, t1, xs, K(5))) return -1;
    for (size_t j = 0; j < n; j++)
        d->xnew[j] = x[j] + h * (A71 * K(0)[j] + A73 * K(2)[j] + A74 * K(3)[j] + A75 * K(4)[j] + A76 * K(5)[j]);
    if (rhs(m, t1, d->xnew, K(6))) return -1;
    for (size_t j = 0; j < n; j++) {
        double q = h * (E1 * K(0)[j] + E3 * K(2)[j] + E4 * K(3)[j] + E5 * K(4)[j] + E6 * K(5)[j] + E7 * K(6)[j]);
        q /= scale(d, j, x[j], d->xnew[j]);
        e += q * q;
    }
    *err = sqrt(e / (double)n);
    return 0;
}

/* the dense output of the accepted step of size h (before x is replaced by xnew) */
static void keep_dense(Dopri *d, double h)
{
    size_t n = d->fmu->nx;
    for (size_t j = 0; j < n; j++) {
        double diff = d->xnew[j] - d->x[j], bspl = h * K(0)[j] - diff;
        R(0)[j] = d->x[j];
        R(1)[j] = diff;
        R(2)[j] = bspl;
        R(3)[j] = diff - h * K(6)[j] - bspl;
        R(4)[j] = h * (D1 * K(0)[j] + D3 * K(2)[j] + D4 * K(3)[j] + D5 * K(4)[j] + D6 * K(5)[j] + D7 * K(6)[j]);
    }
}

/* the earliest time in (t_lo, t_hi] where a flagged indicator has crossed, by bisection on the dense output
 * of the step [t0, t0 + h] (n == 0: the states are constant); the right end of the last bracket, as CVode */
static int locate(Dopri *d, double t0, double h, double t_lo, double t_hi, double *t_event)
{
    Fmu *m = d->fmu;
    double tol = root_tolerance(t_hi, t_hi - t_lo);
    double *z_lo = d->z_prev;  /* updated in place: z_prev is read again only after a reset */
    while (t_hi - t_lo > tol) {
        double t_mid = 0.5 * (t_lo + t_hi);
        if (t_mid <= t_lo || t_mid >= t_hi) break;
        if (m->nx) dense_at(d, (t_mid - t0) / h, d->xs);
        if (indicators(m, t_mid, d->xs, d->z_mid)) return -1;
        if (any_crossed(z_lo, d->z_mid, d->hit, m->nz)) {
            t_hi = t_mid;
        } else {
            t_lo = t_mid;
            memcpy(z_lo, d->z_mid, m->nz * sizeof(double));
        }
    }
    *t_event = t_hi;
    return 0;
}

/* after an accepted step [t0, t0 + h] with the FMU at (t0 + h, xnew): a state event in it? 1 (at *t_event),
 * 0 or 2 (none; z_prev now the indicators at t0 + h; 2: the FMU was moved to probe an indicator) or -1 */
static int check_events(Dopri *d, double t0, double h, double *t_event)
{
    Fmu *m = d->fmu;
    size_t nz = m->nz;
    double t1 = t0 + h;
    int s = ((GetReals)m->get_z)(m->instance, d->z, nz);  /* the FMU is at (t1, xnew): k(6)'s evaluation */
    if (s > 1) return fail(m, CALL_GET_Z, s, t1);
    bool zero = false;
    for (size_t i = 0; i < nz; i++) zero = zero || d->z_prev[i] == 0;
    if (zero) {  /* an indicator on zero (just after its event): its sign is the one it takes leaving zero,
                    probed just after the step's start, as CVode */
        double t_probe = t0 + fmax(1e-6 * h, root_tolerance(t1, h));
        if (m->nx) dense_at(d, (t_probe - t0) / h, d->xs);
        if (indicators(m, t_probe, d->xs, d->z_mid)) return -1;
        for (size_t i = 0; i < nz; i++)
            if (d->z_prev[i] == 0) d->z_prev[i] = d->z_mid[i];
    }
    bool any = false;
    for (size_t i = 0; i < nz; i++) {
        d->hit[i] = crossed(d->z_prev[i], d->z[i]);
        any = any || d->hit[i];
    }
    if (!any) {
        memcpy(d->z_prev, d->z, nz * sizeof(double));
        return zero ? 2 : 0;
    }
    if (locate(d, t0, h, t0, t1, t_event)) return -1;
    return 1;
}

/* restart at d->t from the FMU's states: x, atol = rtol * |nominal|, k(0), the indicators; 0 or -1 */
static int dopri_restart(Dopri *d)
{
    Fmu *m = d->fmu;
    size_t n = m->nx;
    int s;
    if (n) {
        s = ((GetReals)m->get_x)(m->instance, d->x, n);
        if (s > 1) return fail(m, CALL_GET_X, s, d->t);
        s = ((GetReals)m->get_nominals)(m->instance, d->atol, n);
        if (s > 1) return fail(m, CALL_GET_NOMINALS, s, d->t);
        for (size_t j = 0; j < n; j++) d->atol[j] = d->rtol * fabs(d->atol[j]);
        if (rhs(m, d->t, d->x, K(0))) return -1;
    }
    if (m->nz && indicators(m, d->t, d->x, d->z_prev)) return -1;
    d->restart = d->inputs = 0;
    return 0;
}

/* after an input changed, the FMU still at (d->t, d->x): k(0) and the indicators again; 0 or -1 */
static int dopri_inputs(Dopri *d)
{
    Fmu *m = d->fmu;
    size_t n = m->nx;
    if (n && derivatives(m, d->t, K(0))) return -1;
    if (m->nz) {
        int s = ((GetReals)m->get_z)(m->instance, d->z_prev, m->nz);
        if (s > 1) return fail(m, CALL_GET_Z, s, d->t);
    }
    d->inputs = 0;
    return 0;
}

/* no continuous state: the indicators depend on time (and held inputs) only */
static int dopri_discrete(Dopri *d, double t_stop)
{
    Fmu *m = d->fmu;
    double t0 = d->t, t_event = t_stop;
    int found = 0;
    if (m->nz) {
        if (indicators(m, t_stop, d->x, d->z)) return ADV_FAILED;
        for (size_t i = 0; i < m->nz; i++) {
            d->hit[i] = crossed(d->z_prev[i], d->z[i]);
            found = found || d->hit[i];
        }
        if (found) {
            if (locate(d, t0, t_stop - t0, t0, t_stop, &t_event)) return ADV_FAILED;
        } else {
            memcpy(d->z_prev, d->z, m->nz * sizeof(double));
        }
    }
    d->t = d->t_reached = t_event;
    if (finish(m, t_event, d->x, false)) return ADV_FAILED;
    if (found) d->restart = 1;
    return found ? ADV_STATE_EVENT : ADV_REACHED;
}

/* the step-size controller (Hairer's, with Lund's stabilization): the factor h_new / h after an error err */
static double step_factor(Dopri *d, double err, bool rejected)
{
    double fac11 = pow(err, 0.2);
    if (rejected) return 1.0 / fmin(5.0, fac11 / 0.9);
    double fac = fac11 / pow(d->facold, 0.04);
    fac = fmax(0.1, fmin(5.0, fac / 0.9));
    return 1.0 / fac;
}

/* integrate towards t_stop, never past it: ADV_REACHED, ADV_STATE_EVENT (the FMU at the event's time and
 * states) or ADV_FAILED (d->fmu says why); d->t_reached the time reached */
int cosim_dopri5_advance(Dopri *d, double t_stop)
{
    Fmu *m = d->fmu;
    size_t n = m->nx;
    m->call = CALL_NONE;
    m->t_set = NAN;  /* the caller may have set the time */
    if (d->restart ? dopri_restart(d) : d->inputs && dopri_inputs(d)) return ADV_FAILED;
    if (n == 0) return dopri_discrete(d, t_stop);
    double hmax = fmin(d->max_step, t_stop - d->t);
    if (d->h <= 0 && initial_step(d, hmax, &d->h)) return ADV_FAILED;
    bool rejected = false, there = false;  /* there: the FMU's last evaluation was at (d->t, d->x) */
    for (long steps = 0; d->t < t_stop; steps++) {
        if (steps >= d->max_steps) return fail(m, CALL_TOO_MANY_STEPS, 0, d->t), ADV_FAILED;
        double remaining = t_stop - d->t;
        double h = fmin(fmin(d->h, d->max_step), remaining);
        if (remaining - h <= root_tolerance(t_stop, h)) h = remaining;  /* no sliver of a step left */
        if (0.1 * h <= fabs(d->t) * 2.220446049250313e-16) return fail(m, CALL_STEP_TOO_SMALL, 0, d->t), ADV_FAILED;
        double err, t0 = d->t, t1 = (h == remaining) ? t_stop : d->t + h, t_event;
        if (trial(d, h, t1, &err)) return ADV_FAILED;
        if (!(err <= 1.0)) {  /* rejected (a NaN error too) */
            d->h = h * (isfinite(err) ? step_factor(d, err, true) : 0.1);
            rejected = true;
            continue;
        }
        double h_next = h * step_factor(d, err, false);
        d->h = rejected ? fmin(h_next, h) : h_next;
        d->facold = fmax(err, 1e-4);
        rejected = false;
        keep_dense(d, t1 - t0);
        int event = m->nz ? check_events(d, t0, t1 - t0, &t_event) : 0;
        if (event < 0) return ADV_FAILED;
        there = event == 0;  /* 2: an indicator probed elsewhere since k(6)'s evaluation */
        if (event == 1) {
            dense_at(d, (t_event - t0) / (t1 - t0), d->x);
            d->t = d->t_reached = t_event;
            d->restart = 1;  /* the event iteration may change the states */
            return finish(m, t_event, d->x, false) ? ADV_FAILED : ADV_STATE_EVENT;
        }
        memcpy(d->x, d->xnew, n * sizeof(double));
        memcpy(K(0), K(6), n * sizeof(double));  /* first same as last */
        d->t = t1;
    }
    d->t_reached = d->t;
    return finish(m, d->t, d->x, there) ? ADV_FAILED : ADV_REACHED;
}

/* ---------------------------------------------------------------------------------------- CVode */

typedef int (*CVodeFn)(void *, double, void *, double *, int);
typedef int (*CVodeReInitFn)(void *, double, void *);
typedef int (*CVodeSetStopTimeFn)(void *, double);
typedef double *(*GetArrayFn)(void *);

typedef struct {
    Fmu *fmu;
    void *mem;               /* CVode's memory, made by the Python side (CVodeCreate, CVodeInit, ...) */
    void *y;                 /* its state N_Vector (nx values, one dummy for a model without states) */
    void *cvode, *reinit, *set_stop, *get_array;  /* CVode, CVodeReInit, CVodeSetStopTime, N_VGetArrayPointer */
    int restart;             /* set by reset: read the FMU's states and re-initialize at t */
    double t;                /* the restart time */
    double t_reached;        /* out */
    int flag;                /* out: CVode's return flag */
} Cv;

/* CVode's right-hand side (CVRhsFn); user_data is the Cv */
int cosim_cv_rhs(double t, void *y, void *ydot, void *user_data)
{
    Cv *c = user_data;
    GetArrayFn data = (GetArrayFn)c->get_array;
    double *dx = data(ydot);
    if (c->fmu->nx == 0) dx[0] = 0.0;
    return rhs(c->fmu, t, data(y), dx);
}

/* CVode's root function (CVRootFn) */
int cosim_cv_roots(double t, void *y, double *gout, void *user_data)
{
    Cv *c = user_data;
    return indicators(c->fmu, t, ((GetArrayFn)c->get_array)(y), gout);
}

/* integrate towards t_stop, never past it (CVodeSetStopTime): ADV_REACHED, ADV_STATE_EVENT or ADV_FAILED
 * (c->fmu says why; CALL_SOLVER: CVode's own failure, c->flag) */
int cosim_cv_advance(Cv *c, double t_stop)
{
    Fmu *m = c->fmu;
    double *x = ((GetArrayFn)c->get_array)(c->y);
    m->call = CALL_NONE;
    m->t_set = NAN;
    if (c->restart) {
        if (m->nx) {
            int s = ((GetReals)m->get_x)(m->instance, x, m->nx);
            if (s > 1) return fail(m, CALL_GET_X, s, c->t), ADV_FAILED;
        } else {
            x[0] = 0.0;
        }
        c->flag = ((CVodeReInitFn)c->reinit)(c->mem, c->t, c->y);
        if (c->flag < 0) return fail(m, CALL_SOLVER, 0, c->t), ADV_FAILED;
        c->restart = 0;
    }
    ((CVodeSetStopTimeFn)c->set_stop)(c->mem, t_stop);
    double t = c->t;
    c->flag = ((CVodeFn)c->cvode)(c->mem, t_stop, c->y, &t, 1);  /* CV_NORMAL */
    if (m->call != CALL_NONE) return ADV_FAILED;  /* a failing FMU call in a callback */
    if (c->flag < 0) return fail(m, CALL_SOLVER, 0, t), ADV_FAILED;
    c->t = c->t_reached = t;
    if (finish(m, t, x, false)) return ADV_FAILED;
    return c->flag == 2 ? ADV_STATE_EVENT : ADV_REACHED;  /* CV_ROOT_RETURN */
}

/* ------------------------------------------------------------------------------- the macro step */

/* one fmiXSet<Type> / fmiXGet<Type> call of a whole buffer: the layout of turn.c's Exchange, filled from
 * Python by the same ctypes type (cosim.fmi.turn.Exchange); `applied` (inputs only): the values last set */
typedef struct {
    void *function;
    const unsigned int *vrs;
    size_t n;
    void *values;
    size_t size;
} Exchange;

typedef struct {
    const void *values;
    size_t size;
    int single;
} Finite;

typedef int (*Exchange2)(void *, const unsigned int *, size_t, void *);
typedef int (*Exchange3)(void *, const unsigned int *, size_t, void *, size_t);

typedef struct {
    Fmu *fmu;
    int cvode;               /* the integrator: 1 a Cv, 0 a Dopri */
    void *integrator;
    size_t n_set, n_get, n_finite;
    const Exchange *sets;
    unsigned char *const *applied;  /* per input buffer, its values as last set (bytes of `size` doubles) */
    const size_t *bytes;            /* per input buffer, the bytes of its values */
    const Exchange *gets;
    const Finite *finite;
    int index;               /* out: which set, get or finite buffer ended the step (STEP_EVENT: the advance's result) */
    int changed;             /* out: an input changed (the integrator re-started) */
    int ended;               /* out: cosim_me_do_step's cosim_me_step result */
} MeStep;

enum { STEP_OK = 0, STEP_SET = 1, STEP_ADVANCE = 2, STEP_EVENT = 3, STEP_GET = 4, STEP_NONFINITE = 5 };

static int exchange(int fmi, void *instance, const Exchange *e)
{
    if (fmi < 3) return ((Exchange2)e->function)(instance, e->vrs, e->n, e->values);
    return ((Exchange3)e->function)(instance, e->vrs, e->n, e->values, e->size);
}

static bool all_finite(const Finite *f)
{
    for (size_t j = 0; j < f->size; j++)
        if (f->single ? !isfinite(((const float *)f->values)[j]) : !isfinite(((const double *)f->values)[j]))
            return false;
    return true;
}

/* One macro step of a model-exchange FMU with continuous real inputs and no time event before t_end: the inputs
 * that changed set (the integrator then re-started at t), the integration to t_end, the outputs read and checked.
 * STEP_OK; STEP_EVENT when the advance stopped at a state event or completedIntegratorStep asked for event mode
 * or termination (the caller goes on from the time reached; the outputs are not read); else what ended it
 * (index: the buffer; the Fmu says which FMI call of an advance). */
int cosim_me_step(MeStep *s, double t, double t_end)
{
    Fmu *m = s->fmu;
    int st;
    s->changed = 0;
    for (size_t i = 0; i < s->n_set; i++) {
        if (memcmp(s->sets[i].values, s->applied[i], s->bytes[i]) == 0) continue;
        st = exchange(m->fmi, m->instance, &s->sets[i]);
        if (st > 1) { m->status = st; s->index = (int)i; return STEP_SET; }
        memcpy(s->applied[i], s->sets[i].values, s->bytes[i]);
        s->changed = 1;
    }
    int ended;
    if (s->cvode) {
        Cv *c = s->integrator;
        if (s->changed) { c->restart = 1; c->t = t; }
        ended = cosim_cv_advance(c, t_end);
    } else {
        Dopri *d = s->integrator;
        if (s->changed) d->inputs = 1;  /* the FMU at (t, x): d->t is t, the caller re-starts it otherwise */
        ended = cosim_dopri5_advance(d, t_end);
    }
    if (ended == ADV_FAILED) return STEP_ADVANCE;
    if (ended == ADV_STATE_EVENT || m->step_event || m->terminate) { s->index = ended; return STEP_EVENT; }
    for (size_t i = 0; i < s->n_get; i++) {
        st = exchange(m->fmi, m->instance, &s->gets[i]);
        if (st > 1) { m->status = st; s->index = (int)i; return STEP_GET; }
    }
    for (size_t i = 0; i < s->n_finite; i++)
        if (!all_finite(&s->finite[i])) { s->index = (int)i; return STEP_NONFINITE; }
    return STEP_OK;
}

/* cosim_me_step as an FMI 2.0 doStep, for a loop that calls each component's turn as set, doStep, get
 * (cosim_steps of turn.c, cosim/engine/cloop.py): the instance is the MeStep, which makes its own exchanges
 * (the turn has none). fmi2Error when the step ended early: ended says how. Offered only where no event can
 * arise in C (ModelExchange.c_turn), so an early end is a failure, which the caller raises. */
int cosim_me_do_step(void *instance, double t, double h, int no_prior)
{
    MeStep *s = instance;
    (void)no_prior;
    s->ended = cosim_me_step(s, t, t + h);
    return s->ended ? 3 : 0;
}
