// tests/gain_json.h — gain.json in the tests: the file of a calibration's
// directory, and a row of the EMVA 1288 datasheet by its symbol and unit.
#pragma once

#include <glib.h>
#include <jansson.h>
#include <string.h>

#include "tests/test.h"

// DIR/gain.json (a failed check when it is missing or not JSON; NULL then).
static inline json_t *gain_json_load(const char *dir)
{
    char *p = g_build_filename(dir, "gain.json", NULL);
    json_t *j = json_load_file(p, 0, NULL);
    CHECK_MSG(j != NULL, "no %s", p);
    g_free(p);
    return j;
}

// The row of rows (a datasheet array) with that symbol and unit, or NULL.
static inline json_t *gain_row(json_t *rows, const char *symbol, const char *unit)
{
    for (size_t i = 0; i < json_array_size(rows); i++) {
        json_t *r = json_array_get(rows, i);
        if (!strcmp(json_string_value(json_object_get(r, "symbol")) ?: "", symbol) &&
            !strcmp(json_string_value(json_object_get(r, "unit")) ?: "", unit))
            return r;
    }
    return NULL;
}

// The value of gain.json's emva1288.datasheet row of that symbol and unit, or NULL.
static inline json_t *gain_sheet_value(json_t *gain, const char *symbol, const char *unit)
{
    return json_object_get(gain_row(json_object_get(json_object_get(gain, "emva1288"), "datasheet"), symbol, unit),
                           "value");
}
