/* A bare FMI 2.0 co-simulation host that makes no call after fmi2Instantiate from the thread that loaded the FMU.
 *
 * FMI 2.0 lets a host call an instance from any thread as long as the calls do not overlap; OSP libcosim
 * steps FMUs from its worker threads. Two ways of it, chosen by MODE:
 *   worker  one thread, started after fmi2Instantiate, makes every later call (libcosim's way: a worker
 *           thread that Python did not start and that calls again and again);
 *   fresh   each later call (setupExperiment, enterInitializationMode, exitInitializationMode, every doStep,
 *           the final getReal) runs on a thread of its own, started and joined in turn.
 * Calls never overlap in either mode.
 *
 *   thread_host MODE BINARY GUID RESOURCE_URI STEPS STEP_SIZE VR [VR ...]
 *
 * prints the Reals VR... after STEPS steps from t = 0, one per line (%.17g), and exits 0; a status worse
 * than fmi2Warning exits 1 naming the call and the time. The host links no Python: a PythonFMU's binary
 * needs libpython loaded by the host process (LD_PRELOAD), as in any C host.
 */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *(*Instantiate)(const char *, int, const char *, const char *, const void *, int, int);
typedef int (*SetupExperiment)(void *, int, double, double, int, double);
typedef int (*Instance)(void *);
typedef int (*DoStep)(void *, double, double, int);
typedef int (*GetReal)(void *, const unsigned int *, size_t, double *);

enum Call { SETUP, ENTER, EXIT, STEP, GET };
static const char *NAMES[] = {"fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
                              "fmi2DoStep", "fmi2GetReal"};

static void logger(void *env, const char *name, int status, const char *category, const char *message, ...) {
    (void)env; (void)status; (void)category;
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%s] ", name);
    vfprintf(stderr, message, args);
    fputc('\n', stderr);
    va_end(args);
}

static struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *allocate, *free, *step_finished, *env;
} callbacks;

typedef struct {
    void *lib, *instance;
    enum Call call;
    int fresh;               /* 1: each call on a new thread */
    long steps;
    double t, h;
    unsigned int *vrs;
    size_t n;
    double *values;
} Host;

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) { fprintf(stderr, "thread_host: %s not found\n", name); exit(1); }
    return f;
}

static void *make_call(void *arg) {
    Host *h = arg;
    int status;
    switch (h->call) {
    case SETUP: status = ((SetupExperiment)sym(h->lib, NAMES[SETUP]))(h->instance, 0, 0.0, 0.0, 0, 0.0); break;
    case ENTER: status = ((Instance)sym(h->lib, NAMES[ENTER]))(h->instance); break;
    case EXIT: status = ((Instance)sym(h->lib, NAMES[EXIT]))(h->instance); break;
    case STEP: status = ((DoStep)sym(h->lib, NAMES[STEP]))(h->instance, h->t, h->h, 1); break;
    default: status = ((GetReal)sym(h->lib, NAMES[GET]))(h->instance, h->vrs, h->n, h->values); break;
    }
    if (status > 1) {  /* worse than fmi2Warning */
        fprintf(stderr, "thread_host: %s returned status %d at t = %g\n", NAMES[h->call], status, h->t);
        exit(1);
    }
    return NULL;
}

static void run_thread(void *(*body)(void *), Host *h) {
    pthread_t thread;
    if (pthread_create(&thread, NULL, body, h) != 0 || pthread_join(thread, NULL) != 0) {
        fprintf(stderr, "thread_host: could not run a thread\n");
        exit(1);
    }
}

static void call(Host *h, enum Call c) {
    h->call = c;
    if (h->fresh) run_thread(make_call, h);
    else make_call(h);
}

static void *session(void *arg) {
    Host *h = arg;
    call(h, SETUP);
    call(h, ENTER);
    call(h, EXIT);
    for (long k = 0; k < h->steps; k++) {
        h->t = (double)k * h->h;
        call(h, STEP);
    }
    call(h, GET);
    return NULL;
}

int main(int argc, char **argv) {
    if (argc < 8 || (strcmp(argv[1], "worker") != 0 && strcmp(argv[1], "fresh") != 0)) {
        fprintf(stderr, "usage: thread_host worker|fresh BINARY GUID RESOURCE_URI STEPS STEP_SIZE VR [VR ...]\n");
        return 2;
    }
    Host h = {0};
    h.fresh = strcmp(argv[1], "fresh") == 0;
    h.lib = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (!h.lib) { fprintf(stderr, "thread_host: %s\n", dlerror()); return 1; }
    callbacks.logger = logger;
    callbacks.allocate = (void *)calloc;
    callbacks.free = (void *)free;
    h.instance = ((Instantiate)sym(h.lib, "fmi2Instantiate"))("host", 1, argv[3], argv[4], &callbacks, 0, 0);
    if (!h.instance) { fprintf(stderr, "thread_host: fmi2Instantiate failed\n"); return 1; }
    h.steps = atol(argv[5]);
    h.h = atof(argv[6]);
    h.n = (size_t)(argc - 7);
    h.vrs = calloc(h.n, sizeof *h.vrs);
    h.values = calloc(h.n, sizeof *h.values);
    for (size_t i = 0; i < h.n; i++) h.vrs[i] = (unsigned int)strtoul(argv[7 + i], NULL, 10);
    if (h.fresh) session(&h);         /* session() starts a thread per call */
    else run_thread(session, &h);     /* one worker thread makes every call */
    for (size_t i = 0; i < h.n; i++) printf("%.17g\n", h.values[i]);
    ((Instance)sym(h.lib, "fmi2Terminate"))(h.instance);
    ((void (*)(void *))sym(h.lib, "fmi2FreeInstance"))(h.instance);
    return 0;
}
