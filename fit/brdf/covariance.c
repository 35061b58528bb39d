// fit/brdf/covariance.c — what a fit's samples share: the cluster-robust
// statistical covariance and the photometric groups' systematic one
// (fit_brdf_shared_covariance).
#define _GNU_SOURCE
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/internal.h"
#include "model/base/vec.h"

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
    fit_brdf_add_f0_uniform(r->model, r);
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
