// calib/gain/capture.c — the gain calibration's frames captured on a rig:
// per gain a probe and an exposure sweep, at the reference gain the flat
// field and the long darks (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

static char *plan_text(const calib_gain_opts_t *c, const char *name, const char *lamps, const char *list,
                       double gain, int repeats)
{
    char *instr = !strcmp(lamps, "none")
                      ? g_strdup_printf("dark frames: leave the flat-field source %s in front of the lens with its "
                                        "lamps off, and shade the lens from room light", c->sample)
                      : g_strdup_printf("put the flat-field source %s in front of the lens, filling the frame (refl "
                                        "switches its lamps)", c->sample);
    char *t = g_strdup_printf("# refl calib gain: %s (written by refl; see rig/session/session.h, Capture sessions)\n"
                              "[plan]\nname = calib gain %s\n[sample]\nname = %s\nkind = uniform_source\n"
                              "instruction = %s\n[angles]\nlist = 0\n[lamps]\nsets = %s\n[exposure]\nmode = fixed\n"
                              "list_us = %s\ngain = %g\npixel_format = %s\n[capture]\nrepeats = %d\n",
                              name, name, c->sample, instr, lamps, list, gain, c->pixel_format, repeats);
    g_free(instr);
    return t;
}

static int run_plan(const calib_gain_opts_t *c, const char *name, const char *lamps, const char *list, double gain,
                    int repeats)
{
    char *p = plan_text(c, name, lamps, list, gain, repeats);
    model_note("capturing %s (%s, lamps %s, %d repeats)", name, gain > 0 ? "gain" : "0 dB", lamps, repeats);
    int rc = calib_capture(c->rig, c->out, name, p, c->progress, c->op);
    g_free(p);
    return rc;
}

// Mean of a session's frames by kind (lamps on / off) at one exposure, per
// camera (in the session's order, at most CALIB_GAIN_MAX_CAMERAS): their number, 0 on error.
static int probe_levels(const char *dir, double *light, double *dark, double *max_dn)
{
    rig_session_t *s = rig_session_open(dir);
    if (!s) return 0;
    const char *names[CALIB_GAIN_MAX_CAMERAS];
    int nc = rig_session_cameras(s, names, CALIB_GAIN_MAX_CAMERAS);
    if (nc > CALIB_GAIN_MAX_CAMERAS) nc = CALIB_GAIN_MAX_CAMERAS;
    for (int k = 0; k < nc; k++) light[k] = dark[k] = NAN;
    for (int i = 0; i < s->n; i++)
        for (int k = 0; k < nc; k++) {
            if (strcmp(names[k], s->rows[i].camera)) continue;
            if (!strcmp(s->rows[i].lamps, "none")) dark[k] = s->rows[i].mean;
            else light[k] = s->rows[i].mean;
            max_dn[k] = calib_full_scale_dn(s->rows[i].pixel_format);
        }
    for (int k = 0; k < nc; k++)
        if (!(isfinite(light[k]) && isfinite(dark[k]))) {
            model_error_set(dir, 0, "the probe session has no light and dark frame of camera %s", names[k]);
            nc = 0;
        }
    if (nc == 0 && s->n == 0) model_error_set(dir, 0, "the probe session has no frames");
    rig_session_free(s);
    return nc;
}

static char *exposure_list(const double *t, int n)
{
    GString *g = g_string_new("");
    for (int i = 0; i < n; i++) g_string_append_printf(g, "%s%.0f", i ? " " : "", t[i]);
    return g_string_free(g, FALSE);
}

// The probe's next exposure for every camera's levels; t_full[k]: camera k's
// estimated exposure of full scale (NAN while unknown). false: done (all known).
static bool probe_next(const double *l, const double *dk, const double *mx, int nc, double *probe, double *t_full)
{
    bool over = false, under = false;
    for (int k = 0; k < nc; k++) {
        double sig = l[k] - dk[k];
        over |= l[k] > 0.6 * mx[k];
        under |= sig < 0.02 * mx[k];
        t_full[k] = l[k] > 0.6 * mx[k] || sig < 0.02 * mx[k] ? NAN : *probe * (mx[k] - dk[k]) / sig;
    }
    if (over) *probe = fmax(10, floor(*probe / 8));
    else if (under) *probe *= 8;
    return over || under;
}

int calib_gain_sweep_exposures(double tmax, int steps, int low_steps, double *t)
{
    int n = 0;
    for (int i = 0; i < low_steps; i++)
        t[n++] = tmax * (low_steps > 1 ? 0.002 * pow(0.12 / 0.002, (double)i / (low_steps - 1)) : 0.002);
    for (int i = 0; i < steps; i++) t[n++] = tmax * (i + 1) / steps;
    qsort(t, n, sizeof *t, model_cmp_double);
    return n;
}

// The probe at one gain: single frames, light and dark, at exposures from
// c->probe_us (x 8 or / 8) until every camera's light is between 2 % and 60 %
// of its full scale; t_sat_us[k]: camera k's estimated exposure of full
// scale (*ncam cameras). false + message.
static bool probe_full_scale(const calib_gain_opts_t *c, double gain, double *t_sat_us, int *ncam)
{
    double probe = c->probe_us, l[CALIB_GAIN_MAX_CAMERAS], dk[CALIB_GAIN_MAX_CAMERAS], mx[CALIB_GAIN_MAX_CAMERAS];
    bool more = true;
    for (int attempt = 0; attempt < 8 && more && probe <= 1e7; attempt++) {
        char *name = g_strdup_printf("probe_g%g_%.0fus", gain, probe);
        char *list = g_strdup_printf("%.0f", probe);
        char *sets = g_strdup_printf("%s; none", c->lamps);
        int rc = run_plan(c, name, sets, list, gain, 1);
        g_free(sets);
        char *dir = g_strdup_printf("%s/%s", c->out, name);
        *ncam = rc == 0 ? probe_levels(dir, l, dk, mx) : 0;
        g_free(list);
        g_free(name);
        g_free(dir);
        if (!*ncam) return false;
        for (int k = 0; k < *ncam; k++)
            model_note("probe at %.0f us: light %.1f DN, dark %.1f DN (camera %d)", probe, l[k], dk[k], k + 1);
        more = probe_next(l, dk, mx, *ncam, &probe, t_sat_us);
    }
    if (more) {
        model_error_set(c->rig, 0, "gain %g dB: no exposure between 10 us and 10 s gives a usable level of the flat "
                        "field for every camera (lamps %s): check the lamps and the source", gain, c->lamps);
        return false;
    }
    return true;
}

// The probe and the sweep at one gain (frame pairs, light and dark): each
// camera's steps up to 1.2 x its full scale (or --max-exposure-us), merged;
// *sweep_dir (g_free) its session; t_sat_us[k]: camera k's estimated
// exposure of full scale (*ncam cameras). false + message.
static bool capture_sweep(const calib_gain_opts_t *c, double gain, char **sweep_dir, double *t_sat_us, int *ncam)
{
    if (!probe_full_scale(c, gain, t_sat_us, ncam)) return false;
    int nt = 0;
    double *t = malloc(sizeof(double) * ((size_t)(c->steps + c->low_steps) * *ncam + 1));
    if (!t) {
        model_error_set(c->rig, 0, "gain %g dB: out of memory for the sweep's exposures", gain);
        return false;
    }
    for (int k = 0; k < *ncam; k++) {
        double tmax = isfinite(c->max_us) ? c->max_us : 1.2 * t_sat_us[k];
        int n = calib_gain_sweep_exposures(tmax, c->steps, c->low_steps, t + nt);
        for (int i = 0; i < n; i++) t[nt + i] = fmax(10, round(t[nt + i]));
        nt += n;
    }
    qsort(t, nt, sizeof *t, model_cmp_double);
    int nu = 0;
    for (int i = 0; i < nt; i++)
        if (!nu || t[i] != t[nu - 1]) t[nu++] = t[i];
    char *list = exposure_list(t, nu);
    char *name = g_strdup_printf("sweep_g%g", gain);
    char *sets = g_strdup_printf("%s; none", c->lamps);
    int rc = run_plan(c, name, sets, list, gain, 2);
    g_free(sets);
    free(t);
    g_free(list);
    if (rc) {
        g_free(name);
        return false;
    }
    *sweep_dir = g_strdup_printf("%s/%s", c->out, name);
    g_free(name);
    return true;
}

// A session of the capture into d and the provenance (role), its directory o->out/name.
static bool add_source(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc,
                       const char *name, int set, const char *role)
{
    calib_gain_source_t *ns = realloc(*src, sizeof **src * (*nsrc + 1));
    if (!ns) {
        model_error_set(o->out, 0, "out of memory for the sessions");
        return false;
    }
    char *dir = g_strdup_printf("%s/%s", o->out, name);
    *src = ns;
    (*src)[(*nsrc)++] = (calib_gain_source_t){ dir, set, role };
    return model_provenance_input(prov, role, dir);
}

void calib_gain_sources_free(calib_gain_source_t *src, int n)
{
    for (int i = 0; i < n; i++) g_free(src[i].dir);
    free(src);
}

bool calib_gain_capture(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc)
{
    double t_start = model_now_s();
    *src = NULL;
    *nsrc = 0;
    if (!model_provenance_input(prov, "rig", o->rig)) return false;
    // sweeps at every gain; the first gives the flat field's exposure
    double t_sat0 = INFINITY;
    for (int gi = 0; gi < o->ngains; gi++) {
        double ts[CALIB_GAIN_MAX_CAMERAS];
        int nc = 0;
        char *sd = NULL;
        if (!capture_sweep(o, o->gains_db[gi], &sd, ts, &nc)) return false;
        for (int k = 0; gi == 0 && k < nc; k++) t_sat0 = fmin(t_sat0, ts[k]);
        char *name = g_path_get_basename(sd);
        bool ok = add_source(o, prov, src, nsrc, name, CALIB_GAIN_SET_SWEEP, "sweep");
        g_free(name);
        g_free(sd);
        if (!ok) return false;
    }
    // the flat field near 50 % of full scale (of the most sensitive camera), its darks, and long darks
    double t_flat = fmax(10, round(0.5 * t_sat0 * 0.95));
    char *fl = g_strdup_printf("%.0f", t_flat);
    char *sets = g_strdup_printf("%s; none", o->lamps);
    int r1 = run_plan(o, "flat", sets, fl, o->gains_db[0], o->flat_frames);
    g_free(sets);
    g_free(fl);
    if (r1 || !add_source(o, prov, src, nsrc, "flat", CALIB_GAIN_SET_FLAT, "flat")) return false;
    char *dl = exposure_list(o->dark_exposures_us, o->ndark_exposures);
    r1 = run_plan(o, "dark", "none", dl, o->gains_db[0], 2);
    g_free(dl);
    if (r1 || !add_source(o, prov, src, nsrc, "dark", CALIB_GAIN_SET_DARK, "dark")) return false;
    model_note("capture done in %.1f s", model_now_s() - t_start);
    return true;
}
