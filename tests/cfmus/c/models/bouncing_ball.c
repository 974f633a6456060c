/*
 * BouncingBall - a ball falling onto a floor at h = 0.
 *
 *   der(h) = v,  der(v) = g                   (in flight)
 *   event indicator z = h; at impact (h <= 0 moving down): v := -e v, h := 0
 *
 * A rebound slower than V_REST ends the motion: the ball then rests at
 * h = 0, v = 0 for good (der = 0, indicator held at 1 so that no further
 * event fires). This keeps the model defined past the Zeno point where the
 * bounces would otherwise accumulate. `bounces` counts the impacts.
 */
#include "model.h"

/* m/s: slowest rebound that still leaves the floor */
#define V_REST 1e-2

typedef struct {
    double h, der_h, v, der_v;  /* states and their derivatives */
    double g, e, h0;            /* parameters */
    int32_t bounces;
    bool resting;
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->g = -9.81;
    d->e = 0.7;
    d->h0 = 1.0;
}

static void initialize(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    d->h = d->h0;
    d->v = 0.0;
    d->bounces = 0;
    d->resting = false;
}

static size_t n_indicators(const void *p)
{
    (void)p;
    return 1;
}

static void derivatives(const void *p, double t, double *dx)
{
    const ModelData *d = p;
    (void)t;
    dx[0] = d->v;
    dx[1] = d->resting ? 0.0 : d->g;
}

static void indicators(const void *p, double t, double *z)
{
    const ModelData *d = p;
    (void)t;
    z[0] = d->resting ? 1.0 : d->h;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    double dx[2];
    derivatives(d, t, dx);
    d->der_h = dx[0];
    d->der_v = dx[1];
}

static void event(void *p, double t, EventUpdate *ev)
{
    ModelData *d = p;
    (void)t;
    if (d->resting || d->h > 0.0 || d->v > 0.0) return;
    if (d->v < 0.0) d->bounces++;
    d->h = 0.0;
    d->v = -d->e * d->v;
    if (d->v < V_REST) {
        d->v = 0.0;
        d->resting = true;
    }
    ev->states_changed = true;
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .n_fixed_states = 2,
    .state_offsets = {offsetof(ModelData, h), offsetof(ModelData, v)},
    .defaults = defaults,
    .initialize = initialize,
    .n_indicators = n_indicators,
    .derivatives = derivatives,
    .indicators = indicators,
    .outputs = outputs,
    .event = event,
};
