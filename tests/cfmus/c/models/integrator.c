/*
 * Integrator - integrates its input:
 *
 *   der(x) = k u
 *
 * u is an input (held over a co-simulation step, so a step adds k u h), k a
 * tunable parameter. Declares FMU state (models.py), so a master can save,
 * restore and serialize it.
 */
#include "model.h"

typedef struct {
    double x, der_x;
    double u;
    double k;
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->x = 0.0;
    d->u = 0.0;
    d->k = 1.0;
}

static void initialize(void *p, double t)
{
    (void)p;   /* x starts at its (exact) start value */
    (void)t;
}

static void derivatives(const void *p, double t, double *dx)
{
    const ModelData *d = p;
    (void)t;
    dx[0] = d->k * d->u;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    derivatives(d, t, &d->der_x);
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .n_fixed_states = 1,
    .state_offsets = {offsetof(ModelData, x)},
    .defaults = defaults,
    .initialize = initialize,
    .derivatives = derivatives,
    .outputs = outputs,
};
