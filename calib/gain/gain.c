// calib/gain/gain.c — the library of `refl calib gain` (calib/gain/gain.h; the command
// is calib/cmd_gain.c): the camera's sensitivity, EMVA 1288 style.
//
// Input: frames of a uniform source (a flat field) at known exposures, light
// (lamps on) and dark (lamps off), from
//   --rig RIG          captured here: per gain a probe, an exposure sweep
//                      (frame pairs, light and dark, up to beyond saturation),
//                      at the first gain also long dark frames (dark current)
//                      and a flat field (many frames at ~50 % of saturation)
//   --session DIR      a session captured elsewhere (light = lamps on, dark = "none")
//   --frames CSV       a manifest "file,exposure_us,kind" (kind dark|light)
// Analysis per gain (EMVA 1288 definitions, see calib/gain/gain.h): photon transfer
// (K, read noise, saturation, SNR, dynamic range), linearity error, response
// (DN/us, and kc per us per unit radiance when the source's radiance is
// given: a virtual rig's truth of it is only recorded beside it, for
// comparison, never used in its place); at the first gain also the dark
// current, the offset and DSNU maps and the PRNU map (flat field).
// Output: DIR/gain.json, DIR/offset_dn.tiff, DIR/dsnu_dn.tiff,
// DIR/prnu_gain.tiff (total: vignetting included, mean 1),
// DIR/prnu_highpass.tiff (smooth part removed, mean 1), DIR/report.html + PNGs.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/report.h"
#include "rig/virtual/truth.h"

// ---------------------------------------------------------------------------
// Numerics


bool calib_gain_polyfit(const double *x, const double *y, int n, int degree, double *c)
{
    if (degree < 1 || degree > 2 || n <= degree) return false;
    int m = degree + 1;
    // scale x for conditioning
    double sx = 0;
    for (int i = 0; i < n; i++) sx = fmax(sx, fabs(x[i]));
    if (!(sx > 0)) return false;
    double A[9] = { 0 }, b[3] = { 0 };
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) };
        for (int r = 0; r < m; r++) {
            b[r] += p[r] * y[i];
            for (int k = 0; k < m; k++) A[r * m + k] += p[r] * p[k];
        }
    }
    if (!model_solve_linear(A, b, m)) return false;
    c[0] = b[0];
    c[1] = b[1] / sx;
    if (degree == 2) c[2] = b[2] / (sx * sx);
    return true;
}

bool calib_gain_polyfit_se(const double *x, const double *y, int n, int degree, double *c, double *se)
{
    if (!calib_gain_polyfit(x, y, n, degree, c)) return false;
    int m = degree + 1;
    if (n <= m) return false;
    double sx = 0;
    for (int i = 0; i < n; i++) sx = fmax(sx, fabs(x[i]));
    // (X^T X)^-1 in the scaled powers (columns solved one at a time)
    double A[9] = { 0 }, Ai[9], h[3];
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) };
        for (int r = 0; r < m; r++)
            for (int k = 0; k < m; k++) A[r * m + k] += p[r] * p[k];
    }
    for (int k = 0; k < m; k++) {
        double B[9], b[3] = { 0 };
        memcpy(B, A, sizeof B);
        b[k] = 1;
        if (!model_solve_linear(B, b, m)) return false;
        for (int r = 0; r < m; r++) Ai[r * m + k] = b[r];
    }
    // the sandwich (X^T X)^-1 X^T diag(e_i^2 / (1 - h_i)^2) X (X^T X)^-1 (HC3)
    double S[9] = { 0 };
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) }, fit = 0, hi = 0;
        for (int r = 0; r < m; r++) fit += c[r] * pow(x[i], r);
        for (int r = 0; r < m; r++) {
            h[r] = 0;
            for (int k = 0; k < m; k++) h[r] += Ai[r * m + k] * p[k];
            hi += p[r] * h[r];
        }
        double e = (y[i] - fit) / fmax(1 - hi, 1e-3);
        for (int r = 0; r < m; r++)
            for (int k = 0; k < m; k++) S[r * m + k] += e * e * h[r] * h[k];
    }
    for (int r = 0; r < m; r++) se[r] = sqrt(fmax(S[r * m + r], 0)) / pow(sx, r);
    return true;
}

// Half the range of the relative deviations 100 (mu - line) / line, %, over
// the points with mu in [lo_dn, hi_dn] (and mu > 0 when positive); each
// point's deviation into dev_pct (NAN outside the range) when given.
static double deviation_half_range(double c0, double c1, const double *t, const double *mu, int n, double lo_dn,
                                   double hi_dn, bool positive, double *dev_pct)
{
    double dmin = INFINITY, dmax = -INFINITY;
    for (int i = 0; i < n; i++) {
        double line = c0 + c1 * t[i], d = 100.0 * (mu[i] - line) / line;
        bool in = mu[i] >= lo_dn && mu[i] <= hi_dn && (!positive || mu[i] > 0);
        if (dev_pct) dev_pct[i] = in ? d : NAN;
        if (in) {
            dmin = fmin(dmin, d);
            dmax = fmax(dmax, d);
        }
    }
    return 0.5 * (dmax - dmin);
}

double calib_gain_linearity(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                            double *slope, double *offset, int *nfit, double *dev_pct)
{
    double *x = malloc(sizeof(double) * (n + 1)), *y = malloc(sizeof(double) * (n + 1));
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] >= lo * sat_dn && mu[i] <= hi * sat_dn) {
            x[m] = t[i];
            y[m] = mu[i];
            m++;
        }
    double c[3] = { NAN, NAN, NAN }, le = NAN;
    if (m >= 3 && calib_gain_polyfit(x, y, m, 1, c)) {
        le = deviation_half_range(c[0], c[1], t, mu, n, lo * sat_dn, hi * sat_dn, false, dev_pct);
    } else if (dev_pct)
        for (int i = 0; i < n; i++) dev_pct[i] = NAN;
    if (slope) *slope = c[1];
    if (offset) *offset = c[0];
    if (nfit) *nfit = m;
    free(x);
    free(y);
    return le;
}

double calib_gain_linearity_r4(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                               double *slope, double *offset, int *nfit, double *dev_pct)
{
    // EMVA 1288 Release 4.0, "Linearity": the regression minimises the
    // relative deviations, i.e. weighted least squares with weights 1/mu^2
    double ts = 0;
    for (int i = 0; i < n; i++) ts = fmax(ts, fabs(t[i]));
    double A[4] = { 0 }, b[2] = { 0 };
    int m = 0;
    for (int i = 0; i < n; i++) {
        if (!(mu[i] >= lo * sat_dn && mu[i] <= hi * sat_dn && mu[i] > 0) || !(ts > 0)) continue;
        double w = 1 / (mu[i] * mu[i]), x = t[i] / ts;
        A[0] += w;
        A[1] += w * x;
        A[3] += w * x * x;
        b[0] += w * mu[i];
        b[1] += w * x * mu[i];
        m++;
    }
    A[2] = A[1];
    double le = NAN, c0 = NAN, c1 = NAN;
    if (m >= 3 && model_solve_linear(A, b, 2)) {
        c0 = b[0];
        c1 = b[1] / ts;
        le = deviation_half_range(c0, c1, t, mu, n, lo * sat_dn, hi * sat_dn, true, dev_pct);
    } else if (dev_pct)
        for (int i = 0; i < n; i++) dev_pct[i] = NAN;
    if (slope) *slope = c1;
    if (offset) *offset = c0;
    if (nfit) *nfit = m;
    return le;
}

double calib_gain_parametric_a(const double *t, const double *mu, int n, double sat)
{
    double A[9] = { 0 }, b[3] = { 0 }, ts = 0, ss = 0;   // column scales
    for (int i = 0; i < n; i++) {
        ts = fmax(ts, fabs(t[i]));
        ss = fmax(ss, fabs(mu[i]));
    }
    if (!(ts > 0) || !(ss > 0)) return 0;
    int m = 0;
    for (int i = 0; i < n; i++) {
        double ti = t[i], si = mu[i];
        if (!(si > 0) || (sat > 0 && si > 0.9 * sat) || !isfinite(ti)) continue;
        double x[3] = { ti / ts, 1, -si * si / (ss * ss) };
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++) A[3 * r + c] += x[r] * x[c];
            b[r] += x[r] * si;
        }
        m++;
    }
    if (m < 5 || !model_solve_linear(A, b, 3)) return 0;
    double a = b[2] / (ss * ss);
    return isfinite(a) && a > 0 && a < 1e-3 ? a : 0;
}

bool calib_gain_linearisation(const double *t, const double *mu, int n, double sat, model_lin_t *table,
                              double *a_per_dn, double *anchor_slope, double *anchor_offset)
{
    memset(table, 0, sizeof *table);
    *a_per_dn = calib_gain_parametric_a(t, mu, n, sat);
    double *x = malloc(sizeof(double) * (n + 1) * 2), *y = x + n + 1, c[3];
    if (!x) {
        model_error_set(NULL, 0, "out of memory for the linearisation");
        return false;
    }
    // the anchor: small-signal response from 5..70 % of saturation (above the
    // low end, below the knee of a sensor's top end)
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] >= 0.05 * sat && mu[i] <= 0.7 * sat) {
            x[m] = t[i];
            y[m] = mu[i];
            m++;
        }
    if (m < 4 || !calib_gain_polyfit(x, y, m, 2, c) || !(c[1] > 0)) {
        free(x);
        model_error_set(NULL, 0, "linearisation: %d sweep steps between 5 %% and 70 %% of saturation (%.6g DN); the "
                        "small-signal response needs at least 4 with a rising signal", m, sat);
        return false;
    }
    *anchor_slope = c[1];
    *anchor_offset = c[0];
    // the table: every step up to saturation, measured -> anchored linear
    m = 0;
    double tlast = -INFINITY;
    for (int i = 0; i < n; i++)
        if (mu[i] <= sat && t[i] > tlast) {
            tlast = t[i];
            x[m] = mu[i];
            y[m] = c[0] + c[1] * t[i];
            m++;
        }
    // the linear signal must rise: steps whose anchored value is not above 0 (exposures shorter than the
    // offset c0 / r allows) carry nothing
    int k0 = 0;
    while (k0 < m && !(y[k0] > 0)) k0++;
    bool ok = model_lin_monotone(x + k0, y + k0, m - k0, table);
    free(x);
    if (!ok) {
        char *e = g_strdup(model_last_error());
        model_error_set(NULL, 0, "linearisation: %s", e);
        g_free(e);
    }
    return ok;
}

bool calib_gain_ptc(const double *t, const double *mu, const double *var, const double *var_y, int n,
                    double var_dark_dn2, double quant_dn, calib_gain_ptc_t *o)
{
    memset(o, 0, sizeof *o);
    if (n < 6) {
        model_error_set(NULL, 0, "photon transfer: %d exposure steps; at least 6 are needed", n);
        return false;
    }
    int imax = 0;
    for (int i = 1; i < n; i++)
        if (var[i] > var[imax]) imax = i;
    // saturation: the variance must drop after its maximum (EMVA 1288)
    bool drop = false;
    for (int i = imax + 1; i < n; i++)
        if (var[i] < 0.9 * var[imax]) drop = true;
    if (!drop) {
        model_error_set(NULL, 0, "photon transfer: the variance does not drop after its maximum %.4g DN^2 at %.6g us "
                        "(mean %.6g DN above dark, the longest exposure of %d is %.6g us): the sweep does not reach "
                        "saturation; extend it to longer exposures", var[imax], t[imax], mu[imax], n, t[n - 1]);
        return false;
    }
    o->i_sat = imax;
    o->saturation_dn = mu[imax];
    double *x = malloc(sizeof(double) * n), *y = malloc(sizeof(double) * n);
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] > 0 && mu[i] <= 0.7 * o->saturation_dn) {
            x[m] = mu[i];
            y[m] = var[i];
            m++;
        }
    double c2[3], c1[3], se2[3];
    bool ok = m >= 5 && calib_gain_polyfit(x, y, m, 2, c2) && calib_gain_polyfit(x, y, m, 1, c1);
    o->system_gain_std_dn_per_e = ok && calib_gain_polyfit_se(x, y, m, 2, c2, se2) ? se2[1] : NAN;
    free(x);
    free(y);
    if (!ok || !(c2[1] > 0)) {
        model_error_set(NULL, 0, "photon transfer: %d points below 70 %% of saturation (%.6g DN); the fit of the "
                        "variance against the mean failed (at least 5 are needed, with a rising variance)",
                        m, o->saturation_dn);
        return false;
    }
    o->n_ptc_fit = m;
    o->system_gain_dn_per_e = c2[1];
    o->system_gain_linear_dn_per_e = c1[1];
    double rd2 = var_dark_dn2 - quant_dn * quant_dn / 12.0;
    o->read_noise_dn = rd2 > 0 ? sqrt(rd2) : 0;
    o->read_noise_e = o->read_noise_dn / o->system_gain_dn_per_e;
    o->saturation_capacity_e = o->saturation_dn / o->system_gain_dn_per_e;
    o->dynamic_range = o->read_noise_e > 0 ? o->saturation_capacity_e / o->read_noise_e : NAN;
    o->linearity_error_pct = calib_gain_linearity_r4(t, mu, n, o->saturation_dn, 0.05, 0.95,
                                                     &o->response_dn_per_us, &o->response_offset_dn, &o->n_lin_fit,
                                                     NULL);
    o->linearity_error_r3_pct = calib_gain_linearity(t, mu, n, o->saturation_dn, 0.05, 0.95, NULL, NULL, NULL, NULL);
    o->snr_max = 0;
    for (int i = 0; i <= imax; i++) {
        double vy = var_y ? var_y[i] : var[i];
        if (vy > 0) o->snr_max = fmax(o->snr_max, mu[i] / sqrt(vy));
    }
    return true;
}

double calib_gain_correlation(const float *a, const float *b, long n)
{
    double sa = 0, sb = 0;
    for (long i = 0; i < n; i++) {
        sa += a[i];
        sb += b[i];
    }
    double ma = sa / n, mb = sb / n, saa = 0, sbb = 0, sab = 0;
    for (long i = 0; i < n; i++) {
        double da = a[i] - ma, db = b[i] - mb;
        saa += da * da;
        sbb += db * db;
        sab += da * db;
    }
    if (!(saa > 0 && sbb > 0)) return NAN;
    return sab / sqrt(saa * sbb);
}

bool calib_gain_highpass(const float *in, int w, int h, float *out)
{
    double A[36] = { 0 }, b[6] = { 0 };
    const double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1);
    const double sx = cx > 0 ? cx : 1, sy = cy > 0 ? cy : 1;
    for (int y = 0; y < h; y++) {
        double v = (y - cy) / sy;
        // per row: sums over x of the x-dependent terms, then the outer product
        double S[5] = { 0 }, T[3] = { 0 };   // sum u^k (k 0..4), sum u^k * in (k 0..2)
        for (int x = 0; x < w; x++) {
            double u = (x - cx) / sx, f = in[(size_t)y * w + x];
            double u2 = u * u;
            S[0] += 1;
            S[1] += u;
            S[2] += u2;
            S[3] += u2 * u;
            S[4] += u2 * u2;
            T[0] += f;
            T[1] += f * u;
            T[2] += f * u2;
        }
        // basis: 1, u, v, u^2, u v, v^2  = u^a v^b
        static const int pa[6] = { 0, 1, 0, 2, 1, 0 }, pb[6] = { 0, 0, 1, 0, 1, 2 };
        for (int r = 0; r < 6; r++) {
            b[r] += T[pa[r]] * pow(v, pb[r]);
            for (int k = 0; k < 6; k++) A[r * 6 + k] += S[pa[r] + pa[k]] * pow(v, pb[r] + pb[k]);
        }
    }
    if (!model_solve_linear(A, b, 6)) return false;
    for (int y = 0; y < h; y++) {
        double v = (y - cy) / sy;
        for (int x = 0; x < w; x++) {
            double u = (x - cx) / sx;
            double s = b[0] + b[1] * u + b[2] * v + b[3] * u * u + b[4] * u * v + b[5] * v * v;
            size_t i = (size_t)y * w + x;
            out[i] = s != 0 ? (float)(in[i] / s) : NAN;
        }
    }
    return true;
}

// ---------------------------------------------------------------------------
// Frames and groups

void calib_gain_data_free(calib_gain_data_t *d)
{
    for (int i = 0; i < d->nf; i++) {
        free(d->f[i].path);
        free(d->f[i].where);
    }
    for (int i = 0; i < d->ng; i++) {
        free(d->g[i].idx);
        free(d->g[i].error);
    }
    free(d->f);
    free(d->g);
}

static void add_frame(calib_gain_data_t *d, const calib_gain_frame_t *f)
{
    d->f = realloc(d->f, sizeof *d->f * (d->nf + 1));
    d->f[d->nf++] = *f;
}

static const char *frame_name(const calib_gain_frame_t *f, char *buf, size_t size)
{
    if (f->line > 0) snprintf(buf, size, "%s:%d (%s)", f->where, f->line, f->path);
    else snprintf(buf, size, "%s (session %s, step %d)", f->path, f->where, f->step);
    return buf;
}

// Load a frame; errors name the manifest line or the session step.
static float *frame_load(const calib_gain_frame_t *f, int *w, int *h)
{
    bool q = model_error_quiet_thread(true);
    float *img = NULL;
    char sha[65];
    if (f->sha256[0]) {
        if (!model_sha256_file(f->path, sha)) goto fail;
        if (strcmp(sha, f->sha256)) {
            model_error_set(f->path, 0, "sha256 %s differs from the journal's %s: the frame was changed or damaged",
                            sha, f->sha256);
            goto fail;
        }
    }
    img = model_image_read_float(f->path, w, h);
    if (!img) goto fail;
    model_error_quiet_thread(q);
    return img;
fail:;
    char *why = g_strdup(model_last_error());
    model_error_quiet_thread(q);
    if (f->line > 0) model_error_set(f->where, f->line, "frame %s: %s", f->path, why);
    else model_error_set(f->path, 0, "step %d of the session %s: %s", f->step, f->where, why);
    g_free(why);
    return NULL;
}

static void roi_of(const calib_gain_data_t *d, int w, int h, int r[4])
{
    if (d->roi[2] > 0) memcpy(r, d->roi, sizeof d->roi);
    else {
        r[0] = r[1] = 0;
        r[2] = w;
        r[3] = h;
    }
}

static int group_find(calib_gain_data_t *d, double exposure_us, double gain_db, bool dark, int set)
{
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->exposure_us == exposure_us && g->gain_db == gain_db && g->dark == dark && g->set == set) return i;
    }
    d->g = realloc(d->g, sizeof *d->g * (d->ng + 1));
    d->g[d->ng] = (calib_gain_group_t){ .exposure_us = exposure_us, .gain_db = gain_db, .dark = dark, .set = set,
                              .var_dn2 = NAN };
    return d->ng++;
}

void calib_gain_make_groups(calib_gain_data_t *d)
{
    for (int i = 0; i < d->nf; i++) {
        const calib_gain_frame_t *f = &d->f[i];
        int set = f->set == CALIB_GAIN_SET_ANY ? CALIB_GAIN_SET_SWEEP : f->set;
        int gi = group_find(d, f->exposure_us, f->gain_db, f->dark, set);
        calib_gain_group_t *g = &d->g[gi];
        g->idx = realloc(g->idx, sizeof(int) * (g->n + 1));
        g->idx[g->n++] = i;
    }
}

typedef struct {
    calib_gain_data_t *d;
    int      done;
    int      total;
    double   t0;
} pass1_t;

static void pass1_rows(void *ctx, int begin, int end, int thread)
{
    (void)thread;
    pass1_t *P = ctx;
    calib_gain_data_t *d = P->d;
    for (int gi = begin; gi < end; gi++) {
        calib_gain_group_t *g = &d->g[gi];
        float *prev = NULL;
        double sum_mean = 0, sum_var = 0;
        int npairs = 0;
        for (int k = 0; k < g->n && !g->error; k++) {
            const calib_gain_frame_t *f = &d->f[g->idx[k]];
            int w, h;
            float *img = frame_load(f, &w, &h);
            if (!img) {
                g->error = g_strdup(model_last_error());
                break;
            }
            char nb[1024];
            if (k == 0) {
                g->width = w;
                g->height = h;
            } else if (w != g->width || h != g->height) {
                g->error = g_strdup_printf("%s: %dx%d pixels, the other frames of this exposure are %dx%d",
                                           frame_name(f, nb, sizeof nb), w, h, g->width, g->height);
                free(img);
                break;
            }
            int r[4];
            roi_of(d, w, h, r);
            if (r[0] + r[2] > w || r[1] + r[3] > h) {
                g->error = g_strdup_printf("%s: the region %d,%d,%d,%d does not fit the %dx%d frame",
                                           frame_name(f, nb, sizeof nb), r[0], r[1], r[2], r[3], w, h);
                free(img);
                break;
            }
            double s = 0, sd = 0, sdd = 0;
            long nsat = 0, np = (long)r[2] * r[3];
            for (int y = r[1]; y < r[1] + r[3]; y++) {
                const float *row = img + (size_t)y * w;
                const float *prow = prev ? prev + (size_t)y * w : NULL;
                for (int x = r[0]; x < r[0] + r[2]; x++) {
                    s += row[x];
                    if (row[x] >= f->max_dn) nsat++;
                    if (prow) {
                        double dd = (double)row[x] - prow[x];
                        sd += dd;
                        sdd += dd * dd;
                    }
                }
            }
            sum_mean += s / np;
            if (k == 0) g->sat_frac = (double)nsat / np;
            if (prev) {
                double md = sd / np;
                sum_var += 0.5 * (sdd / np - md * md);
                npairs++;
                free(prev);
                prev = NULL;
                free(img);
            } else
                prev = img;
        }
        free(prev);
        if (!g->error) {
            g->mean_dn = sum_mean / g->n;
            g->var_dn2 = npairs ? sum_var / npairs : NAN;
        }
        int done = __atomic_add_fetch(&P->done, g->n, __ATOMIC_ACQ_REL);
        if (P->total > 100 && (done * 10 / P->total) != ((done - g->n) * 10 / P->total))
            fprintf(stderr, "refl calib gain: read %d/%d frames (%.0f s)\n", done, P->total, model_now_s() - P->t0);
    }
}

bool calib_gain_frame_stats(calib_gain_data_t *d)
{
    pass1_t P = { d, 0, d->nf, model_now_s() };
    model_parallel_for(d->ng, 1, model_default_threads(), pass1_rows, &P);
    for (int i = 0; i < d->ng; i++)
        if (d->g[i].error) {
            model_error_set(NULL, 0, "%s", d->g[i].error);
            return false;
        }
    // one frame size
    for (int i = 1; i < d->ng; i++)
        if (d->g[i].width != d->g[0].width || d->g[i].height != d->g[0].height) {
            char nb[1024];
            model_error_set(NULL, 0, "%s: %dx%d pixels, but %dx%d elsewhere in the input",
                            frame_name(&d->f[d->g[i].idx[0]], nb, sizeof nb), d->g[i].width, d->g[i].height,
                            d->g[0].width, d->g[0].height);
            return false;
        }
    return true;
}

// ---------------------------------------------------------------------------
// Analysis of one gain

void calib_gain_an_free(calib_gain_an_t *a)
{
    double *arrays[] = { a->t, a->mu_y, a->var_y, a->mu_d, a->var_d, a->mu, a->var, a->dev_pct, a->snr, a->mu_p,
                         a->dark_t_us };
    for (size_t i = 0; i < sizeof arrays / sizeof arrays[0]; i++) free(arrays[i]);
}

static int cmp_group_t(const void *a, const void *b)
{
    const calib_gain_group_t *const *x = a, *const *y = b;
    return ((*x)->exposure_us > (*y)->exposure_us) - ((*x)->exposure_us < (*y)->exposure_us);
}

// The linearisation of a's sweep and the Release 4.0 LE of the signal through
// it (the table's and the parametric form's; the range 5..95 % of saturation
// mapped through each), for the report.
static bool analyse_linearisation(calib_gain_an_t *a)
{
    const double sat = a->ptc.saturation_dn;
    if (!calib_gain_linearisation(a->t, a->mu, a->n, sat, &a->lin, &a->lin_a_per_dn, &a->lin_anchor_dn_per_us,
                                  &a->lin_anchor_offset_dn)) {
        char *m = g_strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g dB: %s", a->gain_db, m);
        g_free(m);
        return false;
    }
    double *v = malloc(sizeof(double) * a->n);
    if (!v) return false;
    model_lin_t par = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = a->lin_a_per_dn };
    for (int k = 0; k < 2; k++) {
        const model_lin_t *L = k ? &par : &a->lin;
        for (int i = 0; i < a->n; i++) v[i] = model_linearise(L, a->mu[i], 1, NULL);
        double lo = model_linearise(L, 0.05 * sat, 1, NULL), hi = model_linearise(L, 0.95 * sat, 1, NULL);
        *(k ? &a->le_linearised_param_pct : &a->le_linearised_pct) =
            calib_gain_linearity_r4(a->t, v, a->n, 1, lo, hi, NULL, NULL, NULL, NULL);
    }
    free(v);
    return true;
}

bool calib_gain_analyse(calib_gain_data_t *d, double gain_db, int min_steps, double quant_dn, calib_gain_an_t *a)
{
    memset(a, 0, sizeof *a);
    a->gain_db = gain_db;
    a->radiance = NAN;
    a->kc_per_us = NAN;
    // dark model: mean and variance against exposure (all dark groups of this gain)
    int nd = 0, nl = 0;
    double *dt = malloc(sizeof(double) * d->ng), *dm = malloc(sizeof(double) * d->ng),
           *dv = malloc(sizeof(double) * d->ng);
    int ndv = 0;
    double *dtv = malloc(sizeof(double) * d->ng);
    calib_gain_group_t **light = malloc(sizeof *light * d->ng);
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != gain_db) continue;
        if (g->dark) {
            dt[nd] = g->exposure_us;
            dm[nd] = g->mean_dn;
            nd++;
            if (isfinite(g->var_dn2)) {
                dtv[ndv] = g->exposure_us;
                dv[ndv] = g->var_dn2;
                ndv++;
            }
        } else if (g->set == CALIB_GAIN_SET_SWEEP && g->n >= 2)
            light[nl++] = g;
    }
    bool ok = false;
    if (nd == 0 || ndv == 0) {
        model_error_set(NULL, 0, "gain %g dB: no dark frame pairs (kind dark, at least two frames at an exposure); the "
                        "dark level and temporal dark noise need them", gain_db);
        goto done;
    }
    a->ndark = nd;
    a->dark_t_us = malloc(sizeof(double) * nd);
    if (a->dark_t_us) memcpy(a->dark_t_us, dt, sizeof(double) * nd);
    a->dark_t_min_us = INFINITY;
    a->dark_t_max_us = -INFINITY;
    for (int i = 0; i < nd; i++) {
        a->dark_t_min_us = fmin(a->dark_t_min_us, dt[i]);
        a->dark_t_max_us = fmax(a->dark_t_max_us, dt[i]);
    }
    double c[3], cse[3];
    a->dark_slope_std_dn_per_us = NAN;
    a->var_dark_std_dn2 = NAN;
    if (a->dark_t_max_us > a->dark_t_min_us && calib_gain_polyfit(dt, dm, nd, 1, c)) {
        a->dark_intercept_dn = c[0];
        a->dark_slope_dn_per_us = c[1];
        if (nd >= 3 && calib_gain_polyfit_se(dt, dm, nd, 1, c, cse)) a->dark_slope_std_dn_per_us = cse[1];
    } else {
        double s = 0;
        for (int i = 0; i < nd; i++) s += dm[i];
        a->dark_intercept_dn = s / nd;
        a->dark_slope_dn_per_us = 0;
    }
    double dvc[3];
    bool dv_fit = false;
    {
        double tmin = INFINITY, tmax = -INFINITY;
        for (int i = 0; i < ndv; i++) {
            tmin = fmin(tmin, dtv[i]);
            tmax = fmax(tmax, dtv[i]);
        }
        dv_fit = ndv >= 3 && tmax > tmin && calib_gain_polyfit(dtv, dv, ndv, 1, dvc);
        a->dark_var_slope_dn2_per_us = dv_fit ? dvc[1] : NAN;
        double dvse[3];
        if (dv_fit) {
            a->var_dark_dn2 = dvc[0];
            if (calib_gain_polyfit_se(dtv, dv, ndv, 1, dvc, dvse)) a->var_dark_std_dn2 = dvse[0];
        } else {
            double s = 0, ss = 0;
            for (int i = 0; i < ndv; i++) s += dv[i];
            a->var_dark_dn2 = s / ndv;
            for (int i = 0; i < ndv; i++) ss += (dv[i] - a->var_dark_dn2) * (dv[i] - a->var_dark_dn2);
            if (ndv >= 2) a->var_dark_std_dn2 = sqrt(ss / (ndv - 1) / ndv);
        }
    }
    if (nl < min_steps) {
        model_error_set(NULL, 0, "gain %g dB: too few sweep steps: %d exposures with a pair of light frames, EMVA 1288 "
                        "asks for at least %d (capture more exposures, e.g. --steps 50)", gain_db, nl, min_steps);
        goto done;
    }
    qsort(light, nl, sizeof *light, cmp_group_t);
    a->n = nl;
#define ALLOC(p) a->p = calloc(nl, sizeof(double))
    ALLOC(t); ALLOC(mu_y); ALLOC(var_y); ALLOC(mu_d); ALLOC(var_d); ALLOC(mu); ALLOC(var); ALLOC(dev_pct); ALLOC(snr);
#undef ALLOC
    for (int i = 0; i < nl; i++) {
        calib_gain_group_t *g = light[i];
        a->t[i] = g->exposure_us;
        a->mu_y[i] = g->mean_dn;
        a->var_y[i] = g->var_dn2;
        // the dark pair at the same exposure, else the dark model
        calib_gain_group_t *best = NULL;
        for (int k = 0; k < d->ng; k++) {
            calib_gain_group_t *h = &d->g[k];
            if (h->gain_db == gain_db && h->dark && h->exposure_us == g->exposure_us && isfinite(h->var_dn2) &&
                (!best || h->n > best->n))
                best = h;
        }
        if (best) {
            a->mu_d[i] = best->mean_dn;
            a->var_d[i] = best->var_dn2;
        } else {
            a->mu_d[i] = a->dark_intercept_dn + a->dark_slope_dn_per_us * g->exposure_us;
            a->var_d[i] = dv_fit ? dvc[0] + dvc[1] * g->exposure_us : a->var_dark_dn2;
        }
        a->mu[i] = a->mu_y[i] - a->mu_d[i];
        a->var[i] = a->var_y[i] - a->var_d[i];
        a->snr[i] = a->var_y[i] > 0 ? a->mu[i] / sqrt(a->var_y[i]) : NAN;
    }
    if (!calib_gain_ptc(a->t, a->mu, a->var, a->var_y, nl, a->var_dark_dn2, quant_dn, &a->ptc)) {
        char *m = g_strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g dB: %s", gain_db, m);
        g_free(m);
        goto done;
    }
    // the 1-sigmas of read noise and dark current: K's and the dark fits' in quadrature (relative)
    {
        const calib_gain_ptc_t *p = &a->ptc;
        double kr = p->system_gain_std_dn_per_e / p->system_gain_dn_per_e;
        double rr = p->read_noise_dn > 0 ? a->var_dark_std_dn2 / (2 * p->read_noise_dn * p->read_noise_dn) : NAN;
        a->read_noise_std_e = p->read_noise_e * hypot(rr, kr);
        a->dark_current_std_e_per_s = 1e6 / p->system_gain_dn_per_e *
                                      hypot(a->dark_slope_std_dn_per_us, a->dark_slope_dn_per_us * kr);
    }
    calib_gain_linearity_r4(a->t, a->mu, nl, a->ptc.saturation_dn, 0.05, 0.95, NULL, NULL, NULL, a->dev_pct);
    if (!analyse_linearisation(a)) {   // consumers fall back to the parametric form
        fprintf(stderr, "refl calib gain: warning: %s; the parametric S(1 - aS) applies\n", model_last_error());
        memset(&a->lin, 0, sizeof a->lin);
    }
    {
        double *x = malloc(sizeof(double) * nl), *y = malloc(sizeof(double) * nl), q[3];
        int m = 0;
        for (int i = 0; i < nl; i++)
            if (a->mu[i] <= 0.7 * a->ptc.saturation_dn) {
                x[m] = a->t[i];
                y[m] = a->mu[i];
                m++;
            }
        a->response0_dn_per_us = m >= 4 && calib_gain_polyfit(x, y, m, 2, q) ? q[1] : NAN;
        free(x);
        free(y);
    }
    ok = true;
done:
    free(dt);
    free(dm);
    free(dv);
    free(dtv);
    free(light);
    return ok;
}

// ---------------------------------------------------------------------------
// Maps (flat field, dark)

void calib_gain_maps_free(calib_gain_maps_t *m)
{
    free(m->offset);
    free(m->dsnu);
    free(m->prnu);
    free(m->prnu_hp);
    calib_gain_spatial_t *sp = &m->sp;
    free(sp->spec_h_dark);   // the four spectrograms' one block
    double *prof[] = { sp->col_dark, sp->row_dark, sp->col_light, sp->row_light };
    for (int i = 0; i < 4; i++) free(prof[i]);
    free(sp->defect_map);
}

// Average of a group's frames (full frame) into out (w*h doubles summed then divided).
static bool group_average(const calib_gain_data_t *d, const calib_gain_group_t *g, int w, int h, float *out)
{
    size_t n = (size_t)w * h;
    double *sum = calloc(n, sizeof(double));
    for (int k = 0; k < g->n; k++) {
        int fw, fh;
        float *img = frame_load(&d->f[g->idx[k]], &fw, &fh);
        if (!img) {
            free(sum);
            return false;
        }
        for (size_t i = 0; i < n; i++) sum[i] += img[i];
        free(img);
    }
    for (size_t i = 0; i < n; i++) out[i] = (float)(sum[i] / g->n);
    free(sum);
    return true;
}

static double roi_mean_var(const calib_gain_data_t *d, const float *m, int w, int h, double *var)
{
    int r[4];
    roi_of(d, w, h, r);
    double s = 0, ss = 0;
    long np = (long)r[2] * r[3];
    for (int y = r[1]; y < r[1] + r[3]; y++)
        for (int x = r[0]; x < r[0] + r[2]; x++) {
            double v = m[(size_t)y * w + x];
            s += v;
            ss += v * v;
        }
    double mean = s / np;
    if (var) *var = ss / np - mean * mean;
    return mean;
}

double calib_gain_spatial_std(double s, double tau, double npix)
{
    if (!(s > 0) || !(npix > 1) || !(tau >= 0)) return NAN;
    return sqrt((4 * s * s * tau + 2 * tau * tau) / npix) / (2 * s);
}

bool calib_gain_make_maps(calib_gain_data_t *d, const calib_gain_an_t *a, calib_gain_maps_t *m)
{
    memset(m, 0, sizeof *m);
    const double sat = a->ptc.saturation_dn;
    // the flat: the flat set's light group, else the sweep group with the most
    // frames (ties: nearest 50 % of saturation) below saturation
    calib_gain_group_t *flat = NULL;
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->gain_db == a->gain_db && !g->dark && g->set == CALIB_GAIN_SET_FLAT && (!flat || g->n > flat->n))
            flat = g;
    }
    if (!flat)
        for (int i = 0; i < d->ng; i++) {
            calib_gain_group_t *g = &d->g[i];
            if (g->gain_db != a->gain_db || g->dark || g->n < 2) continue;
            // the dark-subtracted level of this group
            double lv = g->mean_dn - (a->dark_intercept_dn + a->dark_slope_dn_per_us * g->exposure_us);
            if (lv > 0.9 * sat && g->n <= 2) continue;
            double lf = flat ? flat->mean_dn - (a->dark_intercept_dn + a->dark_slope_dn_per_us * flat->exposure_us)
                             : 0;
            if (!flat || g->n > flat->n || (g->n == flat->n && fabs(lv - 0.5 * sat) < fabs(lf - 0.5 * sat)))
                flat = g;
        }
    if (!flat) {
        model_error_set(NULL, 0, "gain %g dB: no flat-field frames (light, at least two at one exposure)", a->gain_db);
        return false;
    }
    // its dark: the same exposure (most frames), else the dark group with the most frames
    calib_gain_group_t *dark = NULL;
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->gain_db == a->gain_db && g->dark && g->exposure_us == flat->exposure_us && (!dark || g->n > dark->n))
            dark = g;
    }
    m->dark_same_exposure = dark != NULL;
    if (!dark)
        for (int i = 0; i < d->ng; i++) {
            calib_gain_group_t *g = &d->g[i];
            if (g->gain_db == a->gain_db && g->dark && (!dark || g->n > dark->n)) dark = g;
        }
    char nb[1024];
    double dark_level = a->dark_intercept_dn + a->dark_slope_dn_per_us * flat->exposure_us;
    m->flat_level_dn = flat->mean_dn - dark_level;
    m->flat_exposure_us = flat->exposure_us;
    m->flat_sat_frac = flat->sat_frac;
    m->flat_frames = flat->n;
    // the exposure of 50 % of saturation, from the linearity line
    const double t_half = (0.5 * sat - a->ptc.response_offset_dn) / a->ptc.response_dn_per_us;
    if (flat->sat_frac > 1e-4 || m->flat_level_dn > 0.9 * sat) {
        model_error_set(NULL, 0, "%s: the flat field (%d frames at %.6g us) is saturated: mean %.1f DN above dark "
                        "(%.1f DN grey value), %.3f %% of its pixels at full scale; saturation is at %.1f DN above "
                        "dark: use an exposure near %.0f %% of it (~%.6g us)",
                        frame_name(&d->f[flat->idx[0]], nb, sizeof nb), flat->n, flat->exposure_us, m->flat_level_dn,
                        flat->mean_dn, 100 * flat->sat_frac, sat, 50.0, t_half);
        return false;
    }
    if (m->flat_level_dn < 0.1 * sat) {
        model_error_set(NULL, 0, "%s: the flat field (%d frames at %.6g us) is too dark: mean %.2f DN above dark "
                        "(%.1f DN grey value, dark %.1f DN), below 10 %% of saturation (%.1f DN above dark): use an "
                        "exposure near 50 %% of saturation (~%.6g us)", frame_name(&d->f[flat->idx[0]], nb, sizeof nb),
                        flat->n, flat->exposure_us, m->flat_level_dn, flat->mean_dn, dark_level, sat, t_half);
        return false;
    }
    int w = flat->width, h = flat->height;
    size_t n = (size_t)w * h;
    m->w = w;
    m->h = h;
    m->offset = malloc(n * sizeof(float));
    m->dsnu = malloc(n * sizeof(float));
    m->prnu = malloc(n * sizeof(float));
    m->prnu_hp = malloc(n * sizeof(float));
    fprintf(stderr, "refl calib gain: flat field: %d light frames at %.6g us (%.0f DN above dark, %.0f %% of "
            "saturation), %d dark frames at %.6g us\n", flat->n, flat->exposure_us, m->flat_level_dn,
            100 * m->flat_level_dn / sat, dark->n, dark->exposure_us);
    if (!group_average(d, dark, w, h, m->offset) || !group_average(d, flat, w, h, m->prnu)) return false;
    m->dark_frames = dark->n;
    m->dark_exposure_us = dark->exposure_us;
    // dark level at the flat's exposure
    double dshift = m->dark_same_exposure ? 0 : a->dark_slope_dn_per_us * (flat->exposure_us - dark->exposure_us);
    double dvar;
    double dmean = roi_mean_var(d, m->offset, w, h, &dvar);
    int roi[4];
    roi_of(d, w, h, roi);
    const double npix = (double)roi[2] * roi[3];
    m->dark_var_dn2 = isfinite(dark->var_dn2) ? dark->var_dn2 : a->var_dark_dn2;
    m->dsnu_total_raw_dn = sqrt(fmax(dvar, 0));
    double dtau = m->dark_var_dn2 / dark->n, d2 = dvar - dtau;
    m->dsnu_dn = sqrt(fmax(d2, 0));
    m->dsnu_std_dn = calib_gain_spatial_std(m->dsnu_dn, dtau, npix);
    // the signal, linearised as every consumer linearises it (the PRNU of the
    // linear signal: a compressive response would flatten it)
    bool lin = a->lin.kind != MODEL_LIN_NONE && a->lin.n >= 2;
    double slope2 = 0;
    for (size_t i = 0; i < n; i++) {
        double sg = m->prnu[i] - (m->offset[i] + dshift), sl = 1;
        if (lin) sg = model_linearise(&a->lin, sg, 1, &sl);
        slope2 += sl * sl;
        m->prnu[i] = (float)sg;   // signal
        m->dsnu[i] = (float)(m->offset[i] - dmean);
    }
    slope2 /= (double)n;
    m->flat_linearised = lin;
    double svar, smean = roi_mean_var(d, m->prnu, w, h, &svar);
    m->flat_var_dn2 = isfinite(flat->var_dn2) ? flat->var_dn2 : NAN;
    double tvar = ((isfinite(m->flat_var_dn2) ? m->flat_var_dn2 / flat->n : 0) + m->dark_var_dn2 / dark->n) * slope2;
    m->signal_temporal_var_dn2 = tvar;
    m->flat_pixel_std_rel = sqrt(tvar) / smean;
    m->prnu_total_pct = 100 * sqrt(fmax(svar - tvar, 0)) / smean;
    if (!calib_gain_highpass(m->prnu, w, h, m->prnu_hp)) {
        model_error_set(NULL, 0, "flat field: the smooth-surface fit is singular (%dx%d frames)", w, h);
        return false;
    }
    // spatial variance of the high-pass map, in DN^2 of the signal
    double hvar;
    roi_mean_var(d, m->prnu_hp, w, h, &hvar);
    double hp2 = hvar - tvar / (smean * smean);
    m->prnu_pct = 100 * sqrt(fmax(hp2, 0));
    m->prnu_std_stat_pct = 100 * calib_gain_spatial_std(m->prnu_pct / 100, tvar / (smean * smean), npix);
    // The PRNU of the linear signal scales with the linearisation's log-slope
    // d ln S / d ln S_m at the flat's level, which the sweep fixes only as
    // well as two linearisations of it agree there (the monotone table in use
    // and the parametric S(1 - aS) of the same sweep): their relative
    // difference times the PRNU, a systematic part in quadrature.
    m->prnu_std_lin_pct = 0;
    if (lin && a->lin.kind == MODEL_LIN_MONOTONE && isfinite(a->lin_a_per_dn) && m->flat_level_dn > 0) {
        model_lin_t par = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = a->lin_a_per_dn };
        double L = m->flat_level_dn, dm, dp;
        double s1 = model_linearise(&a->lin, L, 1, &dm), s2 = model_linearise(&par, L, 1, &dp);
        if (s1 > 0 && s2 > 0 && dm > 0 && dp > 0) {
            m->flat_log_slope = dm * L / s1;
            m->flat_log_slope_parametric = dp * L / s2;
            m->prnu_std_lin_pct = m->prnu_pct * fabs(m->flat_log_slope / m->flat_log_slope_parametric - 1);
        }
    }
    m->prnu_std_pct = hypot(m->prnu_std_stat_pct, m->prnu_std_lin_pct);
    // the total map normalised to mean 1 (over the whole frame)
    double s = 0;
    for (size_t i = 0; i < n; i++) s += m->prnu[i];
    s /= n;
    m->prnu_mean_dn = s;
    for (size_t i = 0; i < n; i++) m->prnu[i] = (float)(m->prnu[i] / s);
    return true;
}

// ---------------------------------------------------------------------------
// Inputs

static char *trim(char *s)
{
    while (*s == ' ' || *s == '\t') s++;
    char *e = s + strlen(s);
    while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r' || e[-1] == '\n')) *--e = 0;
    return s;
}

bool calib_gain_read_manifest(const char *path, int max_dn, calib_gain_data_t *d)
{
    char *text = model_read_file(path, NULL);
    if (!text) return false;
    char *dir = g_path_get_dirname(path);
    bool ok = false;
    int line = 0, nframes = 0;
    char *save = NULL;
    for (char *l = text, *next; l; l = next) {
        next = strchr(l, '\n');
        if (next) *next++ = 0;
        line++;
        char *s = trim(l);
        if (!*s || *s == '#') continue;
        char *f[4] = { 0 };
        int nf = 0;
        for (char *p = strtok_r(s, ",", &save); p && nf < 4; p = strtok_r(NULL, ",", &save)) f[nf++] = trim(p);
        if (nf == 3 && nframes == 0 && !strcmp(f[0], "file") && !strcmp(f[1], "exposure_us") && !strcmp(f[2], "kind"))
            continue;   // the header
        if (nf != 3) {
            model_error_set(path, line, "expected 3 fields file,exposure_us,kind, found %d", nf);
            goto done;
        }
        double e;
        if (!model_parse_double(f[1], &e) || !(e > 0)) {
            model_error_set(path, line, "exposure_us '%s' is not a positive number (microseconds)", f[1]);
            goto done;
        }
        // kind: dark | light (the sweep and the dark model), flat | flat-dark (the spatial set: many frames at
        // one level for DSNU, PRNU, spectrograms and defects; aliases spatial-light | spatial-dark)
        bool dark = !strcmp(f[2], "dark") || !strcmp(f[2], "flat-dark") || !strcmp(f[2], "spatial-dark");
        bool flat = !strcmp(f[2], "flat") || !strcmp(f[2], "flat-dark") || !strcmp(f[2], "spatial-light") ||
                    !strcmp(f[2], "spatial-dark");
        if (!dark && !flat && strcmp(f[2], "light")) {
            model_error_set(path, line, "kind '%s' must be dark, light (the sweep), flat or flat-dark (the spatial "
                            "set; also spatial-light, spatial-dark)", f[2]);
            goto done;
        }
        if (!*f[0]) {
            model_error_set(path, line, "empty file name");
            goto done;
        }
        calib_gain_frame_t fr = { .path = f[0][0] == '/' ? g_strdup(f[0]) : g_build_filename(dir, f[0], NULL),
                        .where = g_strdup(path), .line = line, .exposure_us = e, .gain_db = 0, .dark = dark,
                        .set = flat ? CALIB_GAIN_SET_FLAT : CALIB_GAIN_SET_ANY, .max_dn = max_dn, .nlamps = -1 };
        if (access(fr.path, R_OK) != 0) {
            model_error_set(path, line, "frame %s: %s", fr.path, strerror(errno));
            g_free(fr.path);
            g_free(fr.where);
            goto done;
        }
        add_frame(d, &fr);
        nframes++;
    }
    if (!nframes) {
        model_error_set(path, 0, "no frames listed (lines file,exposure_us,kind)");
        goto done;
    }
    ok = true;
done:
    g_free(dir);
    free(text);
    return ok;
}

static int format_max(const char *pf)
{
    if (!strcmp(pf, "Mono8")) return 255;
    if (!strcmp(pf, "Mono12")) return 4095;
    return 65535;
}

static int lamps_on(const char *lamps, int nlamps_rig)
{
    if (!strcmp(lamps, "none")) return 0;
    if (!strcmp(lamps, "all")) return nlamps_rig;
    int n = 1;
    for (const char *p = lamps; *p; p++) n += *p == '+';
    return n;
}

// Frames of one camera of a session; set: the role of its frames (CALIB_GAIN_SET_ANY: by lamps).
bool calib_gain_add_session(calib_gain_data_t *d, const char *dir, const char *camera, int set,
                            json_t **facts_out)
{
    rig_session_t *s = rig_session_open_camera(dir, camera);   // NULL: the first camera's frames
    if (!s) return false;
    int nlr = -1;
    json_t *lamps = s->facts ? json_object_get(s->facts, "lamps") : NULL;
    if (json_is_array(lamps)) nlr = (int)json_array_size(lamps);
    bool ok = true;
    for (int i = 0; i < s->n && ok; i++) {
        const rig_frame_row_t *r = &s->rows[i];
        const char *unit = r->gain_unit[0] ? r->gain_unit : "dB";   // an older session's gain: dB
        if (!d->gain_unit[0]) snprintf(d->gain_unit, sizeof d->gain_unit, "%s", unit);
        if (strcmp(d->gain_unit, unit)) {
            model_error_set(dir, 0, "frame %s: gain unit '%s', the run's other frames '%s': one calibration needs "
                            "one unit of gain", r->file, unit, d->gain_unit);
            ok = false;
            break;
        }
        snprintf(d->camera, sizeof d->camera, "%s", r->camera);
        int on = lamps_on(r->lamps, nlr);
        calib_gain_frame_t f = { .path = g_strdup_printf("%s/%s", dir, r->file), .where = g_strdup(dir), .line = 0,
                       .step = r->step, .exposure_us = r->exposure_us, .gain_db = r->gain, .dark = on == 0,
                       .set = set, .max_dn = format_max(r->pixel_format), .nlamps = on };
        snprintf(f.sha256, sizeof f.sha256, "%s", r->sha256);
        add_frame(d, &f);
    }
    if (ok && facts_out && !*facts_out && s->facts) *facts_out = json_incref(s->facts);
    rig_session_free(s);
    return ok;
}

bool calib_gain_truth_radiance(json_t *facts, const char **truth_path, double *radiance_per_lamp)
{
    json_t *v = facts ? json_object_get(facts, "virtual_rig") : NULL;
    const char *truth = json_string_value(json_object_get(v, "truth"));
    const char *sample = json_string_value(json_object_get(v, "sample"));
    if (truth_path) *truth_path = truth;
    *radiance_per_lamp = NAN;
    if (!truth || !sample) return false;
    bool q = model_error_quiet_thread(true);   // a comparison: no truth, no column
    rig_truth_t *t = rig_truth_load(truth);
    bool ok = t && rig_truth_uniform_radiance(t, sample, radiance_per_lamp);
    rig_truth_free(t);
    model_error_quiet_thread(q);
    if (!ok) *radiance_per_lamp = NAN;
    return ok;
}

// ---------------------------------------------------------------------------
// Capture on a rig

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
    fprintf(stderr, "refl calib gain: capturing %s (%s, lamps %s, %d repeats)\n", name, gain > 0 ? "gain" : "0 dB",
            lamps, repeats);
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
            max_dn[k] = format_max(s->rows[i].pixel_format);
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

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
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

// Probe and sweep at one gain; t_sat_us[k]: camera k's estimated exposure of
// full scale (*ncam cameras).
int calib_gain_sweep_exposures(double tmax, int steps, int low_steps, double *t)
{
    int n = 0;
    for (int i = 0; i < low_steps; i++)
        t[n++] = tmax * (low_steps > 1 ? 0.002 * pow(0.12 / 0.002, (double)i / (low_steps - 1)) : 0.002);
    for (int i = 0; i < steps; i++) t[n++] = tmax * (i + 1) / steps;
    qsort(t, n, sizeof *t, cmp_double);
    return n;
}

static bool capture_sweep(const calib_gain_opts_t *c, double gain, char **sweep_dir, double *t_sat_us, int *ncam)
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
            fprintf(stderr, "refl calib gain: probe at %.0f us: light %.1f DN, dark %.1f DN (camera %d)\n", probe,
                    l[k], dk[k], k + 1);
        more = probe_next(l, dk, mx, *ncam, &probe, t_sat_us);
    }
    if (more) {
        model_error_set(c->rig, 0, "gain %g dB: no exposure between 10 us and 10 s gives a usable level of the flat "
                        "field for every camera (lamps %s): check the lamps and the source", gain, c->lamps);
        return false;
    }
    // each camera's steps up to 1.2 x its full scale (or --max-exposure-us), merged
    int nt = 0;
    double *t = malloc(sizeof(double) * (c->steps + c->low_steps) * *ncam);
    for (int k = 0; k < *ncam; k++) {
        double tmax = isfinite(c->max_us) ? c->max_us : 1.2 * t_sat_us[k];
        int n = calib_gain_sweep_exposures(tmax, c->steps, c->low_steps, t + nt);
        for (int i = 0; i < n; i++) t[nt + i] = fmax(10, round(t[nt + i]));
        nt += n;
    }
    qsort(t, nt, sizeof *t, cmp_double);
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

// ---------------------------------------------------------------------------
// Output

static json_t *jreal(double x) { return isfinite(x) ? json_real(x) : json_null(); }

static json_t *jarray(const double *v, int n)
{
    json_t *a = json_array();
    for (int i = 0; i < n; i++) json_array_append_new(a, jreal(v[i]));
    return a;
}


// The exposures of the dark groups the dark level and dark current were
// fitted over (us, one per group); null when unknown.
static json_t *dark_exposures_json(const calib_gain_an_t *a)
{
    if (!(a->ndark > 0) || !a->dark_t_us) return json_null();
    return jarray(a->dark_t_us, a->ndark);
}

static json_t *gain_json(const calib_gain_an_t *a)
{
    json_t *o = json_object();
    const calib_gain_ptc_t *p = &a->ptc;
    json_object_set_new(o, "gain_db", json_real(a->gain_db));
    json_object_set_new(o, "system_gain_dn_per_e", jreal(p->system_gain_dn_per_e));
    json_object_set_new(o, "system_gain_linear_fit_dn_per_e", jreal(p->system_gain_linear_dn_per_e));
    json_object_set_new(o, "read_noise_e", jreal(p->read_noise_e));
    json_object_set_new(o, "read_noise_dn", jreal(p->read_noise_dn));
    json_object_set_new(o, "dark_temporal_variance_dn2", jreal(a->var_dark_dn2));
    json_object_set_new(o, "saturation_dn", jreal(p->saturation_dn));
    json_object_set_new(o, "saturation_exposure_us", jreal(a->t[p->i_sat]));
    json_object_set_new(o, "saturation_capacity_e", jreal(p->saturation_capacity_e));
    json_object_set_new(o, "linearity_error_pct", jreal(p->linearity_error_pct));
    json_object_set_new(o, "linearity_error_r3_pct", jreal(p->linearity_error_r3_pct));
    json_object_set_new(o, "linearity_error_linearised_pct", jreal(a->le_linearised_pct));
    json_object_set_new(o, "linearity_error_linearised_parametric_pct", jreal(a->le_linearised_param_pct));
    json_object_set_new(o, "snr_max", jreal(p->snr_max));
    json_object_set_new(o, "snr_max_db", jreal(20 * log10(p->snr_max)));
    json_object_set_new(o, "dynamic_range", jreal(p->dynamic_range));
    json_object_set_new(o, "dynamic_range_db", jreal(20 * log10(p->dynamic_range)));
    json_object_set_new(o, "response_dn_per_us", jreal(p->response_dn_per_us));
    json_object_set_new(o, "response_offset_dn", jreal(p->response_offset_dn));
    json_object_set_new(o, "radiance", jreal(a->radiance));
    if (isfinite(a->radiance_truth)) json_object_set_new(o, "radiance_truth", json_real(a->radiance_truth));
    json_object_set_new(o, "kc_per_us", jreal(a->kc_per_us));
    json_object_set_new(o, "response_small_signal_dn_per_us", jreal(a->response0_dn_per_us));
    json_object_set_new(o, "kc_small_signal_per_us", jreal(a->kc0_per_us));
    json_object_set_new(o, "dark_current_dn_per_s", jreal(a->dark_slope_dn_per_us * 1e6));
    json_object_set_new(o, "dark_current_e_per_s", jreal(a->dark_slope_dn_per_us * 1e6 / p->system_gain_dn_per_e));
    json_object_set_new(o, "dark_level_dn", jreal(a->dark_intercept_dn));
    json_object_set_new(o, "dark_exposures_us", dark_exposures_json(a));
    json_object_set_new(o, "dark_current_from_variance_e_per_s",
                        jreal(a->dark_var_slope_dn2_per_us * 1e6 / (p->system_gain_dn_per_e * p->system_gain_dn_per_e)));
    const calib_gain_photon_t *ph = &a->ph;
#define PHOTON(key, v) json_object_set_new(o, key, ph->measured ? jreal(v) : json_string("not measured"))
    PHOTON("quantum_efficiency", ph->qe);
    PHOTON("responsivity_dn_per_photon", ph->responsivity_dn_per_photon);
    PHOTON("absolute_sensitivity_threshold_photons", ph->mu_p_min);
    PHOTON("saturation_capacity_photons", ph->mu_p_sat);
#undef PHOTON
    json_object_set_new(o, "absolute_sensitivity_threshold_e", jreal(ph->mu_e_min));
    json_object_set_new(o, "dynamic_range_r4", jreal(ph->dynamic_range));
    json_object_set_new(o, "n_steps", json_integer(a->n));
    json_object_set_new(o, "n_ptc_fit", json_integer(p->n_ptc_fit));
    json_object_set_new(o, "n_linearity_fit", json_integer(p->n_lin_fit));
    json_t *c = json_object();
    json_object_set_new(c, "exposure_us", jarray(a->t, a->n));
    json_object_set_new(c, "mean_dn", jarray(a->mu_y, a->n));
    json_object_set_new(c, "dark_mean_dn", jarray(a->mu_d, a->n));
    json_object_set_new(c, "signal_dn", jarray(a->mu, a->n));
    json_object_set_new(c, "variance_dn2", jarray(a->var_y, a->n));
    json_object_set_new(c, "dark_variance_dn2", jarray(a->var_d, a->n));
    json_object_set_new(c, "signal_variance_dn2", jarray(a->var, a->n));
    json_object_set_new(c, "snr", jarray(a->snr, a->n));
    json_object_set_new(c, "linearity_deviation_pct", jarray(a->dev_pct, a->n));
    if (a->mu_p) json_object_set_new(c, "photons", jarray(a->mu_p, a->n));
    double *kc = malloc(sizeof(double) * (a->n + 1));
    for (int i = 0; i < a->n; i++) kc[i] = isfinite(a->radiance) ? a->mu[i] / a->radiance : NAN;
    json_object_set_new(c, "kc", jarray(kc, a->n));
    free(kc);
    json_object_set_new(o, "curves", c);
    return o;
}

static bool write_map(const char *dir, const char *name, const calib_gain_maps_t *m, const float *map, const char *what)
{
    char *path = g_build_filename(dir, name, NULL);
    const char *meta[] = { "content", what, "software", "refl calib gain " REFL_VERSION, NULL };
    bool ok = model_tiff_write_float(path, m->w, m->h, map, meta);
    g_free(path);
    return ok;
}


bool calib_gain_write_maps(const char *dir, const calib_gain_maps_t *m)
{
    return write_map(dir, "offset_dn.tiff", m, m->offset, "dark level (offset) map, DN") &&
           write_map(dir, "dsnu_dn.tiff", m, m->dsnu, "dark signal non-uniformity: dark level minus its mean, DN") &&
           write_map(dir, "prnu_gain.tiff", m, m->prnu,
                     "relative sensitivity g(x,y), mean 1: flat field minus dark, incl. vignetting") &&
           write_map(dir, "prnu_highpass.tiff", m, m->prnu_hp,
                     "PRNU: flat field divided by its quadratic smooth surface (vignetting removed), mean ~1");
}

// A session of the capture into d and the provenance (role), its directory o->out/name.
static bool add_source(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc,
                       const char *name, int set, const char *role)
{
    char *dir = g_strdup_printf("%s/%s", o->out, name);
    *src = realloc(*src, sizeof **src * (*nsrc + 1));
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
    fprintf(stderr, "refl calib gain: capture done in %.1f s\n", model_now_s() - t_start);
    return true;
}

// gain.json: the definitions of its figures.
static json_t *conventions_json(const calib_gain_opts_t *o, const calib_gain_data_t *d)
{
    json_t *cv = json_object();
    json_object_set_new(cv, "grey_values", json_string("DN of the frames' pixel format (unscaled)"));
    json_object_set_new(cv, "signal", json_string("mean grey value minus the mean dark grey value at the same "
                                                  "exposure (EMVA 1288 mu_y - mu_y.dark)"));
    json_object_set_new(cv, "temporal_variance", json_string("var(A - B) / 2 of a frame pair, minus its dark "
                                                             "counterpart"));
    json_object_set_new(cv, "system_gain_dn_per_e", json_string(
        "slope at zero signal of a quadratic least-squares fit of the variance against the signal over 0..70 % of "
        "saturation (the small-signal K; system_gain_linear_fit_dn_per_e is EMVA 1288's straight line over the "
        "same range)"));
    json_object_set_new(cv, "read_noise_e", json_string("sqrt(sigma^2_y.dark - q^2/12) / K, sigma^2_y.dark the "
                                                        "dark temporal variance extrapolated to exposure 0"));
    json_object_set_new(cv, "saturation_dn", json_string("signal (above dark) where the temporal variance peaks"));
    json_object_set_new(cv, "linearity_error_pct", json_string(
        "EMVA 1288 Release 4.0, section Linearity: the line a0 + a1 t of signal against exposure through the "
        "steps between 5 % and 95 % of saturation minimising the squared relative deviations "
        "sum((mu_i - a0 - a1 t_i) / mu_i)^2; delta_i = 100 (mu_i - line_i) / line_i; LE = (max delta - min "
        "delta) / 2 in %. linearity_error_r3_pct: the same with Release 3's unweighted least-squares line"));
    json_object_set_new(cv, "linearisation", json_string(
        "measured signal above dark S_m (DN) -> linear signal S (DN) at the reference gain (at gain factor f "
        "relative to it: S = f T(S_m / f)). monotone: a monotone piecewise-cubic Hermite interpolant (Fritsch & "
        "Carlson 1980, knot slopes by Fritsch & Butland 1984) through (measured_dn, linear_dn): every sweep step "
        "up to saturation, made monotone by isotonic regression, from (0, 0); linear_dn = anchor_offset_dn + "
        "anchor_response_dn_per_us t, the small-signal line of a quadratic fit of signal against exposure over "
        "5..70 % of saturation. parametric: S_m = S (1 - a S), a_per_dn from a least-squares fit over the steps "
        "below 90 % of saturation. method: what the consumers apply. linearity_error_linearised_pct: the "
        "Release 4.0 LE of the sweep's signal through the table (its own check; _parametric_pct: through S(1 - aS))"));
    json_object_set_new(cv, "prnu_pct", json_string(
        "std of the flat field (light minus dark averages, each pixel's signal through the linearisation as every "
        "consumer applies it: flat_field.linearised) divided by its quadratic smooth surface (vignetting "
        "and illumination fall-off removed), temporal noise of the averages subtracted (EMVA 1288 variance "
        "correction); prnu_total_pct: the same without removing the smooth part (vignetting included)"));
    json_object_set_new(cv, "dsnu_dn", json_string("std of the averaged dark frame, temporal noise of the average "
                                                   "subtracted"));
    json_object_set_new(cv, "prnu_gain_map", json_string("g(x,y) of the imaging model: flat field minus dark, "
                                                         "mean 1 over the frame, vignetting included"));
    json_object_set_new(cv, "kc_per_us", json_string("response_dn_per_us (slope of the linearity line) / the "
                                                     "source's radiance (--radiance): kc per us at that gain for g "
                                                     "of mean 1"));
    json_object_set_new(cv, "kc_small_signal_per_us", json_string(
        "slope at exposure 0 of a quadratic least-squares fit of the signal against exposure over 0..70 % of "
        "saturation, per unit radiance (free of the non-linearity's compression)"));
    json_object_set_new(cv, "radiance_truth", json_string("the virtual rig's truth of the radiance, for comparison "
                                                          "only (not used in the figures)"));
    json_object_set_new(cv, "dark_current", json_string("slope of the mean dark level against exposure; "
                                                        "dark_current_from_variance_e_per_s: slope of the dark "
                                                        "temporal variance against exposure / K^2; "
                                                        "dark_exposures_us: the exposures (us) of the dark groups "
                                                        "both were fitted over, one per group"));
    json_object_set_new(cv, "emva1288", json_string("the EMVA 1288 Release 4.0 Linear datasheet, each row with its "
                                                    "definition; quantum_efficiency etc. \"not measured\" without "
                                                    "--irradiance"));
    json_object_set_new(cv, "dynamic_range", json_string("saturation_capacity_e / read_noise_e"));
    json_object_set_new(cv, "statistics_region", d->roi[2] > 0 ? json_pack("[iiii]", d->roi[0], d->roi[1], d->roi[2],
                                                                           d->roi[3])
                                                               : json_string("whole frame"));
    json_object_set_new(cv, "quantisation_step_dn", json_real(o->quant_dn));
    return cv;
}

// gain.json's "linearisation" (calib_gain_lin_from_json reads it).
static json_t *lin_json(const calib_gain_opts_t *o, const calib_gain_an_t *a)
{
    bool table = a->lin.kind == MODEL_LIN_MONOTONE && a->lin.n >= 2;
    bool mono = o->linearisation != MODEL_LIN_PARAMETRIC && table;
    json_t *l = json_object();
    json_object_set_new(l, "method", json_string(mono ? "monotone" : "parametric"));
    json_object_set_new(l, "a_per_dn", json_real(a->lin_a_per_dn));
    if (table) {
        json_object_set_new(l, "measured_dn", jarray(a->lin.m, a->lin.n));
        json_object_set_new(l, "linear_dn", jarray(a->lin.s, a->lin.n));
    }
    json_object_set_new(l, "anchor_response_dn_per_us", jreal(a->lin_anchor_dn_per_us));
    json_object_set_new(l, "anchor_offset_dn", jreal(a->lin_anchor_offset_dn));
    json_object_set_new(l, "linearity_error_linearised_pct", jreal(a->le_linearised_pct));
    json_object_set_new(l, "linearity_error_linearised_parametric_pct", jreal(a->le_linearised_param_pct));
    return l;
}

bool calib_gain_lin_from_json(json_t *gj, const char *path, model_lin_t *out)
{
    memset(out, 0, sizeof *out);
    json_t *l = json_object_get(gj, "linearisation");
    if (!l) {   // a file from before the table: the parametric form of its reference gain's curves
        json_t *gains = json_object_get(gj, "gains"), *g0 = NULL;
        for (size_t k = 0; k < json_array_size(gains); k++) {
            json_t *e = json_array_get(gains, k);
            if (fabs(json_number_value(json_object_get(e, "gain_db")) -
                     json_number_value(json_object_get(gj, "gain_db"))) < 1e-9)
                g0 = e;
        }
        json_t *cv = json_object_get(g0 ? g0 : gj, "curves");
        json_t *t = json_object_get(cv, "exposure_us"), *S = json_object_get(cv, "signal_dn");
        size_t n = json_array_size(t);
        if (n != json_array_size(S) || n < 5 || n > 100000) return true;
        double *tv = malloc(sizeof(double) * n * 2), *sv = tv + n;
        if (!tv) return true;
        for (size_t i = 0; i < n; i++) {
            tv[i] = json_is_number(json_array_get(t, i)) ? json_number_value(json_array_get(t, i)) : NAN;
            sv[i] = json_is_number(json_array_get(S, i)) ? json_number_value(json_array_get(S, i)) : NAN;
        }
        json_t *sat = json_object_get(gj, "saturation_dn");
        out->a_per_dn = calib_gain_parametric_a(tv, sv, (int)n, json_is_number(sat) ? json_number_value(sat) : 0);
        out->kind = out->a_per_dn > 0 ? MODEL_LIN_PARAMETRIC : MODEL_LIN_NONE;
        free(tv);
        return true;
    }
    const char *method = json_string_value(json_object_get(l, "method"));
    json_t *a = json_object_get(l, "a_per_dn");
    if (!json_is_object(l) || !method || (strcmp(method, "monotone") && strcmp(method, "parametric")) ||
        (a && !json_is_number(a))) {
        model_error(path, 0, "linearisation: needs method \"monotone\" or \"parametric\" and a number a_per_dn "
                    "(refl calib gain writes it; run it again)");
        return false;
    }
    double av = a ? json_number_value(a) : 0;
    if (!strcmp(method, "parametric")) {
        if (!(av >= 0 && av < 1e-3)) {
            model_error(path, 0, "linearisation: a_per_dn %g is outside [0, 1e-3) per DN", av);
            return false;
        }
        *out = (model_lin_t){ .kind = av > 0 ? MODEL_LIN_PARAMETRIC : MODEL_LIN_NONE, .a_per_dn = av };
        return true;
    }
    json_t *jm = json_object_get(l, "measured_dn"), *js = json_object_get(l, "linear_dn");
    size_t n = json_array_size(jm);
    if (n < 2 || n > MODEL_LIN_MAX || json_array_size(js) != n) {
        model_error(path, 0, "linearisation: the monotone table needs measured_dn and linear_dn of equal length, "
                    "2 to %d knots (has %zu and %zu)", MODEL_LIN_MAX, n, json_array_size(js));
        return false;
    }
    double m[MODEL_LIN_MAX], s[MODEL_LIN_MAX];
    for (size_t i = 0; i < n; i++) {
        json_t *x = json_array_get(jm, i), *y = json_array_get(js, i);
        if (!json_is_number(x) || !json_is_number(y) ||
            (i > 0 && !(json_number_value(x) > m[i - 1] && json_number_value(y) > s[i - 1]))) {
            model_error(path, 0, "linearisation: knot %zu: measured_dn and linear_dn must be numbers, both "
                        "strictly increasing", i);
            return false;
        }
        m[i] = json_number_value(x);
        s[i] = json_number_value(y);
    }
    if (!model_lin_knots(m, s, (int)n, out)) {
        char *e = g_strdup(model_last_error());
        model_error(path, 0, "linearisation: %s", e);
        g_free(e);
        return false;
    }
    out->a_per_dn = av;
    return true;
}

json_t *calib_gain_json(const calib_gain_opts_t *o, const calib_gain_data_t *d, const calib_gain_an_t *an, int ngains,
                        const calib_gain_maps_t *maps, const char *truth, json_t *prov)
{
    const calib_gain_an_t *a = &an[0];
    const double K = a->ptc.system_gain_dn_per_e;
    json_t *root = json_object();
    json_object_set_new(root, "calibration", json_string("gain (EMVA 1288 style)"));
    if (d->camera[0]) json_object_set_new(root, "camera", json_string(d->camera));
    json_object_set_new(root, "gain_db", json_real(a->gain_db));
    json_object_set_new(root, "gain_unit", json_string(d->gain_unit[0] ? d->gain_unit : "dB"));
    json_object_set_new(root, "system_gain_dn_per_e", jreal(K));
    json_object_set_new(root, "read_noise_e", jreal(a->ptc.read_noise_e));
    json_object_set_new(root, "saturation_dn", jreal(a->ptc.saturation_dn));
    json_object_set_new(root, "linearity_error_pct", jreal(a->ptc.linearity_error_pct));
    json_object_set_new(root, "linearity_error_r3_pct", jreal(a->ptc.linearity_error_r3_pct));
    json_object_set_new(root, "linearisation", lin_json(o, a));
    json_object_set_new(root, "dsnu_dn", jreal(maps->dsnu_dn));
    json_object_set_new(root, "dsnu_e", jreal(maps->dsnu_dn / K));
    json_object_set_new(root, "prnu_pct", jreal(maps->prnu_pct));
    json_object_set_new(root, "prnu_total_pct", jreal(maps->prnu_total_pct));
    json_object_set_new(root, "dark_current_e_per_s", jreal(a->dark_slope_dn_per_us * 1e6 / K));
    json_object_set_new(root, "dark_current_dn_per_s", jreal(a->dark_slope_dn_per_us * 1e6));
    json_object_set_new(root, "dark_level_dn", jreal(a->dark_intercept_dn));
    json_object_set_new(root, "dark_exposures_us", dark_exposures_json(a));
    json_object_set_new(root, "saturation_capacity_e", jreal(a->ptc.saturation_capacity_e));
    json_object_set_new(root, "snr_max", jreal(a->ptc.snr_max));
    json_object_set_new(root, "snr_max_db", jreal(20 * log10(a->ptc.snr_max)));
    json_object_set_new(root, "dynamic_range", jreal(a->ptc.dynamic_range));
    json_object_set_new(root, "dynamic_range_db", jreal(20 * log10(a->ptc.dynamic_range)));
    json_object_set_new(root, "kc_per_us", jreal(a->kc_per_us));
    json_object_set_new(root, "kc_small_signal_per_us", jreal(a->kc0_per_us));
    json_object_set_new(root, "response_dn_per_us", jreal(a->ptc.response_dn_per_us));
    json_t *f = json_object();
    json_object_set_new(f, "exposure_us", json_real(maps->flat_exposure_us));
    json_object_set_new(f, "level_dn", json_real(maps->flat_level_dn));
    json_object_set_new(f, "level_of_saturation", jreal(maps->flat_level_dn / a->ptc.saturation_dn));
    json_object_set_new(f, "light_frames", json_integer(maps->flat_frames));
    json_object_set_new(f, "dark_frames", json_integer(maps->dark_frames));
    json_object_set_new(f, "dark_exposure_us", json_real(maps->dark_exposure_us));
    json_object_set_new(f, "width", json_integer(maps->w));
    json_object_set_new(f, "height", json_integer(maps->h));
    json_object_set_new(f, "linearised", json_boolean(maps->flat_linearised));
    json_object_set_new(f, "pixel_std_rel", jreal(maps->flat_pixel_std_rel));
    json_object_set_new(root, "flat_field", f);
    json_t *sd = json_object();
    json_object_set_new(sd, "system_gain_dn_per_e", jreal(a->ptc.system_gain_std_dn_per_e));
    json_object_set_new(sd, "read_noise_e", jreal(a->read_noise_std_e));
    json_object_set_new(sd, "dsnu_dn", jreal(maps->dsnu_std_dn));
    json_object_set_new(sd, "prnu_pct", jreal(maps->prnu_std_pct));
    json_t *pp = json_object();
    json_object_set_new(pp, "statistical", jreal(maps->prnu_std_stat_pct));
    json_object_set_new(pp, "linearisation_slope", jreal(maps->prnu_std_lin_pct));
    json_object_set_new(sd, "prnu_pct_parts", pp);
    json_object_set_new(sd, "dark_current_e_per_s", jreal(a->dark_current_std_e_per_s));
    json_object_set_new(root, "std", sd);
    json_object_set_new(root, "std_method", json_string(
        "1-sigma of the figures of the same name, from the fits' statistics (units as theirs): "
        "system_gain_dn_per_e: the standard error of the linear coefficient of the photon-transfer quadratic "
        "(heteroscedasticity-consistent sandwich, HC3: each point's own residual, since a variance's scatter grows "
        "with it); read_noise_e: the dark variance's intercept standard error (of its fit against exposure, HC3) "
        "over 2 sigma^2_d and K's relative 1-sigma in quadrature; dark_current_e_per_s: the dark mean's slope "
        "standard error (HC3) and K's in quadrature; dsnu_dn and prnu_pct: the temporal noise tau left in the "
        "averaged frames, a fixed pattern of std s over N pixels giving var(s^2) = (4 s^2 tau + 2 tau^2) / N, "
        "1-sigma = sqrt of that / (2 s) (the pattern itself is the sensor's, not a sample of it); prnu_pct "
        "besides: the linearisation's log-slope d ln S / d ln S_m at the flat's level, the monotone table's "
        "against the parametric S(1 - aS)'s of the same sweep, their relative difference times prnu_pct, in "
        "quadrature (prnu_pct_parts: statistical, linearisation_slope)"));
    json_object_set_new(root, "maps", json_pack("{s:s, s:s, s:s, s:s, s:s}", "offset_dn", "offset_dn.tiff", "dsnu_dn",
                                                "dsnu_dn.tiff", "prnu_gain", "prnu_gain.tiff", "prnu_highpass",
                                                "prnu_highpass.tiff", "defects", "defects.tiff"));
    json_object_set_new(root, "quantum_efficiency", a->ph.measured ? jreal(a->ph.qe) : json_string("not measured"));
    json_object_set_new(root, "emva1288", calib_gain_emva_json(o, an, maps));
    json_t *pg = json_array();
    for (int i = 0; i < ngains; i++) json_array_append_new(pg, gain_json(&an[i]));
    json_object_set_new(root, "gains", pg);
    json_object_set_new(root, "conventions", conventions_json(o, d));
    if (truth) json_object_set_new(root, "virtual_truth", json_string(truth));
    json_object_set_new(root, "provenance", json_incref(prov));
    return root;
}

// report.html: the summary table's rows (g_free each), returns their count (at most max).
static int summary_rows(const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps, char **rows, int max)
{
    const calib_gain_an_t *a = &an[0];
    const double K = a->ptc.system_gain_dn_per_e;
    int nr = 0;
    rows[nr++] = g_strdup_printf("system gain K|%.5g DN/e-|small-signal; straight-line fit %.5g", K,
                                 a->ptc.system_gain_linear_dn_per_e);
    rows[nr++] = g_strdup_printf("read noise|%.4g e- (%.4g DN)|", a->ptc.read_noise_e, a->ptc.read_noise_dn);
    rows[nr++] = g_strdup_printf("saturation|%.1f DN above dark (%.0f e-)|at %.6g us", a->ptc.saturation_dn,
                                 a->ptc.saturation_capacity_e, a->t[a->ptc.i_sat]);
    const calib_gain_photon_t *ph = &a->ph;
    if (ph->measured)
        rows[nr++] = g_strdup_printf("quantum efficiency|%.2f %%|responsivity R %.5g DN/photon at %.6g nm, %.6g "
                                     "uW/cm^2, pixel %.6g um^2", 100 * ph->qe, ph->responsivity_dn_per_photon,
                                     ph->wavelength_nm, ph->irradiance_uw_cm2, ph->pixel_area_um2);
    else
        rows[nr++] = g_strdup("quantum efficiency|not measured|give --irradiance, --pixel-area-um2 (or "
                              "--pixel-pitch-um) and --wavelength-nm");
    char pmin[64] = "not measured", psat[64] = "not measured";
    if (ph->measured) {
        snprintf(pmin, sizeof pmin, "%.4g photons", ph->mu_p_min);
        snprintf(psat, sizeof psat, "%.6g photons", ph->mu_p_sat);
    }
    rows[nr++] = g_strdup_printf("absolute sensitivity threshold|%.4g e- (%s)|SNR = 1 of the linear model",
                                 ph->mu_e_min, pmin);
    rows[nr++] = g_strdup_printf("saturation capacity|%.6g e- (%s)|EMVA 1288 R4 dynamic range %.0f (%.1f dB)",
                                 ph->mu_e_sat, psat, ph->dynamic_range, 20 * log10(ph->dynamic_range));
    rows[nr++] = g_strdup_printf("DSNU row / column / pixel|%.3g / %.3g / %.3g DN|total %.3g DN (averaged dark)",
                                 maps->sp.dsnu.row, maps->sp.dsnu.col, maps->sp.dsnu.pixel, maps->sp.dsnu.total);
    rows[nr++] = g_strdup_printf("PRNU row / column / pixel|%.3g / %.3g / %.3g %%|total %.3g %% (flat minus dark, "
                                 "vignetting included)", maps->sp.prnu.row, maps->sp.prnu.col, maps->sp.prnu.pixel,
                                 maps->sp.prnu.total);
    rows[nr++] = g_strdup_printf("defect pixels|hot %d, dead %d, bright %d|beyond %g robust standard deviations",
                                 maps->sp.defects.hot, maps->sp.defects.dead, maps->sp.defects.bright,
                                 maps->sp.defects.nsigma);
    rows[nr++] = g_strdup_printf("linearity error|%.3f %%|EMVA 1288 Release 4.0, 5..95 %% of saturation (Release 3's "
                                 "unweighted line: %.3f %%)", a->ptc.linearity_error_pct, a->ptc.linearity_error_r3_pct);
    rows[nr++] = g_strdup_printf("response linearisation|%s|LE after it %.3g %% (S(1 - aS), a = %.3g per DN: %.3g %%)",
                                 a->lin.kind == MODEL_LIN_MONOTONE ? "monotone table" : "none made",
                                 a->le_linearised_pct, a->lin_a_per_dn, a->le_linearised_param_pct);
    rows[nr++] = g_strdup_printf("SNR max|%.1f (%.1f dB)|", a->ptc.snr_max, 20 * log10(a->ptc.snr_max));
    rows[nr++] = g_strdup_printf("dynamic range|%.0f (%.1f dB)|", a->ptc.dynamic_range,
                                 20 * log10(a->ptc.dynamic_range));
    rows[nr++] = g_strdup_printf("dark current|%.3g e-/s (%.3g DN/s)|from the mean; from the variance %.3g e-/s; "
                                 "dark frames from %.6g us to %.6g us", a->dark_slope_dn_per_us * 1e6 / K,
                                 a->dark_slope_dn_per_us * 1e6, a->dark_var_slope_dn2_per_us * 1e6 / (K * K),
                                 a->dark_t_min_us, a->dark_t_max_us);
    rows[nr++] = g_strdup_printf("DSNU|%.3f DN (%.2f e-)|", maps->dsnu_dn, maps->dsnu_dn / K);
    rows[nr++] = g_strdup_printf("PRNU (high-pass)|%.3f %%|smooth part (vignetting) removed", maps->prnu_pct);
    rows[nr++] = g_strdup_printf("flat-field non-uniformity (total)|%.3f %%|vignetting included",
                                 maps->prnu_total_pct);
    for (int i = 0; i < ngains && nr < max; i++)
        rows[nr++] = g_strdup_printf("gain %g dB|K %.5g DN/e-, read noise %.4g e-, sat %.0f DN, LE %.3f %%|"
                                     "response %.5g DN/us, kc %.4g per us (small-signal %.4g)", an[i].gain_db,
                                     an[i].ptc.system_gain_dn_per_e, an[i].ptc.read_noise_e, an[i].ptc.saturation_dn,
                                     an[i].ptc.linearity_error_pct, an[i].ptc.response_dn_per_us, an[i].kc_per_us,
                                     an[i].kc0_per_us);
    if (nr < max && isfinite(a->radiance_truth))
        rows[nr++] = g_strdup_printf("radiance (comparison)|%.6g given|the virtual rig's truth: %.6g", a->radiance,
                                     a->radiance_truth);
    return nr;
}

bool calib_gain_report(const char *dir, const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps,
                       json_t *prov)
{
    char *jp = g_build_filename(dir, "gain.json", NULL);
    fprintf(stderr, "refl calib gain: plotting\n");
    int pr = model_run_script("calib_gain_report.py", jp, dir, NULL);
    g_free(jp);
    if (pr) return false;
    char *hp = g_build_filename(dir, "report.html", NULL);
    FILE *f = model_html_begin(hp, "refl calib gain: camera sensitivity (EMVA 1288 style)", prov);
    if (!f) {
        g_free(hp);
        return false;
    }
    const calib_gain_an_t *a = &an[0];
    model_html_heading(f, "Summary");
    char *rows[32];
    int nr = summary_rows(an, ngains, maps, rows, 32);
    model_html_table(f, "figure|value|notes", (const char *const *)rows, nr);
    for (int i = 0; i < nr; i++) g_free(rows[i]);
    model_html_para(f, "Flat field: %d light frames at %.6g us (%.0f DN above dark, %.0f %% of saturation) and %d "
                    "dark frames at %.6g us. Definitions: see \"conventions\" in gain.json.", maps->flat_frames,
                    maps->flat_exposure_us, maps->flat_level_dn, 100 * maps->flat_level_dn / a->ptc.saturation_dn,
                    maps->dark_frames, maps->dark_exposure_us);
    fprintf(f, "<p><b><a href=\"datasheet.html\">EMVA 1288 Release 4.0 Linear summary datasheet</a></b> "
            "(gain.json \"emva1288\": every figure with its definition)</p>\n");
    model_html_heading(f, "Photon transfer");
    model_html_figure(f, "ptc.png", "temporal variance against signal (dark subtracted), with the K fit");
    model_html_heading(f, "Linearity");
    model_html_figure(f, "linearity.png", "signal against exposure with the line of EMVA 1288 Release 4.0 (least "
                      "squared relative deviations), and the relative deviation from it (5..95 % of saturation)");
    model_html_figure(f, "linearisation.png", "the response linearisation: linear over measured signal at the "
                      "monotone table's knots, and the parametric S(1 - aS)'s");
    model_html_heading(f, "SNR");
    model_html_figure(f, "snr.png", "signal-to-noise ratio against signal, with the ideal shot-noise limit");
    model_html_heading(f, "Response (kc) per gain");
    model_html_figure(f, "kc.png", "signal per unit radiance against exposure at each gain");
    model_html_heading(f, "PRNU");
    model_html_figure(f, "prnu_map.png", "relative sensitivity: total (incl. vignetting) and high-pass");
    model_html_figure(f, "prnu_hist.png", "histograms of the high-pass PRNU map and of the DSNU map");
    model_html_heading(f, "Dark signal");
    model_html_figure(f, "dark.png", "mean dark level against exposure (dark current) and dark temporal variance, "
                      "with the dark current from each");
    model_html_heading(f, "EMVA 1288: SNR against photons");
    model_html_figure(f, "snr_photons.png", "SNR against photons per pixel (electrons without --irradiance): "
                      "measured, the linear model and the ideal");
    model_html_heading(f, "EMVA 1288: spatial nonuniformity");
    model_html_para(f, "DSNU total %.3g DN: row %.3g, column %.3g, pixel %.3g DN. PRNU total %.3g %%: row %.3g, column "
                    "%.3g, pixel %.3g %% (of the averaged flat minus dark, vignetting included); of the high-pass flat "
                    "(vignetting removed): row %.3g, column %.3g, pixel %.3g %%.", maps->sp.dsnu.total,
                    maps->sp.dsnu.row, maps->sp.dsnu.col, maps->sp.dsnu.pixel, maps->sp.prnu.total, maps->sp.prnu.row,
                    maps->sp.prnu.col, maps->sp.prnu.pixel, maps->sp.prnu_hp.row, maps->sp.prnu_hp.col,
                    maps->sp.prnu_hp.pixel);
    model_html_figure(f, "spectrogram_h.png", "horizontal spectrograms (column patterns)");
    model_html_figure(f, "spectrogram_v.png", "vertical spectrograms (row patterns)");
    model_html_figure(f, "profiles.png", "horizontal and vertical profiles");
    model_html_heading(f, "EMVA 1288: defect pixels");
    model_html_para(f, "hot %d, dead %d, bright %d (beyond %g robust standard deviations; defects.tiff)",
                    maps->sp.defects.hot, maps->sp.defects.dead, maps->sp.defects.bright,
                    maps->sp.defects.nsigma);
    model_html_figure(f, "log_histograms.png", "logarithmic histograms with the defect thresholds");
    model_html_figure(f, "defect_map.png", "the defect map");
    bool ok = model_html_end(f, hp);
    g_free(hp);
    return ok;
}

calib_gain_opts_t calib_gain_defaults(void)
{
    static const double gains[] = { 0 }, darks[] = { 100000, 500000, 1000000, 2000000 };
    return (calib_gain_opts_t){ .gains_db = gains, .ngains = 1, .dark_exposures_us = darks, .ndark_exposures = 4,
                                .sample = "flat_field", .lamps = "all", .pixel_format = "Mono12", .steps = 50,
                                .flat_frames = 16, .progress = -1, .probe_us = 1000, .max_us = NAN,
                                .min_steps = 50, .radiance = NAN, .max_dn = 65535, .quant_dn = 1, .report = true,
                                .linearisation = MODEL_LIN_MONOTONE, .low_steps = 16, .irradiance_uw_cm2 = NAN,
                                .pixel_area_um2 = NAN, .wavelength_nm = NAN, .defect_sigma = 6,
                                .photodiode_na = NAN, .photodiode_a_per_w = NAN, .photodiode_mm2 = NAN };
}

// The frames of a manifest into d (and the provenance).
static bool manifest_frames(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *prov)
{
    if (!calib_gain_read_manifest(o->frames, o->max_dn, d) || !model_provenance_input(prov, "manifest", o->frames))
        return false;
    if (o->ngains != 1) {
        model_error_set(o->frames, 0, "a manifest holds frames of one gain: give at most one --gains value (its "
                        "label)");
        return false;
    }
    snprintf(d->gain_unit, sizeof d->gain_unit, "dB");
    for (int i = 0; i < d->nf; i++) d->f[i].gain_db = o->gains_db[0];
    // the frames themselves
    for (int i = 0; i < d->nf; i++) {
        char role[64];
        snprintf(role, sizeof role, "frame line %d", d->f[i].line);
        if (!model_provenance_input(prov, role, d->f[i].path)) {
            char *m = g_strdup(model_last_error());
            model_error_set(o->frames, d->f[i].line, "frame %s: %s", d->f[i].path, m);
            g_free(m);
            return false;
        }
    }
    return true;
}

// The sessions of the run: captured on o->rig, or given (and the provenance).
static bool gather_sources(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc)
{
    if (o->rig) return calib_gain_capture(o, prov, src, nsrc);
    *src = calloc(o->nsessions, sizeof **src);
    *nsrc = 0;
    for (int i = 0; i < o->nsessions; i++) {
        (*src)[(*nsrc)++] = (calib_gain_source_t){ g_strdup(o->sessions[i]), CALIB_GAIN_SET_ANY, "session" };
        if (!model_provenance_input(prov, "session", o->sessions[i])) return false;
    }
    return true;
}

// The cameras to calibrate (names[], at most CALIB_GAIN_MAX_CAMERAS): those
// of the first session, or o->camera when it has frames there. 0 on error.
static int run_cameras(const calib_gain_opts_t *o, const calib_gain_source_t *src, int nsrc,
                       char names[][32])
{
    rig_session_t *s = nsrc ? rig_session_open(src[0].dir) : NULL;
    if (!s) {
        if (!nsrc) model_error_set(NULL, 0, "no session to read");
        return 0;
    }
    const char *nm[CALIB_GAIN_MAX_CAMERAS];
    int nc = rig_session_cameras(s, nm, CALIB_GAIN_MAX_CAMERAS), n = 0;
    GString *list = g_string_new("");
    for (int k = 0; k < nc && k < CALIB_GAIN_MAX_CAMERAS; k++) {
        g_string_append_printf(list, "%s%s", k ? ", " : "", nm[k]);
        if (!o->camera || !strcmp(o->camera, nm[k])) snprintf(names[n++], 32, "%s", nm[k]);
    }
    if (nc > CALIB_GAIN_MAX_CAMERAS && !o->camera) {
        model_error_set(src[0].dir, 0, "%d cameras: refl calib gain calibrates at most %d at once (give --camera "
                        "NAME)", nc, CALIB_GAIN_MAX_CAMERAS);
        n = 0;
    } else if (!n && nc)
        model_error_set(src[0].dir, 0, "no camera '%s' in the session (its cameras: %s)", o->camera, list->str);
    else if (!nc)
        model_error_set(src[0].dir, 0, "the session has no frames");
    g_string_free(list, TRUE);
    rig_session_free(s);
    return n;
}

// Every gain present (rig: in the order asked; else in order of appearance):
// *an gets *ngains analyses (even on failure: the ones made).
static bool analyse_all(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *facts, calib_gain_an_t **an,
                        int *ngains)
{
    double *gl = malloc(sizeof(double) * (d->ng + o->ngains));
    int ng = 0;
    if (o->rig)
        for (int i = 0; i < o->ngains; i++) gl[ng++] = o->gains_db[i];
    else
        for (int i = 0; i < d->ng; i++) {
            bool seen = false;
            for (int k = 0; k < ng; k++) seen |= gl[k] == d->g[i].gain_db;
            if (!seen) gl[ng++] = d->g[i].gain_db;
        }
    double truth_per_lamp;
    calib_gain_truth_radiance(facts, NULL, &truth_per_lamp);
    *an = calloc(ng, sizeof **an);
    bool ok = true;
    for (int i = 0; i < ng && ok; i++) {
        calib_gain_an_t *a = &(*an)[i];
        *ngains = i + 1;
        if (!(ok = calib_gain_analyse(d, gl[i], o->min_steps, o->quant_dn, a))) break;
        // radiance of the light frames: given; the truth's for the comparison
        int nl = -1;
        for (int k = 0; k < d->nf; k++)
            if (d->f[k].gain_db == gl[i] && !d->f[k].dark) nl = d->f[k].nlamps;
        a->radiance = o->radiance;
        a->radiance_truth = nl > 0 ? truth_per_lamp * nl : NAN;
        a->kc_per_us = a->ptc.response_dn_per_us / a->radiance;
        a->kc0_per_us = a->response0_dn_per_us / a->radiance;
        if (!(ok = calib_gain_an_photons(o, a))) {
            char *m = g_strdup(model_last_error());
            model_error_set(NULL, 0, "gain %g dB: %s", gl[i], m);
            g_free(m);
            break;
        }
        fprintf(stderr, "refl calib gain: gain %g dB: K %.5g DN/e-, read noise %.4g e-, saturation %.1f DN, LE %.3f "
                "%%, %d steps\n", gl[i], a->ptc.system_gain_dn_per_e, a->ptc.read_noise_e, a->ptc.saturation_dn,
                a->ptc.linearity_error_pct, a->n);
    }
    free(gl);
    return ok;
}

// One camera's frames (d) analysed into dir: gain.json, the maps and the
// report; top (may be NULL): gain.json and the maps also there.
static bool run_one(const calib_gain_opts_t *o, calib_gain_data_t *d, json_t *facts, json_t *prov, const char *dir,
                    const char *top, calib_gain_result_t *r)
{
    calib_gain_an_t *an = NULL;
    int ngains = 0;
    calib_gain_maps_t maps = { 0 };
    json_t *root = NULL;
    bool ok = false;
    const char *truth = NULL;
    double truth_per_lamp;
    if (!model_mkdir_p(dir)) return false;
    calib_gain_make_groups(d);
    fprintf(stderr, "refl calib gain: analysing %d frames (%d exposure groups)%s%s\n", d->nf, d->ng,
            d->camera[0] ? " of camera " : "", d->camera);
    if (!calib_gain_frame_stats(d) || !analyse_all(o, d, facts, &an, &ngains)) goto done;
    if (!calib_gain_make_maps(d, &an[0], &maps) || !calib_gain_make_spatial(d, &maps, o->defect_sigma, o->quant_dn) ||
        !calib_gain_write_maps(dir, &maps) || !calib_gain_write_defects(dir, &maps))
        goto done;
    if (top && !(calib_gain_write_maps(top, &maps) && calib_gain_write_defects(top, &maps))) goto done;
    calib_gain_truth_radiance(facts, &truth, &truth_per_lamp);
    root = calib_gain_json(o, d, an, ngains, &maps, truth, prov);
    ok = true;
    for (int k = 0; k < (top ? 2 : 1) && ok; k++) {
        char *jp = g_build_filename(k ? top : dir, "gain.json", NULL);
        ok = model_write_json(jp, root);
        g_free(jp);
    }
    if (ok && o->report)
        ok = calib_gain_report(dir, an, ngains, &maps, prov) &&
             calib_gain_datasheet_html(dir, json_object_get(root, "emva1288"), prov);
    if (!ok) goto done;
    *r = (calib_gain_result_t){ .system_gain_dn_per_e = an[0].ptc.system_gain_dn_per_e,
                                .read_noise_e = an[0].ptc.read_noise_e, .saturation_dn = an[0].ptc.saturation_dn,
                                .linearity_error_pct = an[0].ptc.linearity_error_pct, .dsnu_dn = maps.dsnu_dn,
                                .prnu_pct = maps.prnu_pct };
    snprintf(r->camera, sizeof r->camera, "%s", d->camera);
    snprintf(r->dir, sizeof r->dir, "%s", dir);
done:
    for (int i = 0; an && i < ngains; i++) calib_gain_an_free(&an[i]);
    free(an);
    calib_gain_maps_free(&maps);
    json_decref(root);
    return ok;
}

bool calib_gain_run(const calib_gain_opts_t *o, calib_gain_result_t *r, int max, int *n)
{
    *n = 0;
    if (o->rig && o->steps < o->min_steps) {
        model_error_set(NULL, 0, "too few sweep steps: --steps %d, EMVA 1288 asks for at least %d (--min-steps)",
                        o->steps, o->min_steps);
        return false;
    }
    calib_gain_source_t *src = NULL;
    int nsrc = 0, nc = 0;
    char names[CALIB_GAIN_MAX_CAMERAS][32];
    json_t *facts = NULL, *prov = NULL;
    bool ok = false;
    double t_start = model_now_s();
    if (!model_mkdir_p(o->out)) return false;
    prov = model_provenance(o->argc, o->argv);
    if (o->frames) {
        calib_gain_data_t d = { 0 };
        memcpy(d.roi, o->roi, sizeof d.roi);
        ok = manifest_frames(o, &d, prov) && max > 0 && run_one(o, &d, NULL, prov, o->out, NULL, &r[0]);
        calib_gain_data_free(&d);
        *n = ok;
        goto done;
    }
    if (!gather_sources(o, prov, &src, &nsrc) || !(nc = run_cameras(o, src, nsrc, names))) goto done;
    ok = true;
    for (int k = 0; k < nc && ok; k++) {
        calib_gain_data_t d = { 0 };
        memcpy(d.roi, o->roi, sizeof d.roi);
        for (int i = 0; i < nsrc && ok; i++) ok = calib_gain_add_session(&d, src[i].dir, names[k], src[i].set, &facts);
        char *dir = nc > 1 ? g_build_filename(o->out, names[k], NULL) : g_strdup(o->out);
        calib_gain_result_t rk;
        ok = ok && run_one(o, &d, facts, prov, dir, nc > 1 && k == 0 ? o->out : NULL, &rk);
        if (ok && *n < max) r[(*n)++] = rk;
        g_free(dir);
        calib_gain_data_free(&d);
    }
done:
    if (ok) fprintf(stderr, "refl calib gain: wrote %s/gain.json (%.1f s)\n", o->out, model_now_s() - t_start);
    calib_gain_sources_free(src, nsrc);
    json_decref(facts);
    json_decref(prov);
    return ok;
}
