// tests/fuzz_dispatch.h — one fuzz input through one of refl's text parsers.
//
// The first byte selects the parser (byte % 6): 0 D3D scene, 1 OBJ scene,
// 2 INI, 3 materials, 4 lamps, 5 sensor; the rest of the input is the text
// (not NUL-terminated, so reads past its end are caught by AddressSanitizer).
// Used by the libFuzzer target (tests/fuzz_parsers.c) and by the corpus replay
// test (tests/test_corpus.c).
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "model/model.h"

enum { REFL_FUZZ_D3D, REFL_FUZZ_OBJ, REFL_FUZZ_INI, REFL_FUZZ_MATERIALS, REFL_FUZZ_LAMPS,
       REFL_FUZZ_SENSOR, REFL_FUZZ_NPARSERS };

// Parse the input with the parser its first byte selects, free the result.
// Returns true when the parse succeeded; false (with model_last_error() set)
// when the input was rejected, or false with an error for an empty input.
static inline bool refl_fuzz_parse(const uint8_t *data, size_t len)
{
    if (len == 0) {
        model_error(NULL, 0, "empty fuzz input (the first byte selects the parser)");
        return false;
    }
    const char *text = (const char *)data + 1;
    size_t n = len - 1;
    switch (data[0] % REFL_FUZZ_NPARSERS) {
    case REFL_FUZZ_D3D: {
        model_scene_t *s = model_scene_parse_d3d(text, n, "fuzz.d3d", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_OBJ: {
        model_scene_t *s = model_scene_parse_obj(text, n, "fuzz.obj", NULL);
        model_scene_free(s);
        return s != NULL;
    }
    case REFL_FUZZ_INI: {
        model_ini_t *ini = model_ini_parse(text, n, "fuzz.ini");
        model_ini_free(ini);
        return ini != NULL;
    }
    case REFL_FUZZ_MATERIALS: {
        model_materials_t *m = model_materials_parse(text, n, "fuzz-materials.ini");
        model_materials_free(m);
        return m != NULL;
    }
    case REFL_FUZZ_LAMPS: {
        model_lamps_t *l = model_lamps_parse(text, n, "fuzz-lamps.ini");
        model_lamps_free(l);
        return l != NULL;
    }
    default: {
        model_sensor_t s;
        return model_sensor_parse(text, n, "fuzz-sensor.ini", &s);
    }
    }
}

static inline void refl_fuzz_one(const uint8_t *data, size_t len)
{
    (void)refl_fuzz_parse(data, len);
}
