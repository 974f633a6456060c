/*
 * Stair - a counter driven by time events only (no continuous states).
 *
 * counter starts at 1 and increments at every t = 1, 2, 3, ... s, announced
 * through nextEventTime; ramp = 0.5 * counter. At t = t_terminate the model
 * asks to end the simulation (model exchange: terminateSimulation from the
 * discrete update; co-simulation: the step stops there). A co-simulation step
 * that crosses t_reject is rejected (fmi2Discard / fmi3Discard, nothing
 * changes), to exercise an importer's handling of a genuinely rejected step.
 */
#include "model.h"

typedef struct {
    int32_t counter;
    double ramp;
    double t_terminate, t_reject;
    double next_tick;  /* time of the next increment */
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->t_terminate = 10.5;
    d->t_reject = 1e300;
}

static void initialize(void *p, double t)
{
    ModelData *d = p;
    d->counter = 1;
    d->next_tick = floor(t) + 1.0;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    d->ramp = 0.5 * d->counter;
}

static void event(void *p, double t, EventUpdate *ev)
{
    ModelData *d = p;
    while (fmu_time_reached(t, d->next_tick)) {
        d->counter++;
        d->next_tick += 1.0;
    }
    if (fmu_time_reached(t, d->t_terminate)) {
        ev->terminate = true;
        return;
    }
    ev->next_time_defined = true;
    ev->next_time = fmin(d->next_tick, d->t_terminate);
}

static bool rejects_step(const void *p, double t0, double t1, double *t_reject)
{
    const ModelData *d = p;
    *t_reject = d->t_reject;
    return t0 < d->t_reject && !fmu_time_reached(d->t_reject, t1);
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .defaults = defaults,
    .initialize = initialize,
    .outputs = outputs,
    .event = event,
    .rejects_step = rejects_step,
};
