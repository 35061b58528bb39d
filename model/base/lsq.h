// model/base/lsq.h — non-linear least squares for refl: Ceres Solver behind a C
// header (model/base/lsq.cc). A problem holds parameter blocks (arrays the caller
// owns; the solver updates them in place), residual blocks computed by C
// callbacks with analytic Jacobians, bounds, fixed parameters (masks),
// Gaussian priors and robust losses. After lsq_solve, lsq_covariance gives
// the covariance of the estimate.
//
// Cost: 1/2 sum_blocks rho(|r_block|^2) with r the residual vector of a block
// (weight it yourself: r = (model - data) / sigma). The covariance is
// (J^T J)^-1 at the solution, with J the Jacobian of the (loss-scaled)
// residuals; it is the covariance of the estimate when the residuals are
// scaled by their standard deviations. Fixed parameters have zero rows and
// columns.
#pragma once

#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct lsq_problem lsq_problem_t;

// A residual block: from the parameter blocks it reads (params[k], in the
// order given to lsq_add_residual) compute nres residuals; when jacobians is
// not NULL, each non-NULL jacobians[k] receives d residuals / d params[k],
// row-major nres x size_k. Return false when the residuals cannot be computed
// at these parameters (the solver then takes a smaller step).
typedef bool (*lsq_residual_fn)(void *ctx, const double *const *params, double *residuals, double **jacobians);

typedef enum {
    LSQ_LOSS_NONE = 0,   // rho(s) = s
    LSQ_LOSS_HUBER,      // quadratic within scale, linear beyond
    LSQ_LOSS_CAUCHY,     // rho(s) = b log(1 + s/b), b = scale^2
    LSQ_LOSS_SOFT_L1,    // rho(s) = 2 b (sqrt(1 + s/b) - 1)
} lsq_loss_t;

lsq_problem_t *lsq_problem_new(void);
void           lsq_problem_free(lsq_problem_t *p);    // accepts NULL

// Register x[0..n-1] as a parameter block (n >= 1; x stays owned by the
// caller and must live as long as the problem). Registering it again is an
// error. Returns false with a message (model_last_error, kept but not printed: the caller reports it).
bool lsq_add_parameters(lsq_problem_t *p, double *x, int n);
// Bounds of parameter i of block x (either may be -INFINITY / INFINITY).
bool lsq_set_bounds(lsq_problem_t *p, double *x, int i, double lo, double hi);
// Fix parameters of block x: fixed[i] true holds x[i] at its value (NULL:
// the whole block). A block with every parameter fixed is constant.
bool lsq_set_fixed(lsq_problem_t *p, double *x, const bool *fixed);
// A residual block of nres residuals reading nblocks registered parameter
// blocks, with an optional robust loss (scale: the residual size where it
// starts, ignored for LSQ_LOSS_NONE). ctx is passed to fn as it is.
bool lsq_add_residual(lsq_problem_t *p, lsq_residual_fn fn, void *ctx, int nres, int nblocks, double *const *blocks,
                      lsq_loss_t loss, double scale);
// The same without a loss, for blocks of many residuals (a few thousand
// samples of a material): Ceres sees the block through the QR factor of its
// Jacobian (sum of block sizes + 1 residuals), which has the block's cost,
// gradient, J^T J and so its steps and covariance. Fits of a million
// residuals cost Ceres a few thousand rows. Residuals are only meaningful
// through the cost (lsq_solve's summary); the covariance is unchanged.
bool lsq_add_residual_folded(lsq_problem_t *p, lsq_residual_fn fn, void *ctx, int nres, int nblocks,
                             double *const *blocks);
// A Gaussian prior on parameter i of block x: one residual (x[i] - mean) / sigma.
bool lsq_add_prior(lsq_problem_t *p, double *x, int i, double mean, double sigma);

typedef struct {
    int    max_iterations;      // default 200
    double function_tolerance;  // default 1e-10 (relative cost change)
    double parameter_tolerance; // default 1e-10
    double gradient_tolerance;  // default 1e-12
    int    threads;             // default 0 = the machine's cores
    bool   verbose;             // Ceres's per-iteration lines (Ceres prints them) and its full report (model_note)
    // Small problems (<= 400 parameters): the normal equations by Cholesky
    // instead of QR of the Jacobian. Faster (the step's linear algebra costs
    // N p^2 / 2 instead of 2 N p^2) at a squared condition number; the steps
    // agree to rounding on well-posed problems (default false: QR).
    bool   normal_equations;
} lsq_options_t;

lsq_options_t lsq_defaults(void);

typedef struct {
    int    iterations;
    double initial_cost, final_cost;   // 1/2 sum rho(|r|^2)
    int    nresiduals, nparameters, nfree;   // residuals; parameters; not fixed
    bool   converged;                  // a tolerance was met (not the iteration limit, not a failure)
    bool   usable;                     // the parameters hold a usable solution
    char   termination[32];            // "CONVERGENCE", "NO_CONVERGENCE", "FAILURE", "USER_SUCCESS", ...
    char   message[256];               // Ceres's own explanation
    double time_s;
} lsq_summary_t;

// Solve (opt NULL = defaults). Returns summary->usable.
bool lsq_solve(lsq_problem_t *p, const lsq_options_t *opt, lsq_summary_t *summary);
// Covariance of block x at the current parameters (after lsq_solve): cov is
// n x n row-major. false (message) when J^T J is rank deficient in the free
// parameters.
bool lsq_covariance(lsq_problem_t *p, double *x, double *cov);
// Covariance between blocks x (n) and y (m): n x m row-major.
bool lsq_covariance_cross(lsq_problem_t *p, double *x, double *y, double *cov);
// The same from ceres::Covariance (DENSE_SVD of the whole Jacobian), which
// lsq_covariance_cross reproduces faster: for checking it.
bool lsq_covariance_reference(lsq_problem_t *p, double *x, double *y, double *cov);

// Compare the Jacobians of fn at blocks against central differences (step
// h_rel * max(|x|, 1)): max_abs_err (may be NULL) = the largest
// |analytic - numeric| over every entry; true when each entry is within
// tol_abs + tol_rel * |numeric|.
bool lsq_check_jacobian(lsq_residual_fn fn, void *ctx, int nres, int nblocks, const int *sizes,
                        double *const *blocks, double h_rel, double tol_abs, double tol_rel, double *max_abs_err);

#ifdef __cplusplus
}
#endif
