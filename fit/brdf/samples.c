// fit/brdf/samples.c — BRDF sample files for refl fit brdf: CSV (read here),
// MERL .binary (model/brdf/table.c) and RGL .bsdf (model/brdf/rgl.c), told
// apart by content, never by extension; the channel fitted; and the samples'
// weights: the solid angle each stands for in (omega_i, omega_o) (default),
// uniform, or the CSV's weight column (fit.h: fit_read_opts_t).
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/brdf.h"
#include "model/base/vec.h"

fit_read_opts_t fit_read_defaults(void)
{
    return (fit_read_opts_t){ .weights = FIT_WEIGHTS_SOLID_ANGLE, .channel = 0 };
}

bool fit_weights_parse(const char *s, fit_weights_t *out)
{
    static const char *names[] = { "solid-angle", "uniform", "column" };
    for (int k = 0; s && k < 3; k++)
        if (!strcmp(s, names[k])) {
            *out = (fit_weights_t)k;
            return true;
        }
    return false;
}

// ---------------------------------------------------------------------------
// Solid angles of scattered directions: rings of equal theta

// The edges of ring r of n increasing zenith angles th: midpoints, the ends
// half a spacing beyond the outer rings (clipped to 0 and pi/2); one ring: 0..pi/2.
static void ring_edges(const double *th, int n, int r, double *lo, double *hi)
{
    if (n < 2) {
        *lo = 0;
        *hi = M_PI / 2;
        return;
    }
    *lo = r > 0 ? 0.5 * (th[r - 1] + th[r]) : fmax(0, th[0] - 0.5 * (th[1] - th[0]));
    *hi = r + 1 < n ? 0.5 * (th[r] + th[r + 1]) : fmin(M_PI / 2, th[n - 1] + 0.5 * (th[n - 1] - th[n - 2]));
}

typedef struct {
    double th, ph;
    int    at;
} dir_t;

static int dir_cmp(const void *a, const void *b)
{
    const dir_t *p = a, *q = b;
    if (p->th != q->th) return p->th < q->th ? -1 : 1;
    if (p->ph != q->ph) return p->ph < q->ph ? -1 : 1;
    return p->at - q->at;
}

static bool same(double a, double b) { return fabs(a - b) < 1e-9; }

// The azimuth interval of member k of a ring's n sorted azimuths ph (0..2 pi):
// the midpoints to its neighbours; a ring whose wrap-around gap is over twice
// its widest other gap is open (the data cover part of the circle), its ends
// extended by half their neighbour's spacing; one azimuth: 2 pi.
static double ring_dphi(const double *ph, int n, int k)
{
    if (n < 2) return 2 * M_PI;
    double widest = 0;
    for (int q = 0; q + 1 < n; q++) widest = fmax(widest, ph[q + 1] - ph[q]);
    double wrap = 2 * M_PI - (ph[n - 1] - ph[0]);
    double before = k > 0 ? ph[k] - ph[k - 1] : wrap, after = k + 1 < n ? ph[k + 1] - ph[k] : wrap;
    if (wrap > 2 * widest) {
        if (k == 0) before = after;
        if (k == n - 1) after = before;
    }
    return 0.5 * (before + after);
}

// Solid angles (sr) of the distinct directions d[0..n) sorted by (theta, phi): area[k].
// false: out of memory.
static bool ring_areas(const dir_t *d, int n, double *area)
{
    double *rth = malloc((size_t)(n > 0 ? n : 1) * sizeof *rth), *ph = malloc((size_t)(n > 0 ? n : 1) * sizeof *ph);
    if (!rth || !ph) {
        free(rth);
        free(ph);
        return false;
    }
    int nr = 0;
    for (int k = 0; k < n; k++)
        if (k == 0 || !same(d[k].th, d[k - 1].th)) rth[nr++] = d[k].th;
    for (int k = 0, r = 0; k < n; r++) {
        int e = k;
        while (e < n && same(d[e].th, d[k].th)) e++;
        double lo, hi;
        ring_edges(rth, nr, r, &lo, &hi);
        for (int q = k; q < e; q++) ph[q - k] = d[q].ph;
        for (int q = k; q < e; q++) area[q] = (cos(lo) - cos(hi)) * ring_dphi(ph, e - k, q - k);
        k = e;
    }
    free(rth);
    free(ph);
    return true;
}

static double wrap_phi(double p)
{
    p = fmod(p, 2 * M_PI);
    return p < 0 ? p + 2 * M_PI : p;
}

// Distinct directions of the samples idx[0..n) (angles ang[4 i + off], [4 i + off + 1])
// and the area of each sample's; samples sharing a direction share it equally.
static bool areas_of(const double *ang, const int *idx, int n, int off, double *area_of_sample)
{
    dir_t *d = malloc((size_t)n * sizeof *d);
    double *a = malloc((size_t)n * sizeof *a);
    dir_t *u = malloc((size_t)n * sizeof *u);
    if (!d || !a || !u) {
        free(d);
        free(a);
        free(u);
        return false;
    }
    for (int k = 0; k < n; k++) {
        double th = ang[4 * idx[k] + off], ph = th < 1e-12 ? 0 : wrap_phi(ang[4 * idx[k] + off + 1]);
        d[k] = (dir_t){ th, ph, k };
    }
    qsort(d, (size_t)n, sizeof *d, dir_cmp);
    int m = 0;
    for (int k = 0; k < n; k++)
        if (k == 0 || !same(d[k].th, d[k - 1].th) || !same(d[k].ph, d[k - 1].ph)) u[m++] = d[k];
    if (!ring_areas(u, m, a)) {
        free(d);
        free(a);
        free(u);
        return false;
    }
    for (int k = 0, q = -1; k < n; k++) {
        if (k == 0 || !same(d[k].th, d[k - 1].th) || !same(d[k].ph, d[k - 1].ph)) q++;
        int e = k;
        while (e + 1 < n && same(d[e + 1].th, d[k].th) && same(d[e + 1].ph, d[k].ph)) e++;
        for (int z = k; z <= e; z++) area_of_sample[d[z].at] = a[q] / (e - k + 1);
        k = e;
    }
    free(d);
    free(a);
    free(u);
    return true;
}

static int cmp_in(const void *a, const void *b, void *ctx)
{
    const double *ang = ctx;
    int i = *(const int *)a, j = *(const int *)b;
    for (int q = 0; q < 2; q++)
        if (!same(ang[4 * i + q], ang[4 * j + q])) return ang[4 * i + q] < ang[4 * j + q] ? -1 : 1;
    return i - j;
}

bool fit_solid_angles(int n, const double *ang, double *w)
{
    int *idx = malloc((size_t)(n > 0 ? n : 1) * sizeof *idx);
    double *ai = malloc((size_t)(n > 0 ? n : 1) * sizeof *ai), *ao = malloc((size_t)(n > 0 ? n : 1) * sizeof *ao);
    bool ok = idx && ai && ao;
    for (int k = 0; ok && k < n; k++) idx[k] = k;
    if (ok) qsort_r(idx, (size_t)n, sizeof *idx, cmp_in, (void *)ang);
    // the incident directions' areas, then per incident direction the outgoing ones'
    double *tmp = ok ? malloc((size_t)(n > 0 ? n : 1) * sizeof *tmp) : NULL;
    ok = ok && tmp && areas_of(ang, idx, n, 0, tmp);
    for (int k = 0; ok && k < n; k++) ai[idx[k]] = tmp[k];
    for (int k = 0; ok && k < n;) {
        int e = k;
        while (e < n && same(ang[4 * idx[e]], ang[4 * idx[k]]) && same(ang[4 * idx[e] + 1], ang[4 * idx[k] + 1])) e++;
        ok = areas_of(ang, idx + k, e - k, 2, tmp);
        // the incident direction's area was shared by its e - k samples: undo that share
        for (int q = k; ok && q < e; q++) ao[idx[q]] = tmp[q - k] * (e - k);
        k = e;
    }
    for (int k = 0; ok && k < n; k++) w[k] = ai[k] * ao[k];
    if (!ok) model_error(NULL, 0, "out of memory for the samples' solid angles");
    free(idx);
    free(ai);
    free(ao);
    free(tmp);
    return ok;
}

// Scattered samples: a k-nearest-neighbour estimate. An isotropic BRDF
// depends on (omega_i, omega_o) only up to a turn about the normal, so each
// sample is the point (u = cos theta_i, omega_o turned by -phi_i) where the
// measure d omega_i d omega_o integrated over phi_i is 2 pi du d omega_o:
// locally Euclidean in (u, the sphere's tangent plane), a ball of radius r
// has measure 2 pi (4/3) pi r^3. A sample's solid angle is that of the ball
// reaching its K-th nearest neighbour, over K (among a strided subset of M
// reference samples when n M would exceed 4e8: times M / n). Balls cut by
// the domain's edges (normal incidence, grazing) overstate their samples'.
bool fit_solid_angles_knn(int n, const double *ang, double *w)
{
    enum { K = 8 };
    if (n <= K) {
        for (int k = 0; k < n; k++) w[k] = 4 * M_PI * M_PI / n;
        return true;
    }
    double *p = malloc(4 * (size_t)n * sizeof *p);
    if (!p) {
        model_error(NULL, 0, "out of memory for the samples' solid angles");
        return false;
    }
    for (int k = 0; k < n; k++) {
        double ti = ang[4 * k], to = ang[4 * k + 2], dp = ang[4 * k + 3] - ang[4 * k + 1];
        p[4 * k] = cos(ti);
        p[4 * k + 1] = sin(to) * cos(dp);
        p[4 * k + 2] = sin(to) * sin(dp);
        p[4 * k + 3] = cos(to);
    }
    int M = n;
    if ((double)n * n > 4e8) M = (int)fmax(4 * K, 4e8 / n);
    if (M > n) M = n;
    double stride = (double)n / M;
    for (int i = 0; i < n; i++) {
        double best[K];
        for (int q = 0; q < K; q++) best[q] = INFINITY;
        for (int m = 0; m < M; m++) {
            int j = (int)(m * stride);
            if (j == i) continue;
            double d0 = p[4 * i] - p[4 * j], d1 = p[4 * i + 1] - p[4 * j + 1], d2 = p[4 * i + 2] - p[4 * j + 2];
            double d3 = p[4 * i + 3] - p[4 * j + 3], dd = d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3;
            if (dd >= best[K - 1]) continue;
            int q = K - 1;
            while (q > 0 && best[q - 1] > dd) {
                best[q] = best[q - 1];
                q--;
            }
            best[q] = dd;
        }
        double r = sqrt(best[K - 1]);
        w[i] = 2 * M_PI * (4.0 / 3) * M_PI * r * r * r / K * ((double)M / n);
    }
    free(p);
    return true;
}

// Rings for grids (few incident directions, each with rings of outgoing
// ones), else the k-nearest-neighbour estimate; *how says which.
static bool solid_angles_auto(int n, const double *ang, double *w, const char **how)
{
    int *idx = malloc((size_t)(n > 0 ? n : 1) * sizeof *idx);
    if (!idx) return false;
    for (int k = 0; k < n; k++) idx[k] = k;
    qsort_r(idx, (size_t)n, sizeof *idx, cmp_in, (void *)ang);
    int groups = 0;
    for (int k = 0; k < n; k++)
        if (k == 0 || !same(ang[4 * idx[k]], ang[4 * idx[k - 1]]) || !same(ang[4 * idx[k] + 1], ang[4 * idx[k - 1] + 1]))
            groups++;
    free(idx);
    bool grid = n >= 16 && groups <= n / 8;
    *how = grid ? "rings" : "k-nearest";
    return grid ? fit_solid_angles(n, ang, w) : fit_solid_angles_knn(n, ang, w);
}

// Weights to mean 1 (the fit's statistics count samples), the sum of the
// solid angles kept in s->omega_sr2.
static void normalise(fit_samples_t *s, bool solid)
{
    double sum = 0;
    for (int k = 0; k < s->n; k++) sum += s->w[k];
    if (solid) s->omega_sr2 = sum;
    for (int k = 0; k < s->n && sum > 0; k++) s->w[k] *= s->n / sum;
}

// ---------------------------------------------------------------------------
// CSV

// Split a CSV line into up to 8 numbers; -1 when a field is not a number.
static int csv_numbers(char *line, double *v, int max, char **bad)
{
    int n = 0;
    char *p = line;
    for (;;) {
        while (*p == ' ' || *p == '\t') p++;
        char *e;
        errno = 0;
        double x = strtod(p, &e);
        if (e == p) {
            *bad = p;
            return -1;
        }
        if (n < max) v[n] = x;
        n++;
        p = e;
        while (*p == ' ' || *p == '\t' || *p == '\r') p++;
        if (*p == ',') {
            p++;
            continue;
        }
        if (*p == 0 || *p == '\n') return n;
        *bad = p;
        return -1;
    }
}

// The CSV's samples; ang (4 per sample: theta_i, phi_i, theta_o, phi_o in
// radians) and whether every line had a weight column, for the weights.
static fit_samples_t *read_csv(const char *path, double **ang, bool *has_w)
{
    int nang = 0, cap = 0;
    *ang = NULL;
    *has_w = true;
    size_t len = 0;
    char *text = model_read_file(path, &len);
    if (!text) return NULL;
    fit_samples_t *s = fit_samples_new();
    if (!s) {
        free(text);
        model_error(path, 0, "out of memory");
        return NULL;
    }
    snprintf(s->source, sizeof s->source, "%s", path);
    model_sha256_hex(text, len, s->sha256);
    int lineno = 0, data_lines = 0, skipped = 0;
    bool ok = true;
    for (char *line = text, *next; line && *line && ok; line = next) {
        lineno++;
        next = strchr(line, '\n');
        if (next) *next++ = 0;
        char *p = line;
        while (*p == ' ' || *p == '\t') p++;
        if (*p == 0 || *p == '\r' || *p == '#') continue;
        double v[8];
        char *bad = NULL;
        int n = csv_numbers(p, v, 8, &bad);
        if (n < 0) {
            if (data_lines == 0 && s->n == 0 && !skipped) {   // the header line
                data_lines++;
                continue;
            }
            model_error(path, lineno, "not a number at '%.20s': each line is theta_i,phi_i,theta_o,phi_o,f_r[,weight] "
                        "(degrees, 1/sr)", bad);
            ok = false;
            break;
        }
        data_lines++;
        if (n != 5 && n != 6) {
            model_error(path, lineno, "%d fields; each line is theta_i,phi_i,theta_o,phi_o,f_r[,weight]", n);
            ok = false;
            break;
        }
        for (int k = 0; k < n; k++)
            if (!isfinite(v[k])) {
                model_error(path, lineno, "field %d is %g: NaN and inf are refused (a missing sample is left out)", k + 1, v[k]);
                ok = false;
            }
        if (!ok) break;
        if (v[0] < 0 || v[0] > 90 || v[2] < 0 || v[2] > 90) {
            model_error(path, lineno, "theta_i = %g, theta_o = %g: zenith angles are 0..90 degrees", v[0], v[2]);
            ok = false;
            break;
        }
        if (n == 5) *has_w = false;
        double w = n == 6 ? v[5] : 1;
        if (!(w > 0)) {
            model_error(path, lineno, "weight = %g: weights are > 0", w);
            ok = false;
            break;
        }
        const double d = M_PI / 180;
        if (nang == cap) {
            cap = cap ? 2 * cap : 1024;
            double *na = realloc(*ang, (size_t)cap * 4 * sizeof *na);
            if (!na) {
                model_error(path, lineno, "out of memory");
                ok = false;
                break;
            }
            *ang = na;
        }
        if (fit_samples_add_angles(s, v[0] * d, v[1] * d, v[2] * d, v[3] * d, v[4], w)) {
            for (int k = 0; k < 4; k++) (*ang)[4 * nang + k] = v[k] * d;
            nang++;
            s->n_negative += v[4] < 0;
        } else {
            if (v[0] < 90 && v[2] < 90) {
                model_error(path, lineno, "out of memory");
                ok = false;
                break;
            }
            skipped++;   // grazing: no reflection to fit
        }
    }
    free(text);
    if (ok && s->n == 0) {
        model_error(path, 0, "no samples (every line is a comment, the header or at 90 degrees)");
        ok = false;
    }
    if (!ok) {
        fit_samples_free(s);
        free(*ang);
        *ang = NULL;
        return NULL;
    }
    return s;
}


// A file whose first 4 KiB hold a NUL or other control bytes is no CSV.
static bool looks_binary(const unsigned char *h, size_t n)
{
    for (size_t k = 0; k < n; k++)
        if ((h[k] < 0x20 && h[k] != '\t' && h[k] != '\n' && h[k] != '\r' && h[k] != '\f') || h[k] == 0x7f) return true;
    return false;
}

static fit_samples_t *load_csv(const char *path, const fit_read_opts_t *o)
{
    double *ang = NULL;
    bool has_w = false;
    fit_samples_t *s = read_csv(path, &ang, &has_w);
    if (!s) return NULL;
    bool ok = true;
    if (o->weights == FIT_WEIGHTS_COLUMN && !has_w) {
        model_error(path, 0, "--weights column: not every line has a weight (the 6th field)");
        ok = false;
    } else if (o->weights == FIT_WEIGHTS_UNIFORM) {
        for (int k = 0; k < s->n; k++) s->w[k] = 1;
    } else if (o->weights == FIT_WEIGHTS_SOLID_ANGLE) {
        ok = solid_angles_auto(s->n, ang, s->w, &s->omega_how);
    }
    free(ang);
    if (!ok) {
        fit_samples_free(s);
        return NULL;
    }
    normalise(s, o->weights == FIT_WEIGHTS_SOLID_ANGLE);
    return s;
}

// ---------------------------------------------------------------------------
// MERL and RGL

// The MERL binary (read by model/brdf/table.c, its one owner): one sample per
// cell centre above the horizon, R = f_r (n.l), weighted by the cell's measure
// in (omega_i, omega_o); missing cells are skipped.
static fit_samples_t *load_merl(const char *path, const fit_read_opts_t *o)
{
    if (o->weights == FIT_WEIGHTS_COLUMN) {
        model_error(path, 0, "--weights column: a MERL file has no weight column (solid-angle or uniform)");
        return NULL;
    }
    model_brdf_table_t *t = model_brdf_table_load_channel(path, o->channel);
    if (!t) return NULL;
    fit_samples_t *s = fit_samples_new();
    if (!s) {
        model_brdf_table_free(t);
        model_error(path, 0, "out of memory");
        return NULL;
    }
    snprintf(s->source, sizeof s->source, "%s", path);
    snprintf(s->sha256, sizeof s->sha256, "%s", model_brdf_table_sha256(t));
    const double *f = model_brdf_table_values_const(t);
    bool ok = true;
    for (int i = 0; i < MODEL_MERL_TH && ok; i++)
        for (int j = 0; j < MODEL_MERL_TD && ok; j++)
            for (int k = 0; k < MODEL_MERL_PD; k++) {
                double v = f[((size_t)i * MODEL_MERL_TD + j) * MODEL_MERL_PD + k];
                model_cosines_t c;
                model_brdf_table_cell(i, j, k, &c);
                if (isnan(v) || !(c.nl > 0 && c.nv > 0)) continue;
                double w = o->weights == FIT_WEIGHTS_SOLID_ANGLE ? model_brdf_table_cell_solid_angle(i, j, k) : 1;
                s->omega_how = "cells";
                if (!fit_samples_add(s, &c, v * c.nl, w)) {
                    model_error(path, 0, "out of memory");
                    ok = false;
                    break;
                }
            }
    model_brdf_table_free(t);
    if (!ok) {
        fit_samples_free(s);
        return NULL;
    }
    normalise(s, o->weights == FIT_WEIGHTS_SOLID_ANGLE);
    return s;
}


// An RGL file at the directions it measured: every measured incident
// direction (isotropic: the first phi_i) with the outgoing directions of its
// value grid's nodes (model_brdf_rgl_nodes: where the file holds a value, so a
// narrow specular peak is sampled as densely as the file measured it);
// f_r = the evaluation / cos(theta_o). Solid-angle weight: the node's outgoing
// solid angle times the incident ring's (theta_i between midpoints,
// ring_edges; its phi_i share 2 pi / the phi_i measured).
static bool rgl_slice(fit_samples_t *s, const model_brdf_rgl_t *r, const double *chw, const fit_read_opts_t *o,
                      int a, int b, double w_in, model_vec3_t *wo, double *dw)
{
    model_vec3_t wi;
    int n = model_brdf_rgl_nodes(r, a, b, &wi, wo, dw);
    s->nodes_total += model_brdf_rgl_nodes_max(r);
    if (!(wi.z > 0)) return true;
    for (int k = 0; k < n; k++) {
        double fr = model_brdf_rgl_eval(r, wi, wo[k], chw) / wo[k].z;
        model_cosines_t c = model_cosines(v3(0, 0, 1), wi, wo[k]);
        double w = o->weights == FIT_WEIGHTS_SOLID_ANGLE ? w_in * dw[k] : 1;
        s->fr_max = fmax(s->fr_max, fr);
        if (!(w > 0)) continue;   // a node on the square's u_theta = 0 edge: no solid angle
        if (!fit_samples_add(s, &c, fr * c.nl, w)) return false;
        s->nodes_used++;
        s->n_negative += fr < 0;
    }
    return true;
}

static fit_samples_t *load_rgl(const char *path, const fit_read_opts_t *o)
{
    if (o->weights == FIT_WEIGHTS_COLUMN) {
        model_error(path, 0, "--weights column: an RGL file has no weight column (solid-angle or uniform)");
        return NULL;
    }
    model_brdf_rgl_t *r = model_brdf_rgl_load(path);
    if (!r) return NULL;
    int nt = model_brdf_rgl_ntheta(r), np = model_brdf_rgl_isotropic(r) ? 1 : model_brdf_rgl_nphi(r);
    int nmax = model_brdf_rgl_nodes_max(r);
    double *chw = malloc((size_t)model_brdf_rgl_channels(r) * sizeof *chw), *th = malloc((size_t)nt * sizeof *th);
    double *dw = malloc((size_t)nmax * sizeof *dw);
    model_vec3_t *wo = malloc((size_t)nmax * sizeof *wo);
    fit_samples_t *s = chw && th && dw && wo ? fit_samples_new() : NULL;
    bool ok = s && model_brdf_rgl_channel_weights(r, o->channel, chw, path);
    if (s) {
        snprintf(s->source, sizeof s->source, "%s", path);
        snprintf(s->sha256, sizeof s->sha256, "%s", model_brdf_rgl_sha256(r));
        s->omega_how = "nodes";
    } else {
        model_error(path, 0, "out of memory");
    }
    for (int b = 0; ok && b < nt; b++) th[b] = model_brdf_rgl_theta_i(r, b);
    for (int a = 0; ok && a < np; a++)
        for (int b = 0; ok && b < nt; b++) {
            double lo, hi;
            ring_edges(th, nt, b, &lo, &hi);
            if (!(ok = rgl_slice(s, r, chw, o, a, b, (cos(lo) - cos(hi)) * 2 * M_PI / np, wo, dw)))
                model_error(path, 0, "out of memory");
        }
    free(th);
    free(chw);
    free(dw);
    free(wo);
    model_brdf_rgl_free(r);
    if (ok && s->n == 0) {
        model_error(path, 0, "RGL file: no measured direction above the surface");
        ok = false;
    }
    if (!ok) {
        fit_samples_free(s);
        return NULL;
    }
    normalise(s, o->weights == FIT_WEIGHTS_SOLID_ANGLE);
    return s;
}

fit_samples_t *fit_samples_load(const char *path, const fit_read_opts_t *opts)
{
    fit_read_opts_t o = opts ? *opts : fit_read_defaults();
    FILE *f = fopen(path, "rb");
    if (!f) {
        model_error(path, 0, "cannot open: %s", strerror(errno));
        return NULL;
    }
    unsigned char h[4096];
    size_t got = fread(h, 1, sizeof h, f);
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    fclose(f);
    if (got >= 12 && size > 0 && model_brdf_table_sniff(h, (size_t)size)) return load_merl(path, &o);
    if (model_brdf_rgl_sniff(h, got)) return load_rgl(path, &o);
    if (looks_binary(h, got)) {
        model_error(path, 0, "a binary file that is neither a MERL table (int32 dims 90 90 180, %zu bytes) nor an RGL "
                    ".bsdf (starting \"tensor_file\"): refl fit brdf reads those and CSV text",
                    (size_t)12 + 3 * (size_t)MODEL_MERL_TH * MODEL_MERL_TD * MODEL_MERL_PD * sizeof(double));
        return NULL;
    }
    if (o.channel != 0) {
        model_error(path, 0, "--channel %s: a CSV holds one f_r per line (only luma)",
                    model_channel_name((model_channel_t)o.channel));
        return NULL;
    }
    return load_csv(path, &o);
}

fit_samples_t *fit_samples_read(const char *path) { return fit_samples_load(path, NULL); }

fit_samples_t *fit_samples_read_csv(const char *path)
{
    double *ang = NULL;
    bool has_w;
    fit_samples_t *s = read_csv(path, &ang, &has_w);   // the file's weights as they are
    free(ang);
    return s;
}

fit_samples_t *fit_samples_read_merl(const char *path)
{
    fit_read_opts_t o = fit_read_defaults();
    o.weights = FIT_WEIGHTS_UNIFORM;
    return load_merl(path, &o);
}

// ---------------------------------------------------------------------------
// Samples over Ngan et al.'s (2005) integral

fit_samples_t *fit_samples_ngan(double (*R)(const void *ctx, const model_cosines_t *c), const void *ctx, int stride)
{
    if (stride < 1) stride = 1;
    fit_samples_t *s = fit_samples_new();
    if (!s) {
        model_error(NULL, 0, "out of memory for the reference samples");
        return NULL;
    }
    snprintf(s->source, sizeof s->source, "Ngan reference samples (MERL cells, every %d in theta_d and phi_d)", stride);
    const double cmin = cos(FIT_NGAN_THETA_MAX_DEG * M_PI / 180);
    for (int i = 0; i < MODEL_MERL_TH; i++)
        for (int j = stride / 2; j < MODEL_MERL_TD; j += stride)
            for (int k = stride / 2; k < MODEL_MERL_PD; k += stride) {
                model_cosines_t c;
                model_brdf_table_cell(i, j, k, &c);
                if (!(c.nl >= cmin && c.nv >= cmin)) continue;
                double v = R(ctx, &c);
                // every stride x stride block of (theta_d, phi_d) cells stands for the whole block
                double w = model_brdf_table_cell_solid_angle(i, j, k) * stride * stride;
                if (!isfinite(v)) {
                    model_error(NULL, 0, "the reference BRDF is not finite at theta_h cell %d, theta_d %d, phi_d %d", i,
                                j, k);
                    fit_samples_free(s);
                    return NULL;
                }
                if (!fit_samples_add(s, &c, v, w)) {
                    model_error(NULL, 0, "out of memory for the reference samples");
                    fit_samples_free(s);
                    return NULL;
                }
            }
    s->omega_how = "cells";
    normalise(s, true);
    return s;
}

double fit_mixture_R(const void *ctx, const model_cosines_t *c)
{
    const fit_mixture_t *m = ctx;
    double R = 0;
    for (int k = 0; k < m->n; k++) R += m->weight[k] * model_material_eval(m->mat[k], c);
    return R;
}
