/*
 * Forgetful - start values, the order of the calls that set them, and a log without an environment.
 *
 *   y = p;  z: an output declared initial="exact", which keeps the start value the importer set.
 *
 * As some exporters' FMI 2 FMUs do, fmi2SetupExperiment resets every variable to its default (values
 * set before it are forgotten: FMPy and libcosim set start values after it), and log messages carry a
 * NULL componentEnvironment (FMI 1.0: a NULL component). Initialization fails for p < 0, with the reason logged.
 */
#include <stdio.h>

#include "model.h"

typedef struct {
    double p, y, z;
    char why[96];  /* internal: the reason p is invalid */
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    ModelData *d = p;
    d->p = 1.0;
    d->z = 0.0;
}

static void initialize(void *p, double t)
{
    (void)p;
    (void)t;
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    d->y = d->p;
}

static const char *invalid(const void *p)
{
    ModelData *d = (ModelData *)p;
    if (d->p >= 0.0) return NULL;
    snprintf(d->why, sizeof d->why, "p = %g is negative; p must be >= 0", d->p);
    return d->why;
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .defaults = defaults,
    .initialize = initialize,
    .outputs = outputs,
    .invalid = invalid,
    .fmi2_setup_resets = true,
    .null_log_environment = true,
};
