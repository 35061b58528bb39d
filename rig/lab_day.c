// rig/lab_day.c — the lab day of a lab file on a rig (rig_lab_day_write): the capture plans
// the day takes (the first check of the workpiece, the reference white under each lamp, each
// coupon on its wedge), generated for the rig's own lamps and written by the plan format's owner
// (rig_plan_text), and day.sh, the day's facts as shell assignments for scripts/demo.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/base/report.h"
#include "model/model.h"
#include "rig/lab.h"
#include "rig/rig.h"

typedef struct {
    const rig_lab_t *lab;
    char           **lamps;   // the rig's lamps, NULL-terminated
    int              nlamps;
    const char      *rig_path, *dir;
} day_t;

static int cmp_desc(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x < y) - (x > y);
}

// A plan of one sample kind; arrays empty (filled by the callers).
static rig_plan_t *plan_new(const char *name, const char *sample, const char *kind, int nangles, int nsets, int nexp)
{
    rig_plan_t *p = calloc(1, sizeof *p);
    if (!p) return NULL;
    p->angles_deg = calloc((size_t)nangles + 1, sizeof *p->angles_deg);
    p->lamp_sets = calloc((size_t)nsets + 1, sizeof *p->lamp_sets);
    p->exposures_us = calloc((size_t)nexp + 1, sizeof *p->exposures_us);
    if (!p->angles_deg || !p->lamp_sets || !p->exposures_us) {
        rig_plan_free(p);
        return NULL;
    }
    snprintf(p->name, sizeof p->name, "%s", name);
    snprintf(p->operator_name, sizeof p->operator_name, "lab");
    snprintf(p->sample, sizeof p->sample, "%s", sample);
    snprintf(p->sample_kind, sizeof p->sample_kind, "%s", kind);
    snprintf(p->pixel_format, sizeof p->pixel_format, "Mono12");
    p->repeats = 1;
    p->settle_ms = 50;
    p->frame_timeout_s = 10;
    p->retries = 2;
    p->target_fraction = 0.9;
    return p;
}

// Each of the rig's lamps alone.
static void each_lamp(const day_t *d, rig_plan_t *p)
{
    for (int l = 0; l < d->nlamps; l++) snprintf(p->lamp_sets[p->nlamp_sets++], sizeof p->lamp_sets[0], "%s", d->lamps[l]);
}

// The plan's text (read back to check it), written to dir/file; the path goes to out.
static bool write_plan(const day_t *d, rig_plan_t *p, const char *file, const char *what, rig_lab_day_t *out)
{
    char *comment = g_strdup_printf("refl plan day: %s, for the lamps of %s (lab file %s, sha256 %s).\nWritten "
                                    "for this rig and lab: edit the lab file, not this plan.", what, d->rig_path,
                                    d->lab->path, d->lab->sha256);
    char *text = rig_plan_text(p, comment), *path = g_build_filename(d->dir, file, NULL);
    rig_plan_t *back = NULL;
    bool ok = text && (back = rig_plan_parse(text, strlen(text), path)) && model_write_file_atomic(path, text);
    if (!ok && text && !back) {
        char *m = g_strdup(model_last_error());
        model_error_set(path, 0, "the generated plan does not read back (%s)", m);
        g_free(m);
    }
    if (ok) out->plans[out->nplans++] = g_strdup(path);
    rig_plan_free(back);
    free(text);
    g_free(comment);
    g_free(path);
    rig_plan_free(p);
    return ok;
}

// check_lamps: every set's lamps are the rig's (NAME+NAME..., all, none).
static bool check_sets(const day_t *d, rig_plan_t *p)
{
    const rig_lab_t *L = d->lab;
    gchar **sets = g_strsplit(L->workpiece.check_lamps, ";", -1);
    bool ok = true;
    for (int s = 0; sets[s] && ok; s++) {
        char *set = g_strstrip(sets[s]);
        if (!*set) continue;
        gchar **names = g_strsplit(set, "+", -1);
        for (int n = 0; names[n] && ok; n++) {
            char *nm = g_strstrip(names[n]);
            bool known = !strcmp(nm, "all") || !strcmp(nm, "none");
            for (int l = 0; l < d->nlamps && !known; l++) known = !strcmp(d->lamps[l], nm);
            if (!known) {
                GString *g = g_string_new("");
                for (int l = 0; l < d->nlamps; l++) g_string_append_printf(g, "%s%s", l ? ", " : "", d->lamps[l]);
                model_error_set(L->path, L->workpiece.check_lamps_line, "[workpiece] check_lamps: the rig %s has no "
                                "lamp '%s' (its lamps: %s)", d->rig_path, nm, g->str);
                g_string_free(g, TRUE);
                ok = false;
            }
        }
        g_strfreev(names);
        if (ok && p->nlamp_sets < RIG_LAB_MAX_ITEMS)
            snprintf(p->lamp_sets[p->nlamp_sets++], sizeof p->lamp_sets[0], "%s", set);
    }
    g_strfreev(sets);
    return ok;
}

// The first session of the day: the workpiece at its views under the check lamps, with darks.
static bool check_plan(const day_t *d, rig_lab_day_t *out)
{
    const rig_lab_t *L = d->lab;
    if (L->workpiece.plan) {
        out->plans[out->nplans++] = g_strdup(L->workpiece.plan);
        return true;
    }
    int nsets = L->workpiece.check_lamps[0] ? RIG_LAB_MAX_ITEMS : d->nlamps;
    rig_plan_t *p = plan_new("the workpiece: a first session, each view under the check lamps, with darks",
                             L->workpiece.sample, "workpiece", L->workpiece.nangles, nsets, 1);
    if (!p) return model_error_set(NULL, 0, "out of memory"), false;
    memcpy(p->angles_deg, L->workpiece.angles_deg, sizeof(double) * (size_t)L->workpiece.nangles);
    p->nangles = L->workpiece.nangles;
    if (L->workpiece.check_lamps[0]) {
        if (!check_sets(d, p)) {
            rig_plan_free(p);
            return false;
        }
    } else {
        each_lamp(d, p);
    }
    p->exposures_us[p->nexposures++] = L->workpiece.check_exposure_us;
    p->dark_every = p->nangles;
    return write_plan(d, p, "check.ini", "the workpiece's first session", out);
}

static bool white_plan(const day_t *d, rig_lab_day_t *out)
{
    const rig_lab_t *L = d->lab;
    if (L->white.plan) {
        out->plans[out->nplans++] = g_strdup(L->white.plan);
        return true;
    }
    rig_plan_t *p = plan_new("reference white, each lamp alone (kc*I per lamp)", L->white.sample, "reference_white",
                             L->white.nangles, d->nlamps, 1);
    if (!p) return model_error_set(NULL, 0, "out of memory"), false;
    memcpy(p->angles_deg, L->white.angles_deg, sizeof(double) * (size_t)L->white.nangles);
    p->nangles = L->white.nangles;
    each_lamp(d, p);
    p->exposures_us[p->nexposures++] = L->white.exposure_us;
    return write_plan(d, p, "reference_white.ini", "the reference white under each lamp", out);
}

static bool coupon_plan(const day_t *d, const rig_lab_coupon_t *k, rig_lab_day_t *out)
{
    if (k->plan) {
        out->plans[out->nplans++] = g_strdup(k->plan);
        return true;
    }
    char name[128], file[RIG_LAB_NAME_MAX + 16];
    snprintf(name, sizeof name, "%s coupon on a %g deg wedge, each lamp, bracketed", k->name, k->tilt_deg);
    rig_plan_t *p = plan_new(name, k->sample, "material_coupon", k->nangles, d->nlamps, k->nexposures);
    if (!p) return model_error_set(NULL, 0, "out of memory"), false;
    memcpy(p->angles_deg, k->angles_deg, sizeof(double) * (size_t)k->nangles);
    p->nangles = k->nangles;
    each_lamp(d, p);
    memcpy(p->exposures_us, k->exposures_us, sizeof(double) * (size_t)k->nexposures);
    p->nexposures = k->nexposures;
    qsort(p->exposures_us, (size_t)p->nexposures, sizeof(double), cmp_desc);   // a ladder: longest first
    p->auto_exposure = true;
    p->target_fraction = k->target_fraction;
    p->tilt_deg = k->tilt_deg;
    p->tilt_azimuth_deg = k->tilt_azimuth_deg;
    snprintf(file, sizeof file, "coupon_%s.ini", k->name);
    return write_plan(d, p, file, "a coupon on its wedge under each lamp", out);
}

// ---- day.sh ----------------------------------------------------------------------------------

static void put(GString *s, const char *var, const char *value)
{
    char *q = g_shell_quote(value ? value : "");
    g_string_append_printf(s, "%s=%s\n", var, q);
    g_free(q);
}

static void put_num(GString *s, const char *var, double v)
{
    char b[64] = "";
    if (isfinite(v)) snprintf(b, sizeof b, "%.10g", v);
    put(s, var, b);
}

static char *num_list(const double *v, int n, const char *sep)
{
    GString *g = g_string_new("");
    for (int i = 0; i < n; i++) g_string_append_printf(g, "%s%.10g", i ? sep : "", v[i]);
    return g_string_free(g, FALSE);
}

// VAR=('a' 'b' ...) of n strings got by item(i).
static void put_array(GString *s, const char *var, int n, const char *(*item)(const rig_lab_t *, int, char *),
                      const rig_lab_t *L)
{
    g_string_append_printf(s, "%s=(", var);
    for (int i = 0; i < n; i++) {
        char buf[128];
        char *q = g_shell_quote(item(L, i, buf));
        g_string_append_printf(s, "%s%s", i ? " " : "", q);
        g_free(q);
    }
    g_string_append(s, ")\n");
}

static const char *c_name(const rig_lab_t *L, int i, char *b) { (void)b; return L->coupons[i].name; }
static const char *c_scene(const rig_lab_t *L, int i, char *b) { (void)b; return L->coupons[i].scene; }
static const char *c_tilt(const rig_lab_t *L, int i, char *b)
{
    snprintf(b, 128, "%.10g", L->coupons[i].tilt_deg);
    return b;
}
static const char *c_cells(const rig_lab_t *L, int i, char *b)
{
    snprintf(b, 128, "%.10g", L->coupons[i].albedo_cells_mm);
    return L->coupons[i].albedo_cells_mm > 0 ? b : "";
}
static const char *c_window(const rig_lab_t *L, int i, char *b)
{
    snprintf(b, 128, "%d", L->coupons[i].window_px);
    return L->coupons[i].window_px ? b : "";
}
static const char *c_step(const rig_lab_t *L, int i, char *b)
{
    snprintf(b, 128, "%d", L->coupons[i].step_px);
    return L->coupons[i].step_px ? b : "";
}
static const char *p_name(const rig_lab_t *L, int i, char *b) { (void)b; return L->workpiece.priors[i]; }
static const char *d_name(const rig_lab_t *L, int i, char *b) { (void)b; return L->descriptions[i].name; }
static const char *d_scene(const rig_lab_t *L, int i, char *b) { (void)b; return L->descriptions[i].scene; }
static const char *d_expect(const rig_lab_t *L, int i, char *b)
{
    (void)b;
    return L->descriptions[i].correct ? "correct" : "incorrect";
}
static const char *d_what(const rig_lab_t *L, int i, char *b)
{
    (void)b;
    return L->descriptions[i].what[0] ? L->descriptions[i].what : L->descriptions[i].name;
}

static char *day_script(const day_t *d, const rig_lab_day_t *out)
{
    const rig_lab_t *L = d->lab;
    GString *s = g_string_new("");
    g_string_append_printf(s, "# refl plan day: the lab day's facts of the lab file %s (sha256 %s) on the rig %s,\n"
                           "# as shell assignments for scripts/demo (lengths mm, angles deg, exposures us).\n",
                           L->path, L->sha256, d->rig_path);
    put(s, "LAB_FILE", L->path);
    put(s, "LAB_NAME", L->name);
    put(s, "LAB_GEOMETRY_TILTS", L->geometry.tilts);
    put(s, "LAB_GEOMETRY_ANGLES", L->geometry.angles);
    put_num(s, "LAB_GEOMETRY_EXPOSURE_US", L->geometry.exposure_us);
    put(s, "LAB_BOARD_SAMPLE", L->geometry.board_sample);
    put_num(s, "LAB_BOARD_CORNERS_W", L->geometry.corners_w);
    put_num(s, "LAB_BOARD_CORNERS_H", L->geometry.corners_h);
    put_num(s, "LAB_BOARD_SQUARE_MM", L->geometry.square_mm);
    put_num(s, "LAB_BOARD_HEIGHT_MM", L->geometry.height_mm);
    char *centre = num_list(L->sphere.centre_mm, 3, ",");
    put(s, "LAB_SPHERE_SAMPLE", L->sphere.sample);
    put(s, "LAB_SPHERE_CENTRE_MM", centre);
    g_free(centre);
    put_num(s, "LAB_SPHERE_RADIUS_MM", L->sphere.radius_mm);
    put_num(s, "LAB_LAMP_RADIUS_MM", L->lamp_radius_mm);
    put_num(s, "LAB_RADIANCE", L->flat_field.radiance);
    put(s, "LAB_RADIANCE_UNIT", L->flat_field.unit);
    put(s, "LAB_WHITE_SCENE", L->white.scene);
    put(s, "LAB_WHITE_CERTIFICATE", L->white.certificate);
    put_num(s, "LAB_WHITE_ALBEDO", L->white.albedo);
    put_num(s, "LAB_WHITE_ALBEDO_STD", L->white.albedo_std);
    put(s, "LAB_CHECK_PLAN", out->plans[0]);
    put(s, "LAB_WHITE_PLAN", out->plans[1]);
    put_array(s, "LAB_COUPON_NAMES", L->ncoupons, c_name, L);
    g_string_append(s, "LAB_COUPON_PLANS=(");
    for (int k = 0; k < L->ncoupons; k++) {
        char *q = g_shell_quote(out->plans[2 + k]);
        g_string_append_printf(s, "%s%s", k ? " " : "", q);
        g_free(q);
    }
    g_string_append(s, ")\n");
    put_array(s, "LAB_COUPON_SCENES", L->ncoupons, c_scene, L);
    put_array(s, "LAB_COUPON_TILTS_DEG", L->ncoupons, c_tilt, L);
    put_array(s, "LAB_COUPON_ALBEDO_CELLS_MM", L->ncoupons, c_cells, L);
    put_array(s, "LAB_COUPON_WINDOW_PX", L->ncoupons, c_window, L);
    put_array(s, "LAB_COUPON_STEP_PX", L->ncoupons, c_step, L);
    put(s, "LAB_WORKPIECE_SAMPLE", L->workpiece.sample);
    put(s, "LAB_WORKPIECE_SCENE", L->workpiece.scene);
    char *angles = num_list(L->workpiece.angles_deg, L->workpiece.nangles, ",");
    char *exps = num_list(L->workpiece.exposures_us, L->workpiece.nexposures, ",");
    put(s, "LAB_WORKPIECE_ANGLES_DEG", angles);
    put(s, "LAB_WORKPIECE_EXPOSURES_US", exps);
    g_free(angles);
    g_free(exps);
    put_array(s, "LAB_PRIORS", L->workpiece.npriors, p_name, L);
    put_array(s, "LAB_DESC_NAMES", L->ndescriptions, d_name, L);
    put_array(s, "LAB_DESC_SCENES", L->ndescriptions, d_scene, L);
    put_array(s, "LAB_DESC_EXPECT", L->ndescriptions, d_expect, L);
    put_array(s, "LAB_DESC_WHAT", L->ndescriptions, d_what, L);
    return g_string_free(s, FALSE);
}

bool rig_lab_day_write(const rig_lab_t *lab, const char *rig_path, const char *dir, rig_lab_day_t *out)
{
    memset(out, 0, sizeof *out);
    day_t d = { .lab = lab, .rig_path = rig_path, .dir = dir };
    if (!rig_file_lamp_names(rig_path, &d.lamps, &d.nlamps)) return false;
    bool ok = true;
    if (d.nlamps == 0) {
        model_error_set(rig_path, 0, "the rig has no lamps: the lab day lights every sample by the rig's lamps");
        ok = false;
    }
    if (ok && g_mkdir_with_parents(dir, 0777) != 0) {
        model_error_set(dir, 0, "cannot create the directory: %s", g_strerror(errno));
        ok = false;
    }
    ok = ok && check_plan(&d, out) && white_plan(&d, out);
    for (int k = 0; ok && k < lab->ncoupons; k++) ok = coupon_plan(&d, &lab->coupons[k], out);
    if (ok) {
        char *text = day_script(&d, out);
        out->script = g_build_filename(dir, "day.sh", NULL);
        ok = model_write_file_atomic(out->script, text);
        g_free(text);
    }
    g_strfreev(d.lamps);
    if (!ok) rig_lab_day_free(out);
    return ok;
}

void rig_lab_day_free(rig_lab_day_t *d)
{
    if (!d) return;
    for (int k = 0; k < d->nplans; k++) g_free(d->plans[k]);
    g_free(d->script);
    memset(d, 0, sizeof *d);
}
