// rig/session/plan.c — capture plans: parse the plan file, build the step list, check
// it against a rig, and the hardware floor of a step list (see rig/rig.h,
// "Capture sessions").
// Allocations go through GLib (g_malloc0_n, g_strdup): out of memory ends the
// process with GLib's message rather than a NULL dereference; GLib allocates
// with the system malloc, so the frees below are free().
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/camera/pixfmt.h"
#include "rig/session/plan_views.h"
#include "rig/rig.h"

#define MAX_STEPS 1000000

static const char *const sections[] = { "plan", "sample", "angles", "lamps", "exposure", "capture", "operator" };
static const char *const keys[] = {
    "plan: format_version name operator notes", "sample: name kind tilt_deg tilt_azimuth_deg instruction", "angles: list range",
    "lamps: sets", "operator: end",
    "exposure: mode list_us target_fraction roi gain pixel_format",
    "capture: repeats dark_every settle_ms lamp_settle_ms frame_timeout_s retries",
};
static const char *const kinds[] = { "material_coupon", "reference_white", "chessboard", "mirror_sphere",
                                     "workpiece", "uniform_source" };

static const model_ini_entry_t *get(const model_ini_t *ini, const char *sec, const char *key)
{
    return model_ini_get(ini, sec, key);
}

static int sec_line(const model_ini_t *ini, const char *sec) { return model_ini_section_line(ini, sec); }

// Numbers of a list value; false (reported) on a bad one.
static bool parse_numbers(const model_ini_t *ini, const model_ini_entry_t *e, double **out, int *n)
{
    gchar **w = g_strsplit_set(e->value, " \t,", -1);
    int cap = 0;
    for (int i = 0; w[i]; i++) cap++;
    *out = g_malloc0_n((size_t)cap + 1, sizeof **out);
    *n = 0;
    bool ok = true;
    for (int i = 0; w[i] && ok; i++) {
        if (!w[i][0]) continue;
        if (!model_parse_double(w[i], &(*out)[*n])) {
            model_error(ini->path, e->line, "[%s] %s: '%s' is not a number", e->section, e->key, w[i]);
            ok = false;
        }
        (*n)++;
    }
    g_strfreev(w);
    if (ok && *n == 0) {
        model_error(ini->path, e->line, "[%s] %s is empty: give at least one value", e->section, e->key);
        ok = false;
    }
    return ok;
}

// An optional number in [lo, hi] (a whole number when integer); absent keeps *v.
static bool get_number(const model_ini_t *ini, const char *sec, const char *key, double *v, double lo,
                       double hi, bool integer)
{
    if (!model_ini_double_in(ini, sec, key, v, false, lo, false, hi, NULL)) return false;
    const model_ini_entry_t *e = get(ini, sec, key);
    if (e && integer && *v != floor(*v)) {
        model_error(ini->path, e->line, "[%s] %s = '%s' is not a whole number", sec, key, e->value);
        return false;
    }
    return true;
}

static void copy_text(const model_ini_t *ini, const char *sec, const char *key, char *out, size_t size)
{
    snprintf(out, size, "%s", model_ini_text(ini, sec, key, ""));
}

static int cmp_desc(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x > y ? -1 : x < y;
}

static bool check_keys(const model_ini_t *ini)
{
    for (int i = 0; i < ini->nsections; i++) {
        bool known = false;
        for (size_t k = 0; k < sizeof sections / sizeof sections[0]; k++) known |= !strcmp(ini->sections[i], sections[k]);
        known |= rig_plan_view_section(ini->sections[i]);   // [view NAME]: rig/session/plan_views.c checks its keys
        if (!known) {
            model_error(ini->path, ini->section_lines[i], "unknown section [%s]: a plan has [plan], [sample], "
                        "[angles], [lamps], [exposure], [capture], [operator] and [view NAME]", ini->sections[i]);
            return false;
        }
    }
    for (int i = 0; i < ini->nentries; i++) {
        const model_ini_entry_t *e = &ini->entries[i];
        for (size_t k = 0; k < sizeof keys / sizeof keys[0]; k++) {
            size_t n = strlen(e->section);
            if (strncmp(keys[k], e->section, n) || keys[k][n] != ':') continue;
            gchar **w = g_strsplit(keys[k] + n + 2, " ", -1);
            bool ok = false;
            for (int j = 0; w[j]; j++) ok |= !strcmp(w[j], e->key);
            g_strfreev(w);
            if (!ok) {
                model_error(ini->path, e->line, "[%s]: unknown key '%s' (keys: %s)", e->section, e->key,
                            keys[k] + n + 2);
                return false;
            }
        }
    }
    return true;
}

// [plan] format_version: 1 when absent; a higher one than this refl reads is refused.
static bool parse_format_version(rig_plan_t *p, const model_ini_t *ini)
{
    double v = 1;
    if (!get_number(ini, "plan", "format_version", &v, 1, 1e6, true)) return false;
    if (v > RIG_PLAN_FORMAT_VERSION) {
        model_error(ini->path, get(ini, "plan", "format_version")->line, "[plan] format_version = %.0f: a plan "
                    "of a newer refl (this refl reads format_version up to %d)", v, RIG_PLAN_FORMAT_VERSION);
        return false;
    }
    p->format_version = (int)v;
    return true;
}

static bool parse_lamp_sets(rig_plan_t *p, const model_ini_t *ini)
{
    const model_ini_entry_t *e = get(ini, "lamps", "sets");
    if (!e) {
        model_error(ini->path, sec_line(ini, "lamps"), "[lamps] needs sets = SET; SET; ... (a SET is "
                    "NAME+NAME, all or none)");
        return false;
    }
    p->lamp_sets_line = e->line;
    gchar **w = g_strsplit(e->value, ";", -1);
    int n = 0;
    for (int i = 0; w[i]; i++) n++;
    p->lamp_sets = g_malloc0_n((size_t)n + 1, sizeof *p->lamp_sets);
    bool ok = true;
    for (int i = 0; w[i] && ok; i++) {
        char *s = g_strstrip(w[i]);
        if (!*s) {
            model_error(ini->path, e->line, "[lamps] sets: empty lamp set (set %d); write none for all lamps off",
                        i + 1);
            ok = false;
            break;
        }
        gchar **names = g_strsplit(s, "+", -1);
        GString *norm = g_string_new("");
        for (int k = 0; names[k] && ok; k++) {
            char *nm = g_strstrip(names[k]);
            if (!*nm || strchr(nm, ' ') || strchr(nm, ',')) {
                model_error(ini->path, e->line, "[lamps] sets: bad lamp name '%s' in set '%s' (join names with +)",
                            nm, s);
                ok = false;
            }
            if ((!strcmp(nm, "all") || !strcmp(nm, "none")) && names[1]) {
                model_error(ini->path, e->line, "[lamps] sets: '%s' cannot be combined with other lamps in '%s'",
                            nm, s);
                ok = false;
            }
            g_string_append_printf(norm, "%s%s", k ? "+" : "", nm);
        }
        if (ok && norm->len >= sizeof p->lamp_sets[0]) {
            model_error(ini->path, e->line, "[lamps] sets: set '%s' is too long", s);
            ok = false;
        }
        if (ok) snprintf(p->lamp_sets[p->nlamp_sets++], sizeof p->lamp_sets[0], "%s", norm->str);
        g_string_free(norm, TRUE);
        g_strfreev(names);
    }
    g_strfreev(w);
    return ok;
}

static bool parse_angles(rig_plan_t *p, const model_ini_t *ini)
{
    const model_ini_entry_t *l = get(ini, "angles", "list"), *r = get(ini, "angles", "range");
    if (!!l == !!r) {
        model_error(ini->path, l && r ? r->line : sec_line(ini, "angles"),
                    "[angles] needs exactly one of list = DEG DEG ... or range = START STOP STEP");
        return false;
    }
    if (l) return parse_numbers(ini, l, &p->angles_deg, &p->nangles);
    double *v = NULL;
    int n = 0;
    if (!parse_numbers(ini, r, &v, &n)) {
        free(v);
        return false;
    }
    bool ok = false;
    if (n != 3) {
        model_error(ini->path, r->line, "[angles] range = START STOP STEP: %d values given, 3 needed", n);
    } else if (!(v[2] != 0) || (v[1] - v[0]) * v[2] < 0) {
        model_error(ini->path, r->line, "[angles] range = %s: the step %g must be non-zero and go from %g towards "
                    "%g", r->value, v[2], v[0], v[1]);
    } else if (fabs((v[1] - v[0]) / v[2]) > 100000) {
        model_error(ini->path, r->line, "[angles] range = %s: more than 100000 angles", r->value);
    } else {
        int cnt = (int)floor((v[1] - v[0]) / v[2] + 1e-9) + 1;
        p->angles_deg = g_malloc0_n((size_t)cnt, sizeof(double));
        for (int i = 0; i < cnt; i++) p->angles_deg[i] = v[0] + i * v[2];
        p->nangles = cnt;
        ok = true;
    }
    free(v);
    return ok;
}

static bool parse_exposure(rig_plan_t *p, const model_ini_t *ini)
{
    int sl = sec_line(ini, "exposure");
    const model_ini_entry_t *m = get(ini, "exposure", "mode"), *l = get(ini, "exposure", "list_us");
    if (!m || (strcmp(m->value, "fixed") && strcmp(m->value, "auto"))) {
        model_error(ini->path, m ? m->line : sl, "[exposure] mode = %s: write mode = fixed (list_us) or mode = auto "
                    "(bracketing over list_us)", m ? m->value : "(missing)");
        return false;
    }
    p->auto_exposure = !strcmp(m->value, "auto");
    if (!l) {
        model_error(ini->path, sl, "[exposure] needs list_us = US US ... (exposure times in microseconds)");
        return false;
    }
    p->exposure_line = l->line;
    if (!parse_numbers(ini, l, &p->exposures_us, &p->nexposures)) return false;
    for (int i = 0; i < p->nexposures; i++)
        if (!(p->exposures_us[i] > 0 && p->exposures_us[i] <= 1e8)) {
            model_error(ini->path, l->line, "[exposure] list_us: %g us is out of range (0 < us <= 1e8)",
                        p->exposures_us[i]);
            return false;
        }
    if (p->auto_exposure) qsort(p->exposures_us, (size_t)p->nexposures, sizeof(double), cmp_desc);
    for (int i = 0; i + 1 < p->nexposures && p->auto_exposure; i++)
        if (p->exposures_us[i] == p->exposures_us[i + 1]) {
            model_error(ini->path, l->line, "[exposure] list_us: %g us given twice", p->exposures_us[i]);
            return false;
        }
    p->target_fraction = 0.9;
    if (!get_number(ini, "exposure", "target_fraction", &p->target_fraction, 1e-6, 1, false)) return false;
    if (get(ini, "exposure", "target_fraction") && !p->auto_exposure) {
        model_error(ini->path, get(ini, "exposure", "target_fraction")->line,
                    "[exposure] target_fraction is for mode = auto only");
        return false;
    }
    const model_ini_entry_t *roi = get(ini, "exposure", "roi");
    if (roi) {
        double *v = NULL;
        int n = 0;
        bool ok = parse_numbers(ini, roi, &v, &n);
        if (ok && (n != 4 || v[0] < 0 || v[1] < 0 || v[2] < 1 || v[3] < 1 || v[0] != floor(v[0]) ||
                   v[1] != floor(v[1]) || v[2] != floor(v[2]) || v[3] != floor(v[3]) || v[0] + v[2] > 65536 ||
                   v[1] + v[3] > 65536)) {
            model_error(ini->path, roi->line, "[exposure] roi = %s: write roi = X Y WIDTH HEIGHT (whole pixels, "
                        "width and height >= 1)", roi->value);
            ok = false;
        }
        for (int i = 0; ok && i < 4; i++) p->roi[i] = (int)v[i];
        free(v);
        if (!ok) return false;
    }
    if (!get_number(ini, "exposure", "gain", &p->gain, 0, 100, false)) return false;
    copy_text(ini, "exposure", "pixel_format", p->pixel_format, sizeof p->pixel_format);
    if (!p->pixel_format[0]) snprintf(p->pixel_format, sizeof p->pixel_format, "Mono12");
    rig_pixfmt_t pf;
    if (!rig_pixfmt_from_name(p->pixel_format, &pf)) {
        model_error(ini->path, get(ini, "exposure", "pixel_format")->line,
                    "[exposure] pixel_format = %s: write Mono8, Mono12 or Mono16 (or Mono10, Mono10p, Mono12p, "
                    "Mono10Packed, Mono12Packed)", p->pixel_format);
        return false;
    }
    return true;
}

// The sample's operator step, as the operator reads it.
static void sample_instruction(const rig_plan_t *p, char *out, size_t size)
{
    static const char *const what[][2] = {
        { "material_coupon", "put coupon %s" }, { "reference_white", "put the reference white %s" },
        { "chessboard", "mount the calibration board %s" }, { "mirror_sphere", "place the chrome ball %s" },
        { "workpiece", "put the workpiece %s" }, { "uniform_source", "put the flat-field source %s" },
    };
    const char *fmt = "put the sample %s";
    for (size_t k = 0; k < sizeof what / sizeof what[0]; k++)
        if (!strcmp(p->sample_kind, what[k][0])) fmt = what[k][1];
    char head[256];
    snprintf(head, sizeof head, fmt, p->sample);
    if (!strcmp(p->sample_kind, "uniform_source"))
        snprintf(out, size, "%s in front of the lens, filling the frame", head);
    else if (p->tilt_deg != 0)
        snprintf(out, size, "%s on the %g deg wedge (hinge at azimuth %g deg) at the turntable centre, facing the "
                 "camera", head, p->tilt_deg, p->tilt_azimuth_deg);
    else if (!strcmp(p->sample_kind, "mirror_sphere"))
        snprintf(out, size, "%s at the turntable centre", head);
    else
        snprintf(out, size, "%s flat at the turntable centre%s", head,
                 !strcmp(p->sample_kind, "chessboard") ? ", facing the camera" : "");
}

// The operator steps: the [sample] one (generated, or [sample] instruction),
// and [operator] end.
static bool parse_operator(rig_plan_t *p, const model_ini_t *ini)
{
    p->ops = g_malloc0_n(2, sizeof *p->ops);
    rig_op_step_t *o = &p->ops[0];
    const model_ini_entry_t *e = get(ini, "sample", "instruction");
    if (e && !e->value[0]) {
        model_error(ini->path, e->line, "[sample] instruction is empty: write what the operator does, or leave the "
                    "key out");
        return false;
    }
    if (e) snprintf(o->instruction, sizeof o->instruction, "%s", e->value);
    else sample_instruction(p, o->instruction, sizeof o->instruction);
    o->pose = true;
    snprintf(o->sample, sizeof o->sample, "%s", p->sample);
    o->tilt_deg = p->tilt_deg;
    o->tilt_azimuth_deg = p->tilt_azimuth_deg;
    p->nops = 1;
    if ((e = get(ini, "operator", "end"))) {
        if (!e->value[0]) {
            model_error(ini->path, e->line, "[operator] end is empty: write what the operator does after the last "
                        "frame, or leave the key out");
            return false;
        }
        snprintf(p->ops[1].instruction, sizeof p->ops[1].instruction, "%s", e->value);
        p->nops = 2;
    }
    return true;
}

static bool build_steps(rig_plan_t *p, const model_ini_t *ini)
{
    double light = (double)p->nangles * p->nlamp_sets * p->nexposures * p->repeats;
    double total = light + (p->dark_every ? floor(light / p->dark_every) : 0);
    if (total > MAX_STEPS) {
        model_error(ini->path, sec_line(ini, "angles"), "the plan has %.0f steps; at most %d fit one session: split "
                    "it", total, MAX_STEPS);
        return false;
    }
    bool end = p->nops > 1;
    p->steps = g_malloc0_n((size_t)total + 2 + end, sizeof *p->steps);
    int n = 0, nlight = 0, group = 0;
    p->steps[n++] = (rig_step_t){ .kind = RIG_STEP_OPERATOR, .op = 0, .angle_index = -1, .lamp_set = -1,
                                  .exposure_index = -1, .group = -1, .lamps = "none" };
    for (int a = 0; a < p->nangles; a++)
        for (int l = 0; l < p->nlamp_sets; l++)
            for (int r = 0; r < p->repeats; r++, group++)
                for (int e = 0; e < p->nexposures; e++) {
                    if (!rig_plan_view_takes(p, a, l, e)) continue;   // [view NAME] (rig/session/plan_views.c)
                    rig_step_t *s = &p->steps[n++];
                    s->kind = RIG_STEP_LIGHT;
                    s->op = -1;
                    s->angle_index = a;
                    s->lamp_set = l;
                    s->exposure_index = e;
                    s->repeat = r;
                    s->group = group;
                    s->angle_deg = p->angles_deg[a];
                    snprintf(s->lamps, sizeof s->lamps, "%s", p->lamp_sets[l]);
                    s->exposure_us = p->exposures_us[e];
                    s->gain = p->gain;
                    if (p->dark_every && ++nlight % p->dark_every == 0) {
                        rig_step_t *d = &p->steps[n++];
                        *d = *s;
                        d->kind = RIG_STEP_DARK;
                        d->group = -1;
                        d->lamp_set = -1;
                        snprintf(d->lamps, sizeof d->lamps, "none");
                    }
                }
    if (end)
        p->steps[n++] = (rig_step_t){ .kind = RIG_STEP_OPERATOR, .op = 1, .angle_index = -1, .lamp_set = -1,
                                      .exposure_index = -1, .group = -1, .lamps = "none" };
    // Order in the file: angle, lamp set, exposure, repeat; with repeats the
    // bracket of one repeat is kept together (exposure inside repeat).
    for (int i = 0; i < n; i++) p->steps[i].index = i;
    p->nsteps = n;
    return true;
}

rig_plan_t *rig_plan_parse(const char *text, size_t len, const char *name)
{
    model_ini_t *ini = model_ini_parse(text, len, name);
    if (!ini) return NULL;
    rig_plan_t *p = g_malloc0_n(1, sizeof *p);
    bool ok = false;
    p->path = g_strdup(name);
    p->text = g_strndup(text, len);
    model_sha256_hex(text, len, p->sha256);
    if (!check_keys(ini)) goto done;
    for (size_t k = 0; k < 5; k++) {
        static const char *const need[] = { "sample", "angles", "lamps", "exposure", NULL };
        if (!need[k]) break;
        if (!sec_line(ini, need[k])) {
            model_error(ini->path, 0, "missing section [%s] (see examples/plans/)", need[k]);
            goto done;
        }
    }
    if (!parse_format_version(p, ini)) goto done;
    copy_text(ini, "plan", "name", p->name, sizeof p->name);
    copy_text(ini, "plan", "operator", p->operator_name, sizeof p->operator_name);
    copy_text(ini, "plan", "notes", p->notes, sizeof p->notes);
    copy_text(ini, "sample", "name", p->sample, sizeof p->sample);
    copy_text(ini, "sample", "kind", p->sample_kind, sizeof p->sample_kind);
    if (!p->sample[0]) {
        model_error(ini->path, sec_line(ini, "sample"), "[sample] needs name = NAME");
        goto done;
    }
    bool kind_ok = false;
    for (size_t k = 0; k < sizeof kinds / sizeof kinds[0]; k++) kind_ok |= !strcmp(p->sample_kind, kinds[k]);
    if (!kind_ok) {
        const model_ini_entry_t *e = get(ini, "sample", "kind");
        model_error(ini->path, e ? e->line : sec_line(ini, "sample"), "[sample] kind = %s: write material_coupon, "
                    "reference_white, chessboard, mirror_sphere, workpiece or uniform_source", e ? e->value : "(missing)");
        goto done;
    }
    if (!get_number(ini, "sample", "tilt_deg", &p->tilt_deg, -80, 80, false) ||
        !get_number(ini, "sample", "tilt_azimuth_deg", &p->tilt_azimuth_deg, -360, 360, false))
        goto done;
    if (!parse_operator(p, ini) || !parse_angles(p, ini) || !parse_lamp_sets(p, ini) || !parse_exposure(p, ini))
        goto done;
    double v = 1;
    if (!get_number(ini, "capture", "repeats", &v, 1, 10000, true)) goto done;
    p->repeats = (int)v;
    v = 0;
    if (!get_number(ini, "capture", "dark_every", &v, 0, 1e6, true)) goto done;
    p->dark_every = (int)v;
    if (!get_number(ini, "capture", "settle_ms", &p->settle_ms, 0, 3.6e6, false) ||
        !get_number(ini, "capture", "lamp_settle_ms", &p->lamp_settle_ms, 0, 3.6e6, false))
        goto done;
    p->frame_timeout_s = 10;
    v = 2;
    if (!get_number(ini, "capture", "frame_timeout_s", &p->frame_timeout_s, 0.01, 3600, false) ||
        !get_number(ini, "capture", "retries", &v, 0, 100, true))
        goto done;
    p->retries = (int)v;
    for (int i = 0; i < p->nangles; i++)
        if (!(fabs(p->angles_deg[i]) <= 1e4)) {
            const model_ini_entry_t *e = get(ini, "angles", "list");
            if (!e) e = get(ini, "angles", "range");
            model_error(ini->path, e->line, "[angles]: %g deg is beyond the turntable's range (-10000 .. 10000)",
                        p->angles_deg[i]);
            goto done;
        }
    ok = rig_plan_views_parse(p, ini) && build_steps(p, ini);
done:
    model_ini_free(ini);
    if (!ok) {
        rig_plan_free(p);
        return NULL;
    }
    return p;
}

rig_plan_t *rig_plan_load(const char *path)
{
    size_t len = 0;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    rig_plan_t *p = rig_plan_parse(text, len, path);
    free(text);
    return p;
}

void rig_plan_free(rig_plan_t *p)
{
    if (!p) return;
    free(p->path);
    g_free(p->text);
    free(p->angles_deg);
    free(p->lamp_sets);
    free(p->exposures_us);
    free(p->steps);
    free(p->ops);
    rig_plan_views_free(p);
    free(p);
}

static uint32_t all_mask(const rig_lamps_t *l)
{
    return !l ? 0 : rig_lamps_count(l) >= 32 ? 0xffffffffu : ((uint32_t)1 << rig_lamps_count(l)) - 1;
}

// One camera against the plan: every exposure, the gain and the format set and
// read back (the exposure restored), the ROI within its frame. 0 or RIG_ERR_*.
static int bind_camera(const rig_plan_t *p, rig_camera_t *c)
{
    int rc;
    rig_frame_meta_t before, m;
    bool q = model_error_quiet_thread(true);
    rc = rig_camera_settings(c, &before);
    if (!rc && (rc = rig_camera_set_pixel_format(c, p->pixel_format)))
        model_error(p->path, 0, "[exposure] pixel_format = %s: the camera refuses it (%s)", p->pixel_format,
                    model_last_error());
    if (!rc && (rc = rig_camera_set_gain(c, p->gain)))
        model_error(p->path, 0, "[exposure] gain = %g: the camera refuses it (%s)", p->gain, model_last_error());
    for (int i = 0; !rc && i < p->nexposures; i++) {
        double us = p->exposures_us[i];
        if ((rc = rig_camera_set_exposure_us(c, us)) == 0 && (rc = rig_camera_settings(c, &m)) == 0 &&
            !(fabs(m.exposure_us - us) <= 0.01 * us + 1)) {
            rc = RIG_ERR_INVALID;
        }
        if (rc)
            model_error(p->path, p->exposure_line, "[exposure] list_us: the camera %s does not accept %g us",
                        rig_camera_name(c), us);
    }
    if (!rc && !(rc = rig_camera_settings(c, &m)) && p->roi[2] &&
        (p->roi[0] + p->roi[2] > m.width || p->roi[1] + p->roi[3] > m.height)) {
        model_error(p->path, 0, "[exposure] roi %d %d %d %d does not fit the %d x %d frame of the camera %s",
                    p->roi[0], p->roi[1], p->roi[2], p->roi[3], m.width, m.height, rig_camera_name(c));
        rc = RIG_ERR_INVALID;
    }
    model_error_quiet_thread(q);
    if (!rc) {
        rig_camera_set_exposure_us(c, before.exposure_us);
    } else {
        // re-report the plan error loudly unless the caller silenced errors
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(NULL, 0, "%s", msg);
    }
    return rc;
}

int rig_plan_bind(rig_plan_t *p, rig_t *r)
{
    uint32_t *masks = g_malloc0_n((size_t)p->nlamp_sets + 1, sizeof *masks);
    int rc = 0;
    for (int s = 0; s < p->nlamp_sets; s++) {
        if (!strcmp(p->lamp_sets[s], "none")) continue;
        if (!strcmp(p->lamp_sets[s], "all")) {
            masks[s] = all_mask(r->lamps);
            continue;
        }
        gchar **names = g_strsplit(p->lamp_sets[s], "+", -1);
        for (int k = 0; names[k] && !rc; k++) {
            int i = rig_lamps_find(r->lamps, names[k]);
            if (i < 0) {
                GString *known = g_string_new("");
                for (int j = 0; r->lamps && j < rig_lamps_count(r->lamps); j++)
                    g_string_append_printf(known, "%s%s", j ? ", " : "", rig_lamps_name(r->lamps, j));
                model_error(p->path, p->lamp_sets_line, "[lamps] sets: the rig %s has no lamp '%s' (its lamps: %s)",
                            r->path, names[k], known->len ? known->str : "none");
                g_string_free(known, TRUE);
                rc = RIG_ERR_INVALID;
            }
            masks[s] |= 1u << (i & 31);
        }
        g_strfreev(names);
        if (rc) goto done;
    }
    for (int i = 0; i < p->nsteps; i++)
        p->steps[i].lamp_mask = p->steps[i].lamp_set >= 0 ? masks[p->steps[i].lamp_set] : 0;
    bool moves = false;
    for (int i = 0; i < p->nangles; i++) moves |= p->angles_deg[i] != 0;
    if (moves && !r->turntable) {
        model_error(p->path, 0, "[angles]: the plan turns the sample but the rig %s has no turntable", r->path);
        rc = RIG_ERR_NO_DEVICE;
        goto done;
    }
    if (!r->camera) {
        model_error(p->path, 0, "the rig %s has no camera: a capture needs one", r->path);
        rc = RIG_ERR_NO_DEVICE;
        goto done;
    }
    if (r->virt) {
        // the sample must exist and take its pose; nothing is put on the
        // table (the operator step poses it)
        bool q = model_error_quiet_thread(true);
        int e = rig_virtual_check_sample_pose(r->virt, p->sample, p->tilt_deg, p->tilt_azimuth_deg);
        model_error_quiet_thread(q);
        if (e) {
            model_error(p->path, 0, "[sample] name = %s, tilt %g deg: the virtual rig (truth file %s) refuses it: %s",
                        p->sample, p->tilt_deg, rig_virtual_truth_path(r->virt), model_last_error());
            rc = RIG_ERR_INVALID;
            goto done;
        }
    }
    // Every camera: set every exposure, the gain and the format, read them back.
    for (int k = 0; k < r->ncameras && !rc; k++) rc = bind_camera(p, r->cameras[k]);
done:
    free(masks);
    return rc;
}

int rig_plan_operator_pose(const rig_plan_t *p, rig_t *r, int step, char *what, size_t size)
{
    const rig_step_t *s = step >= 0 && step < p->nsteps ? &p->steps[step] : NULL;
    if (!s || s->kind != RIG_STEP_OPERATOR || s->op < 0 || s->op >= p->nops)
        return rig_fail(RIG_ERR_INVALID, "plan %s: step %d is not an operator step", p->path, step);
    const rig_op_step_t *o = &p->ops[s->op];
    char buf[256];
    if (!what) {
        what = buf;
        size = sizeof buf;
    }
    if (!o->pose) {
        snprintf(what, size, "no pose to set");
        return 0;
    }
    if (!r->virt) {
        snprintf(what, size, "real rig: the operator put %s (tilt %g deg, hinge azimuth %g deg)", o->sample,
                 o->tilt_deg, o->tilt_azimuth_deg);
        return 0;
    }
    int rc = rig_virtual_set_sample_pose(r->virt, o->sample, o->tilt_deg, o->tilt_azimuth_deg);
    if (rc) return rc;
    snprintf(what, size, "virtual rig: sample %s posed at tilt %g deg, hinge azimuth %g deg", o->sample, o->tilt_deg,
             o->tilt_azimuth_deg);
    double turn, dx, dy;
    size_t n = strlen(what);
    if (rig_virtual_last_placement(r->virt, &turn, &dx, &dy) && n < size)
        snprintf(what + n, size - n, "; truth placement error: turn %.3f deg, shift %.3f %.3f mm", turn, dx, dy);
    return 0;
}

double rig_plan_floor_s(const rig_plan_t *p, const rig_t *r, int from_step)
{
    double t = 0, angle = NAN;
    uint32_t mask = 0;
    for (int i = from_step; i < p->nsteps; i++) {
        const rig_step_t *s = &p->steps[i];
        if (s->kind == RIG_STEP_OPERATOR) continue;   // the operator's time is not the hardware's
        double motion = 0, settle = 0, lamp = 0;
        if (r->turntable && !(s->angle_deg == angle)) {
            if (isfinite(angle)) motion = rig_motion_time_s(s->angle_deg - angle, r->speed_deg_s, r->accel_deg_s2);
            settle = 1e-3 * p->settle_ms;
            angle = s->angle_deg;
        }
        if (s->lamp_mask != mask) {
            lamp = (r->lamps ? rig_lamps_settle_s(r->lamps, mask, s->lamp_mask) : 0) + 1e-3 * p->lamp_settle_ms;
            mask = s->lamp_mask;
        }
        t += (isfinite(motion) ? motion : 0) + fmax(settle, lamp) + 1e-6 * s->exposure_us;
    }
    return t;
}

// ---------------------------------------------------------------------------
// The plan as text (rig_plan_text): what rig_plan_parse reads back to the same
// steps.

// The shortest decimal of v that reads back as v.
static void put_number(GString *t, double v)
{
    char b[40];
    for (int prec = 6; prec <= 17; prec++) {
        snprintf(b, sizeof b, "%.*g", prec, v);
        if (strtod(b, NULL) == v) break;
    }
    g_string_append(t, b);
}

// key = text, when the text is one a plan file holds as it is.
static bool put_text(GString *t, const char *key, const char *v, bool optional)
{
    if (optional && !v[0]) return true;
    bool bad = strchr(v, '\n') || strchr(v, '\r') || v[0] == '#' || strstr(v, " #") || strstr(v, "\t#") ||
               v[0] == ' ' || (v[0] && v[strlen(v) - 1] == ' ');
    if (bad) {
        model_error(NULL, 0, "capture plan: %s = '%s' cannot be written to a plan file (a line break, a '#' after a "
                    "blank or blanks at the ends)", key, v);
        return false;
    }
    g_string_append_printf(t, "%s = %s\n", key, v);
    return true;
}

static void put_list(GString *t, const char *key, const double *v, int n, const bool *take)
{
    g_string_append_printf(t, "%s =", key);
    for (int i = 0; i < n; i++)
        if (!take || take[i]) {
            g_string_append_c(t, ' ');
            put_number(t, v[i]);
        }
    g_string_append_c(t, '\n');
}

static bool put_sets(GString *t, const rig_plan_t *p, const bool *take)
{
    g_string_append(t, "sets =");
    bool first = true;
    for (int i = 0; i < p->nlamp_sets; i++) {
        if (take && !take[i]) continue;
        if (strchr(p->lamp_sets[i], ';') || strchr(p->lamp_sets[i], '#') || !p->lamp_sets[i][0]) {
            model_error(NULL, 0, "capture plan: lamp set '%s' cannot be written to a plan file", p->lamp_sets[i]);
            return false;
        }
        g_string_append_printf(t, "%s %s", first ? "" : ";", p->lamp_sets[i]);
        first = false;
    }
    g_string_append_c(t, '\n');
    return true;
}

static bool put_views(GString *t, const rig_plan_t *p)
{
    for (int k = 0; k < p->nviews; k++) {
        const rig_plan_view_t *v = &p->views[k];
        if (!rig_plan_view_section(v->name) || strchr(v->name, ']') || strchr(v->name, '#')) {
            model_error(NULL, 0, "capture plan: '%s' is not a view's section name (view NAME)", v->name);
            return false;
        }
        g_string_append_printf(t, "\n[%s]\nangle_deg = ", v->name);
        put_number(t, p->angles_deg[v->angle_index]);
        g_string_append_c(t, '\n');
        if (!put_sets(t, p, v->sets)) return false;
        put_list(t, "list_us", p->exposures_us, p->nexposures, v->exposures);
    }
    return true;
}

char *rig_plan_text(const rig_plan_t *p, const char *comment)
{
    GString *t = g_string_new("");
    if (comment) {
        gchar **lines = g_strsplit(comment, "\n", -1);
        for (int i = 0; lines[i]; i++) g_string_append_printf(t, "#%s%s\n", lines[i][0] ? " " : "", lines[i]);
        g_strfreev(lines);
    }
    g_string_append_printf(t, "[plan]\nformat_version = %d\n", RIG_PLAN_FORMAT_VERSION);
    bool ok = put_text(t, "name", p->name, true) && put_text(t, "operator", p->operator_name, true) &&
              put_text(t, "notes", p->notes, true);
    g_string_append(t, "\n[sample]\n");
    ok = ok && put_text(t, "name", p->sample, false) && put_text(t, "kind", p->sample_kind, false);
    g_string_append(t, "tilt_deg = ");
    put_number(t, p->tilt_deg);
    g_string_append(t, "\ntilt_azimuth_deg = ");
    put_number(t, p->tilt_azimuth_deg);
    g_string_append_c(t, '\n');
    if (p->nops > 0) {   // the operator's instruction, when not the one [sample] generates
        char gen[sizeof p->ops[0].instruction];
        sample_instruction(p, gen, sizeof gen);
        if (strcmp(gen, p->ops[0].instruction)) ok = ok && put_text(t, "instruction", p->ops[0].instruction, false);
    }
    if (p->nops > 1) {
        g_string_append(t, "\n[operator]\n");
        ok = ok && put_text(t, "end", p->ops[1].instruction, false);
    }
    g_string_append(t, "\n[angles]\n");
    put_list(t, "list", p->angles_deg, p->nangles, NULL);
    g_string_append(t, "\n[lamps]\n");
    ok = ok && put_sets(t, p, NULL);
    g_string_append_printf(t, "\n[exposure]\nmode = %s\n", p->auto_exposure ? "auto" : "fixed");
    put_list(t, "list_us", p->exposures_us, p->nexposures, NULL);
    if (p->auto_exposure) {
        g_string_append(t, "target_fraction = ");
        put_number(t, p->target_fraction);
        g_string_append_c(t, '\n');
    }
    if (p->roi[2]) g_string_append_printf(t, "roi = %d %d %d %d\n", p->roi[0], p->roi[1], p->roi[2], p->roi[3]);
    g_string_append(t, "gain = ");
    put_number(t, p->gain);
    g_string_append_c(t, '\n');
    ok = ok && put_text(t, "pixel_format", p->pixel_format[0] ? p->pixel_format : "Mono12", false);
    g_string_append_printf(t, "\n[capture]\nrepeats = %d\ndark_every = %d\nsettle_ms = ", p->repeats, p->dark_every);
    put_number(t, p->settle_ms);
    g_string_append(t, "\nlamp_settle_ms = ");
    put_number(t, p->lamp_settle_ms);
    g_string_append(t, "\nframe_timeout_s = ");
    put_number(t, p->frame_timeout_s);
    g_string_append_printf(t, "\nretries = %d\n", p->retries);
    ok = ok && put_views(t, p);
    char *s = g_string_free(t, !ok);
    return s;
}
