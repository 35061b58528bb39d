// fit/brdf/fit.c — BRDF samples, fitting the reflection models of
// model/brdf/brdf.c to them with model/base/lsq.h (the sample files are read
// by fit/brdf/samples.c; a fit's priors entry is written by fit/priors.c).
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/brdf.h"
#include "model/base/vec.h"

// ---------------------------------------------------------------------------
// Samples

fit_samples_t *fit_samples_new(void)
{
    return calloc(1, sizeof(fit_samples_t));
}

void fit_samples_free(fit_samples_t *s)
{
    if (!s) return;
    free(s->c);
    free(s->R);
    free(s->w);
    free(s->disc_at);
    free(s->disc);
    free(s);
}

bool fit_samples_add(fit_samples_t *s, const model_cosines_t *c, double R, double weight)
{
    if (!(c->nl > 0) || !(c->nv > 0) || !isfinite(R) || !isfinite(weight) || !(weight > 0)) return false;
    if (s->n == s->cap) {
        int cap = s->cap ? 2 * s->cap : 1024;
        model_cosines_t *nc = realloc(s->c, (size_t)cap * sizeof *nc);
        if (nc) s->c = nc;
        double *nR = realloc(s->R, (size_t)cap * sizeof *nR);
        if (nR) s->R = nR;
        double *nw = realloc(s->w, (size_t)cap * sizeof *nw);
        if (nw) s->w = nw;
        if (!nc || !nR || !nw) return false;
        s->cap = cap;
    }
    if (s->disc_at && s->n >= s->disc_cap) {
        int *na = realloc(s->disc_at, (size_t)s->cap * sizeof *na);
        if (!na) return false;
        s->disc_at = na;
        for (int i = s->disc_cap; i < s->cap; i++) s->disc_at[i] = -1;
        s->disc_cap = s->cap;
    }
    s->c[s->n] = *c;
    s->R[s->n] = R;
    s->w[s->n] = weight;
    if (s->disc_at) s->disc_at[s->n] = -1;
    s->n++;
    return true;
}

bool fit_samples_add_disc(fit_samples_t *s, const model_cosines_t *c, const model_cosines_t *disc, double R,
                          double weight)
{
    if (!disc) return fit_samples_add(s, c, R, weight);
    if (!s->disc_at) {   // the first finite lamp: every earlier sample is a point lamp's
        int cap = s->cap > s->n ? s->cap : s->n + 1;
        if (!(s->disc_at = malloc((size_t)cap * sizeof *s->disc_at))) return false;
        for (int i = 0; i < cap; i++) s->disc_at[i] = -1;
        s->disc_cap = cap;
    }
    if (s->ndisc + 4 > s->disc_alloc) {
        int cap = s->disc_alloc ? 2 * s->disc_alloc : 4096;
        model_cosines_t *nd = realloc(s->disc, (size_t)cap * sizeof *nd);
        if (!nd) return false;
        s->disc = nd;
        s->disc_alloc = cap;
    }
    if (!fit_samples_add(s, c, R, weight)) return false;
    memcpy(s->disc + s->ndisc, disc, 4 * sizeof *disc);
    s->disc_at[s->n - 1] = s->ndisc;
    s->ndisc += 4;
    return true;
}

void fit_samples_eval_n(const fit_samples_t *s, model_brdf_t m, const double *p, int off, int cnt, double *R,
                        double *dR)
{
    model_brdf_eval_n(m, p, s->c + off, cnt, R, dR);
    if (!s->disc_at) return;
    int np = model_brdf_nparams(m);
    for (int k = 0; k < cnt; k++) {
        int at = s->disc_at[off + k];
        if (at < 0) continue;
        double r4[4], j4[4 * MODEL_BRDF_MAX_PARAMS];
        model_brdf_eval_n(m, p, s->disc + at, 4, r4, dR ? j4 : NULL);
        R[k] = 0.25 * (r4[0] + r4[1] + r4[2] + r4[3]);
        if (dR)
            for (int j = 0; j < np; j++)
                dR[k * np + j] = 0.25 * (j4[j] + j4[np + j] + j4[2 * np + j] + j4[3 * np + j]);
    }
}

double fit_samples_rms(const fit_samples_t *s, model_brdf_t m, const double *p)
{
    double sw = 0, ss = 0, Rb[256];
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, NULL);
        for (int k = 0; k < cnt; k++) {
            double e = Rb[k] - s->R[i0 + k];
            sw += s->w[i0 + k];
            ss += s->w[i0 + k] * e * e;
        }
    }
    return sw > 0 ? sqrt(ss / sw) : NAN;
}

double fit_samples_rms_of_cov(const fit_samples_t *s, model_brdf_t m, const double *p, const double *C)
{
    int np = model_brdf_nparams(m);
    for (int a = 0; a < np * np; a++)
        if (!isfinite(C[a])) return NAN;
    double sw = 0, tr = 0, Rb[256], Jb[256 * MODEL_BRDF_MAX_PARAMS];
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, Jb);
        for (int k = 0; k < cnt; k++) {
            const double *J = Jb + k * np;
            double q = 0;   // J^T C J
            for (int a = 0; a < np; a++)
                for (int b = 0; b < np; b++) q += J[a] * C[a * np + b] * J[b];
            sw += s->w[i0 + k];
            tr += s->w[i0 + k] * q;
        }
    }
    return sw > 0 ? sqrt(fmax(tr, 0) / sw) : NAN;
}

double fit_samples_eval(const fit_samples_t *s, model_brdf_t m, const double *p, int i)
{
    double r;
    fit_samples_eval_n(s, m, p, i, 1, &r, NULL);
    return r;
}

static model_vec3_t dir_of(double theta, double phi)
{
    return v3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
}

bool fit_samples_add_angles(fit_samples_t *s, double theta_i, double phi_i, double theta_o, double phi_o, double f_r,
                            double weight)
{
    model_cosines_t c = model_cosines(v3(0, 0, 1), dir_of(theta_i, phi_i), dir_of(theta_o, phi_o));
    return fit_samples_add(s, &c, f_r * c.nl, weight);
}

// ---------------------------------------------------------------------------
// Fitting

enum { BLOCK = 2048 };

typedef struct {
    const fit_samples_t *s;
    int                  off, cnt;
    model_brdf_t         m;
    int                  np;
} block_t;

static bool block_res(void *ctx, const double *const *p, double *r, double **J)
{
    const block_t *b = ctx;
    double *jac = J && J[0] ? J[0] : NULL;
    fit_samples_eval_n(b->s, b->m, p[0], b->off, b->cnt, r, jac);
    for (int k = 0; k < b->cnt; k++) {
        int i = b->off + k;
        if (!isfinite(r[k])) return false;
        double sw = b->s->w[i] == 1 ? 1 : sqrt(b->s->w[i]);
        r[k] = sw * (r[k] - b->s->R[i]);
        if (jac && sw != 1)
            for (int j = 0; j < b->np; j++) jac[k * b->np + j] *= sw;
    }
    return true;
}

fit_brdf_options_t fit_brdf_defaults(void)
{
    return (fit_brdf_options_t){ .threads = 0, .starts = 3, .noise_sigma = 0, .verbose = false, .cv_folds = 5,
                                 .cv_seed = 1, .loss = LSQ_LOSS_NONE, .loss_scale = 2 };
}

bool fit_loss_parse(const char *s, lsq_loss_t *out)
{
    if (!strcmp(s, "l2")) *out = LSQ_LOSS_NONE;
    else if (!strcmp(s, "huber")) *out = LSQ_LOSS_HUBER;
    else if (!strcmp(s, "cauchy")) *out = LSQ_LOSS_CAUCHY;
    else return false;
    return true;
}

const char *fit_loss_name(lsq_loss_t l)
{
    return l == LSQ_LOSS_HUBER ? "huber" : l == LSQ_LOSS_CAUCHY ? "cauchy" : l == LSQ_LOSS_SOFT_L1 ? "soft_l1" : "l2";
}

// 1.4826 median |sqrt(w) (R_model - R)| at p: the weighted residuals' std,
// robust to outliers (1 for noise-weighted samples would be their model's).
static double robust_std(const fit_samples_t *s, model_brdf_t m, const double *p)
{
    double *a = malloc((size_t)(s->n ? s->n : 1) * sizeof *a), Rb[256];
    if (!a) return NAN;
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, NULL);
        for (int k = 0; k < cnt; k++) a[i0 + k] = sqrt(s->w[i0 + k]) * fabs(Rb[k] - s->R[i0 + k]);
    }
    qsort(a, (size_t)s->n, sizeof *a, model_cmp_double);
    double med = s->n ? (s->n % 2 ? a[s->n / 2] : 0.5 * (a[s->n / 2 - 1] + a[s->n / 2])) : NAN;
    free(a);
    return 1.4826 * med;
}

// The diffuse level: the median of R / n.l away from the mirror direction.
static double diffuse_level(const fit_samples_t *s)
{
    double *v = malloc((size_t)s->n * sizeof *v);
    if (!v) return 0.1;
    int k = 0;
    for (int i = 0; i < s->n; i++)
        if (s->c[i].nh < 0.9) v[k++] = s->R[i] / s->c[i].nl;
    if (k < 10) {
        k = 0;
        for (int i = 0; i < s->n; i++) v[k++] = s->R[i] / s->c[i].nl;
    }
    qsort(v, (size_t)k, sizeof *v, model_cmp_double);
    double med = k ? v[k / 2] : 0.1;
    free(v);
    return med;
}

static double clampd(double x, double lo, double hi) { return x < lo ? lo : x > hi ? hi : x; }

// Starting point number `start` for model m.
static void start_point(const fit_samples_t *s, model_brdf_t m, int start, double kd_thesis, double *p)
{
    static const double ns_phong[] = { 20, 200, 2000, 5 }, rough0[] = { 0.05, 0.15, 0.4, 0.8 };
    // Ashikhmin-Shirley starts with a broad lobe: its Rs is also the lobe's
    // weight, and from a sharp lobe on a matte sample Rs falls to its bound 0,
    // where ns has no gradient and the fit stops on that plateau (the demo's
    // plywood: rms 0.021 there, 0.014 at the optimum from ns 2)
    static const double ns_as[] = { 2, 30, 300, 3000 };
    const double *ns0 = m == MODEL_BRDF_ASHIKHMIN_SHIRLEY ? ns_as : ns_phong;
    static const double rough2[] = { 0.3, 0.6, 0.9, 0.2 };   // ggx2's second lobe: broader than the first
    int np = model_brdf_nparams(m);
    double peak = 0;
    for (int i = 0; i < s->n; i++) peak = fmax(peak, s->R[i] - kd_thesis * s->c[i].nl);
    for (int j = 0; j < np; j++) {
        const char *n = model_brdf_param_name(m, j);
        double lo, hi, v = 0.5;
        model_brdf_param_range(m, j, &lo, &hi);
        if (!strcmp(n, "kd")) v = model_brdf_is_physical(m) ? kd_thesis * M_PI : kd_thesis;
        else if (!strcmp(n, "ns")) v = ns0[start % 4];
        else if (!strcmp(n, "m") || !strcmp(n, "alpha")) v = rough0[start % 4];
        else if (!strcmp(n, "F0")) v = 0.5;
        else if (!strcmp(n, "ks")) v = model_brdf_is_physical(m) ? 0.5 : fmax(peak, 1e-3);
        else if (!strcmp(n, "ks2")) v = 0.1;
        else if (!strcmp(n, "alpha2")) v = fmax(rough2[start % 4], 2 * rough0[start % 4]);
        else if (!strcmp(n, "Rd")) v = kd_thesis * M_PI;
        else if (!strcmp(n, "Rs")) v = fmax(0.05, fmax(peak, 1e-3) * 8 * M_PI / (ns0[start % 4] + 1));
        double span = isfinite(hi) ? hi - lo : 1;
        p[j] = clampd(v, lo + 1e-6 * span, isfinite(hi) ? hi - 1e-6 * span : v);
    }
}

// One solve from p. With a robust loss (o->loss, loss_abs its scale in the
// weighted residuals' units) each sample is a residual block of its own (the
// loss acts per sample); else blocks of BLOCK samples, folded.
static bool solve_once(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *o, double loss_abs,
                       double *p, const bool *fixed, lsq_summary_t *sum, lsq_problem_t **keep, block_t **keep_blocks)
{
    int np = model_brdf_nparams(m);
    bool robust = o->loss != LSQ_LOSS_NONE && loss_abs > 0;
    int bs = robust ? 1 : BLOCK;
    int nb = (s->n + bs - 1) / bs;
    block_t *blocks = calloc((size_t)nb, sizeof *blocks);
    lsq_problem_t *pr = lsq_problem_new();
    bool ok = blocks && pr && lsq_add_parameters(pr, p, np);
    for (int j = 0; ok && j < np; j++) {
        double lo, hi;
        model_brdf_param_range(m, j, &lo, &hi);
        ok = lsq_set_bounds(pr, p, j, lo, hi);
    }
    if (ok && fixed) {
        bool any = false;
        for (int j = 0; j < np; j++) any |= fixed[j];
        if (any) ok = lsq_set_fixed(pr, p, fixed);
    }
    double *bl[] = { p };
    for (int b = 0; ok && b < nb; b++) {
        blocks[b] = (block_t){ s, b * bs, s->n - b * bs < bs ? s->n - b * bs : bs, m, np };
        ok = robust ? lsq_add_residual(pr, block_res, &blocks[b], 1, 1, bl, o->loss, loss_abs)
                    : lsq_add_residual_folded(pr, block_res, &blocks[b], blocks[b].cnt, 1, bl);
    }
    lsq_options_t fo = lsq_defaults();
    fo.threads = o->threads;
    fo.verbose = o->verbose;
    if (ok) ok = lsq_solve(pr, &fo, sum);
    if (ok && keep) {
        *keep = pr;
        *keep_blocks = blocks;
        return true;
    }
    lsq_problem_free(pr);
    free(blocks);
    return ok;
}

// Reset out for model m; false (message) when the samples are too few.
static bool begin_result(const fit_samples_t *s, model_brdf_t m, fit_brdf_result_t *out)
{
    memset(out, 0, sizeof *out);
    out->model = m;
    out->nparams = model_brdf_nparams(m);
    out->cv_rms = out->cv_se = NAN;   // set by fit_brdf_models' cross-validation
    out->chi2_dof = NAN;
    if (!s || s->n < out->nparams + 1) {
        model_error(s ? s->source : "samples", 0, "%d samples: too few to fit %s (%d parameters)", s ? s->n : 0,
                    model_brdf_name(m), out->nparams);
        return false;
    }
    return true;
}

bool fit_brdf(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *opt, fit_brdf_result_t *out)
{
    fit_brdf_options_t o = opt ? *opt : fit_brdf_defaults();
    if (!begin_result(s, m, out)) return false;
    int np = out->nparams;
    double kd0 = diffuse_level(s);
    bool has_rough = false;
    for (int j = 0; j < np; j++) {
        const char *n = model_brdf_param_name(m, j);
        has_rough |= !strcmp(n, "ns") || !strcmp(n, "m") || !strcmp(n, "alpha") || !strcmp(n, "alpha2");
    }
    int starts = has_rough ? (o.starts > 0 ? o.starts : 1) : 1;
    if (m == MODEL_BRDF_ASHIKHMIN_SHIRLEY && starts < 4) starts = 4;   // broad to sharp lobes (start_point)
    double best[MODEL_BRDF_MAX_PARAMS], best_cost = INFINITY;
    lsq_summary_t best_sum;
    memset(&best_sum, 0, sizeof best_sum);
    int iters = 0;
    // ggx2 contains ggx (ks2 = 0): one more start from the one-lobe fit, so
    // that ggx2 never fits worse than ggx (from the generic starts it could
    // stop with two lobes sharing a single one's highlight, rms 0.022 on
    // exact ggx samples)
    double from_ggx[MODEL_BRDF_MAX_PARAMS];
    bool have_ggx = false;
    if (m == MODEL_BRDF_GGX2) {
        fit_brdf_result_t *g = malloc(sizeof *g);
        bool q = model_error_quiet_thread(true);
        if (g && fit_brdf(s, MODEL_BRDF_GGX, &o, g)) {   // kd, ks, alpha, F0
            double a2 = fmin(1.0, fmax(3 * g->p[2], 0.3));
            double v[] = { g->p[0], g->p[1], g->p[2], 1e-3, a2, g->p[3] };
            memcpy(from_ggx, v, sizeof v);
            have_ggx = true;
        }
        model_error_quiet_thread(q);
        free(g);
    }
    for (int st = 0; st < starts + have_ggx; st++) {
        double p[MODEL_BRDF_MAX_PARAMS];
        if (st < starts) start_point(s, m, st, kd0, p);
        else memcpy(p, from_ggx, sizeof p);
        lsq_summary_t sum;
        bool q = model_error_quiet_thread(true);
        bool ok = solve_once(s, m, &o, 0, p, NULL, &sum, NULL, NULL);   // least squares; the loss in the polish
        model_error_quiet_thread(q);
        iters += sum.iterations;
        if (ok && sum.final_cost < best_cost) {
            best_cost = sum.final_cost;
            memcpy(best, p, sizeof p);
            best_sum = sum;
        }
    }
    if (!isfinite(best_cost)) {
        model_error(s->source, 0, "fitting %s failed from every starting point: %s", model_brdf_name(m),
                    model_last_error());
        return false;
    }
    // Polish from the best start, keeping the problem for the covariance.
    if (!fit_brdf_from(s, m, &o, best, out)) return false;
    out->summary.iterations += iters;
    return true;
}

// F0 the samples cannot measure: only the products P = ks*F0 (and ks2*F0 in
// ggx2) are. With ks at most ks_hi, F0 lies in [max(F0_lo, P / ks_hi), F0_hi];
// *a, *b that interval.
static void f0_interval(model_brdf_t m, int jk, int jF, const double *p, double *a, double *b)
{
    double klo, khi, flo, fhi;
    model_brdf_param_range(m, jF, &flo, &fhi);
    *a = flo;
    int j2 = model_brdf_param_index(m, "ks2");
    for (int t = 0; t < 2; t++) {
        int j = t ? j2 : jk;
        if (j < 0) continue;
        model_brdf_param_range(m, j, &klo, &khi);
        double prod = p[j] * p[jF];
        if (isfinite(khi) && khi > 0) *a = fmax(*a, prod / khi);
    }
    *b = fhi;
    if (*a > *b) *a = *b;
}

// Hold F0 at the middle of its interval (the mean of a uniform over it) with
// ks = P / F0, and fit the other parameters again with it.
static bool hold_f0(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *o, fit_brdf_result_t *out,
                    lsq_problem_t **pr, block_t **blocks)
{
    int jF = model_brdf_param_index(m, "F0"), jk = model_brdf_param_index(m, "ks");
    int jk2 = model_brdf_param_index(m, "ks2");
    double a, b, lo, hi, prod = out->p[jk] * out->p[jF], prod2 = jk2 >= 0 ? out->p[jk2] * out->p[jF] : 0;
    f0_interval(m, jk, jF, out->p, &a, &b);
    out->f0_unmeasured = true;
    out->f0_lo = a;
    out->f0_hi = b;
    out->p[jF] = 0.5 * (a + b);
    out->p[jk] = out->p[jF] > 0 ? prod / out->p[jF] : out->p[jk];
    model_brdf_param_range(m, jk, &lo, &hi);
    out->p[jk] = clampd(out->p[jk], lo, hi);
    int j2 = model_brdf_param_index(m, "ks2");   // ggx2: its second lobe scales alike
    if (j2 >= 0 && out->p[jF] > 0) {
        model_brdf_param_range(m, j2, &lo, &hi);
        out->p[j2] = clampd(prod2 / out->p[jF], lo, hi);
    }
    for (int j = 0; j < out->nparams; j++) out->fixed[j] = false;
    out->fixed[jF] = true;
    lsq_problem_free(*pr);
    free(*blocks);
    *pr = NULL;
    *blocks = NULL;
    lsq_summary_t s2;
    if (!solve_once(s, m, o, out->loss_scale, out->p, out->fixed, &s2, pr, blocks)) {
        model_error(s->source, 0, "fitting %s with F0 held failed: %s", model_brdf_name(m), model_last_error());
        return false;
    }
    s2.iterations += out->summary.iterations;
    out->summary = s2;
    return true;
}

// Held parameters (other than F0 over its interval) that do not change R at
// all over the samples (ggx2's second lobe's alpha2 when ks2 is 0; a lobe's
// roughness when its weight is 0): any value in their interval fits alike,
// [alpha, hi] for alpha2 (the lobes are ordered), else the physical range.
// Each is stated as that interval (free_lo, free_hi), held at its middle with
// a uniform's std (variance on the covariance's diagonal, uncorrelated);
// the others keep their best value, std 0.
static void state_free_intervals(const fit_samples_t *s, model_brdf_t m, fit_brdf_result_t *out)
{
    int np = out->nparams, cand = 0;
    for (int j = 0; j < np; j++) {
        out->held_free[j] = false;
        cand += out->fixed[j] && !(out->f0_unmeasured && !strcmp(model_brdf_param_name(m, j), "F0"));
    }
    if (!cand || !out->cov_ok) return;
    double g[MODEL_BRDF_MAX_PARAMS] = { 0 }, r2 = 0, Rb[64], Jb[64 * MODEL_BRDF_MAX_PARAMS];
    for (int i0 = 0; i0 < s->n; i0 += 64) {
        int cnt = s->n - i0 < 64 ? s->n - i0 : 64;
        fit_samples_eval_n(s, m, out->p, i0, cnt, Rb, Jb);
        for (int k = 0; k < cnt; k++) {
            r2 += s->w[i0 + k] * Rb[k] * Rb[k];
            for (int j = 0; j < np; j++) g[j] += s->w[i0 + k] * Jb[k * np + j] * Jb[k * np + j];
        }
    }
    int ja = model_brdf_param_index(m, "alpha");
    for (int j = 0; j < np; j++) {
        const char *n = model_brdf_param_name(m, j);
        if (!out->fixed[j] || (out->f0_unmeasured && !strcmp(n, "F0"))) continue;
        double lo, hi;
        model_brdf_param_range(m, j, &lo, &hi);
        if (!strcmp(n, "alpha2") && ja >= 0) lo = out->p[ja];
        if (!isfinite(hi) || !(hi > lo)) continue;
        // the largest change of R it could make over its interval, against R's size
        if (!(sqrt(g[j]) * (hi - lo) <= 1e-9 * sqrt(r2) + 1e-300)) continue;
        out->held_free[j] = true;
        out->free_lo[j] = lo;
        out->free_hi[j] = hi;
        out->p[j] = 0.5 * (lo + hi);
        out->std[j] = (hi - lo) / sqrt(12);
        for (int b = 0; b < np; b++) out->cov[j * np + b] = out->cov[b * np + j] = 0;
        out->cov[j * np + j] = out->std[j] * out->std[j];
    }
}

// F0 held over its interval (f0_unmeasured): its uniform's variance added to
// out->cov along the line ks*F0 = const, J J^T var_u with J = d(params)/dF0 =
// (ks: -ks/F0, ks2: -ks2/F0, F0: 1); F0's other rows and columns are 0.
static void add_f0_uniform(model_brdf_t m, fit_brdf_result_t *out)
{
    int np = out->nparams, jF = model_brdf_param_index(m, "F0"), jk = model_brdf_param_index(m, "ks");
    if (!out->f0_unmeasured || jF < 0 || jk < 0 || !(out->p[jF] > 0)) return;
    double J[MODEL_BRDF_MAX_PARAMS] = { 0 }, w = out->f0_hi - out->f0_lo, var_u = w * w / 12;
    J[jF] = 1;
    J[jk] = -out->p[jk] / out->p[jF];
    int j2 = model_brdf_param_index(m, "ks2");
    if (j2 >= 0) J[j2] = -out->p[j2] / out->p[jF];
    for (int a = 0; a < np; a++) out->cov[a * np + jF] = out->cov[jF * np + a] = 0;
    for (int a = 0; a < np; a++)
        for (int b = 0; b < np; b++) out->cov[a * np + b] += J[a] * J[b] * var_u;
}

// The fit's figures and covariance at out->p (pr: the solved problem).
// Parameters the samples cannot separate are held (F0 first). With F0
// unmeasured, the covariance gets its interval's uniform along the line
// ks*F0 = const: J J^T var_u with J = d(params)/dF0 = (ks: -ks/F0, F0: 1).
static void finish(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *o, fit_brdf_result_t *out,
                   lsq_problem_t *pr)
{
    int np = out->nparams;
    double sw = 0, rss = 0, rss_f = 0, Rb[256];
    out->n_downweighted = 0;
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, out->p, i0, cnt, Rb, NULL);
        for (int k = 0; k < cnt; k++) {
            int i = i0 + k;
            double e = Rb[k] - s->R[i];
            sw += s->w[i];
            rss += s->w[i] * e * e;
            rss_f += s->w[i] * (e / s->c[i].nl) * (e / s->c[i].nl);
            out->n_downweighted += out->loss_scale > 0 && s->w[i] * e * e > out->loss_scale * out->loss_scale;
        }
    }
    out->n = s->n;
    out->rss = rss;
    out->rms = sqrt(rss / sw);
    out->ngan_error = out->rms;
    out->rms_fr = sqrt(rss_f / sw);
    double N = s->n, k = np;
    double rn = fmax(rss / N * (N / sw), 1e-300);   // per-sample mean square (weights normalised)
    out->aic = N * log(rn) + 2 * k;
    out->bic = N * log(rn) + k * log(N);
    bool q = model_error_quiet_thread(true);
    bool anyfixed = false;
    for (int j = 0; j < np; j++) anyfixed |= out->fixed[j];
    if (anyfixed) lsq_set_fixed(pr, out->p, out->fixed);
    bool cov_ok = lsq_covariance(pr, out->p, out->cov);
    for (int pass = 0; !cov_ok && pass < np; pass++) {
        // hold a parameter the samples cannot separate: ggx2's second lobe (absent from
        // one-lobe samples), F0, then roughness
        const char *order[] = { "alpha2", "F0", "ks2", "ks", "ns", "m", "alpha", "kd", "Rs", "Rd" };
        for (size_t t = 0; t < sizeof order / sizeof order[0]; t++) {
            int j = model_brdf_param_index(m, order[t]);
            if (j >= 0 && !out->fixed[j]) {
                out->fixed[j] = true;
                break;
            }
        }
        lsq_set_fixed(pr, out->p, out->fixed);
        cov_ok = lsq_covariance(pr, out->p, out->cov);
    }
    model_error_quiet_thread(q);
    out->nfree = np;
    for (int j = 0; j < np; j++) out->nfree -= out->fixed[j];
    double dof = N - out->nfree;
    out->chi2_dof = s->noise_weighted && dof > 0 ? rss / dof : NAN;
    double s2 = o->noise_sigma > 0 ? o->noise_sigma * o->noise_sigma : (dof > 0 ? rss / dof : 0);
    if (out->loss != LSQ_LOSS_NONE && !(o->noise_sigma > 0)) {
        // robust: the residual scale without the outliers' squares
        double rs = robust_std(s, m, out->p);
        if (isfinite(rs)) s2 = rs * rs;
    }
    out->sigma = sqrt(s2);
    out->cov_ok = cov_ok;
    for (int a = 0; a < np * np; a++) out->cov[a] = cov_ok ? out->cov[a] * s2 : NAN;
    if (cov_ok) add_f0_uniform(m, out);
    for (int j = 0; j < np; j++) out->std[j] = cov_ok ? sqrt(fmax(out->cov[j * np + j], 0)) : NAN;
    state_free_intervals(s, m, out);
}

// ggx2's two lobes are interchangeable: the first is made the sharper
// (alpha <= alpha2) by swapping (ks, alpha) with (ks2, alpha2), which leaves
// R unchanged.
static void order_lobes(model_brdf_t m, double *p)
{
    int ja = model_brdf_param_index(m, "alpha"), jb = model_brdf_param_index(m, "alpha2");
    int ka = model_brdf_param_index(m, "ks"), kb = model_brdf_param_index(m, "ks2");
    if (ja < 0 || jb < 0 || ka < 0 || kb < 0 || !(p[ja] > p[jb])) return;
    double t = p[ja];
    p[ja] = p[jb], p[jb] = t;
    t = p[ka];
    p[ka] = p[kb], p[kb] = t;
}

bool fit_brdf_from(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *opt, const double *start,
                   fit_brdf_result_t *out)
{
    fit_brdf_options_t o = opt ? *opt : fit_brdf_defaults();
    if (!begin_result(s, m, out)) return false;
    int np = out->nparams;
    lsq_problem_t *pr = NULL;
    block_t *blocks = NULL;
    memcpy(out->p, start, (size_t)np * sizeof *start);
    for (int j = 0; j < np; j++) {
        double lo, hi;
        model_brdf_param_range(m, j, &lo, &hi);
        out->p[j] = clampd(out->p[j], lo, hi);
    }
    out->loss = o.loss;
    if (o.loss != LSQ_LOSS_NONE) {
        // the loss's scale in the weighted residuals' units: sigma itself for
        // noise-weighted samples, else the robust std of a least-squares fit
        double unit = 1;
        if (!s->noise_weighted) {
            lsq_summary_t s0;
            bool q = model_error_quiet_thread(true);
            if (solve_once(s, m, &o, 0, out->p, NULL, &s0, NULL, NULL)) unit = robust_std(s, m, out->p);
            model_error_quiet_thread(q);
        }
        out->loss_scale = (o.loss_scale > 0 ? o.loss_scale : 2) * (isfinite(unit) && unit > 0 ? unit : 1);
    }
    if (!solve_once(s, m, &o, out->loss_scale, out->p, NULL, &out->summary, &pr, &blocks)) {
        model_error(s->source, 0, "fitting %s failed: %s", model_brdf_name(m), model_last_error());
        return false;
    }
    // Fresnel: where the samples' v.h stays far from grazing, F = F0 + (1-F0)(1-v.h)^5
    // hardly changes and only the product ks*F0 is measured. F0 is then only
    // known to lie in an interval (f0_interval): it is held at its middle,
    // with the std of a uniform over it, and ks = ks*F0 / F0.
    int jF = model_brdf_param_index(m, "F0"), jk = model_brdf_param_index(m, "ks");
    bool ok = true;
    if (jF >= 0 && jk >= 0) {
        // the largest relative change of F over the samples: (1-F0) f5 / F
        // grows with f5 = (1-v.h)^5, so it is the one at the smallest v.h
        double vh_min = 1;
        for (int i = 0; i < s->n; i++) vh_min = fmin(vh_min, s->c[i].vh);
        double x = 1 - vh_min, f5 = x * x * x * x * x, F = out->p[jF] + (1 - out->p[jF]) * f5;
        double var = F > 0 ? (1 - out->p[jF]) * f5 / F : 0;
        out->fresnel_variation = var;
        if (var < 0.05) ok = hold_f0(s, m, &o, out, &pr, &blocks);
    }
    if (ok) order_lobes(m, out->p);
    if (ok) finish(s, m, &o, out, pr);
    // F0 fitted free: measured only if the samples say more about it than its
    // interval does (a std below the uniform's), else held as above
    if (ok && jF >= 0 && jk >= 0 && !out->f0_unmeasured) {
        double a, b;
        f0_interval(m, jk, jF, out->p, &a, &b);
        if (out->fixed[jF] || !(out->std[jF] < (b - a) / sqrt(12))) {
            ok = hold_f0(s, m, &o, out, &pr, &blocks);
            if (ok) order_lobes(m, out->p);
    if (ok) finish(s, m, &o, out, pr);
        }
    }
    lsq_problem_free(pr);
    free(blocks);
    return ok;
}
// ---------------------------------------------------------------------------
// What the samples share: the cluster-robust covariance and the photometric
// groups' systematic part (fit_brdf_shared_covariance)

typedef struct {
    long long key;
    int       i;
} keyed_t;

static int cmp_keyed(const void *a, const void *b)
{
    long long x = ((const keyed_t *)a)->key, y = ((const keyed_t *)b)->key;
    return (x > y) - (x < y);
}

// key[i] numbered 0..G-1 into id[i] (equal keys alike, in key order); G, or
// -1 when out of memory.
static int number_keys(int n, const long long *key, int *id)
{
    keyed_t *k = malloc((size_t)(n > 0 ? n : 1) * sizeof *k);
    if (!k) return -1;
    for (int i = 0; i < n; i++) k[i] = (keyed_t){ key[i], i };
    qsort(k, (size_t)n, sizeof *k, cmp_keyed);
    int g = -1;
    for (int i = 0; i < n; i++) {
        if (i == 0 || k[i].key != k[i - 1].key) g++;
        id[k[i].i] = g;
    }
    free(k);
    return g + 1;
}

// The inverse of the symmetric positive definite n x n A (row-major) by its
// Cholesky factor; false when A is not positive definite.
static bool spd_inverse(int n, const double *A, double *Ai)
{
    double L[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS] = { 0 };
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double v = A[i * n + j];
            for (int k = 0; k < j; k++) v -= L[i * n + k] * L[j * n + k];
            if (i == j) {
                if (!(v > 1e-300 * (fabs(A[i * n + i]) + 1e-300)) || !isfinite(v)) return false;
                L[i * n + i] = sqrt(v);
            } else {
                L[i * n + j] = v / L[j * n + j];
            }
        }
    // columns of A^-1: solve L L^T x = e_c
    for (int c = 0; c < n; c++) {
        double y[MODEL_BRDF_MAX_PARAMS];
        for (int i = 0; i < n; i++) {
            double v = i == c;
            for (int k = 0; k < i; k++) v -= L[i * n + k] * y[k];
            y[i] = v / L[i * n + i];
        }
        for (int i = n - 1; i >= 0; i--) {
            double v = y[i];
            for (int k = i + 1; k < n; k++) v -= L[k * n + i] * Ai[k * n + c];
            Ai[i * n + c] = v / L[i * n + i];
        }
    }
    return true;
}

// The symmetric n x n A with its negative eigenvalues set to 0 (A = V diag(max(lambda, 0)) V^T).
static void psd_clip(int n, double *A)
{
    double V[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS], D[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    memcpy(D, A, (size_t)(n * n) * sizeof *D);
    model_sym_eigen(n, D, V);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double v = 0;
            for (int k = 0; k < n; k++) v += V[i * n + k] * fmax(D[k * n + k], 0) * V[j * n + k];
            A[i * n + j] = v;
        }
}

// V += sign * G/(G-1) H^-1 (sum_g u_g u_g^T) H^-1 over the G clusters' scores u (G x nf).
static void add_sandwich(int nf, const double *Hi, const double *u, int G, double sign, double *V)
{
    double M[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS] = { 0 }, T[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    for (int g = 0; g < G; g++)
        for (int a = 0; a < nf; a++)
            for (int b = 0; b < nf; b++) M[a * nf + b] += u[g * nf + a] * u[g * nf + b];
    double f = sign * (double)G / (G - 1);
    for (int a = 0; a < nf; a++)
        for (int b = 0; b < nf; b++) {
            double v = 0;
            for (int k = 0; k < nf; k++) v += Hi[a * nf + k] * M[k * nf + b];
            T[a * nf + b] = v;
        }
    for (int a = 0; a < nf; a++)
        for (int b = 0; b < nf; b++) {
            double v = 0;
            for (int k = 0; k < nf; k++) v += T[a * nf + k] * Hi[k * nf + b];
            V[a * nf + b] += f * v;
        }
}

// The clusters of one way (ids, NULL: none) numbered into *out (freed by the
// caller); their number, 0 when none, -1 when out of memory.
static int clusters_of(int n, const int *ids, long long *key, int **out)
{
    *out = NULL;
    if (!ids) return 0;
    if (!(*out = malloc((size_t)(n > 0 ? n : 1) * sizeof **out))) return -1;
    for (int i = 0; i < n; i++) key[i] = ids[i];
    return number_keys(n, key, *out);
}

// The scores u of each way's clusters and the groups' b = sum w J R, and H,
// over the free parameters fi (nf of them) at r->p.
typedef struct {
    int     nf, fi[MODEL_BRDF_MAX_PARAMS];
    int    *id[3], G[3];           // frame, place, frame & place
    double *u[3], *b;
    double  H[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
} shared_sums_t;

static void shared_accumulate(const fit_samples_t *s, const fit_shared_t *sh, const fit_brdf_result_t *r,
                              shared_sums_t *a)
{
    int np = r->nparams, nf = a->nf;
    double Rb[256], Jb[256 * MODEL_BRDF_MAX_PARAMS];
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, r->model, r->p, i0, cnt, Rb, Jb);
        for (int k = 0; k < cnt; k++) {
            int i = i0 + k;
            double w = s->w[i], e = Rb[k] - s->R[i], J[MODEL_BRDF_MAX_PARAMS];
            for (int x = 0; x < nf; x++) J[x] = Jb[k * np + a->fi[x]];
            for (int x = 0; x < nf; x++)
                for (int y = 0; y < nf; y++) a->H[x * nf + y] += w * J[x] * J[y];
            for (int way = 0; way < 3; way++)
                if (a->u[way])
                    for (int x = 0; x < nf; x++) a->u[way][a->id[way][i] * nf + x] += w * e * J[x];
            if (a->b && sh->group[i] >= 0 && sh->group[i] < sh->ngroups)
                for (int x = 0; x < nf; x++) a->b[sh->group[i] * nf + x] += w * s->R[i] * J[x];
        }
    }
}

// r's statistical covariance from the sandwich V (nf x nf over fi): the held
// parameters' stated parts kept (F0 over its interval, the free intervals).
static void shared_set_cov(const shared_sums_t *a, const double *V, fit_brdf_result_t *r)
{
    int np = r->nparams;
    for (int j = 0; j < np; j++) r->std_chi2[j] = r->std[j];
    for (int x = 0; x < np * np; x++) r->cov[x] = 0;
    for (int x = 0; x < a->nf; x++)
        for (int y = 0; y < a->nf; y++) r->cov[a->fi[x] * np + a->fi[y]] = V[x * a->nf + y];
    add_f0_uniform(r->model, r);
    for (int j = 0; j < np; j++)
        if (r->held_free[j]) r->cov[j * np + j] = (r->free_hi[j] - r->free_lo[j]) * (r->free_hi[j] - r->free_lo[j]) / 12;
    for (int j = 0; j < np; j++) r->std[j] = sqrt(fmax(r->cov[j * np + j], 0));
    r->cov_ok = true;
}

bool fit_brdf_shared_covariance(const fit_samples_t *s, const fit_shared_t *sh, fit_brdf_result_t *r, double *dp)
{
    int np = r->nparams, n = s->n;
    shared_sums_t a = { 0 };
    for (int j = 0; j < np; j++)
        if (!r->fixed[j]) a.fi[a.nf++] = j;
    if (a.nf == 0 || n <= a.nf) {
        model_error(s->source, 0, "%s: no free parameter or too few samples for the shared covariance",
                    model_brdf_name(r->model));
        return false;
    }
    long long *key = malloc((size_t)n * sizeof *key);
    bool ok = key != NULL;
    if (ok) {
        a.G[0] = clusters_of(n, sh->frame, key, &a.id[0]);
        a.G[1] = clusters_of(n, sh->place, key, &a.id[1]);
        ok = a.G[0] >= 0 && a.G[1] >= 0;
    }
    bool use[3] = { ok && a.G[0] >= FIT_MIN_CLUSTERS, ok && a.G[1] >= FIT_MIN_CLUSTERS, false };
    use[2] = use[0] && use[1];
    if (use[2]) {
        a.id[2] = malloc((size_t)n * sizeof *a.id[2]);
        for (int i = 0; a.id[2] && i < n; i++) key[i] = (long long)a.id[0][i] * a.G[1] + a.id[1][i];
        a.G[2] = a.id[2] ? number_keys(n, key, a.id[2]) : -1;
        ok = a.G[2] > 0;
    }
    bool robust = ok && r->loss == LSQ_LOSS_NONE && (use[0] || use[1]);
    for (int way = 0; ok && robust && way < 3; way++)
        if (use[way] && !(a.u[way] = calloc((size_t)a.G[way] * a.nf, sizeof *a.u[way]))) ok = false;
    bool groups = ok && sh->group && sh->group_rel && sh->ngroups > 0;
    if (groups && !(a.b = calloc((size_t)sh->ngroups * a.nf, sizeof *a.b))) ok = false;
    double Hi[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    if (!ok) model_error(s->source, 0, "out of memory for the shared covariance");
    if (ok) {
        shared_accumulate(s, sh, r, &a);
        if (!(ok = spd_inverse(a.nf, a.H, Hi)))
            model_error(s->source, 0, "%s: the normal matrix is singular; the shared covariance is not computed",
                        model_brdf_name(r->model));
    }
    if (ok && robust) {
        double V[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS] = { 0 };
        double floor_var[MODEL_BRDF_MAX_PARAMS] = { 0 };
        for (int way = 0; way < 3; way++)
            if (a.u[way]) {
                double W[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS] = { 0 };
                add_sandwich(a.nf, Hi, a.u[way], a.G[way], 1, W);
                for (int x = 0; x < a.nf * a.nf; x++) V[x] += (way == 2 ? -1 : 1) * W[x];
                for (int x = 0; x < a.nf; x++) floor_var[x] = fmax(floor_var[x], W[x * a.nf + x]);
            }
        // the two-way difference can cancel below every one-way clustering (where the model's misfit
        // varies with the geometry, sums over large clusters cancel): each variance is at least the
        // largest one-way clustering's (a diagonal added: still positive semi-definite)
        psd_clip(a.nf, V);
        for (int x = 0; x < a.nf; x++) V[x * a.nf + x] = fmax(V[x * a.nf + x], floor_var[x]);
        shared_set_cov(&a, V, r);
        r->shared_done = true;
        r->clusters_frame = use[0] ? a.G[0] : 0;
        r->clusters_place = use[1] ? a.G[1] : 0;
    }
    if (ok && groups) {
        for (int x = 0; x < np * np; x++) r->cov_groups[x] = 0;
        for (int g = 0; g < sh->ngroups; g++) {
            double d[MODEL_BRDF_MAX_PARAMS] = { 0 };
            for (int x = 0; x < a.nf; x++) {
                double v = 0;
                for (int y = 0; y < a.nf; y++) v += Hi[x * a.nf + y] * a.b[g * a.nf + y];
                d[a.fi[x]] = v * sh->group_rel[g];
            }
            for (int x = 0; x < np; x++)
                for (int y = 0; y < np; y++) r->cov_groups[x * np + y] += d[x] * d[y];
            if (dp) memcpy(dp + (size_t)g * np, d, (size_t)np * sizeof *d);
        }
        r->groups_ok = true;
    }
    for (int way = 0; way < 3; way++) {
        free(a.id[way]);
        free(a.u[way]);
    }
    free(a.b);
    free(key);
    return ok;
}

// ---------------------------------------------------------------------------
// Priors

bool fit_brdf_model_list(const char *name, model_brdf_t models[MODEL_BRDF_COUNT], int *nmodels)
{
    *nmodels = 0;
    if (!strcmp(name, "all")) {
        for (int m = 0; m < MODEL_BRDF_COUNT; m++) models[(*nmodels)++] = (model_brdf_t)m;
        return true;
    }
    int m = model_brdf_from_name(name);
    if (m < 0) return false;
    models[(*nmodels)++] = (model_brdf_t)m;
    return true;
}

// ---------------------------------------------------------------------------
// Model choice by k-fold cross-validation

static int cmp_int(const void *a, const void *b)
{
    int x = *(const int *)a, y = *(const int *)b;
    return (x > y) - (x < y);
}

// fold[i] of each sample: its unit (o->cv_unit, else one of 10 k contiguous
// blocks) dealt to k folds in an order shuffled by the seed. The number of
// distinct units, 0 when out of memory.
static int cv_folds_of(const fit_samples_t *s, const fit_brdf_options_t *o, int k, int *fold)
{
    int n = s->n, *u = malloc((size_t)n * sizeof *u), *ids = malloc((size_t)n * sizeof *ids);
    if (!u || !ids) {
        free(u);
        free(ids);
        return 0;
    }
    long nb = 10L * k < n ? 10L * k : n;
    for (int i = 0; i < n; i++) u[i] = o->cv_unit ? o->cv_unit[i] : (int)((long)i * nb / n);
    memcpy(ids, u, (size_t)n * sizeof *ids);
    qsort(ids, (size_t)n, sizeof *ids, cmp_int);
    int nu = 0;
    for (int i = 0; i < n; i++)
        if (i == 0 || ids[i] != ids[nu - 1]) ids[nu++] = ids[i];
    // a seeded Fisher-Yates shuffle of the unit ids; unit at position j goes to fold j % k
    int *pos = malloc((size_t)nu * sizeof *pos);
    model_rng_t rng = model_rng(o->cv_seed, 19);
    for (int j = nu - 1; pos && j > 0; j--) {
        int r = (int)(model_rng_uniform(&rng) * (j + 1));
        if (r > j) r = j;
        int t = ids[j];
        ids[j] = ids[r], ids[r] = t;
    }
    // pos[j]: the shuffled place of sorted unit j (search the shuffled ids by a sorted copy)
    int *sorted = pos ? malloc((size_t)nu * sizeof *sorted) : NULL;
    if (!sorted) {
        free(u), free(ids), free(pos);
        return 0;
    }
    for (int j = 0; j < nu; j++) sorted[j] = ids[j];
    qsort(sorted, (size_t)nu, sizeof *sorted, cmp_int);
    for (int j = 0; j < nu; j++) {
        int *at = bsearch(&ids[j], sorted, (size_t)nu, sizeof *sorted, cmp_int);
        pos[at - sorted] = j;
    }
    for (int i = 0; i < n; i++) {
        int *at = bsearch(&u[i], sorted, (size_t)nu, sizeof *sorted, cmp_int);
        fold[i] = pos[at - sorted] % k;
    }
    free(u), free(ids), free(pos), free(sorted);
    return nu;
}

// The samples with (fold[i] == f) == keep, lamp discs kept.
static fit_samples_t *cv_subset(const fit_samples_t *s, const int *fold, int f, bool keep)
{
    fit_samples_t *t = fit_samples_new();
    if (!t) return NULL;
    snprintf(t->source, sizeof t->source, "%s", s->source);
    t->noise_weighted = s->noise_weighted;
    for (int i = 0; i < s->n; i++) {
        if ((fold[i] == f) != keep) continue;
        const model_cosines_t *disc = s->disc_at && s->disc_at[i] >= 0 ? s->disc + s->disc_at[i] : NULL;
        if (!fit_samples_add_disc(t, &s->c[i], disc, s->R[i], s->w[i])) {
            fit_samples_free(t);
            return NULL;
        }
    }
    return t;
}

// r's cross-validation: refitted from its full fit without each fold, the
// held-out weighted squares summed. false when a fold could not be fitted.
static bool cv_model(const fit_samples_t *s, const int *fold, int k, const fit_brdf_options_t *o,
                     fit_brdf_result_t *r)
{
    double sw = 0, swe = 0, mse[64], sum = 0, sum2 = 0;
    fit_brdf_options_t fo = *o;
    fo.cv_unit = NULL;
    bool ok = true;
    for (int f = 0; f < k && ok; f++) {
        fit_samples_t *train = cv_subset(s, fold, f, false), *test = cv_subset(s, fold, f, true);
        fit_brdf_result_t *fr = malloc(sizeof *fr);
        ok = train && test && fr && test->n > 0 && fit_brdf_from(train, r->model, &fo, r->p, fr);
        double fw = 0, fe = 0, Rb[256];
        for (int i0 = 0; ok && i0 < test->n; i0 += 256) {
            int cnt = test->n - i0 < 256 ? test->n - i0 : 256;
            fit_samples_eval_n(test, r->model, fr->p, i0, cnt, Rb, NULL);
            for (int j = 0; j < cnt; j++) {
                double e = Rb[j] - test->R[i0 + j];
                fw += test->w[i0 + j];
                fe += test->w[i0 + j] * e * e;
            }
        }
        if (ok) {
            sw += fw, swe += fe;
            mse[f] = fe / fw;
            sum += mse[f], sum2 += mse[f] * mse[f];
        }
        free(fr);
        fit_samples_free(train);
        fit_samples_free(test);
    }
    r->cv_rms = ok && sw > 0 ? sqrt(swe / sw) : NAN;
    double var = k > 1 ? fmax(0.0, (sum2 - sum * sum / k) / (k - 1)) : 0;
    // the standard error of the mean square over folds, carried to the RMS
    r->cv_se = ok && r->cv_rms > 0 ? sqrt(var / k) / (2 * r->cv_rms) : NAN;
    return ok && isfinite(r->cv_rms);
}

// Cross-validate every fitted model of out and choose by the one-standard-error rule.
static void cv_choose(const fit_samples_t *s, const fit_brdf_options_t *o, fit_brdf_models_t *out)
{
    int k = o->cv_folds > 64 ? 64 : o->cv_folds;
    out->cv_seed = o->cv_seed;
    snprintf(out->cv_unit_name, sizeof out->cv_unit_name, "%s",
             o->cv_unit ? (o->cv_unit_name ? o->cv_unit_name : "unit") : "block of samples");
    if (out->nres < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "one model fitted: nothing to choose, no cross-validation");
        return;
    }
    if (k < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "cross-validation off (folds %d): the lowest BIC", o->cv_folds);
        return;
    }
    int *fold = malloc((size_t)s->n * sizeof *fold);
    int nu = fold ? cv_folds_of(s, o, k, fold) : 0;
    if (nu < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "%d %s(s): too few to cross-validate; the lowest BIC", nu,
                 out->cv_unit_name);
        free(fold);
        return;
    }
    if (nu < k) k = nu;
    out->cv_folds = k;
    out->cv_units = nu;
    for (int i = 0; i < out->nres; i++) {
        bool q = model_error_quiet_thread(true);
        if (cv_model(s, fold, k, o, &out->res[i]) &&
            (out->best_cv < 0 || out->res[i].cv_rms < out->res[out->best_cv].cv_rms))
            out->best_cv = i;
        model_error_quiet_thread(q);
    }
    free(fold);
    if (out->best_cv < 0) {
        snprintf(out->cv_note, sizeof out->cv_note, "no model could be cross-validated; the lowest BIC");
        return;
    }
    // the simplest model within one standard error of the lowest held-out RMS
    // (and within rounding of it, for noise-free samples)
    const fit_brdf_result_t *b = &out->res[out->best_cv];
    double tol = b->cv_rms + fmax(isfinite(b->cv_se) ? b->cv_se : 0, 1e-9 * b->cv_rms + 1e-15);
    int pick = out->best_cv;
    for (int i = 0; i < out->nres; i++) {
        const fit_brdf_result_t *r = &out->res[i];
        if (!(r->cv_rms <= tol)) continue;
        const fit_brdf_result_t *p = &out->res[pick];
        if (r->nparams < p->nparams || (r->nparams == p->nparams && r->cv_rms < p->cv_rms)) pick = i;
    }
    out->best = pick;
    out->by_cv = true;
    snprintf(out->cv_note, sizeof out->cv_note, "%d-fold cross-validation over %d %ss", k, nu, out->cv_unit_name);
}

bool fit_brdf_models(const fit_samples_t *s, const model_brdf_t *models, int nmodels, const fit_brdf_options_t *opt,
                     fit_brdf_models_t *out)
{
    fit_brdf_options_t o = opt ? *opt : fit_brdf_defaults();
    bool quiet = model_error_quiet_thread(true);   // each model's message goes to out->error
    out->ntried = out->nres = 0;
    out->best = out->best_bic = out->best_cv = -1;
    out->by_cv = false;
    out->cv_folds = out->cv_units = 0;
    out->cv_note[0] = 0;
    for (int k = 0; k < nmodels && k < MODEL_BRDF_COUNT; k++) {
        fit_brdf_result_t *r = &out->res[out->nres];
        double t0 = model_now_s();
        int t = out->ntried++;
        out->tried[t] = models[k];
        out->at[t] = -1;
        out->error[t][0] = 0;
        bool ok = fit_brdf(s, models[k], &o, r);
        out->time_s[t] = model_now_s() - t0;
        if (!ok) {
            snprintf(out->error[t], sizeof out->error[t], "%s", model_last_error());
            continue;
        }
        out->at[t] = out->nres;
        if (out->best_bic < 0 || r->bic < out->res[out->best_bic].bic) out->best_bic = out->nres;
        out->nres++;
    }
    out->best = out->best_bic;
    if (out->best >= 0) cv_choose(s, &o, out);
    if (out->best < 0) model_error_set(NULL, 0, "no model could be fitted");
    model_error_quiet_thread(quiet);
    return out->best >= 0;
}

json_t *fit_brdf_choice_json(const fit_brdf_models_t *m)
{
    json_t *o = json_object();
    json_object_set_new(o, "rule", json_string(
        m->by_cv ? "k-fold cross-validation: each model refitted without each fold of independent units and its "
                   "held-out weighted RMS of R (cv_rms, 1/sr) computed; chosen: the model with the fewest parameters "
                   "whose cv_rms is within one standard error (cv_rms_se) of the lowest"
                 : m->nres < 2 ? "one model fitted (see note)"
                               : "the lowest BIC (cross-validation not done: see note)"));
    json_object_set_new(o, "criterion", json_string(m->by_cv ? "cv_rms" : m->nres < 2 ? "only_model" : "bic"));
    json_object_set_new(o, "note", json_string(m->cv_note));
    json_object_set_new(o, "folds", json_integer(m->cv_folds));
    json_object_set_new(o, "units", json_integer(m->cv_units));
    json_object_set_new(o, "unit", json_string(m->cv_unit_name));
    json_object_set_new(o, "seed", json_integer((json_int_t)m->cv_seed));
    json_object_set_new(o, "cv_rms_unit", json_string("1/sr, of R = f_r cos(theta_i), weighted"));
    json_object_set_new(o, "chosen", m->best >= 0 ? json_string(model_brdf_name(m->res[m->best].model)) : json_null());
    json_object_set_new(o, "lowest_bic",
                        m->best_bic >= 0 ? json_string(model_brdf_name(m->res[m->best_bic].model)) : json_null());
    json_object_set_new(o, "lowest_cv_rms",
                        m->best_cv >= 0 ? json_string(model_brdf_name(m->res[m->best_cv].model)) : json_null());
    return o;
}

