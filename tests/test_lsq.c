// tests/test_lsq.c — fit/lsq.h (Ceres behind a C header) on problems with
// known answers: a straight line (exact solution and its textbook
// covariance), an exponential decay, bounds, fixed parameters, Gaussian
// priors (the precision-weighted mean), a robust loss against an outlier,
// rank deficiency, and the Jacobian checker against central differences.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fit/lsq.h"
#include "model/internal.h"
#include "tests/test.h"

// ---- a straight line y = a x + b, residual (a x_i + b - y_i) / sigma -------

typedef struct {
    const double *x, *y;
    int           n;
    double        sigma;
} line_t;

static bool line_res(void *ctx, const double *const *p, double *r, double **J)
{
    const line_t *L = ctx;
    for (int i = 0; i < L->n; i++) {
        r[i] = (p[0][0] * L->x[i] + p[0][1] - L->y[i]) / L->sigma;
        if (J && J[0]) {
            J[0][2 * i] = L->x[i] / L->sigma;
            J[0][2 * i + 1] = 1 / L->sigma;
        }
    }
    return true;
}

// The same with a wrong derivative in a (twice the true one).
static bool bad_line_res(void *ctx, const double *const *p, double *r, double **J)
{
    if (!line_res(ctx, p, r, J)) return false;
    const line_t *L = ctx;
    if (J && J[0])
        for (int i = 0; i < L->n; i++) J[0][2 * i] *= 2;
    return true;
}

TEST(lsq_line_exact_and_covariance)
{
    enum { N = 50 };
    double x[N], y[N];
    model_rng_t rng = model_rng(7, 0);
    const double sigma = 0.1;
    for (int i = 0; i < N; i++) {
        x[i] = -1 + 4.0 * i / (N - 1);
        y[i] = 1.5 * x[i] - 0.25 + sigma * model_rng_gauss(&rng);
    }
    line_t L = { x, y, N, sigma };
    double ab[2] = { 0, 0 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, ab, 2));
    double *blocks[] = { ab };
    CHECK(fit_add_residual(p, line_res, &L, N, 1, blocks, FIT_LOSS_NONE, 0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    CHECK(s.converged);
    CHECK(s.nresiduals == N && s.nparameters == 2 && s.nfree == 2);
    CHECK(s.final_cost < s.initial_cost);
    // the normal equations by hand
    double Sx = 0, Sxx = 0, Sy = 0, Sxy = 0;
    for (int i = 0; i < N; i++) {
        Sx += x[i];
        Sxx += x[i] * x[i];
        Sy += y[i];
        Sxy += x[i] * y[i];
    }
    double det = N * Sxx - Sx * Sx;
    double a = (N * Sxy - Sx * Sy) / det, b = (Sxx * Sy - Sx * Sxy) / det;
    CHECK_NEAR(ab[0], a, 1e-7);   // sigma_a ~ 0.01: far below the noise
    CHECK_NEAR(ab[1], b, 1e-7);
    double cov[4];
    CHECK(fit_covariance(p, ab, cov));
    // sigma^2 (X^T X)^-1
    CHECK_REL(cov[0], sigma * sigma * N / det, 1e-6);
    CHECK_REL(cov[3], sigma * sigma * Sxx / det, 1e-6);
    CHECK_REL(cov[1], -sigma * sigma * Sx / det, 1e-6);
    CHECK_REL(cov[1], cov[2], 1e-12);
    fit_problem_free(p);
}

// ---- y = A exp(-k t) -------------------------------------------------------

typedef struct {
    const double *t, *y;
    int           n;
} decay_t;

static bool decay_res(void *ctx, const double *const *p, double *r, double **J)
{
    const decay_t *D = ctx;
    double A = p[0][0], k = p[0][1];
    for (int i = 0; i < D->n; i++) {
        double e = exp(-k * D->t[i]);
        r[i] = A * e - D->y[i];
        if (J && J[0]) {
            J[0][2 * i] = e;
            J[0][2 * i + 1] = -A * D->t[i] * e;
        }
    }
    return true;
}

TEST(lsq_exponential_recovers_truth)
{
    enum { N = 40 };
    double t[N], y[N];
    for (int i = 0; i < N; i++) {
        t[i] = 0.1 * i;
        y[i] = 3.0 * exp(-0.7 * t[i]);
    }
    decay_t D = { t, y, N };
    double Ak[2] = { 1, 0.1 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, Ak, 2));
    double *blocks[] = { Ak };
    CHECK(fit_add_residual(p, decay_res, &D, N, 1, blocks, FIT_LOSS_NONE, 0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    CHECK_NEAR(Ak[0], 3.0, 1e-8);
    CHECK_NEAR(Ak[1], 0.7, 1e-8);
    CHECK(s.iterations > 1);
    CHECK(s.final_cost < 1e-15);
    fit_problem_free(p);
}

TEST(lsq_jacobian_checker)
{
    enum { N = 5 };
    double t[N] = { 0, 0.5, 1, 1.5, 2 }, y[N] = { 1, 2, 3, 4, 5 };
    decay_t D = { t, y, N };
    double Ak[2] = { 2, 0.3 };
    double *blocks[] = { Ak };
    int sizes[] = { 2 };
    double err = -1;
    CHECK(fit_check_jacobian(decay_res, &D, N, 1, sizes, blocks, 1e-6, 1e-7, 1e-6, &err));
    CHECK(err >= 0 && err < 1e-7);
    CHECK_NEAR(Ak[0], 2, 0);   // restored
    // a wrong Jacobian is caught and named
    double x[3] = { 1, 2, 3 }, yy[3] = { 0, 0, 0 };
    line_t L = { x, yy, 3, 0.5 };
    double ab[2] = { 1, 1 };
    double *lb[] = { ab };
    CHECK(fit_check_jacobian(line_res, &L, 3, 1, sizes, lb, 1e-6, 1e-7, 1e-6, NULL));
    CHECK(!fit_check_jacobian(bad_line_res, &L, 3, 1, sizes, lb, 1e-6, 1e-7, 1e-6, &err));
    CHECK_CONTAINS(fit_last_error(), "d r[0] / d block 0[0]");
    CHECK(err > 0.1);
}

// ---- bounds, fixed parameters ------------------------------------------------

typedef struct {
    double target[3];
} target3_t;

// r_i = x_i - target_i
static bool quad_res(void *ctx, const double *const *p, double *r, double **J)
{
    const target3_t *q = ctx;
    for (int i = 0; i < 3; i++) r[i] = p[0][i] - q->target[i];
    if (J && J[0]) {
        memset(J[0], 0, 9 * sizeof(double));
        for (int i = 0; i < 3; i++) J[0][4 * i] = 1;
    }
    return true;
}

TEST(lsq_bounds_and_masks)
{
    target3_t q = { { 3, -1, 5 } };
    double x[3] = { 0, 0, 0 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, x, 3));
    CHECK(fit_set_bounds(p, x, 0, -10, 2));       // the optimum 3 is beyond: stops at 2
    bool fixed[3] = { false, false, true };        // x[2] stays at 0
    CHECK(fit_set_fixed(p, x, fixed));
    double *b[] = { x };
    CHECK(fit_add_residual(p, quad_res, &q, 3, 1, b, FIT_LOSS_NONE, 0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    CHECK_NEAR(x[0], 2, 1e-9);
    CHECK_NEAR(x[1], -1, 1e-7);   // not stalled by the active bound (1e-4 without the active-set pass)
    CHECK_NEAR(x[2], 0, 0);
    CHECK(s.nfree == 2);
    double cov[9];
    CHECK(fit_covariance(p, x, cov));
    CHECK_NEAR(cov[4], 1, 1e-9);    // d r / d x1 = 1, sigma 1
    CHECK_NEAR(cov[8], 0, 0);       // fixed: no variance
    // errors: bounds that exclude the start, unknown blocks, bad sizes
    double other[1] = { 0 };
    CHECK(!fit_set_bounds(p, x, 1, 0, 1));
    CHECK_CONTAINS(fit_last_error(), "outside");
    CHECK(!fit_set_bounds(p, other, 0, 0, 1));
    CHECK_CONTAINS(fit_last_error(), "was not added");
    CHECK(!fit_add_parameters(p, x, 3));
    CHECK_CONTAINS(fit_last_error(), "twice");
    CHECK(!fit_add_prior(p, x, 0, 1, 0));
    CHECK_CONTAINS(fit_last_error(), "sigma");
    fit_problem_free(p);
}

// ---- priors: data x ~ N(m1, s1) and a prior N(m2, s2) -> precision-weighted --

typedef struct {
    double m, s;
} one_t;

static bool one_res(void *ctx, const double *const *p, double *r, double **J)
{
    const one_t *o = ctx;
    r[0] = (p[0][0] - o->m) / o->s;
    if (J && J[0]) J[0][0] = 1 / o->s;
    return true;
}

TEST(lsq_gaussian_prior)
{
    one_t data = { 4.0, 0.5 };
    double x[1] = { 0 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, x, 1));
    double *b[] = { x };
    CHECK(fit_add_residual(p, one_res, &data, 1, 1, b, FIT_LOSS_NONE, 0));
    CHECK(fit_add_prior(p, x, 0, 1.0, 1.0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    double w1 = 1 / 0.25, w2 = 1.0;
    CHECK_NEAR(x[0], (w1 * 4.0 + w2 * 1.0) / (w1 + w2), 1e-7);
    double cov;
    CHECK(fit_covariance(p, x, &cov));
    CHECK_REL(cov, 1 / (w1 + w2), 1e-9);
    fit_problem_free(p);
}

// ---- robust loss: one gross outlier among 20 points of a constant ----------

typedef struct {
    const double *v;
    int           n;
} const_t;

static bool const_res(void *ctx, const double *const *p, double *r, double **J)
{
    const const_t *c = ctx;
    for (int i = 0; i < c->n; i++) {
        r[i] = p[0][0] - c->v[i];
        if (J && J[0]) J[0][i] = 1;
    }
    return true;
}

// Each point its own residual block, so the loss acts per point.
static double fit_constant(const double *v, int n, fit_loss_t loss)
{
    double c[1] = { 0 };
    fit_problem_t *p = fit_problem_new();
    fit_add_parameters(p, c, 1);
    double *b[] = { c };
    const_t *pts = calloc((size_t)n, sizeof *pts);
    for (int i = 0; i < n; i++) {
        pts[i] = (const_t){ v + i, 1 };
        fit_add_residual(p, const_res, &pts[i], 1, 1, b, loss, 0.1);
    }
    fit_summary_t s;
    fit_solve(p, NULL, &s);
    fit_problem_free(p);
    free(pts);
    return c[0];
}

TEST(lsq_robust_loss_resists_outlier)
{
    double v[20];
    for (int i = 0; i < 20; i++) v[i] = 1.0 + 0.01 * ((i % 5) - 2);
    v[7] = 100;
    double plain = fit_constant(v, 20, FIT_LOSS_NONE);
    double huber = fit_constant(v, 20, FIT_LOSS_HUBER);
    double cauchy = fit_constant(v, 20, FIT_LOSS_CAUCHY);
    CHECK(plain > 5);                      // the mean: dragged to ~6
    CHECK_NEAR(huber, 1.0, 0.02);
    CHECK_NEAR(cauchy, 1.0, 0.01);
}

// ---- rank deficiency: y = (a + b) x cannot separate a and b -----------------

static bool sum_res(void *ctx, const double *const *p, double *r, double **J)
{
    (void)ctx;
    for (int i = 0; i < 4; i++) {
        double x = i + 1;
        r[i] = (p[0][0] + p[0][1]) * x - 2 * x;
        if (J && J[0]) {
            J[0][2 * i] = x;
            J[0][2 * i + 1] = x;
        }
    }
    return true;
}

TEST(lsq_rank_deficient_covariance_fails_clearly)
{
    double ab[2] = { 0.3, 0.2 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, ab, 2));
    double *b[] = { ab };
    CHECK(fit_add_residual(p, sum_res, NULL, 4, 1, b, FIT_LOSS_NONE, 0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    CHECK_NEAR(ab[0] + ab[1], 2, 1e-8);
    double cov[4];
    CHECK(!fit_covariance(p, ab, cov));
    CHECK_CONTAINS(fit_last_error(), "rank deficient");
    // a prior on one of them makes it well posed
    CHECK(fit_add_prior(p, ab, 0, 1.0, 0.1));
    CHECK(fit_solve(p, NULL, &s));
    CHECK(fit_covariance(p, ab, cov));
    CHECK_NEAR(ab[0], 1.0, 1e-6);
    CHECK_NEAR(ab[1], 1.0, 1e-6);
    fit_problem_free(p);
}

// ---- a failing callback far from the data is survived -----------------------

static bool sqrt_res(void *ctx, const double *const *p, double *r, double **J)
{
    (void)ctx;
    if (p[0][0] < 0) return false;   // undefined there
    r[0] = sqrt(p[0][0]) - 1.5;
    if (J && J[0]) J[0][0] = 0.5 / sqrt(fmax(p[0][0], 1e-300));
    return true;
}

TEST(lsq_callback_failure_shrinks_step)
{
    double x[1] = { 0.01 };
    fit_problem_t *p = fit_problem_new();
    CHECK(fit_add_parameters(p, x, 1));
    double *b[] = { x };
    CHECK(fit_add_residual(p, sqrt_res, NULL, 1, 1, b, FIT_LOSS_NONE, 0));
    fit_summary_t s;
    CHECK(fit_solve(p, NULL, &s));
    CHECK_NEAR(x[0], 2.25, 1e-8);
    fit_problem_free(p);
}
