/* The log writer's sample join (see cosim/observers/log_writer.py, encode_samples), compiled by
 * cosim/cbuild.py: one pass in C over the numbers orjson wrote instead of a Python object per number. */
#include <stddef.h>
#include <string.h>

/* The log writer's messages of a block of samples in the samples layout (cosim/observers/log_writer.py,
 * encode_samples): the block's times and values as orjson wrote them, two JSON arrays (times: n
 * elements; values: n * width, sample after sample) whose elements are numbers, true, false or null,
 * none holding a comma, joined with the channel's joints (the bytes before the time, between the
 * values, after the last value: width + 2 of them, back to back in joints, joint j ending at
 * ends[j]). An element e of a sample whose fmi2[e] is set is an FMI 2 Boolean (a C int): 0 is written
 * false, anything else true. The messages go to out one after the other, '\n' between them (orjson
 * writes none: a JSON string escapes it); out holds at least times_len + values_len + n * (ends[width
 * + 1] + 1 + 4 * width) bytes. Returns the bytes written, or -1 when the arrays do not hold n and
 * n * width elements. */
ptrdiff_t cosim_samples(const char *times, size_t times_len, const char *values, size_t values_len, size_t n,
                        size_t width, const char *joints, const size_t *ends, const unsigned char *fmi2, char *out)
{
    if (times_len < 2 || values_len < 2)
        return -1;
    const char *t = times + 1, *t_end = times + times_len - 1;  /* inside the brackets */
    const char *v = values + 1, *v_end = values + values_len - 1;
    char *o = out;
    for (size_t k = 0; k < n; k++) {
        if (k > 0)
            *o++ = '\n';
        if (t >= t_end)
            return -1;
        memcpy(o, joints, ends[0]);
        o += ends[0];
        const char *comma = memchr(t, ',', (size_t)(t_end - t));
        const char *end = comma ? comma : t_end;
        memcpy(o, t, (size_t)(end - t));
        o += end - t;
        t = comma ? comma + 1 : t_end;
        for (size_t e = 0; e < width; e++) {
            if (v >= v_end)
                return -1;
            memcpy(o, joints + ends[e], ends[e + 1] - ends[e]);
            o += ends[e + 1] - ends[e];
            comma = memchr(v, ',', (size_t)(v_end - v));
            end = comma ? comma : v_end;
            if (fmi2[e]) {
                int zero = end - v == 1 && *v == '0';
                memcpy(o, zero ? "false" : "true", zero ? 5 : 4);
                o += zero ? 5 : 4;
            } else {
                memcpy(o, v, (size_t)(end - v));
                o += end - v;
            }
            v = comma ? comma + 1 : v_end;
        }
        memcpy(o, joints + ends[width], ends[width + 1] - ends[width]);
        o += ends[width + 1] - ends[width];
    }
    if (t < t_end || v < v_end)
        return -1;
    return o - out;
}
