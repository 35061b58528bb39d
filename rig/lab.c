// rig/lab.c — the lab file's one reader (rig_lab_load: every section, key and value checked,
// file:line errors) and the writer of its [geometry] section (rig_lab_geometry_text).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/lab.h"

// The keys of each section kind ("coupon" stands for every [coupon NAME]).
static const struct {
    const char *kind;
    const char *keys;   // blank-separated
    bool        named;  // [kind NAME]
} sections[] = {
    { "lab", "format_version name", false },
    { "geometry", "tilts angles_deg exposure_us board_sample board_scene board_corners board_square_mm "
                  "board_height_mm", false },
    { "sphere", "sample centre_mm radius_mm", false },
    { "lamps", "radius_mm", false },
    { "flat_field", "radiance radiance_unit", false },
    { "white", "sample scene certificate albedo albedo_std angles_deg exposure_us plan", false },
    { "coupon", "sample scene tilt_deg tilt_azimuth_deg angles_deg angle_step_deg exposures_us target_fraction "
                "albedo_cells_mm window_px step_px plan", true },
    { "workpiece", "sample scene priors angles_deg exposures_us check_lamps check_exposure_us plan", false },
    { "description", "scene expect what", true },
};
enum { NKINDS = sizeof sections / sizeof sections[0] };

typedef struct {
    const model_ini_t *ini;
    char              *dir;   // the lab file's directory
} ctx_t;

static bool fail(const ctx_t *c, int line, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static bool fail(const ctx_t *c, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char *m = g_strdup_vprintf(fmt, ap);
    va_end(ap);
    model_error_set(c->ini->path, line, "%s", m);
    g_free(m);
    return false;
}

// Every section is a known kind and every key one of its kind's.
static bool check_names(const ctx_t *c)
{
    const model_ini_t *ini = c->ini;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        int k = 0;
        for (; k < NKINDS; k++) {
            size_t n = strlen(sections[k].kind);
            if (!strncmp(sec, sections[k].kind, n) &&
                (sections[k].named ? sec[n] == ' ' && sec[n + 1] : sec[n] == 0))
                break;
        }
        if (k == NKINDS)
            return fail(c, ini->section_lines[s], "unknown section [%s]: a lab file has [lab], [geometry], [sphere], "
                        "[lamps], [flat_field], [white], [coupon NAME], [workpiece] and [description NAME] "
                        "(examples/lab.ini)", sec);
        if (sections[k].named && strlen(sec + strlen(sections[k].kind) + 1) >= RIG_LAB_NAME_MAX)
            return fail(c, ini->section_lines[s], "[%s]: the name is too long (at most %d characters)", sec,
                        RIG_LAB_NAME_MAX - 1);
        for (int e = ini->section_first[s]; e < ini->section_first[s] + ini->section_count[s]; e++) {
            const char *key = ini->entries[e].key;
            gchar **ks = g_strsplit(sections[k].keys, " ", -1);
            bool known = false;
            for (int i = 0; ks[i] && !known; i++) known = !strcmp(ks[i], key);
            g_strfreev(ks);
            if (!known)
                return fail(c, ini->entries[e].line, "[%s]: unknown key '%s'; known keys: %s", sec, key,
                            sections[k].keys);
        }
    }
    return true;
}

// A path key resolved against the lab file's directory; the file must be readable.
static bool path_of(const ctx_t *c, const char *sec, const char *key, bool required, char **out)
{
    const model_ini_entry_t *e = model_ini_get(c->ini, sec, key);
    *out = NULL;
    if (!e) return required ? fail(c, model_ini_section_line(c->ini, sec), "[%s] lacks '%s' (a file, relative to "
                                   "the lab file's directory)", sec, key)
                            : true;
    if (!e->value[0]) return fail(c, e->line, "[%s] %s: give a file", sec, key);
    char *p = e->value[0] == '/' ? g_strdup(e->value) : g_build_filename(c->dir, e->value, NULL);
    if (!g_file_test(p, G_FILE_TEST_IS_REGULAR)) {
        fail(c, e->line, "[%s] %s = %s: no such file (%s; paths are relative to the lab file's directory)", sec, key,
             e->value, p);
        g_free(p);
        return false;
    }
    *out = p;
    return true;
}

// A list of numbers separated by blanks or commas, each in [lo, hi], at most max.
static bool list_of(const ctx_t *c, const char *sec, const char *key, double lo, double hi, double *v, int *n,
                    int max, const char *what)
{
    const model_ini_entry_t *e = model_ini_get(c->ini, sec, key);
    if (!e) return true;
    int k = model_parse_doubles(e->value, " \t,", lo, hi, v, max);
    if (k < 0)
        return fail(c, e->line, "[%s] %s = %s: give %s, %g..%g each, at most %d", sec, key, e->value, what, lo, hi,
                    max);
    *n = k;
    return true;
}

static bool name_of(const ctx_t *c, const char *sec, const char *key, char *out, bool required, const char *def)
{
    if (def) snprintf(out, RIG_LAB_NAME_MAX, "%s", def);
    if (!model_ini_string(c->ini, sec, key, out, RIG_LAB_NAME_MAX, required)) return false;
    for (const char *p = out; *p; p++)
        if (!g_ascii_isalnum(*p) && *p != '_' && *p != '-' && *p != '.') {
            const model_ini_entry_t *e = model_ini_get(c->ini, sec, key);
            return fail(c, e ? e->line : 0, "[%s] %s = %s: a name of letters, digits, '_', '-' and '.'", sec, key,
                        out);
        }
    return true;
}

static bool read_lab(const ctx_t *c, rig_lab_t *L)
{
    long v = 0;
    if (!model_ini_section_line(c->ini, "lab"))
        return fail(c, 1, "no [lab] section: a lab file begins with [lab] and format_version = %d "
                    "(examples/lab.ini)", RIG_LAB_FORMAT_VERSION);
    if (!model_ini_int(c->ini, "lab", "format_version", &v, true, 1, 1000000)) return false;
    if (v > RIG_LAB_FORMAT_VERSION)
        return fail(c, model_ini_get(c->ini, "lab", "format_version")->line, "[lab] format_version = %ld: a newer "
                    "lab file format than this refl reads (%d); use a newer refl", v, RIG_LAB_FORMAT_VERSION);
    L->format_version = (int)v;
    return model_ini_string(c->ini, "lab", "name", L->name, sizeof L->name, false);
}

// One --tilts entry T[@AZ][:A,A,...]: tilt -80..80, azimuth and angles numbers.
static bool tilt_entry_ok(const char *spec)
{
    gchar **ta = g_strsplit(spec, ":", 2), **tz = g_strsplit(ta[0], "@", 2);
    double x;
    bool ok = model_parse_double(tz[0], &x) && x >= -80 && x <= 80 && (!tz[1] || model_parse_double(tz[1], &x));
    if (ok && ta[1]) {
        gchar **as = g_strsplit(ta[1], ",", -1);
        int n = 0;
        for (int i = 0; as[i] && ok; i++) ok = model_parse_double(as[i], &x), n++;
        ok = ok && n > 0;
        g_strfreev(as);
    }
    g_strfreev(tz);
    g_strfreev(ta);
    return ok;
}

static bool read_geometry(const ctx_t *c, rig_lab_t *L)
{
    const char *S = "geometry";
    if (!model_ini_section_line(c->ini, S))
        return fail(c, 1, "no [geometry] section: give the board's tilts and angles (refl plan geometry writes the "
                    "section for your camera)");
    const model_ini_entry_t *t = model_ini_get(c->ini, S, "tilts"), *a = model_ini_get(c->ini, S, "angles_deg");
    if (!t || !t->value[0]) return fail(c, model_ini_section_line(c->ini, S), "[geometry] lacks 'tilts'");
    L->geometry.tilts = g_strdup(t->value);
    gchar **specs = g_strsplit_set(t->value, " \t", -1);
    bool good = true;
    for (int i = 0; specs[i] && good; i++)
        if (specs[i][0] && !tilt_entry_ok(specs[i])) {
            fail(c, t->line, "[geometry] tilts: '%s' is not TILT[@AZIMUTH][:ANGLE,ANGLE,...] in degrees (tilt "
                 "-80..80, e.g. 20@90:0,40,80)", specs[i]);
            good = false;
        }
    g_strfreev(specs);
    if (!good) return false;
    double tmp[RIG_LAB_MAX_ANGLES];
    int n = 0;
    if (a) {
        if (!list_of(c, S, "angles_deg", -10000, 10000, tmp, &n, RIG_LAB_MAX_ANGLES, "turntable angles in deg"))
            return false;
        L->geometry.angles = g_strdup(a->value);
        for (char *p = L->geometry.angles; *p; p++)
            if (*p == ',') *p = ' ';
    }
    L->geometry.exposure_us = NAN;
    snprintf(L->geometry.board_sample, sizeof L->geometry.board_sample, "calib_board");
    L->geometry.corners_w = L->geometry.corners_h = 10;
    L->geometry.square_mm = 30;
    L->geometry.height_mm = 5;
    double cw[2];
    n = 0;
    if (!model_ini_double_in(c->ini, S, "exposure_us", &L->geometry.exposure_us, false, 0, true, 1e8, NULL) ||
        !name_of(c, S, "board_sample", L->geometry.board_sample, false, NULL) ||
        !path_of(c, S, "board_scene", false, &L->geometry.board_scene) ||
        !list_of(c, S, "board_corners", 2, 100, cw, &n, 2, "W H inner corners (whole numbers)") ||
        !model_ini_double_in(c->ini, S, "board_square_mm", &L->geometry.square_mm, false, 0, true, 1e4, NULL) ||
        !model_ini_double_in(c->ini, S, "board_height_mm", &L->geometry.height_mm, false, -1e4, false, 1e4, NULL))
        return false;
    if (n == 1 || (n == 2 && (cw[0] != floor(cw[0]) || cw[1] != floor(cw[1]))))
        return fail(c, model_ini_get(c->ini, S, "board_corners")->line, "[geometry] board_corners: give W H, the "
                    "inner corners along the board's x and y (whole numbers, e.g. 10 10)");
    if (n == 2) L->geometry.corners_w = (int)cw[0], L->geometry.corners_h = (int)cw[1];
    return true;
}

static bool read_calibration_facts(const ctx_t *c, rig_lab_t *L)
{
    if (!model_ini_section_line(c->ini, "sphere"))
        return fail(c, 1, "no [sphere] section: give the chrome ball's centre_mm (rig frame, turntable at 0) and "
                    "radius_mm as measured");
    if (!name_of(c, "sphere", "sample", L->sphere.sample, false, "mirror_sphere") ||
        !model_ini_vec3(c->ini, "sphere", "centre_mm", L->sphere.centre_mm, true, "X Y Z (mm, rig frame, angle 0)") ||
        !model_ini_double_in(c->ini, "sphere", "radius_mm", &L->sphere.radius_mm, true, 0, true, 1000, NULL) ||
        !model_ini_double_in(c->ini, "lamps", "radius_mm", &L->lamp_radius_mm, false, 0, false, 1000, NULL))
        return false;
    L->flat_field.radiance = NAN;
    if (!model_ini_double_in(c->ini, "flat_field", "radiance", &L->flat_field.radiance, false, 0, true, 1e30, NULL) ||
        !model_ini_string(c->ini, "flat_field", "radiance_unit", L->flat_field.unit, sizeof L->flat_field.unit,
                          false))
        return false;
    if (isfinite(L->flat_field.radiance) && !L->flat_field.unit[0])
        return fail(c, model_ini_get(c->ini, "flat_field", "radiance")->line, "[flat_field] radiance without "
                    "radiance_unit: name the unit it is measured in (e.g. W/(sr m^2)); kc is per that unit");
    const char *W = "white";
    if (!model_ini_section_line(c->ini, W))
        return fail(c, 1, "no [white] section: give the reference white's scene and its certificate (or albedo)");
    L->white.albedo = 0.99;
    L->white.albedo_std = NAN;
    L->white.exposure_us = 8000;
    L->white.nangles = 3;
    L->white.angles_deg[0] = 0, L->white.angles_deg[1] = 120, L->white.angles_deg[2] = 240;
    if (!name_of(c, W, "sample", L->white.sample, false, "reference_white") ||
        !path_of(c, W, "scene", true, &L->white.scene) || !path_of(c, W, "certificate", false, &L->white.certificate) ||
        !path_of(c, W, "plan", false, &L->white.plan) ||
        !model_ini_double_in(c->ini, W, "albedo", &L->white.albedo, false, 0, true, 1, NULL) ||
        !model_ini_double_in(c->ini, W, "albedo_std", &L->white.albedo_std, false, 0, true, 1, NULL) ||
        !model_ini_double_in(c->ini, W, "exposure_us", &L->white.exposure_us, false, 0, true, 1e8, NULL) ||
        !list_of(c, W, "angles_deg", -10000, 10000, L->white.angles_deg, &L->white.nangles, RIG_LAB_MAX_ANGLES,
                 "turntable angles in deg"))
        return false;
    if (L->white.certificate && model_ini_get(c->ini, W, "albedo"))
        return fail(c, model_ini_get(c->ini, W, "albedo")->line, "[white]: give certificate (the reflectance-factor "
                    "table) or albedo (a Lambertian white), not both");
    return true;
}

static bool read_coupon(const ctx_t *c, const char *sec, rig_lab_coupon_t *k)
{
    snprintf(k->name, sizeof k->name, "%s", sec + strlen("coupon "));
    k->line = model_ini_section_line(c->ini, sec);
    k->target_fraction = 0.9;
    k->nexposures = 3;
    k->exposures_us[0] = 8000, k->exposures_us[1] = 1000, k->exposures_us[2] = 125;
    double step = 20;
    if (!name_of(c, sec, "sample", k->sample, true, NULL) || !path_of(c, sec, "scene", true, &k->scene) ||
        !path_of(c, sec, "plan", false, &k->plan) ||
        !model_ini_double_in(c->ini, sec, "tilt_deg", &k->tilt_deg, false, -80, false, 80, NULL) ||
        !model_ini_double_in(c->ini, sec, "tilt_azimuth_deg", &k->tilt_azimuth_deg, false, -360, false, 360, NULL) ||
        !model_ini_double_in(c->ini, sec, "angle_step_deg", &step, false, 0, true, 360, NULL) ||
        !list_of(c, sec, "angles_deg", -10000, 10000, k->angles_deg, &k->nangles, RIG_LAB_MAX_ANGLES,
                 "turntable angles in deg") ||
        !list_of(c, sec, "exposures_us", 0.001, 1e8, k->exposures_us, &k->nexposures, RIG_LAB_MAX_EXPOSURES,
                 "exposures in us") ||
        !model_ini_double_in(c->ini, sec, "target_fraction", &k->target_fraction, false, 0, true, 1, NULL) ||
        !model_ini_double_in(c->ini, sec, "albedo_cells_mm", &k->albedo_cells_mm, false, 0, false, 1e4, NULL))
        return false;
    long w = 0, s = 0;
    if (!model_ini_int(c->ini, sec, "window_px", &w, false, 1, 255) ||
        !model_ini_int(c->ini, sec, "step_px", &s, false, 1, 255))
        return false;
    k->window_px = (int)w, k->step_px = (int)s;
    if (model_ini_get(c->ini, sec, "angles_deg") && model_ini_get(c->ini, sec, "angle_step_deg"))
        return fail(c, k->line, "[%s]: give angles_deg or angle_step_deg, not both", sec);
    if (!k->nangles)
        for (double a = 0; a < 360 - 1e-9 && k->nangles < RIG_LAB_MAX_ANGLES; a += step) k->angles_deg[k->nangles++] = a;
    return true;
}

static bool read_workpiece(const ctx_t *c, rig_lab_t *L)
{
    const char *S = "workpiece";
    if (!model_ini_section_line(c->ini, S))
        return fail(c, 1, "no [workpiece] section: give the workpiece's sample, scene and the coupons whose priors "
                    "verify it");
    L->workpiece.nangles = 4;
    for (int a = 0; a < 4; a++) L->workpiece.angles_deg[a] = 90 * a;
    static const double ex[] = { 500, 1000, 2000, 4000, 8000, 16000, 32000 };
    L->workpiece.nexposures = (int)(sizeof ex / sizeof ex[0]);
    memcpy(L->workpiece.exposures_us, ex, sizeof ex);
    L->workpiece.check_exposure_us = 20000;
    if (!name_of(c, S, "sample", L->workpiece.sample, true, NULL) || !path_of(c, S, "scene", true, &L->workpiece.scene) ||
        !path_of(c, S, "plan", false, &L->workpiece.plan) ||
        !list_of(c, S, "angles_deg", -10000, 10000, L->workpiece.angles_deg, &L->workpiece.nangles, RIG_LAB_MAX_ANGLES,
                 "turntable angles in deg") ||
        !list_of(c, S, "exposures_us", 0.001, 1e8, L->workpiece.exposures_us, &L->workpiece.nexposures,
                 RIG_LAB_MAX_EXPOSURES, "exposures in us") ||
        !model_ini_string(c->ini, S, "check_lamps", L->workpiece.check_lamps, sizeof L->workpiece.check_lamps, false) ||
        !model_ini_double_in(c->ini, S, "check_exposure_us", &L->workpiece.check_exposure_us, false, 0, true, 1e8, NULL))
        return false;
    const model_ini_entry_t *cl = model_ini_get(c->ini, S, "check_lamps");
    L->workpiece.check_lamps_line = cl ? cl->line : 0;
    const model_ini_entry_t *p = model_ini_get(c->ini, S, "priors");
    if (!p) return fail(c, model_ini_section_line(c->ini, S), "[workpiece] lacks 'priors': name the coupons whose "
                        "materials the workpiece is made of (their priors verify it)");
    gchar **w = g_strsplit_set(p->value, " \t,", -1);
    bool ok = true;
    for (int i = 0; w[i] && ok; i++) {
        if (!w[i][0]) continue;
        if (!rig_lab_coupon(L, w[i]))
            ok = fail(c, p->line, "[workpiece] priors: '%s' is no [coupon %s] of this lab file", w[i], w[i]);
        else if (L->workpiece.npriors == RIG_LAB_MAX_ITEMS)
            ok = fail(c, p->line, "[workpiece] priors: at most %d", RIG_LAB_MAX_ITEMS);
        else
            snprintf(L->workpiece.priors[L->workpiece.npriors++], RIG_LAB_NAME_MAX, "%s", w[i]);
    }
    g_strfreev(w);
    if (ok && !L->workpiece.npriors) ok = fail(c, p->line, "[workpiece] priors: name at least one coupon");
    return ok;
}

static bool read_description(const ctx_t *c, const char *sec, rig_lab_description_t *d)
{
    snprintf(d->name, sizeof d->name, "%s", sec + strlen("description "));
    d->line = model_ini_section_line(c->ini, sec);
    const model_ini_entry_t *e = model_ini_get(c->ini, sec, "expect");
    if (!path_of(c, sec, "scene", true, &d->scene) ||
        !model_ini_string(c->ini, sec, "what", d->what, sizeof d->what, false))
        return false;
    if (!e) return fail(c, d->line, "[%s] lacks 'expect': correct (the workpiece as it is) or incorrect", sec);
    if (strcmp(e->value, "correct") && strcmp(e->value, "incorrect"))
        return fail(c, e->line, "[%s] expect = %s: give correct or incorrect", sec, e->value);
    d->correct = !strcmp(e->value, "correct");
    return true;
}

static bool read_all(const ctx_t *c, rig_lab_t *L)
{
    if (!check_names(c) || !read_lab(c, L) || !read_geometry(c, L) || !read_calibration_facts(c, L)) return false;
    for (int s = 0; s < c->ini->nsections; s++) {
        const char *sec = c->ini->sections[s];
        if (!strncmp(sec, "coupon ", 7)) {
            if (L->ncoupons == RIG_LAB_MAX_ITEMS)
                return fail(c, c->ini->section_lines[s], "at most %d coupons", RIG_LAB_MAX_ITEMS);
            if (!read_coupon(c, sec, &L->coupons[L->ncoupons++])) return false;
        } else if (!strncmp(sec, "description ", 12)) {
            if (L->ndescriptions == RIG_LAB_MAX_ITEMS)
                return fail(c, c->ini->section_lines[s], "at most %d descriptions", RIG_LAB_MAX_ITEMS);
            if (!read_description(c, sec, &L->descriptions[L->ndescriptions++])) return false;
        }
    }
    if (!L->ncoupons) return fail(c, 1, "no [coupon NAME] section: give at least one material coupon");
    if (!L->ndescriptions) return fail(c, 1, "no [description NAME] section: give the descriptions to verify");
    return read_workpiece(c, L);
}

rig_lab_t *rig_lab_parse(const char *text, size_t len, const char *name)
{
    model_ini_t *ini = model_ini_parse(text, len, name);
    if (!ini) return NULL;
    rig_lab_t *L = calloc(1, sizeof *L);
    if (!L) {
        model_ini_free(ini);
        model_error_set(name, 0, "out of memory");
        return NULL;
    }
    L->path = g_strdup(name);
    model_sha256_hex(text, len, L->sha256);
    ctx_t c = { ini, g_path_get_dirname(name) };
    bool ok = read_all(&c, L);
    g_free(c.dir);
    model_ini_free(ini);
    if (!ok) {
        rig_lab_free(L);
        return NULL;
    }
    return L;
}

rig_lab_t *rig_lab_load(const char *path)
{
    size_t len = 0;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    rig_lab_t *L = rig_lab_parse(text, len, path);
    free(text);
    return L;
}

void rig_lab_free(rig_lab_t *L)
{
    if (!L) return;
    g_free(L->path);
    g_free(L->geometry.tilts);
    g_free(L->geometry.angles);
    g_free(L->geometry.board_scene);
    g_free(L->white.scene);
    g_free(L->white.certificate);
    g_free(L->white.plan);
    for (int k = 0; k < L->ncoupons; k++) {
        g_free(L->coupons[k].scene);
        g_free(L->coupons[k].plan);
    }
    g_free(L->workpiece.scene);
    g_free(L->workpiece.plan);
    for (int k = 0; k < L->ndescriptions; k++) g_free(L->descriptions[k].scene);
    free(L);
}

const rig_lab_coupon_t *rig_lab_coupon(const rig_lab_t *L, const char *name)
{
    for (int k = 0; k < L->ncoupons; k++)
        if (!strcmp(L->coupons[k].name, name)) return &L->coupons[k];
    return NULL;
}

char *rig_lab_geometry_text(const rig_lab_geometry_t *g, const char *comment)
{
    GString *t = g_string_new("");
    if (comment) {
        gchar **lines = g_strsplit(comment, "\n", -1);
        for (int i = 0; lines[i]; i++) g_string_append_printf(t, "#%s%s\n", lines[i][0] ? " " : "", lines[i]);
        g_strfreev(lines);
    }
    g_string_append(t, "[geometry]\n");
    g_string_append_printf(t, "tilts = %s\n", g->tilts);
    if (g->angles && g->angles[0]) g_string_append_printf(t, "angles_deg = %s\n", g->angles);
    if (isfinite(g->exposure_us)) g_string_append_printf(t, "exposure_us = %.10g\n", g->exposure_us);
    if (g->board_sample && g->board_sample[0]) g_string_append_printf(t, "board_sample = %s\n", g->board_sample);
    if (g->board_scene && g->board_scene[0]) g_string_append_printf(t, "board_scene = %s\n", g->board_scene);
    g_string_append_printf(t, "board_corners = %d %d\nboard_square_mm = %.10g\nboard_height_mm = %.10g\n",
                           g->corners_w, g->corners_h, g->square_mm, g->height_mm);
    return g_string_free(t, FALSE);
}
