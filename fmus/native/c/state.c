/* FMU state of the native FMUs: a snapshot of an instance taken, restored and freed, and its serialized form
 * (format 2: magic, version, byte-order mark, size, the model's token, FMI version and interface, an FNV-1a
 * checksum), each refused with a logged reason when it is not this model's, this FMI version's and this
 * interface's. The FMI 2 and 3 glue (fmi2Functions.c, fmi3Functions.c) call these; the rest of the runtime is
 * runtime.c. */
#include <stdint.h>
#include <string.h>

#include "runtime.h"

/* ------------------------------------------------------------------ FMU state */

/* What determines the future outputs: the values (every variable: parameters, inputs, the outputs of the last
 * update, the continuous states of model exchange), the internal state, time, t_last and the flags. Not saved: the
 * scratch after values[MODEL_N_VARIABLES] (the parameter-only constants, which model.c computes again after a
 * restore, bit for bit from the bits of the parameters the snapshot restores: a cache, not a state), the
 * detail of the last failed check (written before it is printed), and the instance's settings (name, logger,
 * logging, eventModeUsed). */
struct Snapshot {
    uint64_t magic;             /* SNAPSHOT_MAGIC while the snapshot lives, 0 once freed */
    char token[RT_TOKEN_SIZE];  /* of the model it was taken from (MODEL_TOKEN, NUL-padded) */
    int fmi_version, is_me;     /* of the instance it was taken from */
    double time, t_last;
    int dirty, started, failed;
    int last_check[N_CALLS];
    double data[];              /* values[MODEL_N_VARIABLES], then state[MODEL_N_STATES] */
};

#define N_DATA (MODEL_N_VARIABLES + MODEL_N_STATES)
#define SNAPSHOT_MAGIC 0x50414E53544C4544ull   /* "DELTSNAP" in little-endian byte order */

static const char *kind_name(int is_me) { return is_me ? "model exchange" : "co-simulation"; }

/* 1 when `s` is a live snapshot of this model and build (the token) and, with `same_kind`, was taken from an
 * instance of this FMI version and interface; otherwise 0, logged naming what differs. */
static int snapshot_ok(Instance *inst, const Snapshot *s, int same_kind, const char *function)
{
    if (!s) {
        rt_log(inst, RT_ERROR, "%s: the FMU state is NULL", function);
        return 0;
    }
    if (s->magic != SNAPSHOT_MAGIC) {
        rt_log(inst, RT_ERROR, "%s: %p is not an FMU state of a native delta FMU (or it was freed)", function,
               (const void *)s);
        return 0;
    }
    if (memcmp(s->token, inst->token, RT_TOKEN_SIZE) != 0) {
        rt_log(inst, RT_ERROR, "%s: the FMU state is of another model or build: token %.*s, model %s expects %s",
               function, RT_TOKEN_SIZE - 1, s->token, MODEL_IDENTIFIER, inst->token);
        return 0;
    }
    if (same_kind && s->fmi_version != inst->fmi_version) {
        rt_log(inst, RT_ERROR, "%s: the FMU state was taken by the FMI %d build of %s, this is the FMI %d build",
               function, s->fmi_version, MODEL_IDENTIFIER, inst->fmi_version);
        return 0;
    }
    if (same_kind && s->is_me != inst->is_me) {
        rt_log(inst, RT_ERROR, "%s: the FMU state was taken from a %s instance, this is a %s instance", function,
               kind_name(s->is_me), kind_name(inst->is_me));
        return 0;
    }
    return 1;
}

RtStatus rt_get_snapshot(Instance *inst, Snapshot **snapshot, const char *function)
{
    Snapshot *s;
    size_t i;
    if (!snapshot) {
        rt_log(inst, RT_ERROR, "%s: FMUstate is NULL, no place to return the state in", function);
        return RT_ERROR;
    }
    s = *snapshot;
    if (s && !snapshot_ok(inst, s, 0, function)) return RT_ERROR;   /* reused: one of this model's */
    if (!s) {
        s = (Snapshot *)inst->alloc(1, sizeof(Snapshot) + N_DATA * sizeof(double));
        if (!s) {
            rt_log(inst, RT_ERROR, "%s: out of memory for an FMU state", function);
            return RT_ERROR;
        }
        s->magic = SNAPSHOT_MAGIC;
        memcpy(s->token, inst->token, RT_TOKEN_SIZE);
    }
    s->fmi_version = inst->fmi_version;
    s->is_me = inst->is_me;
    s->time = inst->time;
    s->t_last = inst->t_last;
    s->dirty = inst->dirty;
    s->started = inst->started;
    s->failed = inst->failed;
    for (i = 0; i < N_CALLS; i++) s->last_check[i] = inst->last_check[i];
    memcpy(s->data, inst->values, MODEL_N_VARIABLES * sizeof(double));
    if (MODEL_N_STATES) memcpy(s->data + MODEL_N_VARIABLES, inst->state, MODEL_N_STATES * sizeof(double));
    *snapshot = s;
    return RT_OK;
}

/* The mode stays the instance's (FMI 2.0 section 2.1.8 allows get and set in every state after instantiation; the
 * importer's calling sequence keeps its mode, e.g. a master rolling back in step mode). A state taken before the
 * model started (before initialization ended) set into an instance past initialization starts from its values
 * now, as exitInitializationMode would have; a state taken after set into an instance in initialization keeps its
 * motion through exitInitializationMode (a parameter set there afterwards starts the model again from its start
 * values, as any change of a parameter in initialization does). Model exchange: time and continuous states are the
 * state's until the importer sets its own (setTime, setContinuousStates). */
RtStatus rt_set_snapshot(Instance *inst, const Snapshot *s, const char *function)
{
    size_t i;
    if (!snapshot_ok(inst, s, 1, function)) return RT_ERROR;
    inst->time = s->time;
    inst->t_last = s->t_last;
    inst->dirty = s->dirty;
    inst->started = s->started;
    inst->failed = s->failed;
    for (i = 0; i < N_CALLS; i++) inst->last_check[i] = s->last_check[i];
    memcpy(inst->values, s->data, MODEL_N_VARIABLES * sizeof(double));
    rt_constants_stale(inst);  /* the snapshot's parameters may differ */
    inst->outputs_stale = inst->is_me && MODEL_ME_OUTPUTS;  /* its outputs may be older than its states */
    if (MODEL_N_STATES) memcpy(inst->state, s->data + MODEL_N_VARIABLES, MODEL_N_STATES * sizeof(double));
    if (!inst->started && !(inst->mode & (MODE_INSTANTIATED | MODE_INITIALIZATION))) {
        if (rt_update(inst) != RT_OK) {
            inst->failed = 1;
            return RT_ERROR;
        }
        inst->t_last = inst->time;
    }
    return RT_OK;
}

RtStatus rt_free_snapshot(Instance *inst, Snapshot **snapshot, const char *function)
{
    if (!snapshot || !*snapshot) return RT_OK;   /* FMI: a NULL state is ignored */
    if (!snapshot_ok(inst, *snapshot, 0, function)) return RT_ERROR;   /* not ours to free */
    (*snapshot)->magic = 0;
    inst->free(*snapshot);
    *snapshot = NULL;
    return RT_OK;
}

/* Serialized layout (format 2; integers and doubles in the machine's byte order, which the byte-order mark tells):
 *
 *   offset  bytes              field
 *        0  8                  magic "DLTSTATE"
 *        8  4   uint32         format version (FORMAT_VERSION)
 *       12  4   uint32         byte-order mark 0x01020304
 *       16  8   uint64         size of the whole record in bytes (this layout, checksum included)
 *       24  64  char[64]       the model's token (MODEL_TOKEN: FMI 2 guid / FMI 3 instantiationToken), NUL-padded
 *       88  4   uint32         FMI version of the instance it was taken from (2 or 3)
 *       92  4   uint32         its interface: 0 co-simulation, 1 model exchange
 *       96  4   uint32         MODEL_N_VARIABLES
 *      100  4   uint32         MODEL_N_STATES
 *      104  12  int32[3]       dirty, started, failed
 *      116  20  int32[N_CALLS] last result of each model function
 *      136  8   double         time
 *      144  8   double         t_last
 *      152  8 n double         values[MODEL_N_VARIABLES], then state[MODEL_N_STATES]  (n = their sum)
 * 152 + 8n  8   uint64         FNV-1a 64 of every byte before it
 */
#define FORMAT_VERSION 2u
#define BYTE_ORDER_MARK 0x01020304u
#define AT_VERSION 8
#define AT_ORDER 12
#define AT_SIZE 16
#define AT_TOKEN 24
#define AT_FMI (AT_TOKEN + RT_TOKEN_SIZE)
#define AT_KIND (AT_FMI + 4)
#define AT_N_VARIABLES (AT_KIND + 4)
#define AT_N_STATES (AT_N_VARIABLES + 4)
#define AT_FLAGS (AT_N_STATES + 4)
#define AT_CHECKS (AT_FLAGS + 3 * 4)
#define AT_TIME (AT_CHECKS + N_CALLS * 4)
#define AT_T_LAST (AT_TIME + 8)
#define AT_DATA (AT_T_LAST + 8)
static const char FORMAT_MAGIC[8] = { 'D', 'L', 'T', 'S', 'T', 'A', 'T', 'E' };

size_t rt_serialized_size(void)
{
    return AT_DATA + N_DATA * sizeof(double) + sizeof(uint64_t);
}

static uint64_t fnv1a(const unsigned char *bytes, size_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= bytes[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

static void put_u32(unsigned char *bytes, size_t at, uint32_t v) { memcpy(bytes + at, &v, sizeof v); }
static void put_i32(unsigned char *bytes, size_t at, int v) { int32_t w = (int32_t)v; memcpy(bytes + at, &w, sizeof w); }
static uint32_t get_u32(const unsigned char *bytes, size_t at) { uint32_t v; memcpy(&v, bytes + at, sizeof v); return v; }
static int get_i32(const unsigned char *bytes, size_t at) { int32_t v; memcpy(&v, bytes + at, sizeof v); return (int)v; }

RtStatus rt_serialize(Instance *inst, const Snapshot *s, unsigned char *bytes, size_t size, const char *function)
{
    const size_t n = rt_serialized_size();
    uint64_t total = n, sum;
    size_t i;
    if (!snapshot_ok(inst, s, 0, function)) return RT_ERROR;
    if (!bytes || size != n) {
        rt_log(inst, RT_ERROR, "%s: a serialized FMU state of %s takes %lu bytes, got %s%lu", function,
               MODEL_IDENTIFIER, (unsigned long)n, bytes ? "" : "no buffer, size ", (unsigned long)size);
        return RT_ERROR;
    }
    memset(bytes, 0, n);
    memcpy(bytes, FORMAT_MAGIC, sizeof FORMAT_MAGIC);
    put_u32(bytes, AT_VERSION, FORMAT_VERSION);
    put_u32(bytes, AT_ORDER, BYTE_ORDER_MARK);
    memcpy(bytes + AT_SIZE, &total, sizeof total);
    memcpy(bytes + AT_TOKEN, s->token, RT_TOKEN_SIZE);
    put_u32(bytes, AT_FMI, (uint32_t)s->fmi_version);
    put_u32(bytes, AT_KIND, (uint32_t)s->is_me);
    put_u32(bytes, AT_N_VARIABLES, (uint32_t)MODEL_N_VARIABLES);
    put_u32(bytes, AT_N_STATES, (uint32_t)MODEL_N_STATES);
    put_i32(bytes, AT_FLAGS, s->dirty);
    put_i32(bytes, AT_FLAGS + 4, s->started);
    put_i32(bytes, AT_FLAGS + 8, s->failed);
    for (i = 0; i < N_CALLS; i++) put_i32(bytes, AT_CHECKS + 4 * i, s->last_check[i]);
    memcpy(bytes + AT_TIME, &s->time, sizeof(double));
    memcpy(bytes + AT_T_LAST, &s->t_last, sizeof(double));
    memcpy(bytes + AT_DATA, s->data, N_DATA * sizeof(double));
    sum = fnv1a(bytes, n - sizeof sum);
    memcpy(bytes + n - sizeof sum, &sum, sizeof sum);
    return RT_OK;
}

RtStatus rt_deserialize(Instance *inst, const unsigned char *bytes, size_t size, Snapshot **snapshot,
                        const char *function)
{
    const size_t n = rt_serialized_size();
    uint64_t total, stored, computed;
    char token[RT_TOKEN_SIZE];
    Snapshot *s;
    size_t i;
    if (!snapshot) {
        rt_log(inst, RT_ERROR, "%s: FMUstate is NULL, no place to return the state in", function);
        return RT_ERROR;
    }
    if (!bytes || size < AT_DATA + sizeof(uint64_t)) {
        rt_log(inst, RT_ERROR, "%s: %lu bytes%s are too few for a serialized FMU state (one of %s takes %lu bytes)",
               function, (unsigned long)size, bytes ? "" : " (NULL)", MODEL_IDENTIFIER, (unsigned long)n);
        return RT_ERROR;
    }
    if (memcmp(bytes, FORMAT_MAGIC, sizeof FORMAT_MAGIC) != 0) {
        rt_log(inst, RT_ERROR, "%s: the bytes are not a serialized FMU state of a native delta FMU (no \"DLTSTATE\" "
               "magic)", function);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_VERSION) != FORMAT_VERSION) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state has format version %lu, this FMU reads version %u",
               function, (unsigned long)get_u32(bytes, AT_VERSION), FORMAT_VERSION);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_ORDER) != BYTE_ORDER_MARK) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state was written on a machine of another byte order",
               function);
        return RT_ERROR;
    }
    memcpy(token, bytes + AT_TOKEN, RT_TOKEN_SIZE);
    token[RT_TOKEN_SIZE - 1] = '\0';
    if (memcmp(bytes + AT_TOKEN, inst->token, RT_TOKEN_SIZE) != 0) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is of another model or build: token %s (%lu bytes), "
               "model %s expects %s (%lu bytes)", function, token, (unsigned long)size, MODEL_IDENTIFIER,
               inst->token, (unsigned long)n);
        return RT_ERROR;
    }
    memcpy(&total, bytes + AT_SIZE, sizeof total);
    if (size != n || total != n) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is %lu bytes and its header says %llu, a state of %s "
               "takes %lu bytes (truncated or corrupted)", function, (unsigned long)size, (unsigned long long)total,
               MODEL_IDENTIFIER, (unsigned long)n);
        return RT_ERROR;
    }
    memcpy(&stored, bytes + n - sizeof stored, sizeof stored);
    computed = fnv1a(bytes, n - sizeof stored);
    if (stored != computed) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state is corrupted: checksum %016llx, its bytes give %016llx",
               function, (unsigned long long)stored, (unsigned long long)computed);
        return RT_ERROR;
    }
    if (get_u32(bytes, AT_N_VARIABLES) != MODEL_N_VARIABLES || get_u32(bytes, AT_N_STATES) != MODEL_N_STATES) {
        rt_log(inst, RT_ERROR, "%s: the serialized FMU state has %lu variables and %lu states, %s has %lu and %lu",
               function, (unsigned long)get_u32(bytes, AT_N_VARIABLES), (unsigned long)get_u32(bytes, AT_N_STATES),
               MODEL_IDENTIFIER, (unsigned long)MODEL_N_VARIABLES, (unsigned long)MODEL_N_STATES);
        return RT_ERROR;
    }
    s = (Snapshot *)inst->alloc(1, sizeof(Snapshot) + N_DATA * sizeof(double));   /* always a new one */
    if (!s) {
        rt_log(inst, RT_ERROR, "%s: out of memory for an FMU state", function);
        return RT_ERROR;
    }
    s->magic = SNAPSHOT_MAGIC;
    memcpy(s->token, bytes + AT_TOKEN, RT_TOKEN_SIZE);
    s->fmi_version = (int)get_u32(bytes, AT_FMI);
    s->is_me = (int)get_u32(bytes, AT_KIND);
    s->dirty = get_i32(bytes, AT_FLAGS);
    s->started = get_i32(bytes, AT_FLAGS + 4);
    s->failed = get_i32(bytes, AT_FLAGS + 8);
    for (i = 0; i < N_CALLS; i++) s->last_check[i] = get_i32(bytes, AT_CHECKS + 4 * i);
    memcpy(&s->time, bytes + AT_TIME, sizeof(double));
    memcpy(&s->t_last, bytes + AT_T_LAST, sizeof(double));
    memcpy(s->data, bytes + AT_DATA, N_DATA * sizeof(double));
    if (!snapshot_ok(inst, s, 1, function)) {   /* another FMI version or interface */
        s->magic = 0;
        inst->free(s);
        return RT_ERROR;
    }
    *snapshot = s;
    return RT_OK;
}
