/*
 * Horizon - a clock that refuses to run past its stop time, as some exporters' FMUs do.
 *
 *   der(x) = 1, x(start) = 0;  t_reached = the time the FMU is at.
 *
 * strict_stop_time: a co-simulation step whose t + h (computed here, in double) ends past the
 * stopTime given at setup fails with Error ("Exceeded model finish time", as a 20-sim FMU says),
 * and so does a model exchange SetTime past it. t_reached tells an importer's test which time the
 * FMU last reached, to compare with the stop time exactly.
 */
#include "model.h"

typedef struct {
    double x, der_x;
    double t_reached;
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->x = 0.0;
    d->t_reached = 0.0;
}

static void initialize(void *p, double t)
{
    ((ModelData *)p)->t_reached = t;
}

static void derivatives(const void *p, double t, double *dx)
{
    (void)p;
    (void)t;
    dx[0] = 1.0;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    d->der_x = 1.0;
    d->t_reached = t;
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .n_fixed_states = 1,
    .state_offsets = {offsetof(ModelData, x)},
    .defaults = defaults,
    .initialize = initialize,
    .derivatives = derivatives,
    .outputs = outputs,
    .strict_stop_time = true,
};
