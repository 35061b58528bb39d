// fit/brdf/fit.c — fitting one reflection model of model/brdf/brdf.c to BRDF
// samples with model/base/lsq.h: starts, robust losses, the parameters the
// samples cannot measure held, the covariance (the sample set is
// fit/brdf/sample_set.c, the files fit/brdf/samples.c; a fit's priors entry is
// written by fit/priors.c).
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/internal.h"
#include "model/base/vec.h"

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
    if (!a) {
        model_error_set(s->source, 0, "out of memory");
        return NAN;
    }
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, NULL);
        for (int k = 0; k < cnt; k++) a[i0 + k] = sqrt(s->w[i0 + k]) * fabs(Rb[k] - s->R[i0 + k]);
    }
    double med = model_median(a, s->n);
    free(a);
    return 1.4826 * med;
}

// The diffuse level: the median of R / n.l away from the mirror direction.
static double diffuse_level(const fit_samples_t *s)
{
    double *v = malloc((size_t)(s->n ? s->n : 1) * sizeof *v);
    if (!v) {
        model_error_set(s->source, 0, "out of memory");
        return 0.1;
    }
    int k = 0;
    for (int i = 0; i < s->n; i++)
        if (s->c[i].nh < 0.9) v[k++] = s->R[i] / s->c[i].nl;
    if (k < 10) {
        k = 0;
        for (int i = 0; i < s->n; i++) v[k++] = s->R[i] / s->c[i].nl;
    }
    double med = k ? model_kth(v, k, k / 2) : 0.1;
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
    if (!blocks || !pr) model_error_set(s->source, 0, "out of memory for %d blocks of samples", nb);
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
void fit_brdf_add_f0_uniform(model_brdf_t m, fit_brdf_result_t *out)
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
    if (cov_ok) fit_brdf_add_f0_uniform(m, out);
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
