/*
 * Feedthrough - output = input for every variable type, plus a parameter of
 * each type that only stores its value.
 *
 * The FMI 3 build exposes all fields (Float32 ... Enumeration, Binary and a
 * fixed-size Float64 array); the FMI 2 build exposes the Real (Float64),
 * Integer (Int32), Boolean, String and Enumeration ones. String and Binary
 * outputs own a copy of the input, made only when the input changed, so a
 * pointer returned by a getter stays valid until the input is set again.
 */
#include <stdlib.h>
#include <string.h>

#include "model.h"

/* parameter, input and output fields of one type (CTYPE must be one token) */
#define TRIPLE(CTYPE, NAME) CTYPE NAME##_parameter, NAME##_input, NAME##_output

typedef char *CString;

typedef struct {
    TRIPLE(float, Float32);
    TRIPLE(double, Float64);
    TRIPLE(int8_t, Int8);
    TRIPLE(uint8_t, UInt8);
    TRIPLE(int16_t, Int16);
    TRIPLE(uint16_t, UInt16);
    TRIPLE(int32_t, Int32);
    TRIPLE(uint32_t, UInt32);
    TRIPLE(int64_t, Int64);
    TRIPLE(uint64_t, UInt64);
    TRIPLE(bool, Boolean);
    TRIPLE(CString, String);
    TRIPLE(Blob, Binary);
    TRIPLE(int64_t, Enumeration);
    double Float64_array_input[3], Float64_array_output[3];
} ModelData;

#include "variables.h"

static void defaults(void *p)
{
    static const uint8_t parameter_bytes[] = {0x01, 0x02}, input_bytes[] = {0x0a, 0x0b, 0x0c};
    ModelData *d = p;
    d->Float32_parameter = 0.25f;
    d->Float32_input = 1.5f;
    d->Float64_parameter = 0.5;
    d->Float64_input = 2.5;
    d->Int8_parameter = -1;
    d->Int8_input = -8;
    d->UInt8_parameter = 1;
    d->UInt8_input = 8;
    d->Int16_parameter = -2;
    d->Int16_input = -16;
    d->UInt16_parameter = 2;
    d->UInt16_input = 16;
    d->Int32_parameter = -3;
    d->Int32_input = -32;
    d->UInt32_parameter = 3;
    d->UInt32_input = 32;
    d->Int64_parameter = -4;
    d->Int64_input = -64;
    d->UInt64_parameter = 4;
    d->UInt64_input = 64;
    d->Boolean_parameter = true;
    d->Boolean_input = false;
    fmu_copy_string(&d->String_parameter, "parameter");
    fmu_copy_string(&d->String_input, "input");
    fmu_copy_blob(&d->Binary_parameter, parameter_bytes, sizeof parameter_bytes);
    fmu_copy_blob(&d->Binary_input, input_bytes, sizeof input_bytes);
    d->Enumeration_parameter = 2;
    d->Enumeration_input = 1;
    for (int i = 0; i < 3; i++) d->Float64_array_input[i] = i + 1.0;
}

static void release(void *p)
{
    ModelData *d = p;
    free(d->String_parameter);
    free(d->String_input);
    free(d->String_output);
    d->String_parameter = d->String_input = d->String_output = NULL;
    fmu_free_blob(&d->Binary_parameter);
    fmu_free_blob(&d->Binary_input);
    fmu_free_blob(&d->Binary_output);
}

static void outputs(void *p, double t)
{
    ModelData *d = p;
    (void)t;
    d->Float32_output = d->Float32_input;
    d->Float64_output = d->Float64_input;
    d->Int8_output = d->Int8_input;
    d->UInt8_output = d->UInt8_input;
    d->Int16_output = d->Int16_input;
    d->UInt16_output = d->UInt16_input;
    d->Int32_output = d->Int32_input;
    d->UInt32_output = d->UInt32_input;
    d->Int64_output = d->Int64_input;
    d->UInt64_output = d->UInt64_input;
    d->Boolean_output = d->Boolean_input;
    d->Enumeration_output = d->Enumeration_input;
    memcpy(d->Float64_array_output, d->Float64_array_input, sizeof d->Float64_array_output);
    if (!d->String_output || strcmp(d->String_output, d->String_input) != 0)
        fmu_copy_string(&d->String_output, d->String_input);
    if (!d->Binary_output.data || d->Binary_output.size != d->Binary_input.size ||
        memcmp(d->Binary_output.data, d->Binary_input.data, d->Binary_input.size) != 0)
        fmu_copy_blob(&d->Binary_output, d->Binary_input.data, d->Binary_input.size);
}

static void initialize(void *p, double t)
{
    outputs(p, t);
}

const ModelClass MODEL = {
    .data_size = sizeof(ModelData),
    .defaults = defaults,
    .release = release,
    .initialize = initialize,
    .outputs = outputs,
};
