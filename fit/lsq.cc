// fit/lsq.cc — fit/lsq.h on Ceres Solver (2.x): C callbacks become
// ceres::CostFunction objects, masks become SubsetManifolds, priors are
// one-residual blocks, the covariance comes from ceres::Covariance.
#include "fit/lsq.h"

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace {

thread_local char last_error[1024] = "";

bool fail(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
bool fail(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(last_error, sizeof last_error, fmt, ap);
    va_end(ap);
    return false;
}

class CallbackCost : public ceres::CostFunction {
public:
    CallbackCost(fit_residual_fn fn, void *ctx, int nres, const std::vector<int> &sizes) : fn_(fn), ctx_(ctx)
    {
        set_num_residuals(nres);
        for (int s : sizes) mutable_parameter_block_sizes()->push_back(s);
    }
    bool Evaluate(double const *const *params, double *residuals, double **jacobians) const override
    {
        return fn_(ctx_, params, residuals, jacobians);
    }

private:
    fit_residual_fn fn_;
    void *ctx_;
};

class PriorCost : public ceres::CostFunction {
public:
    PriorCost(int n, int i, double mean, double sigma) : n_(n), i_(i), mean_(mean), sigma_(sigma)
    {
        set_num_residuals(1);
        mutable_parameter_block_sizes()->push_back(n);
    }
    bool Evaluate(double const *const *params, double *residuals, double **jacobians) const override
    {
        residuals[0] = (params[0][i_] - mean_) / sigma_;
        if (jacobians && jacobians[0]) {
            for (int k = 0; k < n_; k++) jacobians[0][k] = 0;
            jacobians[0][i_] = 1 / sigma_;
        }
        return true;
    }

private:
    int n_, i_;
    double mean_, sigma_;
};

}  // namespace

// Ceres logs through glog: keep it quiet (errors reach the caller through
// fit_last_error; fit_options_t.verbose shows the iterations).
static void quiet_logging(void)
{
    static std::once_flag once;
    std::call_once(once, [] {
        FLAGS_minloglevel = 3;
        FLAGS_logtostderr = true;
        if (!google::IsGoogleLoggingInitialized()) google::InitGoogleLogging("refl");
    });
}

struct fit_problem {
    ceres::Problem problem;
    std::map<double *, int> sizes;          // registered blocks
    std::map<double *, std::vector<bool>> fixed;
    int nresiduals = 0;
};

extern "C" {

const char *fit_last_error(void) { return last_error; }

fit_problem_t *fit_problem_new(void)
{
    quiet_logging();
    try {
        return new fit_problem;
    } catch (...) {
        fail("out of memory");
        return nullptr;
    }
}

void fit_problem_free(fit_problem_t *p) { delete p; }

static bool known(fit_problem_t *p, double *x, const char *what)
{
    if (!p || !x) return fail("%s: NULL problem or parameter block", what);
    if (!p->sizes.count(x)) return fail("%s: the parameter block %p was not added (fit_add_parameters)", what, (void *)x);
    return true;
}

bool fit_add_parameters(fit_problem_t *p, double *x, int n)
{
    if (!p || !x || n < 1) return fail("fit_add_parameters: NULL block or size %d < 1", n);
    if (p->sizes.count(x)) return fail("fit_add_parameters: block %p added twice", (void *)x);
    for (int i = 0; i < n; i++)
        if (!std::isfinite(x[i])) return fail("fit_add_parameters: starting value %d of the block is %g", i, x[i]);
    p->problem.AddParameterBlock(x, n);
    p->sizes[x] = n;
    p->fixed[x] = std::vector<bool>(n, false);
    return true;
}

bool fit_set_bounds(fit_problem_t *p, double *x, int i, double lo, double hi)
{
    if (!known(p, x, "fit_set_bounds")) return false;
    int n = p->sizes[x];
    if (i < 0 || i >= n) return fail("fit_set_bounds: parameter %d of a block of %d", i, n);
    if (std::isnan(lo) || std::isnan(hi) || !(lo <= hi)) return fail("fit_set_bounds: bounds [%g, %g]", lo, hi);
    if (x[i] < lo || x[i] > hi)
        return fail("fit_set_bounds: starting value %g of parameter %d is outside [%g, %g]", x[i], i, lo, hi);
    if (std::isfinite(lo)) p->problem.SetParameterLowerBound(x, i, lo);
    if (std::isfinite(hi)) p->problem.SetParameterUpperBound(x, i, hi);
    return true;
}

bool fit_set_fixed(fit_problem_t *p, double *x, const bool *fixed)
{
    if (!known(p, x, "fit_set_fixed")) return false;
    int n = p->sizes[x];
    std::vector<int> idx;
    for (int i = 0; i < n; i++) {
        bool f = fixed ? fixed[i] : true;
        p->fixed[x][i] = f;
        if (f) idx.push_back(i);
    }
    if ((int)idx.size() == n) {
        p->problem.SetParameterBlockConstant(x);
    } else {
        p->problem.SetParameterBlockVariable(x);
        p->problem.SetManifold(x, idx.empty() ? nullptr : new ceres::SubsetManifold(n, idx));
    }
    return true;
}

bool fit_add_residual(fit_problem_t *p, fit_residual_fn fn, void *ctx, int nres, int nblocks, double *const *blocks,
                      fit_loss_t loss, double scale)
{
    if (!p || !fn || nres < 1 || nblocks < 1 || !blocks)
        return fail("fit_add_residual: NULL problem or callback, %d residuals, %d blocks", nres, nblocks);
    std::vector<int> sizes;
    std::vector<double *> bl;
    for (int k = 0; k < nblocks; k++) {
        if (!known(p, blocks[k], "fit_add_residual")) return false;
        sizes.push_back(p->sizes[blocks[k]]);
        bl.push_back(blocks[k]);
    }
    ceres::LossFunction *lf = nullptr;
    if (loss != FIT_LOSS_NONE && !(scale > 0 && std::isfinite(scale)))
        return fail("fit_add_residual: robust loss scale %g must be > 0", scale);
    switch (loss) {
    case FIT_LOSS_NONE: break;
    case FIT_LOSS_HUBER: lf = new ceres::HuberLoss(scale); break;
    case FIT_LOSS_CAUCHY: lf = new ceres::CauchyLoss(scale); break;
    case FIT_LOSS_SOFT_L1: lf = new ceres::SoftLOneLoss(scale); break;
    default: return fail("fit_add_residual: unknown loss %d", (int)loss);
    }
    p->problem.AddResidualBlock(new CallbackCost(fn, ctx, nres, sizes), lf, bl);
    p->nresiduals += nres;
    return true;
}

bool fit_add_prior(fit_problem_t *p, double *x, int i, double mean, double sigma)
{
    if (!known(p, x, "fit_add_prior")) return false;
    int n = p->sizes[x];
    if (i < 0 || i >= n) return fail("fit_add_prior: parameter %d of a block of %d", i, n);
    if (!std::isfinite(mean) || !(sigma > 0) || !std::isfinite(sigma))
        return fail("fit_add_prior: mean %g, sigma %g (sigma must be > 0 and finite)", mean, sigma);
    std::vector<double *> bl{ x };
    p->problem.AddResidualBlock(new PriorCost(n, i, mean, sigma), nullptr, bl);
    p->nresiduals += 1;
    return true;
}

fit_options_t fit_defaults(void)
{
    fit_options_t o;
    o.max_iterations = 200;
    o.function_tolerance = 1e-10;
    o.parameter_tolerance = 1e-10;
    o.gradient_tolerance = 1e-12;
    o.threads = 0;
    o.verbose = false;
    return o;
}

static int cores(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

bool fit_solve(fit_problem_t *p, const fit_options_t *opt, fit_summary_t *s)
{
    fit_options_t o = opt ? *opt : fit_defaults();
    fit_summary_t out;
    memset(&out, 0, sizeof out);
    if (!p) {
        if (s) *s = out;
        return fail("fit_solve: NULL problem");
    }
    ceres::Solver::Options so;
    int nparam = 0;
    for (auto &kv : p->sizes) nparam += kv.second;
    so.linear_solver_type = nparam <= 400 ? ceres::DENSE_QR : ceres::SPARSE_NORMAL_CHOLESKY;
    std::string why;
    if (!so.IsValid(&why)) so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o.max_iterations;
    so.function_tolerance = o.function_tolerance;
    so.parameter_tolerance = o.parameter_tolerance;
    so.gradient_tolerance = o.gradient_tolerance;
    so.num_threads = o.threads > 0 ? o.threads : cores();
    so.minimizer_progress_to_stdout = o.verbose;
    so.logging_type = o.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
    ceres::Solver::Summary sum;
    try {
        ceres::Solve(so, &p->problem, &sum);
    } catch (const std::exception &e) {
        if (s) *s = out;
        return fail("fit_solve: %s", e.what());
    }
    // Ceres projects steps onto the bounds, which stalls the free parameters
    // while one sits at an active bound. Fix the parameters at an active
    // bound (the cost falls outward), solve the rest again, then free them.
    if (sum.IsSolutionUsable()) {
        std::vector<double *> order;
        for (auto &kv : p->sizes) order.push_back(kv.first);
        ceres::Problem::EvaluateOptions eo;
        eo.parameter_blocks = order;
        double cost = 0;
        std::vector<double> grad;
        bool any = false;
        std::map<double *, std::vector<int>> active;
        // The gradient is in the blocks' tangent coordinates: a block with
        // fixed parameters (a subset manifold) has one entry per free
        // parameter, in order.
        size_t total = 0;
        for (double *x : order) total += (size_t)p->problem.ParameterBlockTangentSize(x);
        if (p->problem.Evaluate(eo, &cost, nullptr, &grad, nullptr) && grad.size() == total) {
            size_t off = 0;
            for (double *x : order) {
                int n = p->sizes[x], tn = p->problem.ParameterBlockTangentSize(x);
                if (!p->problem.IsParameterBlockConstant(x)) {
                    int j = 0;
                    for (int i = 0; i < n; i++) {
                        bool fixed_i = tn < n && p->fixed[x][i];
                        if (fixed_i) continue;
                        int gi = tn < n ? j++ : i;
                        if (p->fixed[x][i] || gi >= tn) continue;
                        double lo = p->problem.GetParameterLowerBound(x, i), hi = p->problem.GetParameterUpperBound(x, i);
                        double g = grad[off + (size_t)gi], tol = 1e-12 * std::fmax(1.0, std::fabs(x[i]));
                        if ((x[i] <= lo + tol && g > 0) || (x[i] >= hi - tol && g < 0)) {
                            active[x].push_back(i);
                            any = true;
                        }
                    }
                }
                off += (size_t)tn;
            }
        }
        if (any) {
            for (auto &kv : active) {
                double *x = kv.first;
                int n = p->sizes[x];
                std::vector<int> idx;
                for (int i = 0; i < n; i++)
                    if (p->fixed[x][i] || std::find(kv.second.begin(), kv.second.end(), i) != kv.second.end())
                        idx.push_back(i);
                if ((int)idx.size() == n) p->problem.SetParameterBlockConstant(x);
                else p->problem.SetManifold(x, new ceres::SubsetManifold(n, idx));
            }
            ceres::Solver::Summary sum2;
            try {
                ceres::Solve(so, &p->problem, &sum2);
            } catch (const std::exception &e) {
                if (s) *s = out;
                return fail("fit_solve: %s", e.what());
            }
            for (auto &kv : active) {   // restore the caller's masks
                double *x = kv.first;
                std::vector<bool> f = p->fixed[x];
                bool all = true;
                for (bool b : f) all = all && b;
                if (all) continue;
                p->problem.SetParameterBlockVariable(x);
                std::vector<int> idx;
                for (int i = 0; i < (int)f.size(); i++)
                    if (f[i]) idx.push_back(i);
                p->problem.SetManifold(x, idx.empty() ? nullptr : new ceres::SubsetManifold((int)f.size(), idx));
            }
            double t = sum.total_time_in_seconds + sum2.total_time_in_seconds;
            size_t it = sum.iterations.size() + sum2.iterations.size();
            double c0 = sum.initial_cost;
            sum = sum2;
            sum.initial_cost = c0;
            sum.total_time_in_seconds = t;
            sum.iterations.resize(it);
        }
    }
    out.iterations = (int)sum.iterations.size();
    out.initial_cost = sum.initial_cost;
    out.final_cost = sum.final_cost;
    out.nresiduals = p->nresiduals;
    out.nparameters = nparam;
    int nfree = 0;
    for (auto &kv : p->sizes) {
        if (p->problem.IsParameterBlockConstant(kv.first)) continue;
        for (bool f : p->fixed[kv.first]) nfree += !f;
    }
    out.nfree = nfree;
    out.converged = sum.termination_type == ceres::CONVERGENCE || sum.termination_type == ceres::USER_SUCCESS;
    out.usable = sum.IsSolutionUsable();
    snprintf(out.termination, sizeof out.termination, "%s", ceres::TerminationTypeToString(sum.termination_type));
    snprintf(out.message, sizeof out.message, "%s", sum.message.c_str());
    out.time_s = sum.total_time_in_seconds;
    if (s) *s = out;
    if (!out.usable) return fail("fit_solve: no usable solution (%s: %s)", out.termination, out.message);
    return true;
}

bool fit_covariance_cross(fit_problem_t *p, double *x, double *y, double *cov)
{
    if (!known(p, x, "fit_covariance") || !known(p, y, "fit_covariance")) return false;
    ceres::Covariance::Options co;
    int nparam = 0;
    for (auto &kv : p->sizes) nparam += kv.second;
    co.algorithm_type = nparam <= 1000 ? ceres::DENSE_SVD : ceres::SPARSE_QR;
    co.null_space_rank = 0;
    co.min_reciprocal_condition_number = 1e-14;
    co.num_threads = cores();
    ceres::Covariance c(co);
    std::vector<std::pair<const double *, const double *>> pairs{ { x, y } };
    bool ok;
    try {
        ok = c.Compute(pairs, &p->problem);
    } catch (const std::exception &e) {
        return fail("fit_covariance: %s", e.what());
    }
    if (!ok)
        return fail("fit_covariance: J^T J is rank deficient or ill-conditioned in the free parameters "
                    "(a parameter the data do not constrain: fix it or add a prior)");
    if (!c.GetCovarianceBlock(x, y, cov)) return fail("fit_covariance: the covariance block is not available");
    return true;
}

bool fit_covariance(fit_problem_t *p, double *x, double *cov) { return fit_covariance_cross(p, x, x, cov); }

bool fit_check_jacobian(fit_residual_fn fn, void *ctx, int nres, int nblocks, const int *sizes, double *const *blocks,
                        double h_rel, double tol_abs, double tol_rel, double *max_abs_err)
{
    std::vector<double> r0(nres), rp(nres), rm(nres);
    std::vector<std::vector<double>> J(nblocks);
    std::vector<double *> jp(nblocks);
    for (int k = 0; k < nblocks; k++) {
        J[k].assign((size_t)nres * sizes[k], 0.0);
        jp[k] = J[k].data();
    }
    const double *const *params = blocks;
    if (!fn(ctx, params, r0.data(), jp.data())) return fail("fit_check_jacobian: the residual callback failed");
    bool ok = true;
    double worst = 0;
    for (int k = 0; k < nblocks; k++) {
        for (int i = 0; i < sizes[k]; i++) {
            double x0 = blocks[k][i], h = h_rel * std::fmax(std::fabs(x0), 1.0);
            blocks[k][i] = x0 + h;
            bool a = fn(ctx, params, rp.data(), nullptr);
            blocks[k][i] = x0 - h;
            bool b = fn(ctx, params, rm.data(), nullptr);
            blocks[k][i] = x0;
            if (!a || !b) return fail("fit_check_jacobian: the residual callback failed at a step of block %d[%d]", k, i);
            for (int r = 0; r < nres; r++) {
                double num = (rp[r] - rm[r]) / (2 * h), an = J[k][(size_t)r * sizes[k] + i];
                double e = std::fabs(an - num);
                worst = std::fmax(worst, e);
                if (!(e <= tol_abs + tol_rel * std::fabs(num))) {
                    if (ok)
                        fail("fit_check_jacobian: d r[%d] / d block %d[%d]: analytic %.9g, central difference %.9g", r,
                             k, i, an, num);
                    ok = false;
                }
            }
        }
    }
    if (max_abs_err) *max_abs_err = worst;
    return ok;
}

}  // extern "C"
