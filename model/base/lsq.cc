// model/base/lsq.cc — model/base/lsq.h on Ceres Solver (2.x): C callbacks become
// ceres::CostFunction objects, masks become SubsetManifolds, priors are
// one-residual blocks, the covariance is ceres::Covariance's (computed
// densely here up to 1000 parameters).
#include "model/base/lsq.h"
#include "model/model.h"

#include <ceres/ceres.h>
#include <glog/logging.h>
#include <Eigen/Dense>

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

bool fail(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
bool fail(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    char msg[1024];
    vsnprintf(msg, sizeof msg, fmt, ap);
    model_error_set(nullptr, 0, "%s", msg);
    va_end(ap);
    return false;
}

class CallbackCost : public ceres::CostFunction {
public:
    CallbackCost(lsq_residual_fn fn, void *ctx, int nres, const std::vector<int> &sizes) : fn_(fn), ctx_(ctx)
    {
        set_num_residuals(nres);
        for (int s : sizes) mutable_parameter_block_sizes()->push_back(s);
    }
    bool Evaluate(double const *const *params, double *residuals, double **jacobians) const override
    {
        return fn_(ctx_, params, residuals, jacobians);
    }

private:
    lsq_residual_fn fn_;
    void *ctx_;
};

// A block of m residuals r(x) with Jacobian J (m x n, n = the parameters it
// reads) shown to Ceres through J's QR factorisation J = Q R: n + 1
// residuals [Q^T r; |(I - Q Q^T) r|] with Jacobian [R; 0]. At every point
// this has the same cost, gradient J^T r and Gauss-Newton matrix J^T J as
// the block itself, so the trust-region steps and the covariance are the
// block's; Ceres's work does not grow with m. Without Jacobians (a cost
// evaluation) it returns [0 ... 0; |r|], the same cost.
class FoldedCost : public ceres::CostFunction {
public:
    FoldedCost(lsq_residual_fn fn, void *ctx, int m, const std::vector<int> &sizes)
        : fn_(fn), ctx_(ctx), m_(m), sizes_(sizes)
    {
        n_ = 0;
        for (int s : sizes) {
            mutable_parameter_block_sizes()->push_back(s);
            n_ += s;
        }
        set_num_residuals(n_ + 1);
    }
    bool Evaluate(double const *const *params, double *residuals, double **jacobians) const override
    {
        thread_local std::vector<double> r, jac;
        thread_local std::vector<double *> jp;
        r.resize((size_t)m_);
        if (!jacobians) {
            if (!fn_(ctx_, params, r.data(), nullptr)) return false;
            double ss = 0;
            for (double v : r) ss += v * v;
            std::fill(residuals, residuals + n_, 0.0);
            residuals[n_] = std::sqrt(ss);
            return true;
        }
        // every block's columns (Q spans them all, so any subset Ceres asks for is exact)
        jac.resize((size_t)m_ * n_);
        jp.resize(sizes_.size());
        size_t off = 0;
        for (size_t b = 0; b < sizes_.size(); b++) {
            jp[b] = jac.data() + off;
            off += (size_t)m_ * sizes_[b];
        }
        if (!fn_(ctx_, params, r.data(), jp.data())) return false;
        // QR of [J r]: its last column holds Q^T r over J's columns, then +-|(I - Q Q^T) r|
        thread_local Eigen::MatrixXd A;
        A.resize(m_, n_ + 1);
        int c0 = 0;
        for (size_t b = 0; b < sizes_.size(); b++) {
            Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> Jb(jp[b], m_,
                                                                                                     sizes_[b]);
            A.middleCols(c0, sizes_[b]) = Jb;
            c0 += sizes_[b];
        }
        A.col(n_) = Eigen::Map<const Eigen::VectorXd>(r.data(), m_);
        Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qr(A);
        int k = std::min(m_, n_);
        for (int i = 0; i < n_; i++) residuals[i] = i < k ? A(i, n_) : 0.0;
        residuals[n_] = m_ > n_ ? std::fabs(A(n_, n_)) : 0.0;
        c0 = 0;
        for (size_t b = 0; b < sizes_.size(); b++) {
            int sb = sizes_[b];
            if (jacobians[b])
                for (int i = 0; i <= n_; i++)
                    for (int j = 0; j < sb; j++)
                        jacobians[b][(size_t)i * sb + j] = (i < k && i <= c0 + j) ? A(i, c0 + j) : 0.0;
            c0 += sb;
        }
        return std::isfinite(residuals[n_]);
    }

private:
    lsq_residual_fn fn_;
    void *ctx_;
    int m_, n_;
    std::vector<int> sizes_;
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
// model_last_error; lsq_options_t.verbose shows the iterations).
static void quiet_logging(void)
{
    static std::once_flag once;
    std::call_once(once, [] {
        FLAGS_minloglevel = 3;
        FLAGS_logtostderr = true;
        if (!google::IsGoogleLoggingInitialized()) google::InitGoogleLogging("refl");
    });
}

struct lsq_problem {
    ceres::Problem problem;
    std::map<double *, int> sizes;          // registered blocks
    std::map<double *, std::vector<bool>> fixed;
    int nresiduals = 0;
};

extern "C" {


lsq_problem_t *lsq_problem_new(void)
{
    quiet_logging();
    try {
        return new lsq_problem;
    } catch (...) {
        fail("out of memory");
        return nullptr;
    }
}

void lsq_problem_free(lsq_problem_t *p) { delete p; }

static bool known(lsq_problem_t *p, double *x, const char *what)
{
    if (!p || !x) return fail("%s: NULL problem or parameter block", what);
    if (!p->sizes.count(x)) return fail("%s: the parameter block %p was not added (lsq_add_parameters)", what, (void *)x);
    return true;
}

bool lsq_add_parameters(lsq_problem_t *p, double *x, int n)
{
    if (!p || !x || n < 1) return fail("lsq_add_parameters: NULL block or size %d < 1", n);
    if (p->sizes.count(x)) return fail("lsq_add_parameters: block %p added twice", (void *)x);
    for (int i = 0; i < n; i++)
        if (!std::isfinite(x[i])) return fail("lsq_add_parameters: starting value %d of the block is %g", i, x[i]);
    p->problem.AddParameterBlock(x, n);
    p->sizes[x] = n;
    p->fixed[x] = std::vector<bool>(n, false);
    return true;
}

bool lsq_set_bounds(lsq_problem_t *p, double *x, int i, double lo, double hi)
{
    if (!known(p, x, "lsq_set_bounds")) return false;
    int n = p->sizes[x];
    if (i < 0 || i >= n) return fail("lsq_set_bounds: parameter %d of a block of %d", i, n);
    if (std::isnan(lo) || std::isnan(hi) || !(lo <= hi)) return fail("lsq_set_bounds: bounds [%g, %g]", lo, hi);
    if (x[i] < lo || x[i] > hi)
        return fail("lsq_set_bounds: starting value %g of parameter %d is outside [%g, %g]", x[i], i, lo, hi);
    if (std::isfinite(lo)) p->problem.SetParameterLowerBound(x, i, lo);
    if (std::isfinite(hi)) p->problem.SetParameterUpperBound(x, i, hi);
    return true;
}

bool lsq_set_fixed(lsq_problem_t *p, double *x, const bool *fixed)
{
    if (!known(p, x, "lsq_set_fixed")) return false;
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

// The checks of a residual block's arguments; its blocks and their sizes.
static bool residual_args(lsq_problem_t *p, lsq_residual_fn fn, int nres, int nblocks, double *const *blocks,
                          const char *what, std::vector<int> &sizes, std::vector<double *> &bl)
{
    if (!p || !fn || nres < 1 || nblocks < 1 || !blocks)
        return fail("%s: NULL problem or callback, %d residuals, %d blocks", what, nres, nblocks);
    for (int k = 0; k < nblocks; k++) {
        if (!known(p, blocks[k], what)) return false;
        sizes.push_back(p->sizes[blocks[k]]);
        bl.push_back(blocks[k]);
    }
    return true;
}

bool lsq_add_residual(lsq_problem_t *p, lsq_residual_fn fn, void *ctx, int nres, int nblocks, double *const *blocks,
                      lsq_loss_t loss, double scale)
{
    std::vector<int> sizes;
    std::vector<double *> bl;
    if (!residual_args(p, fn, nres, nblocks, blocks, "lsq_add_residual", sizes, bl)) return false;
    ceres::LossFunction *lf = nullptr;
    if (loss != LSQ_LOSS_NONE && !(scale > 0 && std::isfinite(scale)))
        return fail("lsq_add_residual: robust loss scale %g must be > 0", scale);
    switch (loss) {
    case LSQ_LOSS_NONE: break;
    case LSQ_LOSS_HUBER: lf = new ceres::HuberLoss(scale); break;
    case LSQ_LOSS_CAUCHY: lf = new ceres::CauchyLoss(scale); break;
    case LSQ_LOSS_SOFT_L1: lf = new ceres::SoftLOneLoss(scale); break;
    default: return fail("lsq_add_residual: unknown loss %d", (int)loss);
    }
    p->problem.AddResidualBlock(new CallbackCost(fn, ctx, nres, sizes), lf, bl);
    p->nresiduals += nres;
    return true;
}

bool lsq_add_residual_folded(lsq_problem_t *p, lsq_residual_fn fn, void *ctx, int nres, int nblocks,
                             double *const *blocks)
{
    std::vector<int> sizes;
    std::vector<double *> bl;
    if (!residual_args(p, fn, nres, nblocks, blocks, "lsq_add_residual_folded", sizes, bl)) return false;
    p->problem.AddResidualBlock(new FoldedCost(fn, ctx, nres, sizes), nullptr, bl);
    p->nresiduals += nres;
    return true;
}

bool lsq_add_prior(lsq_problem_t *p, double *x, int i, double mean, double sigma)
{
    if (!known(p, x, "lsq_add_prior")) return false;
    int n = p->sizes[x];
    if (i < 0 || i >= n) return fail("lsq_add_prior: parameter %d of a block of %d", i, n);
    if (!std::isfinite(mean) || !(sigma > 0) || !std::isfinite(sigma))
        return fail("lsq_add_prior: mean %g, sigma %g (sigma must be > 0 and finite)", mean, sigma);
    std::vector<double *> bl{ x };
    p->problem.AddResidualBlock(new PriorCost(n, i, mean, sigma), nullptr, bl);
    p->nresiduals += 1;
    return true;
}

lsq_options_t lsq_defaults(void)
{
    lsq_options_t o;
    o.max_iterations = 200;
    o.function_tolerance = 1e-10;
    o.parameter_tolerance = 1e-10;
    o.gradient_tolerance = 1e-12;
    o.threads = 0;
    o.verbose = false;
    o.normal_equations = false;
    return o;
}

static int cores(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

// Ceres's options for o; *nparam gets the parameters of every block.
static ceres::Solver::Options solver_options(const lsq_problem_t *p, const lsq_options_t &o, int *nparam)
{
    ceres::Solver::Options so;
    *nparam = 0;
    for (auto &kv : p->sizes) *nparam += kv.second;
    so.linear_solver_type = *nparam > 400           ? ceres::SPARSE_NORMAL_CHOLESKY
                            : o.normal_equations ? ceres::DENSE_NORMAL_CHOLESKY
                                                 : ceres::DENSE_QR;
    std::string why;
    if (!so.IsValid(&why)) so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o.max_iterations;
    so.max_num_line_search_step_size_iterations = 0;
    so.function_tolerance = o.function_tolerance;
    so.parameter_tolerance = o.parameter_tolerance;
    so.gradient_tolerance = o.gradient_tolerance;
    so.num_threads = o.threads > 0 ? o.threads : cores();
    so.minimizer_progress_to_stdout = o.verbose;
    so.logging_type = o.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
    return so;
}

// Whether a free parameter sits at one of its bounds.
static bool any_at_bound(lsq_problem_t *p)
{
    bool at_bound = false;
    for (auto &kv : p->sizes) {
        double *x = kv.first;
        if (p->problem.IsParameterBlockConstant(x)) continue;
        for (int i = 0; i < kv.second; i++) {
            double lo = p->problem.GetParameterLowerBound(x, i), hi = p->problem.GetParameterUpperBound(x, i);
            double tol = 1e-12 * std::fmax(1.0, std::fabs(x[i]));
            at_bound |= !p->fixed[x][i] && (x[i] <= lo + tol || x[i] >= hi - tol);
        }
    }
    return at_bound;
}

// The free parameters at a bound where the cost falls outward (the gradient
// points out of the box), by block; false when there is none.
static bool active_bounds(lsq_problem_t *p, std::map<double *, std::vector<int>> &active)
{
    std::vector<double *> order;
    for (auto &kv : p->sizes) order.push_back(kv.first);
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = order;
    double cost = 0;
    std::vector<double> grad;
    bool any = false;
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
    return any;
}

// Solve again with the active parameters fixed, then restore the caller's
// masks; sum becomes the second solve's summary with the first's initial
// cost, and the two solves' time and iterations. false + message when
// Ceres throws.
static bool solve_with_active_fixed(lsq_problem_t *p, const ceres::Solver::Options &so,
                                    const std::map<double *, std::vector<int>> &active, ceres::Solver::Summary &sum)
{
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
        return fail("lsq_solve: %s", e.what());
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
    return true;
}

// The summary the caller gets from Ceres's.
static lsq_summary_t summary_of(lsq_problem_t *p, const ceres::Solver::Summary &sum, int nparam)
{
    lsq_summary_t out;
    memset(&out, 0, sizeof out);
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
    return out;
}

bool lsq_solve(lsq_problem_t *p, const lsq_options_t *opt, lsq_summary_t *s)
{
    lsq_options_t o = opt ? *opt : lsq_defaults();
    lsq_summary_t out;
    memset(&out, 0, sizeof out);
    if (!p) {
        if (s) *s = out;
        return fail("lsq_solve: NULL problem");
    }
    int nparam;
    ceres::Solver::Options so = solver_options(p, o, &nparam);
    ceres::Solver::Summary sum;
    try {
        ceres::Solve(so, &p->problem, &sum);
        if (o.verbose) model_note("%s", sum.FullReport().c_str());
    } catch (const std::exception &e) {
        if (s) *s = out;
        return fail("lsq_solve: %s", e.what());
    }
    // Ceres projects steps onto the bounds, which stalls the free parameters
    // while one sits at an active bound. Fix the parameters at an active
    // bound (the cost falls outward), solve the rest again, then free them.
    // The gradient is only needed when a free parameter sits at a bound.
    if (sum.IsSolutionUsable() && any_at_bound(p)) {
        std::map<double *, std::vector<int>> active;
        if (active_bounds(p, active) && !solve_with_active_fixed(p, so, active, sum)) {
            if (s) *s = out;
            return false;
        }
    }
    out = summary_of(p, sum, nparam);
    if (s) *s = out;
    if (!out.usable) return fail("lsq_solve: no usable solution (%s: %s)", out.termination, out.message);
    return true;
}

// The covariance as ceres::Covariance's DENSE_SVD computes it (J from
// Problem::Evaluate with the loss applied, in the free blocks' tangent
// coordinates; rank deficient when sigma_min / sigma_max of J is below
// sqrt(1e-14); the inverse of J^T J mapped to the ambient space by each
// block's PlusJacobian; zero for constant blocks), without forming J
// densely: J's rows are folded into an n x n triangular factor R (J = Q R)
// by Householder QR one chunk of rows at a time, and the SVD is R's.
// Ceres's own DENSE_SVD takes the SVD of the whole m x n Jacobian, which
// dominates a fit with a million residuals.
static bool covariance_dense(lsq_problem_t *p, double *x, double *y, double *cov)
{
    std::vector<double *> order;
    std::map<double *, int> col;
    int n = 0;
    for (auto &kv : p->sizes) {
        if (p->problem.IsParameterBlockConstant(kv.first)) continue;
        col[kv.first] = n;
        order.push_back(kv.first);
        n += p->problem.ParameterBlockTangentSize(kv.first);
    }
    int nx = p->sizes[x], ny = p->sizes[y];
    std::fill(cov, cov + (size_t)nx * ny, 0.0);
    if (!col.count(x) || !col.count(y)) return true;   // a constant block has no covariance
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = order;
    eo.num_threads = cores();
    ceres::CRSMatrix J;
    if (!p->problem.Evaluate(eo, nullptr, nullptr, nullptr, &J))
        return fail("lsq_covariance: the residuals could not be evaluated at the solution");
    const int chunk = std::max(4096, 4 * n);
    Eigen::MatrixXd R = Eigen::MatrixXd::Zero(n, n), A(n + chunk, n);
    for (int r0 = 0; r0 < J.num_rows; r0 += chunk) {
        int m = std::min(chunk, J.num_rows - r0);
        A.topRows(n + m).setZero();
        A.topRows(n) = R;
        for (int r = 0; r < m; r++)
            for (int k = J.rows[r0 + r]; k < J.rows[r0 + r + 1]; k++) A(n + r, J.cols[k]) = J.values[k];
        Eigen::HouseholderQR<Eigen::MatrixXd> qr(A.topRows(n + m));
        R = qr.matrixQR().topRows(n).triangularView<Eigen::Upper>();
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullV);
    const Eigen::VectorXd &sv = svd.singularValues();
    if (!(sv(0) > 0) || !(sv(n - 1) / sv(0) >= std::sqrt(1e-14)))
        return fail("lsq_covariance: J^T J is rank deficient or ill-conditioned in the free parameters "
                    "(a parameter the data do not constrain: fix it or add a prior)");
    Eigen::MatrixXd V = svd.matrixV();
    Eigen::MatrixXd C = V * sv.array().square().inverse().matrix().asDiagonal() * V.transpose();
    // ambient = P_x C_xy P_y^T with P the blocks' PlusJacobians (identity without a manifold)
    auto plus_jacobian = [&](double *b, int na) {
        int nt = p->problem.ParameterBlockTangentSize(b);
        Eigen::MatrixXd P = Eigen::MatrixXd::Identity(na, nt);
        const ceres::Manifold *mf = p->problem.GetManifold(b);
        if (mf) {
            std::vector<double> pj((size_t)na * nt);
            mf->PlusJacobian(b, pj.data());
            for (int i = 0; i < na; i++)
                for (int j = 0; j < nt; j++) P(i, j) = pj[(size_t)i * nt + j];
        }
        return P;
    };
    Eigen::MatrixXd Px = plus_jacobian(x, nx), Py = plus_jacobian(y, ny);
    Eigen::MatrixXd Cxy = Px * C.block(col[x], col[y], Px.cols(), Py.cols()) * Py.transpose();
    for (int i = 0; i < nx; i++)
        for (int j = 0; j < ny; j++) cov[(size_t)i * ny + j] = Cxy(i, j);
    return true;
}

// ceres::Covariance itself (SPARSE_QR above 1000 parameters; DENSE_SVD is
// what covariance_dense computes).
static bool covariance_ceres(lsq_problem_t *p, double *x, double *y, double *cov, bool dense)
{
    ceres::Covariance::Options co;
    co.algorithm_type = dense ? ceres::DENSE_SVD : ceres::SPARSE_QR;
    co.null_space_rank = 0;
    co.min_reciprocal_condition_number = 1e-14;
    co.num_threads = cores();
    ceres::Covariance c(co);
    std::vector<std::pair<const double *, const double *>> pairs{ { x, y } };
    bool ok;
    try {
        ok = c.Compute(pairs, &p->problem);
    } catch (const std::exception &e) {
        return fail("lsq_covariance: %s", e.what());
    }
    if (!ok)
        return fail("lsq_covariance: J^T J is rank deficient or ill-conditioned in the free parameters "
                    "(a parameter the data do not constrain: fix it or add a prior)");
    if (!c.GetCovarianceBlock(x, y, cov)) return fail("lsq_covariance: the covariance block is not available");
    return true;
}

bool lsq_covariance_cross(lsq_problem_t *p, double *x, double *y, double *cov)
{
    if (!known(p, x, "lsq_covariance") || !known(p, y, "lsq_covariance")) return false;
    int nparam = 0;
    for (auto &kv : p->sizes) nparam += kv.second;
    try {
        return nparam <= 1000 ? covariance_dense(p, x, y, cov) : covariance_ceres(p, x, y, cov, false);
    } catch (const std::exception &e) {
        return fail("lsq_covariance: %s", e.what());
    }
}

bool lsq_covariance_reference(lsq_problem_t *p, double *x, double *y, double *cov)
{
    if (!known(p, x, "lsq_covariance") || !known(p, y, "lsq_covariance")) return false;
    return covariance_ceres(p, x, y, cov, true);
}

bool lsq_covariance(lsq_problem_t *p, double *x, double *cov) { return lsq_covariance_cross(p, x, x, cov); }

bool lsq_check_jacobian(lsq_residual_fn fn, void *ctx, int nres, int nblocks, const int *sizes, double *const *blocks,
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
    if (!fn(ctx, params, r0.data(), jp.data())) return fail("lsq_check_jacobian: the residual callback failed");
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
            if (!a || !b) return fail("lsq_check_jacobian: the residual callback failed at a step of block %d[%d]", k, i);
            for (int r = 0; r < nres; r++) {
                double num = (rp[r] - rm[r]) / (2 * h), an = J[k][(size_t)r * sizes[k] + i];
                double e = std::fabs(an - num);
                worst = std::fmax(worst, e);
                if (!(e <= tol_abs + tol_rel * std::fabs(num))) {
                    if (ok)
                        fail("lsq_check_jacobian: d r[%d] / d block %d[%d]: analytic %.9g, central difference %.9g", r,
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
