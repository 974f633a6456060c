/*
 * core.h - the FMI-version-independent half of the test FMUs: the instance,
 * its mode, variable access through the generated table, the model exchange
 * bookkeeping and the co-simulation stepper (fixed-step RK4 with events).
 *
 * The wrappers (fmi2_wrapper.c, fmi3_wrapper.c) translate the C API of their
 * FMI version into these calls; they own no model logic.
 */
#ifndef CFMU_CORE_H
#define CFMU_CORE_H

#include <stdarg.h>

#include "model.h"

/* Internal step of the co-simulation integrator, s. Steps are shortened to
   land on communication points and time events; state events are located by
   bisection inside a step. */
#define CS_FIXED_STEP 1e-3

typedef enum { IF_MODEL_EXCHANGE, IF_CO_SIMULATION } Interface;

/* Modes of the FMI 2 and FMI 3 state machines (bit flags for "allowed in").
   M_STEP is FMI 2 "step complete" and FMI 3 "step mode". */
typedef enum {
    M_INSTANTIATED = 1 << 0,
    M_CONFIGURATION = 1 << 1,
    M_INITIALIZATION = 1 << 2,
    M_EVENT = 1 << 3,
    M_CONTINUOUS = 1 << 4,
    M_STEP = 1 << 5,
    M_STEP_FAILED = 1 << 6,
    M_TERMINATED = 1 << 7,
    M_ERROR = 1 << 8
} Mode;

#define M_AFTER_INIT (M_EVENT | M_CONTINUOUS | M_STEP | M_STEP_FAILED | M_TERMINATED)

/* Where a log message goes: the wrapper forwards it to the importer. */
typedef void (*LogSink)(void *env, const char *instance_name, Status status, const char *category,
                        const char *message);

typedef enum { STEP_DONE, STEP_TERMINATED, STEP_REJECTED, STEP_FAILED } StepOutcome;

typedef struct {
    int fmi_version;
    Interface iface;
    Mode mode;
    char *name;
    LogSink sink;
    void *sink_env;
    bool logging_on;

    void *data;       /* the model's ModelData */
    bool dirty;       /* outputs must be recomputed before the next read */

    double time;
    bool stop_defined;
    double stop_time;
    bool next_time_defined;
    double next_time;
    bool terminate_requested;   /* the model asked to end the simulation */
    double last_successful_time;
    bool early_return_allowed;  /* FMI 3 co-simulation */

    /* sizes fixed at the end of initialisation, and the stepper's scratch */
    size_t nx, nz;
    double *x, *x_start, *x_try, *k, *z_start, *z_try;
} Instance;

Instance *core_new(int fmi_version, Interface iface, const char *name, LogSink sink, void *env, bool logging_on);
void core_free(Instance *in);
void core_log(Instance *in, Status status, const char *category, const char *format, ...);
void core_debug(Instance *in, const char *format, ...);

/* Logs an error naming fn and returns false if the instance is not in one of modes. */
bool core_allowed(Instance *in, const char *fn, unsigned modes);
Status core_fail(Instance *in, const char *fn, const char *format, ...);

Status core_enter_initialization(Instance *in, double start_time, bool stop_defined, double stop_time);
Status core_exit_initialization(Instance *in);
Status core_reset(Instance *in);

/* Variable access. core_lookup logs and returns NULL for an unknown value
   reference or a variable whose type is not in accepted. */
const VarInfo *core_lookup(Instance *in, const char *fn, unsigned vr, unsigned accepted);
size_t core_length(const Instance *in, const VarInfo *v);
void *core_element(Instance *in, const VarInfo *v);
bool core_can_set(Instance *in, const char *fn, const VarInfo *v);
Status core_after_set(Instance *in, const char *fn, const VarInfo *v, const void *old_value);
void core_update(Instance *in);
Status core_count_error(Instance *in, const char *fn, size_t given, size_t needed);

/* Model exchange. */
size_t core_n_states(const Instance *in);
size_t core_n_indicators(const Instance *in);
Status core_set_time(Instance *in, double t);
Status core_states(Instance *in, const char *fn, double *x, size_t n, bool set);
Status core_derivatives(Instance *in, const char *fn, double *dx, size_t n);
Status core_indicators(Instance *in, const char *fn, double *z, size_t n);
Status core_nominals(Instance *in, const char *fn, double *nominal, size_t n);
void core_event_update(Instance *in, EventUpdate *ev);

/* FMU state, as the Modelica Reference FMUs keep it (their cosimulation.c getFMUState / setFMUState and
   fmi2Functions.c): a state is a copy of the instance followed by a copy of the model's data; setting it copies
   back what the simulation depends on (time, mode, pending events, the model's data), not the name, the
   callbacks or the scratch arrays; serialized, it is those bytes, and de-serializing checks only their size.
   Built in only when the model declares state (compile with -DCFMU_FMU_STATE=1, from models.py); otherwise the
   wrappers return an error, as modelDescription.xml announces. */
#ifndef CFMU_FMU_STATE
#define CFMU_FMU_STATE 0
#endif
size_t core_state_size(void);
Status core_get_state(Instance *in, const char *fn, void **state);
Status core_set_state(Instance *in, const char *fn, const void *state);
void core_free_state(void **state);
Status core_serialize_state(Instance *in, const char *fn, const void *state, unsigned char *bytes, size_t size);
Status core_deserialize_state(Instance *in, const char *fn, const unsigned char *bytes, size_t size, void **state);

/* Co-simulation: one communication step from t to t + h. On STEP_TERMINATED
   the model asked to stop at *t_end (< t + h possibly); on STEP_REJECTED
   nothing changed and the reason was logged. */
StepOutcome core_do_step(Instance *in, double t, double h, double *t_end, bool *event);

#endif
