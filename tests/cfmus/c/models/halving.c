/*
 * Halving - exponential decay with step events:
 *
 *   der(x) = -k x;  after each completed integrator step at which x <= threshold
 *   (1/2 at the start), the model asks for an event (fmi{2,3}CompletedIntegratorStep
 *   enterEventMode); there count += 1 and threshold /= 2.
 *
 * A step event is not located in time: it happens at the end of the integrator
 * step that finds the condition, so its time depends on where the importer
 * completes steps (FMPy and the master: at each output point and event).
 */
#include "model.h"

typedef struct {
    double x, der_x;
    double k;
    int32_t count;
    double threshold;  /* internal: not a model variable */
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->x = 1.0;
    d->k = 1.0;
    d->count = 0;
    d->threshold = 0.5;
}

static void initialize(void *p, double t)
{
    (void)p;
    (void)t;
}

static void derivatives(const void *p, double t, double *dx)
{
    const ModelData *d = p;
    (void)t;
    dx[0] = -d->k * d->x;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    derivatives(d, t, &d->der_x);
}

static bool step_event(const void *p, double t)
{
    const ModelData *d = p;
    (void)t;
    return d->x <= d->threshold;
}

static void event(void *p, double t, EventUpdate *ev)
{
    ModelData *d = p;
    (void)t;
    (void)ev;
    if (d->x <= d->threshold) {
        d->count += 1;
        d->threshold *= 0.5;
    }
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .n_fixed_states = 1,
    .state_offsets = {offsetof(ModelData, x)},
    .defaults = defaults,
    .initialize = initialize,
    .derivatives = derivatives,
    .outputs = outputs,
    .event = event,
    .step_event = step_event,
};
