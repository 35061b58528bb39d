// calib/white.c — the reference white: kc*I per lamp from observations of a
// standard of known reflectance (`refl calib white`): a Lambertian one of
// given albedo, or the reflectance factor by angle of its certificate (the
// table's format: calib/calib.h, calib_white_table_t; its one owner is here).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "model/report.h"
#include "model/vec.h"
#include "rig/rig.h"

// ---------------------------------------------------------------------------
// The reflectance-factor table

void calib_white_table_free(calib_white_table_t *t)
{
    if (!t) return;
    free(t->ti);
    free(t->tr);
    free(t->f);
    free(t);
}

// The distinct values of v[n] ascending into u (*nu).
static void distinct(const double *v, int n, double *u, int *nu)
{
    memcpy(u, v, sizeof *u * (size_t)n);
    qsort(u, (size_t)n, sizeof *u, model_cmp_double);
    *nu = 0;
    for (int i = 0; i < n; i++)
        if (!*nu || u[i] != u[*nu - 1]) u[(*nu)++] = u[i];
}

static int index_of(const double *u, int n, double x)
{
    for (int i = 0; i < n; i++)
        if (u[i] == x) return i;
    return -1;
}

// One data row "ti,tr,f" of line ln into the arrays; false + message.
static bool table_row(char *s, const char *name, int ln, double *ti, double *tr, double *f)
{
    char *p[3], *save = NULL;
    int k = 0;
    for (char *q = strtok_r(s, ",", &save); q; q = strtok_r(NULL, ",", &save)) {
        if (k == 3) {
            k = 4;
            break;
        }
        p[k++] = q;
    }
    if (k != 3 || !model_parse_double(p[0], ti) || !model_parse_double(p[1], tr) || !model_parse_double(p[2], f)) {
        model_error(name, ln, "a row needs three numbers theta_i_deg,theta_r_deg,factor");
        return false;
    }
    if (!(*ti >= 0 && *ti < 90) || !(*tr >= 0 && *tr < 90)) {
        model_error(name, ln, "angles %g, %g: incidence and viewing angles are degrees from the normal in [0, 90)",
                    *ti, *tr);
        return false;
    }
    if (!(*f > 0 && *f <= 2)) {
        model_error(name, ln, "reflectance factor %g: must be in (0, 2] (1 is a perfect Lambertian reflector's)",
                    *f);
        return false;
    }
    return true;
}

// The rows as a full grid into t; false + message (a duplicate or missing pair).
static bool table_grid(calib_white_table_t *t, const double *ti, const double *tr, const double *f, const int *line,
                       int n, const char *name)
{
    t->ti = malloc(sizeof *t->ti * (size_t)n);
    t->tr = malloc(sizeof *t->tr * (size_t)n);
    if (!t->ti || !t->tr) {
        model_error(name, 0, "out of memory for a table of %d rows", n);
        return false;
    }
    distinct(ti, n, t->ti, &t->ni);
    distinct(tr, n, t->tr, &t->nr);
    int *at = calloc((size_t)t->ni * t->nr, sizeof *at);   // the line of each cell (0: none yet)
    t->f = malloc(sizeof *t->f * (size_t)t->ni * t->nr);
    if (!at || !t->f) {
        free(at);
        model_error(name, 0, "out of memory for a table of %d rows", n);
        return false;
    }
    bool ok = true;
    for (int k = 0; ok && k < n; k++) {
        int c = index_of(t->ti, t->ni, ti[k]) * t->nr + index_of(t->tr, t->nr, tr[k]);
        if (at[c]) {
            model_error(name, line[k], "theta_i %g, theta_r %g again (first on line %d)", ti[k], tr[k], at[c]);
            ok = false;
        }
        at[c] = line[k];
        t->f[c] = f[k];
    }
    for (int c = 0; ok && c < t->ni * t->nr; c++)
        if (!at[c]) {
            model_error(name, 0, "no row for theta_i %g, theta_r %g: the rows must form a full grid (every "
                        "theta_i with every theta_r)", t->ti[c / t->nr], t->tr[c % t->nr]);
            ok = false;
        }
    free(at);
    return ok;
}

calib_white_table_t *calib_white_table_parse(const char *text, size_t len, const char *name)
{
    enum { MAXROWS = 10000 };
    calib_white_table_t *t = calloc(1, sizeof *t);
    double *ti = malloc(sizeof(double) * MAXROWS * 3), *tr = ti + MAXROWS, *f = tr + MAXROWS;
    int *line = malloc(sizeof(int) * MAXROWS), n = 0, ln = 0;
    char *buf = g_strndup(text, len);
    bool ok = t && ti && line && buf, header = false;
    if (!ok) model_error(name, 0, "out of memory reading the table");
    for (char *s = buf, *e; ok && s && *s; s = e ? e + 1 : NULL) {
        e = strchr(s, '\n');
        if (e) *e = 0;
        ln++;
        g_strstrip(s);
        if (!*s || *s == '#') continue;
        if (!header) {
            char *h = g_strdelimit(g_strdup(s), " \t", ' ');
            char **w = g_strsplit(h, ",", -1);
            ok = g_strv_length(w) == 3 && !strcmp(g_strstrip(w[0]), "theta_i_deg") &&
                 !strcmp(g_strstrip(w[1]), "theta_r_deg") && !strcmp(g_strstrip(w[2]), "factor");
            g_strfreev(w);
            g_free(h);
            if (!ok) model_error(name, ln, "the first line must be the header theta_i_deg,theta_r_deg,factor");
            header = true;
            continue;
        }
        if (n == MAXROWS) {
            model_error(name, ln, "more than %d rows", MAXROWS);
            ok = false;
            break;
        }
        line[n] = ln;
        ok = table_row(s, name, ln, &ti[n], &tr[n], &f[n]);
        n++;
    }
    if (ok && n == 0) {
        model_error(name, ln, "no rows: the table needs at least one (theta_i_deg,theta_r_deg,factor)");
        ok = false;
    }
    ok = ok && table_grid(t, ti, tr, f, line, n, name);
    if (ok) snprintf(t->path, sizeof t->path, "%s", name);
    g_free(buf);
    free(ti);
    free(line);
    if (!ok) {
        calib_white_table_free(t);
        return NULL;
    }
    return t;
}

calib_white_table_t *calib_white_table_load(const char *path)
{
    gchar *text = NULL;
    gsize len = 0;
    GError *err = NULL;
    if (!g_file_get_contents(path, &text, &len, &err)) {
        model_error(path, 0, "cannot read the reflectance-factor table: %s", err ? err->message : "?");
        g_clear_error(&err);
        return NULL;
    }
    calib_white_table_t *t = calib_white_table_parse(text, len, path);
    if (t) model_sha256_hex(text, len, t->sha256);
    g_free(text);
    return t;
}

// The cell of x in u[n] (ascending) and the weight of the upper knot; clamped.
static int bracket(const double *u, int n, double x, double *w, bool *outside)
{
    if (n == 1 || x <= u[0]) {
        if (x < u[0] && outside) *outside = true;
        *w = 0;
        return 0;
    }
    if (x >= u[n - 1]) {
        if (x > u[n - 1] && outside) *outside = true;
        *w = 1;
        return n - 2;
    }
    int k = 0;
    while (x > u[k + 1]) k++;
    *w = (x - u[k]) / (u[k + 1] - u[k]);
    return k;
}

double calib_white_table_factor(const calib_white_table_t *t, double theta_i_deg, double theta_r_deg, bool *outside)
{
    double wi, wr;
    int i = bracket(t->ti, t->ni, theta_i_deg, &wi, outside), r = bracket(t->tr, t->nr, theta_r_deg, &wr, outside);
    int i1 = t->ni > 1 ? i + 1 : i, r1 = t->nr > 1 ? r + 1 : r;
    const double *f = t->f;
    return (1 - wi) * ((1 - wr) * f[i * t->nr + r] + wr * f[i * t->nr + r1]) +
           wi * ((1 - wr) * f[i1 * t->nr + r] + wr * f[i1 * t->nr + r1]);
}

// ---------------------------------------------------------------------------
// kc*I per lamp

// The median and the scaled MAD of v[n] (sorted in place; v reused).
static double median_mad(double *v, int n, double *mad)
{
    qsort(v, (size_t)n, sizeof *v, model_cmp_double);
    double med = v[n / 2];
    for (int i = 0; i < n; i++) v[i] = fabs(v[i] - med);
    qsort(v, (size_t)n, sizeof *v, model_cmp_double);
    *mad = 1.4826 * v[n / 2];
    return med;
}

// The standard's BRDF at observation o: the table's factor / pi, or albedo / pi.
static double white_brdf(const calib_obs_t *o, double albedo, const calib_white_table_t *t, bool *outside)
{
    if (!t) return albedo / M_PI;
    double ti = acos(fmin(1, o->c.nl)) * 180 / M_PI, tr = acos(fmin(1, o->c.nv)) * 180 / M_PI;
    return calib_white_table_factor(t, ti, tr, outside) / M_PI;
}

// white.json's statement of the white model: the factors at the observed
// geometries (their range and spread: the departure from Lambertian), the
// observations beyond the table's angles.
static json_t *white_model_json(const calib_obs_set_t *obs, double albedo, const calib_white_table_t *t)
{
    if (!t)
        return json_pack("{s:s, s:f, s:s}", "kind", "lambertian", "albedo", albedo, "departure_from_lambertian",
                         "not measured: assumed 0 (give --reflectance-table with the standard's certificate)");
    double fmn = INFINITY, fmx = -INFINITY, sum = 0;
    int nout = 0;
    for (int i = 0; i < obs->n; i++) {
        bool out = false;
        double f = white_brdf(&obs->o[i], albedo, t, &out) * M_PI;
        fmn = fmin(fmn, f);
        fmx = fmax(fmx, f);
        sum += f;
        nout += out;
    }
    double mean = obs->n ? sum / obs->n : NAN;
    json_t *m = json_object();
    json_object_set_new(m, "kind", json_string("reflectance-factor table"));
    json_object_set_new(m, "table", json_string(t->path));
    if (t->sha256[0]) json_object_set_new(m, "sha256", json_string(t->sha256));
    json_object_set_new(m, "factor_nearest_normal", json_real(t->f[0]));   // its smallest angles
    json_object_set_new(m, "factor_observed_min", json_real(fmn));
    json_object_set_new(m, "factor_observed_max", json_real(fmx));
    json_object_set_new(m, "factor_observed_mean", json_real(mean));
    json_object_set_new(m, "departure_from_lambertian_pct", json_real(100 * (fmx - fmn) / mean));
    json_object_set_new(m, "observations_beyond_table", json_integer(nout));
    return m;
}

bool calib_white(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo, const calib_white_table_t *table,
                 const char *out_json, json_t *prov)
{
    json_t *top = json_object();
    json_object_set_new(top, "calibration", json_string("reference white: kc*I per lamp"));
    json_object_set_new(top, "units", json_string("kc_I_per_us: DN per microsecond of exposure at 0 dB gain per "
                                                  "(R in 1/sr / d^2 in mm^2), so P - Pa = kc_I_per_us * t_us * "
                                                  "10^(gain_dB/20) * g(x,y) * R / d^2; reflectance factor: the "
                                                  "standard's radiance over a perfect Lambertian reflector's "
                                                  "(BRDF = factor / pi), angles in degrees from its normal"));
    json_object_set_new(top, "albedo", table ? json_real(table->f[0]) : json_real(albedo));
    json_object_set_new(top, "white_model", white_model_json(obs, albedo, table));
    if (cal->camera[0]) json_object_set_new(top, "camera", json_string(cal->camera));
    json_object_set_new(top, "sample", json_string(obs->sample));
    json_t *arr = json_array();
    double *v = malloc((size_t)(obs->n ? obs->n : 1) * 2 * sizeof *v), *vl = v ? v + (obs->n ? obs->n : 1) : NULL;
    bool ok = v != NULL;
    for (int l = 0; ok && l < cal->lamps->n; l++) {
        int n = 0;
        for (int i = 0; i < obs->n; i++) {
            const calib_obs_t *o = &obs->o[i];
            if (o->lamp != l) continue;
            double g = o->s_dn_per_us * o->d_mm * o->d_mm / o->c.nl;   // kc I f_r
            v[n] = g / white_brdf(o, albedo, table, NULL);
            vl[n] = table ? g / (table->f[0] / M_PI) : v[n];            // the Lambertian assumption
            n++;
        }
        if (n < 10) {
            model_error(out_json, 0, "lamp %s: %d observations of the reference white (need 10): capture it with "
                        "that lamp alone", cal->lamps->lamps[l].name, n);
            ok = false;
            break;
        }
        double mad, madl, med = median_mad(v, n, &mad), medl = median_mad(vl, n, &madl);
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(cal->lamps->lamps[l].name));
        json_object_set_new(e, "kc_I_per_us", json_real(med));
        json_object_set_new(e, "spread_rel", json_real(mad / med));
        json_object_set_new(e, "std_of_median_rel", json_real(1.2533 * mad / med / sqrt(n)));
        json_object_set_new(e, "n_observations", json_integer(n));
        if (table) {
            json_object_set_new(e, "kc_I_lambertian_per_us", json_real(medl));
            json_object_set_new(e, "lambertian_bias_pct", json_real(100 * (medl / med - 1)));
        }
        json_array_append_new(arr, e);
        printf("  %-12s kc*I = %.6g DN/us per (1/sr)/mm^2  (spread %.2f %%, %d windows)", cal->lamps->lamps[l].name,
               med, 100 * mad / med, n);
        if (table) printf("; Lambertian at %.4g: %+.2f %%", table->f[0], 100 * (medl / med - 1));
        printf("\n");
    }
    free(v);
    json_object_set_new(top, "lamps", arr);
    if (prov) json_object_set_new(top, "provenance", json_incref(prov));
    if (ok) {
        char *d = g_path_get_dirname(out_json);
        ok = model_mkdir_p(d) && model_write_json(out_json, top);
        g_free(d);
    }
    json_decref(top);
    return ok;
}
