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
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/rig.h"

// ---------------------------------------------------------------------------
// The reflectance-factor table

void calib_white_table_free(calib_white_table_t *t)
{
    if (!t) return;
    free(t->ti);
    free(t->tr);
    free(t->f);
    free(t->fs);
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

// One data row "ti,tr,f" (ncol 3) or "ti,tr,f,fs" (ncol 4) of line ln into
// the arrays; false + message.
static bool table_row(char *s, const char *name, int ln, int ncol, double *ti, double *tr, double *f, double *fs)
{
    char *p[4], *save = NULL;
    int k = 0;
    for (char *q = strtok_r(s, ",", &save); q; q = strtok_r(NULL, ",", &save)) {
        if (k == ncol) {
            k = ncol + 1;
            break;
        }
        p[k++] = q;
    }
    if (k != ncol || !model_parse_double(p[0], ti) || !model_parse_double(p[1], tr) || !model_parse_double(p[2], f) ||
        (ncol == 4 && !model_parse_double(p[3], fs))) {
        model_error(name, ln, ncol == 4 ? "a row needs four numbers theta_i_deg,theta_r_deg,factor,factor_std"
                                        : "a row needs three numbers theta_i_deg,theta_r_deg,factor");
        return false;
    }
    if (ncol == 4 && !(*fs >= 0 && *fs < 1)) {
        model_error(name, ln, "factor_std %g: the factor's 1-sigma must be in [0, 1)", *fs);
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
static bool table_grid(calib_white_table_t *t, const double *ti, const double *tr, const double *f,
                       const double *fs, const int *line, int n, const char *name)
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
    if (fs) t->fs = malloc(sizeof *t->fs * (size_t)t->ni * t->nr);
    if (!at || !t->f || (fs && !t->fs)) {
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
        if (fs) t->fs[c] = fs[k];
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
    double *ti = malloc(sizeof(double) * MAXROWS * 4), *tr = ti + MAXROWS, *f = tr + MAXROWS, *fs = f + MAXROWS;
    int *line = malloc(sizeof(int) * MAXROWS), n = 0, ln = 0, ncol = 3;
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
            ncol = (int)g_strv_length(w);
            ok = (ncol == 3 || ncol == 4) && !strcmp(g_strstrip(w[0]), "theta_i_deg") &&
                 !strcmp(g_strstrip(w[1]), "theta_r_deg") && !strcmp(g_strstrip(w[2]), "factor") &&
                 (ncol == 3 || !strcmp(g_strstrip(w[3]), "factor_std"));
            g_strfreev(w);
            g_free(h);
            if (!ok)
                model_error(name, ln, "the first line must be the header theta_i_deg,theta_r_deg,factor (with "
                            ",factor_std when the certificate states each factor's 1-sigma)");
            header = true;
            continue;
        }
        if (n == MAXROWS) {
            model_error(name, ln, "more than %d rows", MAXROWS);
            ok = false;
            break;
        }
        line[n] = ln;
        ok = table_row(s, name, ln, ncol, &ti[n], &tr[n], &f[n], &fs[n]);
        n++;
    }
    if (ok && n == 0) {
        model_error(name, ln, "no rows: the table needs at least one (theta_i_deg,theta_r_deg,factor)");
        ok = false;
    }
    ok = ok && table_grid(t, ti, tr, f, ncol == 4 ? fs : NULL, line, n, name);
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

// The table's values v (t->f or t->fs) at the angles, bilinear, clamped.
static double table_interp(const calib_white_table_t *t, const double *f, double theta_i_deg, double theta_r_deg,
                           bool *outside)
{
    double wi, wr;
    int i = bracket(t->ti, t->ni, theta_i_deg, &wi, outside), r = bracket(t->tr, t->nr, theta_r_deg, &wr, outside);
    int i1 = t->ni > 1 ? i + 1 : i, r1 = t->nr > 1 ? r + 1 : r;
    return (1 - wi) * ((1 - wr) * f[i * t->nr + r] + wr * f[i * t->nr + r1]) +
           wi * ((1 - wr) * f[i1 * t->nr + r] + wr * f[i1 * t->nr + r1]);
}

double calib_white_table_factor(const calib_white_table_t *t, double theta_i_deg, double theta_r_deg, bool *outside)
{
    return table_interp(t, t->f, theta_i_deg, theta_r_deg, outside);
}

double calib_white_table_factor_std(const calib_white_table_t *t, double theta_i_deg, double theta_r_deg)
{
    return t->fs ? table_interp(t, t->fs, theta_i_deg, theta_r_deg, NULL) : NAN;
}

// ---------------------------------------------------------------------------
// kc*I per lamp and its uncertainty

const char *const calib_white_part_names[CALIB_WHITE_NPARTS] = { "statistical", "lamp_position", "emission_pattern",
                                                                  "albedo", "flat_field" };

calib_white_options_t calib_white_defaults(void)
{
    return (calib_white_options_t){ .albedo_std = NAN, .draws = 400, .seed = 1 };
}

int calib_region_points(model_vec3_t *q)
{
    int n = 0;
    for (double x = -CALIB_REGION_HALF_MM; x <= CALIB_REGION_HALF_MM + 1e-9; x += CALIB_REGION_STEP_MM)
        for (double y = -CALIB_REGION_HALF_MM; y <= CALIB_REGION_HALF_MM + 1e-9; y += CALIB_REGION_STEP_MM)
            for (int k = 0; k < 2 && n < CALIB_REGION_MAX; k++) q[n++] = v3(x, y, k ? CALIB_REGION_Z1_MM : CALIB_REGION_Z0_MM);
    return n;
}

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

// The standard's BRDF at incidence cosine nl and viewing cosine nv: the
// table's factor / pi, or albedo / pi.
static double white_brdf_at(double nl, double nv, double albedo, const calib_white_table_t *t, bool *outside)
{
    if (!t) return albedo / M_PI;
    double ti = acos(fmin(1, nl)) * 180 / M_PI, tr = acos(fmin(1, nv)) * 180 / M_PI;
    return calib_white_table_factor(t, ti, tr, outside) / M_PI;
}

static double white_brdf(const calib_obs_t *o, double albedo, const calib_white_table_t *t, bool *outside)
{
    return white_brdf_at(o->c.nl, o->c.nv, albedo, t, outside);
}

// The lower triangle L of a symmetric 3 x 3 covariance C = L L^T (a pivot not
// above 0 gives a zero column: that direction is not drawn).
static void chol3(const double C[9], double L[9])
{
    memset(L, 0, 9 * sizeof *L);
    for (int j = 0; j < 3; j++) {
        double d = C[4 * j];
        for (int k = 0; k < j; k++) d -= L[3 * j + k] * L[3 * j + k];
        if (!(d > 0)) continue;
        L[4 * j] = sqrt(d);
        for (int i = j + 1; i < 3; i++) {
            double v = C[3 * i + j];
            for (int k = 0; k < j; k++) v -= L[3 * i + k] * L[3 * j + k];
            L[3 * i + j] = v / L[4 * j];
        }
    }
}

static void draw3(model_rng_t *r, const double L[9], double x[3])
{
    double z[3] = { model_rng_gauss(r), model_rng_gauss(r), model_rng_gauss(r) };
    for (int i = 0; i < 3; i++) x[i] = L[3 * i] * z[0] + L[3 * i + 1] * z[1] + L[3 * i + 2] * z[2];
}

// One observation's geometry for the draws: its point and normal at its
// angle, and what the nominal lamp gives there (distance^2, n.l, BRDF, ln of
// the emission, the pattern's gradient of ln E in (n, t1, t2)).
typedef struct {
    model_vec3_t p, nrm;
    bool         has_normal;
    double       kcI, d2, nl, fr, lnE, g[3];
} white_geo_t;

// The emission's gradient of ln E toward u for the stated pattern s (zeros: none).
static void pattern_gradient(const calib_lamp_sigma_t *s, model_vec3_t u, double g[3])
{
    g[0] = g[1] = g[2] = 0;
    if (!s->have_pattern) return;
    double au = v3_dot(s->axis, u);
    if (!(au > 1e-6)) return;
    g[0] = log(au);
    for (int k = 0; k < 2; k++) g[1 + k] = s->n * v3_dot(s->axis_per_t[k], u) / au;
}

// kc*I of observation o (nominal kcI0, geometry G) with the lamp at Lp (its
// pattern L's, moved there), relative: d'^2/d^2 n.l/n.l' f_r/f_r' E/E'.
static double moved_kcI(const white_geo_t *G, const model_lamp_t *L, model_vec3_t Lp, const calib_obs_t *o,
                        double albedo, const calib_white_table_t *t)
{
    model_vec3_t dv = v3_sub(G->p, Lp);
    double d2 = v3_dot(dv, dv), nl = G->nl, fr = G->fr;
    if (G->has_normal) {
        nl = -v3_dot(G->nrm, dv) / sqrt(d2);
        if (!(nl > 1e-6)) nl = 1e-6;
        fr = white_brdf_at(nl, o->c.nv, albedo, t, NULL);
    }
    model_lamp_t M = *L;
    M.position_mm = Lp;
    double lnE = L->emission_cos_power > 0 ? log(fmax(model_lamp_emission(&M, G->p), 1e-300)) : 0;
    return G->kcI * (d2 / G->d2) * (G->nl / nl) * (G->fr / fr) * exp(G->lnE - lnE);
}

// The std of x[n] about its mean.
static double std_of(const double *x, int n)
{
    double m = 0, v = 0;
    for (int i = 0; i < n; i++) m += x[i];
    m /= n;
    for (int i = 0; i < n; i++) v += (x[i] - m) * (x[i] - m);
    return n > 1 ? sqrt(v / (n - 1)) : NAN;
}

// The number of distinct window positions among the lamp's observations.
static int distinct_windows(const calib_obs_set_t *obs, int lamp, double *tmp)
{
    int n = 0;
    for (int i = 0; i < obs->n; i++)
        if (obs->o[i].lamp == lamp) tmp[n++] = obs->o[i].q[1] * 1e6 + obs->o[i].q[0];
    int d = 0;
    qsort(tmp, (size_t)n, sizeof *tmp, model_cmp_double);
    for (int i = 0; i < n; i++) d += !i || tmp[i] != tmp[i - 1];
    return d;
}

// The sampled parts (lamp position, pattern) of lamp l: draws of kc*I and of
// the irradiance at the region's points q[nq] (nominal irr0); the relative
// 1-sigma of kc*I into *kc_rel and at each point into irr_rel[nq].
typedef struct {
    const calib_obs_set_t *obs;
    const calib_set_t     *cal;
    const white_geo_t     *geo;   // per observation (lamp l's used)
    const int             *idx;   // lamp l's observations
    int                    n, l;
    double                 albedo, kcI;
    const calib_white_table_t *table;
    const model_vec3_t    *q;
    const double          *irr0;
    int                    nq;
} white_draws_t;

static bool sample_part(const white_draws_t *W, int part, const calib_white_options_t *o, double *v, double *kc_rel,
                        double *irr_rel)
{
    const model_lamp_t *L = &W->cal->lamps->lamps[W->l];
    const calib_lamp_sigma_t *S = &W->cal->lamp_sigma[W->l];
    int nd = o->draws > 1 ? o->draws : 2;
    double *k = malloc(sizeof *k * (size_t)nd * (1 + (size_t)W->nq)), *ir = k ? k + nd : NULL, Lc[9], x[3];
    double (*gq)[3] = k ? malloc(sizeof *gq * (size_t)(W->nq ? W->nq : 1)) : NULL;
    if (!gq) {
        free(k);
        model_error_set(NULL, 0, "out of memory for %d draws of lamp %s", nd, L->name);
        return false;
    }
    chol3(part == CALIB_WHITE_POSITION ? S->position_cov_mm2 : S->pattern_cov, Lc);
    model_rng_t rng = model_rng(o->seed, 1000 * (uint64_t)W->l + (uint64_t)part);
    // the region's gradients of ln E for the pattern's draws
    for (int j = 0; j < W->nq; j++) pattern_gradient(S, v3_unit(v3_sub(W->q[j], L->position_mm)), gq[j]);
    for (int d = 0; d < nd; d++) {
        draw3(&rng, Lc, x);
        model_vec3_t Lp = v3_add(L->position_mm, v3(x[0], x[1], x[2]));
        for (int i = 0; i < W->n; i++) {
            const white_geo_t *G = &W->geo[W->idx[i]];
            v[i] = part == CALIB_WHITE_POSITION
                       ? moved_kcI(G, L, Lp, &W->obs->o[W->idx[i]], W->albedo, W->table)
                       : G->kcI * exp(-(x[0] * G->g[0] + x[1] * G->g[1] + x[2] * G->g[2]));
        }
        k[d] = model_kth(v, W->n, W->n / 2);   // the element at n / 2, as median_mad's
        for (int j = 0; j < W->nq; j++) {
            double e;
            if (part == CALIB_WHITE_POSITION) {
                model_lamp_t M = *L;
                M.position_mm = Lp;
                model_vec3_t dv = v3_sub(W->q[j], Lp);
                e = k[d] * model_lamp_emission(&M, W->q[j]) / v3_dot(dv, dv);
            } else {
                model_vec3_t dv = v3_sub(W->q[j], L->position_mm);
                e = k[d] * model_lamp_emission(L, W->q[j]) *
                    exp(x[0] * gq[j][0] + x[1] * gq[j][1] + x[2] * gq[j][2]) / v3_dot(dv, dv);
            }
            ir[(size_t)j * nd + d] = e / W->irr0[j];
        }
    }
    for (int d = 0; d < nd; d++) k[d] /= W->kcI;
    *kc_rel = std_of(k, nd);
    for (int j = 0; j < W->nq; j++) irr_rel[j] = std_of(&ir[(size_t)j * nd], nd);
    free(gq);
    free(k);
    return true;
}

// The albedo's part: the certificate's relative 1-sigma (a table's
// factor_std, its mean relative value over the lamp's observations).
static double albedo_part(const calib_obs_set_t *obs, int l, double albedo, const calib_white_table_t *t,
                          const calib_white_options_t *o)
{
    if (!t) return isfinite(o->albedo_std) ? o->albedo_std / albedo : NAN;
    double s = 0;
    int n = 0;
    for (int i = 0; i < obs->n; i++) {
        const calib_obs_t *b = &obs->o[i];
        if (b->lamp != l) continue;
        double ti = acos(fmin(1, b->c.nl)) * 180 / M_PI, tr = acos(fmin(1, b->c.nv)) * 180 / M_PI;
        double f = calib_white_table_factor(t, ti, tr, NULL);
        double fs = t->fs ? calib_white_table_factor_std(t, ti, tr) : o->albedo_std;
        s += fs / f;
        n++;
    }
    return n && isfinite(s) ? s / n : NAN;
}

static double quad_sum(const double *p, int n)
{
    double s = 0;
    for (int k = 0; k < n; k++)
        if (isfinite(p[k])) s += p[k] * p[k];
    return sqrt(s);
}

// One lamp's kc*I and uncertainty into out (its observations idx[n], geometry
// geo). false + message (out of memory).
static bool white_lamp(const calib_obs_set_t *obs, const calib_set_t *cal, int l, double albedo,
                       const calib_white_table_t *table, const calib_white_options_t *o, white_geo_t *geo,
                       const int *idx, int n, double *v, calib_white_lamp_t *out)
{
    const model_lamp_t *L = &cal->lamps->lamps[l];
    const calib_lamp_sigma_t *S = &cal->lamp_sigma[l];
    memset(out, 0, sizeof *out);
    snprintf(out->name, sizeof out->name, "%s", L->name);
    out->n = n;
    for (int i = 0; i < n; i++) v[i] = geo[idx[i]].kcI;
    double mad, madl;
    out->kcI_per_us = median_mad(v, n, &mad);
    out->spread_rel = mad / out->kcI_per_us;
    for (int i = 0; i < n; i++) {
        const calib_obs_t *b = &obs->o[idx[i]];
        double g = b->s_dn_per_us * b->d_mm * b->d_mm / b->c.nl;
        v[i] = table ? g / (table->f[0] / M_PI) : geo[idx[i]].kcI;   // the Lambertian assumption
    }
    out->kcI_lambertian_per_us = median_mad(v, n, &madl);
    for (int k = 0; k < CALIB_WHITE_NPARTS; k++) out->part_rel[k] = out->irr_part_rel[k] = NAN;
    out->part_rel[CALIB_WHITE_STAT] = 1.2533 * out->spread_rel / sqrt(n);
    out->part_rel[CALIB_WHITE_ALBEDO] = albedo_part(obs, l, albedo, table, o);
    if (cal->flat && cal->flat_pixel_std_rel > 0 && obs->window_px > 0) {
        int nw = distinct_windows(obs, l, v);
        out->part_rel[CALIB_WHITE_FLAT] = 1.2533 * cal->flat_pixel_std_rel / (obs->window_px * sqrt(nw));
    }
    model_vec3_t q[CALIB_REGION_MAX];
    double irr0[CALIB_REGION_MAX], irr[2][CALIB_REGION_MAX];
    int nq = calib_region_points(q);
    for (int j = 0; j < nq; j++) {
        model_vec3_t dv = v3_sub(q[j], L->position_mm);
        irr0[j] = out->kcI_per_us * model_lamp_emission(L, q[j]) / v3_dot(dv, dv);
    }
    white_draws_t W = { .obs = obs, .cal = cal, .geo = geo, .idx = idx, .n = n, .l = l, .albedo = albedo,
                        .kcI = out->kcI_per_us, .table = table, .q = q, .irr0 = irr0, .nq = nq };
    for (int j = 0; j < nq; j++) irr[0][j] = irr[1][j] = NAN;
    if ((S->have_position && !sample_part(&W, CALIB_WHITE_POSITION, o, v, &out->part_rel[CALIB_WHITE_POSITION], irr[0])) ||
        (S->have_pattern && !sample_part(&W, CALIB_WHITE_PATTERN, o, v, &out->part_rel[CALIB_WHITE_PATTERN], irr[1])))
        return false;
    out->std_rel = quad_sum(out->part_rel, CALIB_WHITE_NPARTS);
    out->irr_std_rel = -1;
    for (int j = 0; j < nq; j++) {
        double p[CALIB_WHITE_NPARTS];
        memcpy(p, out->part_rel, sizeof p);
        p[CALIB_WHITE_POSITION] = irr[0][j];
        p[CALIB_WHITE_PATTERN] = irr[1][j];
        double t = quad_sum(p, CALIB_WHITE_NPARTS);
        if (t > out->irr_std_rel) {
            out->irr_std_rel = t;
            memcpy(out->irr_part_rel, p, sizeof p);
            out->irr_worst_mm = q[j];
        }
    }
    return true;
}

bool calib_white_compute(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                         const calib_white_table_t *table, const calib_white_options_t *opt, calib_white_lamp_t *out,
                         const char *out_json)
{
    calib_white_options_t o = opt ? *opt : calib_white_defaults();
    int m = obs->n ? obs->n : 1;
    double *v = malloc(sizeof *v * (size_t)m);
    int *idx = malloc(sizeof *idx * (size_t)m);
    white_geo_t *geo = malloc(sizeof *geo * (size_t)m);
    bool ok = v && idx && geo;
    if (!ok) model_error(out_json, 0, "out of memory for %d observations", obs->n);
    for (int l = 0; ok && l < cal->lamps->n; l++) {
        const model_lamp_t *L = &cal->lamps->lamps[l];
        const calib_lamp_sigma_t *S = &cal->lamp_sigma[l];
        int n = 0;
        for (int i = 0; i < obs->n; i++) {
            const calib_obs_t *b = &obs->o[i];
            if (b->lamp != l) continue;
            white_geo_t *G = &geo[i];
            double ca = cos(b->angle_deg * M_PI / 180), sa = sin(b->angle_deg * M_PI / 180);
            G->p = v3(ca * b->p0_mm[0] - sa * b->p0_mm[1], sa * b->p0_mm[0] + ca * b->p0_mm[1], b->p0_mm[2]);
            G->nrm = v3(ca * b->n0[0] - sa * b->n0[1], sa * b->n0[0] + ca * b->n0[1], b->n0[2]);
            G->has_normal = v3_norm(G->nrm) > 0.5;
            model_vec3_t dv = v3_sub(G->p, L->position_mm);
            G->d2 = v3_dot(dv, dv);
            G->nl = G->has_normal ? -v3_dot(G->nrm, dv) / sqrt(G->d2) : b->c.nl;
            if (!(G->nl > 1e-6)) G->nl = b->c.nl;
            G->fr = white_brdf_at(G->nl, b->c.nv, albedo, table, NULL);
            G->lnE = L->emission_cos_power > 0 ? log(fmax(model_lamp_emission(L, G->p), 1e-300)) : 0;
            pattern_gradient(S, G->d2 > 0 ? v3_scale(dv, 1 / sqrt(G->d2)) : v3(0, 0, 1), G->g);
            // the observation's own kc*I: s d^2 / (f_r n.l) (s of the on-axis intensity)
            G->kcI = b->s_dn_per_us * b->d_mm * b->d_mm / b->c.nl / white_brdf(b, albedo, table, NULL);
            idx[n++] = i;
        }
        if (n < 10) {
            model_error(out_json, 0, "lamp %s: %d observations of the reference white (need 10): capture it with "
                        "that lamp alone", L->name, n);
            ok = false;
            break;
        }
        if (!white_lamp(obs, cal, l, albedo, table, &o, geo, idx, n, v, &out[l])) {
            char *e = g_strdup(model_last_error());
            model_error(out_json, 0, "%s", e);
            g_free(e);
            ok = false;
        }
    }
    free(v);
    free(idx);
    free(geo);
    return ok;
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

static json_t *parts_json(const double *p, double scale)
{
    json_t *j = json_object();
    for (int k = 0; k < CALIB_WHITE_NPARTS; k++)
        json_object_set_new(j, calib_white_part_names[k], model_json_number(scale * p[k]));
    return j;
}

static json_t *lamp_json(const calib_white_lamp_t *w, bool table)
{
    json_t *e = json_object();
    json_object_set_new(e, "name", json_string(w->name));
    json_object_set_new(e, "kc_I_per_us", json_real(w->kcI_per_us));
    json_object_set_new(e, "kc_I_std_per_us", json_real(w->std_rel * w->kcI_per_us));
    json_object_set_new(e, "std_rel", json_real(w->std_rel));
    json_object_set_new(e, "sigma_parts_rel", parts_json(w->part_rel, 1));
    json_object_set_new(e, "spread_rel", json_real(w->spread_rel));
    json_object_set_new(e, "std_of_median_rel", json_real(w->part_rel[CALIB_WHITE_STAT]));
    json_object_set_new(e, "n_observations", json_integer(w->n));
    json_t *r = json_object();
    json_object_set_new(r, "std_max_pct", json_real(100 * w->irr_std_rel));
    json_object_set_new(r, "at_mm", json_pack("[fff]", w->irr_worst_mm.x, w->irr_worst_mm.y, w->irr_worst_mm.z));
    json_object_set_new(r, "parts_pct", parts_json(w->irr_part_rel, 100));
    json_object_set_new(e, "irradiance_samples_region", r);
    if (table) {
        json_object_set_new(e, "kc_I_lambertian_per_us", json_real(w->kcI_lambertian_per_us));
        json_object_set_new(e, "lambertian_bias_pct", json_real(100 * (w->kcI_lambertian_per_us / w->kcI_per_us - 1)));
    }
    return e;
}

// white.json's statement of how the uncertainty was found.
static json_t *uncertainty_json(const calib_white_table_t *t, const calib_white_options_t *o)
{
    json_t *u = json_object();
    json_object_set_new(u, "method", json_string(
        "kc_I_std_per_us = kc_I_per_us * std_rel, std_rel the quadrature sum of sigma_parts_rel (relative 1-sigma "
        "of kc*I; null: that input states no uncertainty, not included): statistical = 1.2533 x scaled MAD / "
        "sqrt(n), the median's standard error; lamp_position = the std of kc*I over draws of the lamp's position "
        "from lamps.json's covariance_mm2 (else std_mm), each observation's distance, n.l, reflectance factor and "
        "emission recomputed and the median taken again; emission_pattern = the same over draws of the pattern's "
        "(n, t1, t2) from lamps.json's emission.covariance_n_t1_t2 (else cos_power_std and axis_std_deg as "
        "independent), ln E moved linearly (d ln E = dn ln(a.u) + n dt.axis_per_t.u / (a.u)); albedo = the "
        "certificate's relative 1-sigma (--albedo-std, or the table's factor_std: its mean relative value over the "
        "lamp's observations, taken as fully correlated); flat_field = 1.2533 x the flat map's relative noise per "
        "pixel (gain.json flat_field.pixel_std_rel) / (window size x sqrt(distinct windows)): the part the "
        "observations of one window share across angles"));
    json_object_set_new(u, "albedo_std", t && t->fs ? json_string("the table's factor_std column")
                                         : isfinite(o->albedo_std) ? json_real(o->albedo_std)
                                                                   : json_string("not stated (give --albedo-std with "
                                                                                 "the certificate's 1-sigma)"));
    json_object_set_new(u, "draws", json_integer(o->draws));
    json_object_set_new(u, "seed", json_integer((json_int_t)o->seed));
    json_object_set_new(u, "irradiance_samples_region", json_string(
        "per lamp: the irradiance kc*I E(q) / |q - L|^2 (the lamp's calibrated position L and pattern E) at the "
        "samples' region, x and y within 60 mm, z 5 and 50 mm (rig frame at angle 0, a 20 mm grid): the largest "
        "total relative 1-sigma over it (std_max_pct, %), where (at_mm) and its parts there (parts_pct, %; the "
        "position's and the pattern's from the same draws, so what the white's own windows fix cancels)"));
    return u;
}

bool calib_white(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo, const calib_white_table_t *table,
                 const calib_white_options_t *opt, const char *out_json, json_t *prov, calib_white_lamp_t *lamps_out)
{
    calib_white_options_t o = opt ? *opt : calib_white_defaults();
    calib_white_lamp_t *wl = calloc((size_t)cal->lamps->n, sizeof *wl);
    if (!wl) {
        model_error(out_json, 0, "out of memory");
        return false;
    }
    if (!calib_white_compute(obs, cal, albedo, table, &o, wl, out_json)) {
        free(wl);
        return false;
    }
    json_t *top = json_object();
    model_json_set_format(top, CALIB_WHITE_FORMAT, CALIB_WHITE_FORMAT_VERSION);
    json_object_set_new(top, "calibration", json_string("reference white: kc*I per lamp"));
    json_object_set_new(top, "units", json_string("kc_I_per_us, kc_I_std_per_us: DN per microsecond of exposure at 0 "
                                                  "dB gain per (R in 1/sr / d^2 in mm^2), so P - Pa = kc_I_per_us * "
                                                  "t_us * 10^(gain_dB/20) * g(x,y) * R / d^2; *_rel: relative (1 = "
                                                  "100 %); *_pct: percent; reflectance factor: the standard's radiance "
                                                  "over a perfect Lambertian reflector's (BRDF = factor / pi), angles "
                                                  "in degrees from its normal; positions mm in the rig frame"));
    json_object_set_new(top, "albedo", table ? json_real(table->f[0]) : json_real(albedo));
    json_object_set_new(top, "white_model", white_model_json(obs, albedo, table));
    json_object_set_new(top, "uncertainty", uncertainty_json(table, &o));
    if (cal->camera[0]) json_object_set_new(top, "camera", json_string(cal->camera));
    json_object_set_new(top, "sample", json_string(obs->sample));
    json_t *arr = json_array();
    for (int l = 0; l < cal->lamps->n; l++) json_array_append_new(arr, lamp_json(&wl[l], table != NULL));
    if (lamps_out) memcpy(lamps_out, wl, sizeof *wl * (size_t)cal->lamps->n);
    free(wl);
    json_object_set_new(top, "lamps", arr);
    if (prov) json_object_set_new(top, "provenance", json_incref(prov));
    char *d = g_path_get_dirname(out_json);
    bool ok = model_mkdir_p(d) && model_write_json(out_json, top);
    g_free(d);
    json_decref(top);
    return ok;
}
