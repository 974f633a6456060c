/*
 * VanDerPol - the Van der Pol oscillator, smooth and event free:
 *
 *   der(x0) = x1,  der(x1) = mu (1 - x0^2) x1 - x0
 */
#include "model.h"

typedef struct {
    double x0, der_x0, x1, der_x1;
    double mu;
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->x0 = 2.0;
    d->x1 = 0.0;
    d->mu = 1.0;
}

static void initialize(void *p, double t)
{
    (void)p;   /* the states start at their (exact) start values */
    (void)t;
}

static void nominals(const void *p, double *nominal)
{
    (void)p;
    nominal[0] = 2.0;   /* the limit cycle reaches |x0| ~ 2, |x1| ~ 2.7 at mu = 1 */
    nominal[1] = 2.0;
}

static void derivatives(const void *p, double t, double *dx)
{
    const ModelData *d = p;
    (void)t;
    dx[0] = d->x1;
    dx[1] = d->mu * (1.0 - d->x0 * d->x0) * d->x1 - d->x0;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    double dx[2];
    derivatives(d, t, dx);
    d->der_x0 = dx[0];
    d->der_x1 = dx[1];
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .n_fixed_states = 2,
    .state_offsets = {offsetof(ModelData, x0), offsetof(ModelData, x1)},
    .defaults = defaults,
    .initialize = initialize,
    .nominals = nominals,
    .derivatives = derivatives,
    .outputs = outputs,
};
