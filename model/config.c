// model/config.c — materials, lamps and sensor files (INI, see model/base/ini.c).
#define _GNU_SOURCE
#include <errno.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

#define NAME_MAX_ 64   // size of the name fields, NUL included

// Split a section header "kind NAME" (blanks already collapsed by the INI
// reader). Copies the kind into kind[] and returns the name ("" if none).
static const char *split_section(const char *sec, char *kind, size_t kind_size)
{
    const char *sp = strchr(sec, ' ');
    size_t n = sp ? (size_t)(sp - sec) : strlen(sec);
    if (n >= kind_size) n = kind_size - 1;
    memcpy(kind, sec, n);
    kind[n] = 0;
    return sp ? sp + 1 : "";
}

// Check and copy "[kind NAME]"'s name. false with a message on error.
static bool section_name(const model_ini_t *ini, int s, const char *want_kind, char out[NAME_MAX_])
{
    int line = ini->section_lines[s];
    const char *sec = ini->sections[s];
    char kind[32];
    const char *name = split_section(sec, kind, sizeof kind);
    if (strcmp(kind, want_kind)) {
        model_error(ini->path, line, "section [%s] is not allowed here: this file holds only [%s NAME] sections",
                    sec, want_kind);
        return false;
    }
    if (!*name) {
        model_error(ini->path, line, "[%s] needs a name: write [%s NAME]", sec, want_kind);
        return false;
    }
    if (strchr(name, ' ')) {
        model_error(ini->path, line, "%s name '%s' contains blanks; use one word (e.g. '_' instead of blanks)",
                    want_kind, name);
        return false;
    }
    if (strlen(name) >= NAME_MAX_) {
        model_error(ini->path, line, "%s name '%s' is %zu characters long; the limit is %d",
                    want_kind, name, strlen(name), NAME_MAX_ - 1);
        return false;
    }
    strcpy(out, name);
    return true;
}

// Parse an entry's value as a number, naming the key on error.
static bool entry_double(const model_ini_t *ini, const model_ini_entry_t *e, double *out)
{
    if (!model_parse_double(e->value, out)) {
        model_error(ini->path, e->line, "%s = '%s' is not a number", e->key, e->value);
        return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// Materials

static void list_models(char *buf, size_t size)
{
    size_t n = 0;
    buf[0] = 0;
    for (int m = 0; m < MODEL_BRDF_COUNT && n < size; m++)
        n += snprintf(buf + n, size - n, "%s%s", m ? ", " : "", model_brdf_name(m));
}

static void list_keys(model_brdf_t m, char *buf, size_t size)
{
    size_t n = snprintf(buf, size, "model");
    for (int i = 0; i < model_brdf_nparams(m) && n < size; i++)
        n += snprintf(buf + n, size - n, ", %s", model_brdf_param_name(m, i));
}

// Ranges as text: "[0, 0.31831]", "[0, inf)".
static void format_range(double lo, double hi, char *buf, size_t size)
{
    if (isinf(hi))
        snprintf(buf, size, "[%g, inf)", lo);
    else
        snprintf(buf, size, "[%g, %g]", lo, hi);
}

// [material NAME] model = table: table = FILE (relative to the INI) or
// generate = RECIPE, exactly one of them.
static bool parse_table_material(const model_ini_t *ini, int s, model_material_t *mat)
{
    const model_ini_entry_t *file = NULL, *gen = NULL;
    const int first = ini->section_first[s], end = first + ini->section_count[s];
    for (int k = first; k < end; k++) {
        const model_ini_entry_t *e = &ini->entries[k];
        if (!strcmp(e->key, "table")) file = e;
        else if (!strcmp(e->key, "generate")) gen = e;
        else if (strcmp(e->key, "model")) {
            model_error(ini->path, e->line, "unknown key '%s' in material '%s' (model table); valid keys: model, "
                        "table (a MERL binary file) or generate (a recipe: %s)", e->key, mat->name,
                        model_brdf_recipe_models());
            return false;
        }
    }
    if (!file == !gen) {
        model_error(ini->path, mat->line, "material '%s' (model table) needs exactly one of 'table = FILE' (a MERL "
                    "binary, relative to this file) and 'generate = RECIPE' (%s)", mat->name,
                    model_brdf_recipe_models());
        return false;
    }
    if (gen) {
        model_brdf_recipe_t r;
        if (!model_brdf_recipe_parse(gen->value, ini->path, gen->line, &r)) return false;
        mat->table = model_brdf_tabulate(&r);
    } else {
        char path[4096];
        const char *slash = strrchr(ini->path, '/');
        if (file->value[0] == '/' || !slash)
            snprintf(path, sizeof path, "%s", file->value);
        else
            snprintf(path, sizeof path, "%.*s/%s", (int)(slash - ini->path), ini->path, file->value);
        bool quiet = model_error_quiet_thread(true);   // reported once below, with the material's line
        mat->table = model_brdf_table_load(path);
        model_error_quiet_thread(quiet);
        if (!mat->table) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error(ini->path, file->line, "material '%s': %s", mat->name, msg);
            return false;
        }
    }
    if (!mat->table) return false;
    mat->model = MODEL_BRDF_LAMBERT;
    mat->p[0] = model_brdf_table_albedo(mat->table, 0, 64) / M_PI;
    return true;
}

static bool parse_material(const model_ini_t *ini, int s, model_material_t *mat)
{
    memset(mat, 0, sizeof *mat);
    mat->line = ini->section_lines[s];
    if (!section_name(ini, s, "material", mat->name)) return false;
    char buf[256];

    const model_ini_entry_t *me = NULL;
    const int first = ini->section_first[s], end = first + ini->section_count[s];
    for (int k = first; k < end && !me; k++)
        if (!strcmp(ini->entries[k].key, "model")) me = &ini->entries[k];
    if (!me) {
        list_models(buf, sizeof buf);
        model_error(ini->path, mat->line, "material '%s' has no 'model = ...' line; models: %s", mat->name, buf);
        return false;
    }
    if (!strcmp(me->value, "table")) return parse_table_material(ini, s, mat);
    int m = model_brdf_from_name(me->value);
    if (m < 0) {
        list_models(buf, sizeof buf);
        model_error(ini->path, me->line, "unknown reflection model '%s' in material '%s'; models: %s",
                    me->value, mat->name, buf);
        return false;
    }
    mat->model = (model_brdf_t)m;
    int np = model_brdf_nparams(mat->model);
    bool have[MODEL_BRDF_MAX_PARAMS] = { false };

    for (int k = first; k < end; k++) {
        const model_ini_entry_t *e = &ini->entries[k];
        if (e == me) continue;
        int i = model_brdf_param_index(mat->model, e->key);
        if (i < 0) {
            list_keys(mat->model, buf, sizeof buf);
            model_error(ini->path, e->line, "unknown key '%s' in material '%s' (model %s); valid keys: %s",
                        e->key, mat->name, model_brdf_name(mat->model), buf);
            return false;
        }
        double v;
        if (!entry_double(ini, e, &v)) return false;
        double lo, hi;
        model_brdf_param_range(mat->model, i, &lo, &hi);
        if (!(v >= lo && v <= hi)) {
            char r[64];
            format_range(lo, hi, r, sizeof r);
            model_error(ini->path, e->line, "%s = %g is out of range %s for model %s (%s)", e->key, v, r,
                        model_brdf_name(mat->model), model_brdf_convention(mat->model));
            return false;
        }
        mat->p[i] = v;
        have[i] = true;
    }
    for (int i = 0; i < np; i++) {
        if (have[i]) continue;
        double d = model_brdf_param_default(mat->model, i);
        if (isnan(d)) {
            list_keys(mat->model, buf, sizeof buf);
            model_error(ini->path, mat->line, "material '%s' (model %s) lacks parameter '%s'; it needs: %s",
                        mat->name, model_brdf_name(mat->model), model_brdf_param_name(mat->model, i), buf);
            return false;
        }
        mat->p[i] = d;
    }
    return true;
}

// build (from the [KIND NAME] sections of an INI: with only_kind, other
// sections are skipped, else every section must be one), parse, load and free
// of a list read from INI (lamps, materials): TYPE has n, path, sha256 and the
// array FIELD whose elements PARSE_ONE(ini, section, &element) fills.
#define INI_LIST_FUNCTIONS(prefix, type, build, kind, parse_one, field, none_msg, free_one)    \
    static type *build(const model_ini_t *ini, bool only_kind)                                  \
    {                                                                                           \
        int n = only_kind ? count_kind(ini, kind) : ini->nsections;                             \
        if (n == 0) {                                                                           \
            model_error(ini->path, 0, none_msg);                                                \
            return NULL;                                                                        \
        }                                                                                       \
        type *out = calloc(1, sizeof *out);                                                     \
        if (out) out->field = calloc(n, sizeof *out->field);                                    \
        if (out) out->path = strdup(ini->path);                                                 \
        if (!out || !out->field || !out->path) {                                                \
            model_error(ini->path, 0, "out of memory");                                         \
            prefix##_free(out);                                                                 \
            return NULL;                                                                        \
        }                                                                                       \
        for (int s = 0; s < ini->nsections; s++) {                                              \
            if (only_kind && !is_kind(ini, s, kind)) continue;                                  \
            bool ok_ = parse_one(ini, s, &out->field[out->n]);                                      \
            out->n++;                                                                           \
            if (!ok_) {                                                                         \
                prefix##_free(out);                                                             \
                return NULL;                                                                    \
            }                                                                                   \
        }                                                                                       \
        return out;                                                                             \
    }                                                                                           \
    type *prefix##_parse(const char *text, size_t len, const char *name)                \
    {                                                                                   \
        model_ini_t *ini = model_ini_parse(text, len, name);                            \
        type *out = ini ? build(ini, false) : NULL;                                     \
        if (out) model_sha256_hex(text ? text : "", text ? len : 0, out->sha256);       \
        model_ini_free(ini);                                                            \
        return out;                                                                     \
    }                                                                                   \
    type *prefix##_load(const char *path)                                               \
    {                                                                                   \
        size_t len;                                                                     \
        char *text = model_read_file(path, &len);                                       \
        type *out = text ? prefix##_parse(text, len, path) : NULL;                      \
        free(text);                                                                     \
        return out;                                                                     \
    }                                                                                   \
    void prefix##_free(type *x)                                                         \
    {                                                                                   \
        if (!x) return;                                                                 \
        for (int i_ = 0; x->field && i_ < x->n; i_++) free_one(&x->field[i_]);          \
        free(x->field);                                                                 \
        free(x->path);                                                                  \
        free(x);                                                                        \
    }


const model_material_t *model_materials_find(const model_materials_t *m, const char *name)
{
    if (!m || !name) return NULL;
    for (int i = 0; i < m->n; i++)
        if (!strcmp(m->materials[i].name, name)) return &m->materials[i];
    return NULL;
}

// ---------------------------------------------------------------------------
// Lamps

// The optional emission pattern of a lamp: emission_cos_power = n (0..1000,
// 0 = isotropic) and emission_axis = x y z (normalised; default toward the
// rig origin, which a lamp at the origin cannot use).
static bool parse_lamp_emission(const model_ini_t *ini, const char *sec, model_lamp_t *lamp)
{
    if (!model_ini_double_in(ini, sec, "emission_cos_power", &lamp->emission_cos_power, false, 0, false, 1000,
                             "0 <= emission_cos_power <= 1000 (0 = isotropic)"))
        return false;
    const model_ini_entry_t *ax = model_ini_get(ini, sec, "emission_axis");
    char what[192];
    snprintf(what, sizeof what, "'x y z': lamp '%s' expects exactly 3 numbers (a direction, rig frame)", lamp->name);
    double a[3];
    if (ax && !model_ini_vec3(ini, sec, "emission_axis", a, true, what)) return false;
    if (ax && !(lamp->emission_cos_power > 0)) {
        model_error(ini->path, ax->line, "emission_axis in lamp '%s' needs emission_cos_power = n > 0 (without it "
                    "the lamp is isotropic)", lamp->name);
        return false;
    }
    if (ax) {
        model_vec3_t d = v3(a[0], a[1], a[2]);
        double len = v3_norm(d);
        if (!(len > 0) || !isfinite(len)) {
            model_error(ini->path, ax->line, "emission_axis = %g %g %g in lamp '%s' is not a direction (zero length)",
                        a[0], a[1], a[2], lamp->name);
            return false;
        }
        lamp->emission_axis = v3_scale(d, 1.0 / len);
    } else if (lamp->emission_cos_power > 0 && !(v3_norm(lamp->position_mm) > 0)) {
        model_error(ini->path, lamp->line, "lamp '%s' at the rig origin has emission_cos_power but no "
                    "emission_axis: give emission_axis = x y z", lamp->name);
        return false;
    }
    return true;
}

static bool parse_lamp(const model_ini_t *ini, int s, model_lamp_t *lamp)
{
    memset(lamp, 0, sizeof *lamp);
    lamp->line = ini->section_lines[s];
    if (!section_name(ini, s, "lamp", lamp->name)) return false;
    const char *sec = ini->sections[s];
    for (int k = ini->section_first[s]; k < ini->section_first[s] + ini->section_count[s]; k++) {
        const model_ini_entry_t *e = &ini->entries[k];
        if (strcmp(e->key, "position_mm") && strcmp(e->key, "intensity") && strcmp(e->key, "radius_mm") &&
            strcmp(e->key, "emission_cos_power") && strcmp(e->key, "emission_axis")) {
            model_error(ini->path, e->line,
                        "unknown key '%s' in lamp '%s'; valid keys: position_mm, intensity, radius_mm, "
                        "emission_cos_power, emission_axis", e->key, lamp->name);
            return false;
        }
    }
    char what[128];
    snprintf(what, sizeof what, "'x y z': lamp '%s' expects exactly 3 numbers (mm, rig frame)", lamp->name);
    double xyz[3];
    if (!model_ini_vec3(ini, sec, "position_mm", xyz, false, what) ||
        !model_ini_double(ini, sec, "intensity", &lamp->intensity, false) ||
        !model_ini_double(ini, sec, "radius_mm", &lamp->radius_mm, false))
        return false;
    const model_ini_entry_t *pos = model_ini_get(ini, sec, "position_mm"), *in = model_ini_get(ini, sec, "intensity"),
                            *rad = model_ini_get(ini, sec, "radius_mm");
    bool have_pos = pos != NULL, have_int = in != NULL;
    if (pos) lamp->position_mm = v3(xyz[0], xyz[1], xyz[2]);
    if (in && !(lamp->intensity > 0)) {
        model_error(ini->path, in->line, "intensity = %g in lamp '%s' must be > 0", lamp->intensity, lamp->name);
        return false;
    }
    if (rad && !(lamp->radius_mm >= 0)) {
        model_error(ini->path, rad->line, "radius_mm = %g in lamp '%s' must be >= 0 (0 = point lamp)",
                    lamp->radius_mm, lamp->name);
        return false;
    }
    if (!have_pos || !have_int) {
        model_error(ini->path, lamp->line, "lamp '%s' lacks '%s'; it needs position_mm = x y z and intensity = I",
                    lamp->name, have_pos ? "intensity" : "position_mm");
        return false;
    }
    return parse_lamp_emission(ini, sec, lamp);
}


int model_lamps_find(const model_lamps_t *l, const char *name)
{
    if (!l || !name) return -1;
    for (int i = 0; i < l->n; i++)
        if (!strcmp(l->lamps[i].name, name)) return i;
    return -1;
}

// ---------------------------------------------------------------------------
// Sensor

model_sensor_t model_sensor_default(void)
{
    return (model_sensor_t){
        .bits = 12,
        .system_gain_dn_per_e = 0.25,
        .full_well_e = 16000,
        .read_noise_e = 6,
        .dark_offset_dn = 64,
        .dsnu_dn = 1.5,
        .prnu_pct = 1,
        .dark_current_e_per_s = 0,
        .exposure_us = 0,
        .vignetting = 0.1,
        .nonlinearity_pct = 2,
        .pattern_seed = 1,
        .noise_seed = 1,
        .knee_e = 0,
        .low_end_gamma = 1,
        .low_end_e = 0,
        .hot_pixel_fraction = 0,
        .hot_pixel_dark_current_e_per_s = 0,
        .row_noise_dn = 0,
    };
}

typedef enum { KEY_BITS, KEY_DOUBLE, KEY_SEED } key_type_t;

// One row per field of model_sensor_t: the allowed range is lo (<= or <) v (<= or <) hi.
typedef struct {
    const char *name;
    key_type_t  type;
    size_t      offset;
    double      lo, hi;
    bool        lo_open, hi_open;
} sensor_key_t;

#define SK_(field, type, lo, hi, lo_open, hi_open) \
    { #field, type, offsetof(model_sensor_t, field), lo, hi, lo_open, hi_open }
static const sensor_key_t sensor_keys[] = {
    SK_(bits, KEY_BITS, 8, 16, false, false),
    SK_(system_gain_dn_per_e, KEY_DOUBLE, 0, INFINITY, true, false),
    SK_(full_well_e, KEY_DOUBLE, 0, INFINITY, true, false),
    SK_(read_noise_e, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(dark_offset_dn, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(dsnu_dn, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(prnu_pct, KEY_DOUBLE, 0, 50, false, false),
    SK_(dark_current_e_per_s, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(exposure_us, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(vignetting, KEY_DOUBLE, 0, 1, false, true),
    SK_(nonlinearity_pct, KEY_DOUBLE, 0, 50, false, false),
    SK_(pattern_seed, KEY_SEED, 0, 0, false, false),
    SK_(noise_seed, KEY_SEED, 0, 0, false, false),
    SK_(knee_e, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(low_end_gamma, KEY_DOUBLE, 0.5, 2, false, false),
    SK_(low_end_e, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(hot_pixel_fraction, KEY_DOUBLE, 0, 1, false, false),
    SK_(hot_pixel_dark_current_e_per_s, KEY_DOUBLE, 0, INFINITY, false, false),
    SK_(row_noise_dn, KEY_DOUBLE, 0, INFINITY, false, false),
};
#undef SK_
#define NSENSOR_KEYS ((int)(sizeof sensor_keys / sizeof sensor_keys[0]))

// A non-negative decimal integer that fits in 64 bits.
static bool parse_u64(const char *s, uint64_t *out)
{
    while (*s == ' ' || *s == '\t') s++;
    if (*s < '0' || *s > '9') return false;
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno == ERANGE) return false;
    while (*end == ' ' || *end == '\t') end++;
    if (*end) return false;
    *out = v;
    return true;
}

static bool sensor_entry(const model_ini_t *ini, const model_ini_entry_t *e, model_sensor_t *s)
{
    const sensor_key_t *k = NULL;
    for (int i = 0; i < NSENSOR_KEYS; i++)
        if (!strcmp(sensor_keys[i].name, e->key)) k = &sensor_keys[i];
    if (!k) {
        char buf[512];
        size_t n = 0;
        buf[0] = 0;
        for (int i = 0; i < NSENSOR_KEYS && n < sizeof buf; i++)
            n += snprintf(buf + n, sizeof buf - n, "%s%s", i ? ", " : "", sensor_keys[i].name);
        model_error(ini->path, e->line, "unknown key '%s' in [sensor]; valid keys: %s", e->key, buf);
        return false;
    }
    char *field = (char *)s + k->offset;
    switch (k->type) {
    case KEY_BITS: {
        long v;
        if (!model_parse_int(e->value, &v) || (v != 8 && v != 12 && v != 16)) {
            model_error(ini->path, e->line, "bits = '%s': must be 8, 12 or 16", e->value);
            return false;
        }
        *(int *)field = (int)v;
        return true;
    }
    case KEY_SEED: {
        uint64_t v;
        if (!parse_u64(e->value, &v)) {
            model_error(ini->path, e->line, "%s = '%s': must be an integer >= 0 (at most 2^64-1)", e->key,
                        e->value);
            return false;
        }
        *(uint64_t *)field = v;
        return true;
    }
    case KEY_DOUBLE: {
        double v;
        if (!entry_double(ini, e, &v)) return false;
        bool ok = (k->lo_open ? v > k->lo : v >= k->lo) && (k->hi_open ? v < k->hi : v <= k->hi);
        if (!ok) {
            char r[64];
            if (isinf(k->hi))
                snprintf(r, sizeof r, "%s %g", k->lo_open ? ">" : ">=", k->lo);
            else
                snprintf(r, sizeof r, "in %c%g, %g%c", k->lo_open ? '(' : '[', k->lo, k->hi,
                         k->hi_open ? ')' : ']');
            model_error(ini->path, e->line, "%s = %g is out of range: must be %s", e->key, v, r);
            return false;
        }
        *(double *)field = v;
        return true;
    }
    }
    return false;
}

bool model_sensor_parse(const char *text, size_t len, const char *name, model_sensor_t *out)
{
    bool ok = false;
    model_sensor_t s = model_sensor_default();
    model_ini_t *ini = model_ini_parse(text, len, name);
    if (!ini) goto done;
    for (int i = 0; i < ini->nsections; i++)
        if (strcmp(ini->sections[i], "sensor")) {
            model_error(ini->path, ini->section_lines[i],
                        "section [%s] is not allowed here: a sensor file has one [sensor] section", ini->sections[i]);
            goto done;
        }
    if (ini->nsections != 1) {
        model_error(ini->path, 0, "no [sensor] section; a sensor file has one [sensor] section");
        goto done;
    }
    for (int k = 0; k < ini->nentries; k++)
        if (!sensor_entry(ini, &ini->entries[k], &s)) goto done;
    *out = s;
    ok = true;
done:
    model_ini_free(ini);
    return ok;
}

bool model_sensor_load(const char *path, model_sensor_t *out)
{
    size_t len;
    char *text = model_read_file(path, &len);
    if (!text) return false;
    bool ok = model_sensor_parse(text, len, path, out);
    free(text);
    return ok;
}

// ---------------------------------------------------------------------------
// Sections of their kind from a file that holds other sections too (e.g. the
// virtual rig's truth file). Duplicate section headers are already errors of
// the INI reader, so names are unique.

static int count_kind(const model_ini_t *ini, const char *kind)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++) {
        char k[32];
        split_section(ini->sections[s], k, sizeof k);
        if (!strcmp(k, kind)) n++;
    }
    return n;
}

static bool is_kind(const model_ini_t *ini, int s, const char *kind)
{
    char k[32];
    split_section(ini->sections[s], k, sizeof k);
    return !strcmp(k, kind);
}

static void material_free_one(model_material_t *m) { model_brdf_table_free(m->table); }
static void lamp_free_one(model_lamp_t *l) { (void)l; }

INI_LIST_FUNCTIONS(model_materials, model_materials_t, materials_build, "material", parse_material, materials,
                   "no [material NAME] sections; add at least one", material_free_one)

INI_LIST_FUNCTIONS(model_lamps, model_lamps_t, lamps_build, "lamp", parse_lamp, lamps,
                   "no [lamp NAME] sections; add at least one lamp", lamp_free_one)

model_materials_t *model_materials_from_ini(const model_ini_t *ini) { return materials_build(ini, true); }
model_lamps_t *model_lamps_from_ini(const model_ini_t *ini) { return lamps_build(ini, true); }

bool model_sensor_from_ini(const model_ini_t *ini, model_sensor_t *out)
{
    model_sensor_t s = model_sensor_default();
    bool found = false;
    for (int i = 0; i < ini->nsections; i++)
        if (!strcmp(ini->sections[i], "sensor")) found = true;
    if (!found) {
        model_error(ini->path, 0, "no [sensor] section; add one (keys as in a sensor file)");
        return false;
    }
    for (int k = 0; k < ini->nentries; k++)
        if (!strcmp(ini->entries[k].section, "sensor") && !sensor_entry(ini, &ini->entries[k], &s)) return false;
    *out = s;
    return true;
}

bool model_sensor_update_from_ini(const model_ini_t *ini, const char *section, model_sensor_t *s)
{
    model_sensor_t t = *s;
    for (int k = 0; k < ini->nentries; k++)
        if (!strcmp(ini->entries[k].section, section) && !sensor_entry(ini, &ini->entries[k], &t)) return false;
    *s = t;
    return true;
}
