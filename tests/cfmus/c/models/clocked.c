/*
 * Clocked - the smallest FMU with an input Clock: `ticks` counts the events
 * at which the importer activates the triggered clock `tick` (model exchange
 * event mode). It exists so that an importer without clock support can be
 * shown to refuse it with a clear message.
 */
#include "model.h"

typedef struct {
    bool tick;
    int32_t ticks;
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    (void)p;
}

static void initialize(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    d->ticks = 0;
    d->tick = false;
}

static void outputs(void *p, double t)
{
    (void)p;
    (void)t;
}

static void event(void *p, double t, EventUpdate *ev)
{
    ModelData *d = p;
    (void)t;
    (void)ev;
    if (d->tick) d->ticks++;
    d->tick = false;   /* a clock is active for one event instant only */
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .defaults = defaults,
    .initialize = initialize,
    .outputs = outputs,
    .event = event,
};
