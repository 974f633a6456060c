/*
 * StateSpace - a linear system whose sizes are structural parameters:
 *
 *   der(x) = A x + B u,   y = C x + D u + offset,   x(t0) = x0
 *
 * with n states, m inputs and r outputs (m, n, r: UInt64 structural
 * parameters, 3 by default). A is n x n, B n x m, C r x n, D r x m, all in
 * row-major order as FMI 3 serialises arrays. offset has the fixed size 3 and
 * is added to the first min(r, 3) outputs. Changing a size re-allocates the
 * arrays and refills them with the defaults below for the new size: a stable
 * A (negative diagonal plus an antisymmetric band, so A + A^T < 0), B = I,
 * C = I plus a superdiagonal of 0.5, D = 0.1 I, x0 = (1, 2, ..., n) and
 * u = (1, -0.5, 1, -0.5, ...).
 */
#include <stdlib.h>

#include "model.h"

/* largest size accepted for m, n and r */
#define MAX_SIZE 1000

typedef struct {
    uint64_t m, n, r;
    double *A, *B, *C, *D, *x0, *u, *y, *x, *der_x;
    double offset[3];
} ModelData;

#include "variables.h"

static void release(void *p)
{
    ModelData *d = p;
    double **arrays[] = {&d->A, &d->B, &d->C, &d->D, &d->x0, &d->u, &d->y, &d->x, &d->der_x};
    for (size_t i = 0; i < sizeof arrays / sizeof arrays[0]; i++) {
        free(*arrays[i]);
        *arrays[i] = NULL;
    }
}

static bool valid(uint64_t size) { return size >= 1 && size <= MAX_SIZE; }

static bool resize(void *p)
{
    ModelData *d = p;
    size_t m = d->m, n = d->n, r = d->r;
    if (!valid(d->m) || !valid(d->n) || !valid(d->r)) return false;
    release(d);
    d->A = calloc(n * n, sizeof(double));
    d->B = calloc(n * m, sizeof(double));
    d->C = calloc(r * n, sizeof(double));
    d->D = calloc(r * m, sizeof(double));
    d->x0 = calloc(n, sizeof(double));
    d->u = calloc(m, sizeof(double));
    d->y = calloc(r, sizeof(double));
    d->x = calloc(n, sizeof(double));
    d->der_x = calloc(n, sizeof(double));
    if (!d->A || !d->B || !d->C || !d->D || !d->x0 || !d->u || !d->y || !d->x || !d->der_x) {
        release(d);
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        d->A[i * n + i] = -1.0 - 0.5 * (double)i;
        if (i + 1 < n) d->A[i * n + i + 1] = 0.5;
        if (i > 0) d->A[i * n + i - 1] = -0.5;
        if (i < m) d->B[i * m + i] = 1.0;
        d->x0[i] = (double)(i + 1);
    }
    for (size_t i = 0; i < r; i++) {
        if (i < n) d->C[i * n + i] = 1.0;
        if (i + 1 < n) d->C[i * n + i + 1] = 0.5;
        if (i < m) d->D[i * m + i] = 0.1;
    }
    for (size_t j = 0; j < m; j++) d->u[j] = j % 2 ? -0.5 : 1.0;
    return true;
}

static void defaults(void *p)
{
    ModelData *d = p;
    d->m = d->n = d->r = 3;
    d->offset[0] = 0.1;
    d->offset[1] = 0.2;
    d->offset[2] = 0.3;
    resize(d);
}

static void initialize(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    for (size_t i = 0; i < d->n; i++) d->x[i] = d->x0[i];
}

static size_t n_states(const void *p)
{
    return ((const ModelData *)p)->n;
}

static void get_states(const void *p, double *x)
{
    const ModelData *d = p;
    for (size_t i = 0; i < d->n; i++) x[i] = d->x[i];
}

static void set_states(void *p, const double *x)
{
    ModelData *d = p;
    for (size_t i = 0; i < d->n; i++) d->x[i] = x[i];
}

static void nominals(const void *p, double *nominal)
{
    const ModelData *d = p;
    for (size_t i = 0; i < d->n; i++) nominal[i] = 1.0;
}

/* out (rows x 1) = M1 v1 + M2 v2 for row-major M1 (rows x n1), M2 (rows x n2) */
static void affine(size_t rows, const double *M1, const double *v1, size_t n1, const double *M2, const double *v2,
                   size_t n2, double *out)
{
    for (size_t i = 0; i < rows; i++) {
        double s = 0.0;
        for (size_t j = 0; j < n1; j++) s += M1[i * n1 + j] * v1[j];
        for (size_t j = 0; j < n2; j++) s += M2[i * n2 + j] * v2[j];
        out[i] = s;
    }
}

static void derivatives(const void *p, double t, double *dx)
{
    const ModelData *d = p;
    (void)t;
    affine(d->n, d->A, d->x, d->n, d->B, d->u, d->m, dx);
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    derivatives(d, t, d->der_x);
    affine(d->r, d->C, d->x, d->n, d->D, d->u, d->m, d->y);
    for (size_t i = 0; i < d->r && i < 3; i++) d->y[i] += d->offset[i];
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .defaults = defaults,
    .release = release,
    .resize = resize,
    .initialize = initialize,
    .n_states = n_states,
    .get_states = get_states,
    .set_states = set_states,
    .nominals = nominals,
    .derivatives = derivatives,
    .outputs = outputs,
};
