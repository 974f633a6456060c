/* benchmarks/master_overhead.py's bare loop: the FMI 2 calls of Gauss-Seidel macro steps and nothing else (no link
 * copy, no status or NaN check, no clock, no observer): per step and component, its fmi2SetReal (or other set)
 * calls, fmi2DoStep, its get calls, as the master makes them. What a master cannot do with fewer instructions. */
#include <stddef.h>

typedef int (*Exchange)(void *, const unsigned int *, size_t, void *);
typedef int (*DoStep)(void *, double, double, int);

typedef struct {
    void *function;
    void *instance;
    const unsigned int *vrs;
    size_t n;
    void *values;
} Call;

typedef struct {
    void *instance;
    void *do_step;
    size_t n_set, n_get;
    const Call *sets;
    const Call *gets;
} Component;

void bare_steps(const Component *c, size_t n, const double *times, const double *steps, size_t n_steps)
{
    for (size_t j = 0; j < n_steps; j++)
        for (size_t i = 0; i < n; i++) {
            for (size_t e = 0; e < c[i].n_set; e++)
                ((Exchange)c[i].sets[e].function)(c[i].sets[e].instance, c[i].sets[e].vrs, c[i].sets[e].n,
                                                  c[i].sets[e].values);
            ((DoStep)c[i].do_step)(c[i].instance, times[j], steps[j], 1);
            for (size_t e = 0; e < c[i].n_get; e++)
                ((Exchange)c[i].gets[e].function)(c[i].gets[e].instance, c[i].gets[e].vrs, c[i].gets[e].n,
                                                  c[i].gets[e].values);
        }
}
