/* The FMU instance shared by the FMI 2.0 and FMI 3.0 entry points (fmi2Functions.c, fmi3Functions.c):
 * variable values, internal state, time, mode and flags, the calls into the model (model.h) with their
 * check results, the co-simulation step with its substeps, and the FMU state snapshots.
 *
 * Each FMI layer embeds Instance as the first member of its own struct (logger and environment) and
 * passes a LogFn that forwards a finished message to the importer's logger.
 */
#ifndef DELTA_RUNTIME_H
#define DELTA_RUNTIME_H

#include <stddef.h>

/* Only the fmi2/fmi3 functions (declared with default visibility by the FMI headers) are exported: the
 * model and runtime symbols of several FMUs loaded into one process must not interpose each other. */
#if defined(__GNUC__) && !defined(_WIN32)
#pragma GCC visibility push(hidden)
#endif

#include "model.h"

/* numerically equal to fmi2Status / fmi3Status */
typedef enum { RT_OK = 0, RT_WARNING = 1, RT_DISCARD = 2, RT_ERROR = 3 } RtStatus;

typedef enum { MODE_INSTANTIATED = 1, MODE_INITIALIZATION = 2, MODE_STEP = 4, MODE_EVENT = 8,
               MODE_CONTINUOUS = 16, MODE_TERMINATED = 32 } Mode;
#define MODES_ANY (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

typedef enum { CALL_START, CALL_REFRESH, CALL_ADVANCE, CALL_DERIVATIVES, CALL_ACCEPT, N_CALLS } ModelCall;

/* Bytes kept of MODEL_TOKEN (NUL-padded) in an instance and in an FMU state; the builds' tokens are 38 characters. */
#define RT_TOKEN_SIZE 64

typedef struct Instance Instance;
typedef void (*LogFn)(Instance *inst, RtStatus status, const char *category, const char *message);
typedef void *(*AllocFn)(size_t n, size_t size);   /* zero-filled, like calloc */
typedef void (*FreeFn)(void *p);

struct Instance {
    double *values;             /* values[MODEL_N_VARIABLES], by value reference; values[0] = time */
    double *state;              /* state[MODEL_N_STATES] */
    double time;
    double t_last;              /* model exchange: time of the last model_advance commit */
    Mode mode;
    int is_me;                  /* model exchange instance (else co-simulation) */
    int fmi_version;            /* 2 or 3: the glue this instance was made by */
    int event_mode_used;        /* FMI 3 co-simulation: exitInitializationMode enters event mode */
    int logging_on;
    int dirty;                  /* an input, parameter, time or state changed: outputs are stale */
    int outputs_stale;          /* model exchange with MODEL_ME_OUTPUTS: the derivatives are current, the outputs
                                   not (model_accept before one is read) */
    int started;                /* model_start ran with the current parameters */
    int failed;                 /* a step failed: no further steps */
    int last_check[N_CALLS];    /* last result of each model function (warnings are logged once) */
    double detail[MODEL_MAX_DETAIL]; /* the values the last failed check's reason prints */
    char *name;
    char token[RT_TOKEN_SIZE];  /* MODEL_TOKEN, NUL-padded: what an FMU state is stamped with */
    const char *const *type_names; /* FMI names of TYPE_REAL, TYPE_BOOLEAN, TYPE_INTEGER, TYPE_STRING */
    LogFn log;
    AllocFn alloc;
    FreeFn free;
};

/* Allocates `size` (>= sizeof(Instance)) zero-filled bytes, the values and state; NULL on failure. */
Instance *rt_new(size_t size, const char *name, int is_me, int fmi_version, const char *const *type_names,
                 AllocFn alloc, FreeFn free_fn, LogFn log);
void rt_free(Instance *inst);
void rt_reset(Instance *inst);    /* back to instantiated, start values, time 0 */

/* "t = %.9g s: <message>" to the importer's logger (OK messages only with logging on). */
void rt_log(Instance *inst, RtStatus status, const char *fmt, ...)
#ifdef __GNUC__
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* 1 when inst is not NULL and its mode is in `modes`; otherwise 0, logged. */
int rt_allowed(Instance *inst, int modes, const char *function);
/* 1 for a model exchange instance (`me` = 1) or a co-simulation one (`me` = 0); otherwise 0, logged. */
int rt_kind(Instance *inst, int me, const char *function);
RtStatus rt_not_supported(Instance *inst, const char *function);

/* Variable access. rt_check_var: vr exists, has `type` and (for_set) may be set now; logged otherwise.
 * rt_get brings the outputs up to date first when they are stale and vr is computed. */
int rt_check_var(Instance *inst, size_t vr, VarType type, int for_set, const char *function);
RtStatus rt_get(Instance *inst, size_t vr, double *value);
void rt_set(Instance *inst, size_t vr, double value);
/* the parameter-only constants to be computed again (a parameter may have changed: see MODEL_N_SCRATCH) */
void rt_constants_stale(Instance *inst);
/* String variables (a closed set of choices, stored as the index of one): the text of the value, or the
 * index of `text` set (an error listing the choices when it is none of them). */
RtStatus rt_get_string(Instance *inst, size_t vr, const char **text, const char *function);
RtStatus rt_set_string(Instance *inst, size_t vr, const char *text, const char *function);
/* Logged error naming vr (and the variable, if it exists) for an access of a type no variable has. */
RtStatus rt_type_error(Instance *inst, size_t vr, const char *type, const char *function);

/* Outputs (and, in model exchange, derivatives) up to date: model_start if needed, then refresh. */
RtStatus rt_update(Instance *inst);
RtStatus rt_exit_initialization(Instance *inst);
/* One co-simulation step; RT_DISCARD (logged) when a check fails, the instance then failed. */
RtStatus rt_do_step(Instance *inst, double t, double h);
/* Model exchange, at a completed integrator step or an event: commit the internal state up to `time`
 * (model_advance when MODEL_ME_ADVANCES), then check the accepted state and, with MODEL_ME_OUTPUTS, compute its
 * outputs (model_accept when MODEL_ME_ACCEPTS). */
RtStatus rt_me_commit(Instance *inst);
void rt_set_time(Instance *inst, double time);
RtStatus rt_get_states(Instance *inst, double *x, size_t nx, const char *function);
RtStatus rt_set_states(Instance *inst, const double *x, size_t nx, const char *function);
RtStatus rt_get_derivatives(Instance *inst, double *dx, size_t nx, const char *function);
RtStatus rt_get_nominals(Instance *inst, double *nominals, size_t nx, const char *function);
RtStatus rt_check_event_indicators(Instance *inst, size_t ni, const char *function);

/* Number of substeps of a step h: Python's max(1, -int(-h // max_step)); 0 (logged) if impossible. */
unsigned long long rt_substeps(Instance *inst, double h);

/* FMU state: a snapshot of the variable values, the internal state, time, t_last and the flags (dirty, started,
 * failed, the last check results), stamped with a magic, the model's token, the FMI version and the interface; the
 * mode is not part of it (the importer's calling sequence keeps it; see rt_set_snapshot in runtime.c). Each call
 * refuses, with RT_ERROR and a logged message, a NULL state and a state of another model, build, FMI version or
 * interface (`function` names the FMI function in the message). */
typedef struct Snapshot Snapshot;
RtStatus rt_get_snapshot(Instance *inst, Snapshot **snapshot, const char *function); /* reuses *snapshot if not NULL */
RtStatus rt_set_snapshot(Instance *inst, const Snapshot *snapshot, const char *function);
RtStatus rt_free_snapshot(Instance *inst, Snapshot **snapshot, const char *function); /* NULL *snapshot: nothing */
size_t rt_serialized_size(void);
RtStatus rt_serialize(Instance *inst, const Snapshot *snapshot, unsigned char *bytes, size_t size,
                      const char *function);
/* A new snapshot from bytes of rt_serialize, checked (format, byte order, token, size, checksum) before use. */
RtStatus rt_deserialize(Instance *inst, const unsigned char *bytes, size_t size, Snapshot **snapshot,
                        const char *function);

#if defined(__GNUC__) && !defined(_WIN32)
#pragma GCC visibility pop
#endif

#endif
