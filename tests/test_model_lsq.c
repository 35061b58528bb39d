// tests/test_model_lsq.c — model/base/lsq.h (Ceres behind a C header) on problems with
// known answers: a straight line (exact solution and its textbook
// covariance), an exponential decay, bounds, fixed parameters, Gaussian
// priors (the precision-weighted mean), a robust loss against an outlier,
// rank deficiency, and the Jacobian checker against central differences.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model/base/lsq.h"
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, ab, 2));
    double *blocks[] = { ab };
    CHECK(lsq_add_residual(p, line_res, &L, N, 1, blocks, LSQ_LOSS_NONE, 0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
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
    CHECK(lsq_covariance(p, ab, cov));
    // sigma^2 (X^T X)^-1
    CHECK_REL(cov[0], sigma * sigma * N / det, 1e-6);
    CHECK_REL(cov[3], sigma * sigma * Sxx / det, 1e-6);
    CHECK_REL(cov[1], -sigma * sigma * Sx / det, 1e-6);
    CHECK_REL(cov[1], cov[2], 1e-12);
    lsq_problem_free(p);
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, Ak, 2));
    double *blocks[] = { Ak };
    CHECK(lsq_add_residual(p, decay_res, &D, N, 1, blocks, LSQ_LOSS_NONE, 0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
    CHECK_NEAR(Ak[0], 3.0, 1e-8);
    CHECK_NEAR(Ak[1], 0.7, 1e-8);
    CHECK(s.iterations > 1);
    CHECK(s.final_cost < 1e-15);
    lsq_problem_free(p);
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
    CHECK(lsq_check_jacobian(decay_res, &D, N, 1, sizes, blocks, 1e-6, 1e-7, 1e-6, &err));
    CHECK(err >= 0 && err < 1e-7);
    CHECK_NEAR(Ak[0], 2, 0);   // restored
    // a wrong Jacobian is caught and named
    double x[3] = { 1, 2, 3 }, yy[3] = { 0, 0, 0 };
    line_t L = { x, yy, 3, 0.5 };
    double ab[2] = { 1, 1 };
    double *lb[] = { ab };
    CHECK(lsq_check_jacobian(line_res, &L, 3, 1, sizes, lb, 1e-6, 1e-7, 1e-6, NULL));
    CHECK(!lsq_check_jacobian(bad_line_res, &L, 3, 1, sizes, lb, 1e-6, 1e-7, 1e-6, &err));
    CHECK_CONTAINS(model_last_error(), "d r[0] / d block 0[0]");
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, x, 3));
    CHECK(lsq_set_bounds(p, x, 0, -10, 2));       // the optimum 3 is beyond: stops at 2
    bool fixed[3] = { false, false, true };        // x[2] stays at 0
    CHECK(lsq_set_fixed(p, x, fixed));
    double *b[] = { x };
    CHECK(lsq_add_residual(p, quad_res, &q, 3, 1, b, LSQ_LOSS_NONE, 0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
    CHECK_NEAR(x[0], 2, 1e-9);
    CHECK_NEAR(x[1], -1, 1e-7);   // not stalled by the active bound (1e-4 without the active-set pass)
    CHECK_NEAR(x[2], 0, 0);
    CHECK(s.nfree == 2);
    double cov[9];
    CHECK(lsq_covariance(p, x, cov));
    CHECK_NEAR(cov[4], 1, 1e-9);    // d r / d x1 = 1, sigma 1
    CHECK_NEAR(cov[8], 0, 0);       // fixed: no variance
    // errors: bounds that exclude the start, unknown blocks, bad sizes
    double other[1] = { 0 };
    CHECK(!lsq_set_bounds(p, x, 1, 0, 1));
    CHECK_CONTAINS(model_last_error(), "outside");
    CHECK(!lsq_set_bounds(p, other, 0, 0, 1));
    CHECK_CONTAINS(model_last_error(), "was not added");
    CHECK(!lsq_add_parameters(p, x, 3));
    CHECK_CONTAINS(model_last_error(), "twice");
    CHECK(!lsq_add_prior(p, x, 0, 1, 0));
    CHECK_CONTAINS(model_last_error(), "sigma");
    lsq_problem_free(p);
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, x, 1));
    double *b[] = { x };
    CHECK(lsq_add_residual(p, one_res, &data, 1, 1, b, LSQ_LOSS_NONE, 0));
    CHECK(lsq_add_prior(p, x, 0, 1.0, 1.0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
    double w1 = 1 / 0.25, w2 = 1.0;
    CHECK_NEAR(x[0], (w1 * 4.0 + w2 * 1.0) / (w1 + w2), 1e-7);
    double cov;
    CHECK(lsq_covariance(p, x, &cov));
    CHECK_REL(cov, 1 / (w1 + w2), 1e-9);
    lsq_problem_free(p);
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
static double fit_constant(const double *v, int n, lsq_loss_t loss)
{
    double c[1] = { 0 };
    lsq_problem_t *p = lsq_problem_new();
    lsq_add_parameters(p, c, 1);
    double *b[] = { c };
    const_t *pts = calloc((size_t)n, sizeof *pts);
    for (int i = 0; i < n; i++) {
        pts[i] = (const_t){ v + i, 1 };
        lsq_add_residual(p, const_res, &pts[i], 1, 1, b, loss, 0.1);
    }
    lsq_summary_t s;
    lsq_solve(p, NULL, &s);
    lsq_problem_free(p);
    free(pts);
    return c[0];
}

TEST(lsq_robust_loss_resists_outlier)
{
    double v[20];
    for (int i = 0; i < 20; i++) v[i] = 1.0 + 0.01 * ((i % 5) - 2);
    v[7] = 100;
    double plain = fit_constant(v, 20, LSQ_LOSS_NONE);
    double huber = fit_constant(v, 20, LSQ_LOSS_HUBER);
    double cauchy = fit_constant(v, 20, LSQ_LOSS_CAUCHY);
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, ab, 2));
    double *b[] = { ab };
    CHECK(lsq_add_residual(p, sum_res, NULL, 4, 1, b, LSQ_LOSS_NONE, 0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
    CHECK_NEAR(ab[0] + ab[1], 2, 1e-8);
    double cov[4];
    CHECK(!lsq_covariance(p, ab, cov));
    CHECK_CONTAINS(model_last_error(), "rank deficient");
    // a prior on one of them makes it well posed
    CHECK(lsq_add_prior(p, ab, 0, 1.0, 0.1));
    CHECK(lsq_solve(p, NULL, &s));
    CHECK(lsq_covariance(p, ab, cov));
    CHECK_NEAR(ab[0], 1.0, 1e-6);
    CHECK_NEAR(ab[1], 1.0, 1e-6);
    lsq_problem_free(p);
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
    lsq_problem_t *p = lsq_problem_new();
    CHECK(lsq_add_parameters(p, x, 1));
    double *b[] = { x };
    CHECK(lsq_add_residual(p, sqrt_res, NULL, 1, 1, b, LSQ_LOSS_NONE, 0));
    lsq_summary_t s;
    CHECK(lsq_solve(p, NULL, &s));
    CHECK_NEAR(x[0], 2.25, 1e-8);
    lsq_problem_free(p);
}

// ---- folded residual blocks and the dense covariance ------------------------

// y = A exp(-k t) + c sin(3 t): blocks {A, k} and {c}; residuals / sigma.
typedef struct {
    const double *t, *y;
    int           n;
    double        sigma;
} two_t;

static bool two_res(void *ctx, const double *const *p, double *r, double **J)
{
    const two_t *d = ctx;
    double A = p[0][0], k = p[0][1], c = p[1][0];
    for (int i = 0; i < d->n; i++) {
        double e = exp(-k * d->t[i]), s = sin(3 * d->t[i]);
        r[i] = (A * e + c * s - d->y[i]) / d->sigma;
        if (J && J[0]) {
            J[0][2 * i] = e / d->sigma;
            J[0][2 * i + 1] = -A * d->t[i] * e / d->sigma;
        }
        if (J && J[1]) J[1][i] = s / d->sigma;
    }
    return true;
}

enum { TWO_N = 3002, TWO_BLOCK = 500 };

typedef struct {
    double t[TWO_N], y[TWO_N];
    two_t  blk[TWO_N / TWO_BLOCK + 1];
    int    nblk;
} two_data_t;

static void two_data(two_data_t *D)
{
    model_rng_t rng = model_rng(11, 3);
    for (int i = 0; i < TWO_N; i++) {
        D->t[i] = 4.0 * i / (TWO_N - 1);
        D->y[i] = 2.5 * exp(-0.8 * D->t[i]) + 0.3 * sin(3 * D->t[i]) + 0.02 * model_rng_gauss(&rng);
    }
    // blocks of 500 and a last one of 2 residuals (fewer than the 3 parameters it reads)
    D->nblk = 0;
    for (int o = 0; o < TWO_N; o += TWO_BLOCK) {
        int n = TWO_N - o < TWO_BLOCK ? TWO_N - o : TWO_BLOCK;
        D->blk[D->nblk++] = (two_t){ D->t + o, D->y + o, n, 0.02 };
    }
}

// Build and solve the problem, folded or plain; options: a prior on c, k held.
static lsq_problem_t *two_problem(two_data_t *D, double *Ak, double *c, bool folded, bool hold_k, bool prior,
                                  lsq_summary_t *s)
{
    Ak[0] = 1;
    Ak[1] = 0.3;
    c[0] = 0;
    if (hold_k) Ak[1] = 0.8;
    lsq_problem_t *p = lsq_problem_new();
    if (!lsq_add_parameters(p, Ak, 2) || !lsq_add_parameters(p, c, 1)) return p;
    lsq_set_bounds(p, Ak, 1, 0.01, 10);
    if (hold_k) lsq_set_fixed(p, Ak, (bool[]){ false, true });
    double *b[] = { Ak, c };
    for (int k = 0; k < D->nblk; k++) {
        if (folded) lsq_add_residual_folded(p, two_res, &D->blk[k], D->blk[k].n, 2, b);
        else lsq_add_residual(p, two_res, &D->blk[k], D->blk[k].n, 2, b, LSQ_LOSS_NONE, 0);
    }
    if (prior) lsq_add_prior(p, c, 0, 0.25, 0.01);
    lsq_solve(p, NULL, s);
    return p;
}

TEST(lsq_folded_blocks_match_plain)
{
    static two_data_t D;
    two_data(&D);
    for (int variant = 0; variant < 3; variant++) {
        bool hold_k = variant == 1, prior = variant == 2;
        double Ak0[2], c0[1], Ak1[2], c1[1];
        lsq_summary_t s0, s1;
        lsq_problem_t *p0 = two_problem(&D, Ak0, c0, false, hold_k, prior, &s0);
        lsq_problem_t *p1 = two_problem(&D, Ak1, c1, true, hold_k, prior, &s1);
        CHECK(s0.usable && s1.usable);
        CHECK(s1.nresiduals == s0.nresiduals);   // the block's residuals, not the folded rows
        // the same steps: the same solution and cost to rounding
        CHECK_REL(Ak1[0], Ak0[0], 1e-9);
        CHECK_REL(Ak1[1], Ak0[1], 1e-9);
        CHECK_REL(c1[0], c0[0], 1e-9);
        CHECK_REL(s1.final_cost, s0.final_cost, 1e-9);
        CHECK_REL(s1.initial_cost, s0.initial_cost, 1e-12);
        if (!hold_k && !prior) {
            CHECK_NEAR(Ak1[0], 2.5, 0.01);
            CHECK_NEAR(Ak1[1], 0.8, 0.01);
            CHECK_NEAR(c1[0], 0.3, 0.01);
            CHECK(fabs(s1.final_cost / (0.5 * TWO_N) - 1) < 0.1);   // residuals at the noise
        }
        // and the same covariance (J^T J is the block's)
        double cA0[4], cA1[4], cx0[2], cx1[2], cc0, cc1;
        CHECK(lsq_covariance(p0, Ak0, cA0) && lsq_covariance(p1, Ak1, cA1));
        CHECK(lsq_covariance_cross(p0, Ak0, c0, cx0) && lsq_covariance_cross(p1, Ak1, c1, cx1));
        CHECK(lsq_covariance(p0, c0, &cc0) && lsq_covariance(p1, c1, &cc1));
        for (int i = 0; i < 4; i++) CHECK_NEAR(cA1[i], cA0[i], 1e-8 * fabs(cA0[0]) + 1e-300);
        for (int i = 0; i < 2; i++) CHECK_NEAR(cx1[i], cx0[i], 1e-8 * sqrt(fabs(cA0[0] * cc0)));
        CHECK_REL(cc1, cc0, 1e-8);
        if (hold_k) CHECK(cA1[3] == 0 && cA1[1] == 0);   // the held parameter has no variance
        if (prior) CHECK(cc1 < 0.01 * 0.01);             // the prior tightens c
        lsq_problem_free(p0);
        lsq_problem_free(p1);
    }
    // errors name the call
    double x[1] = { 0 };
    lsq_problem_t *p = lsq_problem_new();
    double *b[] = { x };
    CHECK(!lsq_add_residual_folded(p, two_res, &D.blk[0], 10, 1, b));
    CHECK_CONTAINS(model_last_error(), "lsq_add_residual_folded");
    lsq_problem_free(p);
}

TEST(lsq_covariance_equals_ceres_dense_svd)
{
    // lsq_covariance folds J into R by chunks of rows; ceres::Covariance
    // (DENSE_SVD) takes the SVD of the whole J. Masks, priors, a robust loss,
    // cross blocks and a constant block must all agree.
    static two_data_t D;
    two_data(&D);
    for (int variant = 0; variant < 4; variant++) {
        double Ak[2] = { 1, 0.3 }, c[1] = { 0 }, z[2] = { 1, 2 };
        lsq_problem_t *p = lsq_problem_new();
        CHECK(lsq_add_parameters(p, Ak, 2) && lsq_add_parameters(p, c, 1) && lsq_add_parameters(p, z, 2));
        CHECK(lsq_set_fixed(p, z, NULL));   // constant: no covariance
        if (variant == 1) CHECK(lsq_set_fixed(p, Ak, (bool[]){ true, false }));
        double *b[] = { Ak, c };
        for (int k = 0; k < D.nblk; k++)
            CHECK(lsq_add_residual(p, two_res, &D.blk[k], D.blk[k].n, 2, b, variant == 3 ? LSQ_LOSS_CAUCHY : LSQ_LOSS_NONE,
                                   1.5));
        if (variant == 2) CHECK(lsq_add_prior(p, c, 0, 0.25, 0.01));
        lsq_summary_t s;
        CHECK(lsq_solve(p, NULL, &s));
        double *blk[] = { Ak, c, z };
        int n[] = { 2, 1, 2 };
        for (int a = 0; a < 3; a++)
            for (int bb = 0; bb < 3; bb++) {
                double mine[4], ref[4];
                CHECK(lsq_covariance_cross(p, blk[a], blk[bb], mine));
                CHECK(lsq_covariance_reference(p, blk[a], blk[bb], ref));
                for (int i = 0; i < n[a] * n[bb]; i++) CHECK_NEAR(mine[i], ref[i], 1e-7 * fabs(ref[i]) + 1e-16);
                if (a == 2 || bb == 2)
                    for (int i = 0; i < n[a] * n[bb]; i++) CHECK(mine[i] == 0);
            }
        lsq_problem_free(p);
    }
}

// model_sym_eigen: a symmetric matrix of known eigenvalues (Q diag(lambda)
// Q^T with Q a rotation) comes back diagonal with those eigenvalues, and
// V diag V^T rebuilds it; without V the diagonal is the same.
TEST(model_sym_eigen_known_answer)
{
    const int n = 4;
    const double lambda[4] = { 3.0, -0.5, 1e-6, 12.0 };
    // Q: a product of rotations in three planes
    double Q[16] = { 0 };
    for (int i = 0; i < n; i++) Q[i * n + i] = 1;
    const int planes[3][2] = { { 0, 1 }, { 1, 3 }, { 0, 2 } };
    const double ang[3] = { 0.3, -1.1, 0.7 };
    for (int r = 0; r < 3; r++) {
        int p = planes[r][0], q = planes[r][1];
        double c = cos(ang[r]), s = sin(ang[r]);
        for (int k = 0; k < n; k++) {
            double a = Q[k * n + p], b = Q[k * n + q];
            Q[k * n + p] = c * a - s * b;
            Q[k * n + q] = s * a + c * b;
        }
    }
    double A[16], A0[16], B[16], V[16];
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double v = 0;
            for (int k = 0; k < n; k++) v += Q[i * n + k] * lambda[k] * Q[j * n + k];
            A[i * n + j] = A0[i * n + j] = B[i * n + j] = v;
        }
    model_sym_eigen(n, A, V);
    double got[4], want[4];
    for (int i = 0; i < n; i++) got[i] = A[i * n + i], want[i] = lambda[i];
    qsort(got, 4, sizeof *got, model_cmp_double);
    qsort(want, 4, sizeof *want, model_cmp_double);
    for (int i = 0; i < n; i++) CHECK_NEAR(got[i], want[i], 1e-12);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            if (i != j) CHECK_NEAR(A[i * n + j], 0, 1e-12);
            double v = 0;
            for (int k = 0; k < n; k++) v += V[i * n + k] * A[k * n + k] * V[j * n + k];
            CHECK_NEAR(v, A0[i * n + j], 1e-12);
        }
    model_sym_eigen(n, B, NULL);
    for (int i = 0; i < n; i++) CHECK_NEAR(B[i * n + i], A[i * n + i], 1e-12);
}
