// calib/lamps/bundle.c — the joint fit (a bundle adjustment) of the lamps and the
// sphere's path over every highlight (calib_lamps_bundle): the path's model,
// the residual of one highlight and its Jacobians, the weights that map it
// back to the camera ray, and the rounds of the solver.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"
#include "model/base/lsq.h"

void lamps_bundle_centre(const calib_lamps_bundle_setup_t *S, double angle_deg, const double *g, double s[3],
                         double ds_dg[21])
{
    double th = angle_deg * M_PI / 180, ct = cos(th), st = sin(th);
    double a0 = S->c0_mm[0] + g[0], a1 = S->c0_mm[1] + g[1], a2 = S->c0_mm[2] + g[2];
    double s0[3] = { ct * a0 - st * a1, st * a0 + ct * a1, a2 };
    double wx = 1e-3 * g[5], wy = 1e-3 * g[6];
    // s = s0 + w x s0 + shift, w = (wx, wy, 0)
    s[0] = s0[0] + wy * s0[2] + g[3];
    s[1] = s0[1] - wx * s0[2] + g[4];
    s[2] = s0[2] + wx * s0[1] - wy * s0[0];
    if (ds_dg) {
        // d s0 / d offset = Rz; d s / d s0 = I + [w]x
        const double Rz[9] = { ct, -st, 0, st, ct, 0, 0, 0, 1 };
        const double M[9] = { 1, 0, wy, 0, 1, -wx, -wy, wx, 1 };
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++)
                ds_dg[i * 7 + j] = M[i * 3] * Rz[j] + M[i * 3 + 1] * Rz[3 + j] + M[i * 3 + 2] * Rz[6 + j];
            ds_dg[i * 7 + 3] = i == 0;
            ds_dg[i * 7 + 4] = i == 1;
        }
        ds_dg[0 * 7 + 5] = 0;
        ds_dg[1 * 7 + 5] = -1e-3 * s0[2];
        ds_dg[2 * 7 + 5] = 1e-3 * s0[1];
        ds_dg[0 * 7 + 6] = 1e-3 * s0[2];
        ds_dg[1 * 7 + 6] = 0;
        ds_dg[2 * 7 + 6] = -1e-3 * s0[0];
    }
}

bool calib_lamps_bundle_residual(void *vctx, const double *const *P, double *res, double **jac)
{
    const calib_lamps_bundle_ctx_t *cx = vctx;
    const calib_lamps_bundle_setup_t *S = cx->setup;
    const double *X = P[0], *g = P[1], r = S->radius_mm, isg = 1 / cx->sigma_rad;
    double s[3], dsdg[21];
    lamps_bundle_centre(S, cx->obs.angle_deg, g, s, dsdg);
    const double C[3] = { S->camera_mm.x, S->camera_mm.y, S->camera_mm.z };
    const double d[3] = { cx->obs.ray.x, cx->obs.ray.y, cx->obs.ray.z };
    double oc[3], pp[3], n[3], u[3], w[3], ul[3];
    for (int i = 0; i < 3; i++) oc[i] = C[i] - s[i];
    double b = d[0] * oc[0] + d[1] * oc[1] + d[2] * oc[2];
    double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r, disc = b * b - cc;
    if (!(disc > 0)) return false;   // the ray misses the sphere at these parameters
    double sq = sqrt(disc), t = -b - sq;
    if (!(t > 0)) return false;
    for (int i = 0; i < 3; i++) {
        pp[i] = C[i] + t * d[i];
        n[i] = (pp[i] - s[i]) / r;
    }
    double dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
    for (int i = 0; i < 3; i++) {
        u[i] = d[i] - 2 * dn * n[i];
        w[i] = X[i] - pp[i];
    }
    double wl = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (!(wl > 1e-9)) return false;
    double r3[3];
    for (int i = 0; i < 3; i++) {
        ul[i] = w[i] / wl;
        r3[i] = ul[i] - u[i];
    }
    const double *Wm = cx->W;
    for (int i = 0; i < 3; i++) res[i] = (Wm[i * 3] * r3[0] + Wm[i * 3 + 1] * r3[1] + Wm[i * 3 + 2] * r3[2]) * isg;
    if (!jac) return true;
    // d t / d s, d p / d s = d (dt/ds)^T, d n / d s = (dp/ds - I) / r,
    // d u / d s = -2 (n (d^T dn/ds) + (d.n) dn/ds)
    double dtds[3], dpds[9], dnds[9], duds[9], Pl[9];
    for (int k = 0; k < 3; k++) dtds[k] = d[k] - (oc[k] - b * d[k]) / sq;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) {
            dpds[i * 3 + k] = d[i] * dtds[k];
            dnds[i * 3 + k] = (dpds[i * 3 + k] - (i == k)) / r;
            Pl[i * 3 + k] = ((i == k) - ul[i] * ul[k]) / wl;
        }
    for (int k = 0; k < 3; k++) {
        double ddn = d[0] * dnds[k] + d[1] * dnds[3 + k] + d[2] * dnds[6 + k];
        for (int i = 0; i < 3; i++) duds[i * 3 + k] = -2 * (n[i] * ddn + dn * dnds[i * 3 + k]);
    }
    if (jac[0])
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++)
                jac[0][i * 3 + k] = (Wm[i * 3] * Pl[k] + Wm[i * 3 + 1] * Pl[3 + k] + Wm[i * 3 + 2] * Pl[6 + k]) * isg;
    if (jac[1]) {
        double drds[9], wd[9];
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++) {
                double a = 0;
                for (int m = 0; m < 3; m++) a += Pl[i * 3 + m] * dpds[m * 3 + k];
                drds[i * 3 + k] = -a - duds[i * 3 + k];
            }
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++)
                wd[i * 3 + k] = (Wm[i * 3] * drds[k] + Wm[i * 3 + 1] * drds[3 + k] + Wm[i * 3 + 2] * drds[6 + k]) * isg;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 7; j++)
                jac[1][i * 7 + j] = wd[i * 3] * dsdg[j] + wd[i * 3 + 1] * dsdg[7 + j] + wd[i * 3 + 2] * dsdg[14 + j];
    }
    return true;
}

// An orthonormal pair perpendicular to the unit vector a.
static void tangent_pair(const double a[3], double e1[3], double e2[3])
{
    double h[3] = { 0, 0, 0 };
    h[fabs(a[2]) < 0.9 ? 2 : 0] = 1;
    double k = h[0] * a[0] + h[1] * a[1] + h[2] * a[2];
    for (int i = 0; i < 3; i++) e1[i] = h[i] - k * a[i];
    double n = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
    for (int i = 0; i < 3; i++) e1[i] /= n;
    e2[0] = a[1] * e1[2] - a[2] * e1[1];
    e2[1] = a[2] * e1[0] - a[0] * e1[2];
    e2[2] = a[0] * e1[1] - a[1] * e1[0];
}

bool calib_lamps_bundle_weight(calib_lamps_bundle_ctx_t *cx, const double X[3], const double g[7])
{
    (void)X;
    const calib_lamps_bundle_setup_t *S = cx->setup;
    const double r = S->radius_mm;
    double s[3];
    lamps_bundle_centre(S, cx->obs.angle_deg, g, s, NULL);
    const double C[3] = { S->camera_mm.x, S->camera_mm.y, S->camera_mm.z };
    const double d[3] = { cx->obs.ray.x, cx->obs.ray.y, cx->obs.ray.z };
    double oc[3], n[3], u[3];
    for (int i = 0; i < 3; i++) oc[i] = C[i] - s[i];
    double b = d[0] * oc[0] + d[1] * oc[1] + d[2] * oc[2];
    double disc = b * b - (oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r);
    if (!(disc > 0)) return false;
    double sq = sqrt(disc), t = -b - sq;
    if (!(t > 0)) return false;
    for (int i = 0; i < 3; i++) n[i] = (C[i] + t * d[i] - s[i]) / r;
    double dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
    for (int i = 0; i < 3; i++) u[i] = d[i] - 2 * dn * n[i];
    // d t / d d = -oc (1 + b / sq); d p / d d = t I + d (dt/dd)^T; d n / d d = (dp/dd) / r;
    // d u / d d = I - 2 (n (n^T + d^T dn/dd) + (d.n) dn/dd)
    double dtdd[3], dndd[9], A[9];
    for (int k = 0; k < 3; k++) dtdd[k] = -oc[k] * (1 + b / sq);
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) dndd[i * 3 + k] = (t * (i == k) + d[i] * dtdd[k]) / r;
    for (int k = 0; k < 3; k++) {
        double ddn = n[k] + d[0] * dndd[k] + d[1] * dndd[3 + k] + d[2] * dndd[6 + k];
        for (int i = 0; i < 3; i++) A[i * 3 + k] = (i == k) - 2 * (n[i] * ddn + dn * dndd[i * 3 + k]);
    }
    // in the tangent planes: A2 = Tu^T A Td (2x2); W = A2^-1 Tu^T
    double td1[3], td2[3], tu1[3], tu2[3];
    tangent_pair(d, td1, td2);
    tangent_pair(u, tu1, tu2);
    const double *Td[2] = { td1, td2 }, *Tu[2] = { tu1, tu2 };
    double A2[4];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            double a = 0;
            for (int p = 0; p < 3; p++)
                for (int q = 0; q < 3; q++) a += Tu[i][p] * A[p * 3 + q] * Td[j][q];
            A2[i * 2 + j] = a;
        }
    double det = A2[0] * A2[3] - A2[1] * A2[2];
    if (!(fabs(det) > 1e-12)) return false;
    double Ai[4] = { A2[3] / det, -A2[1] / det, -A2[2] / det, A2[0] / det };
    for (int i = 0; i < 2; i++)
        for (int k = 0; k < 3; k++) cx->W[i * 3 + k] = Ai[i * 2] * Tu[0][k] + Ai[i * 2 + 1] * Tu[1][k];
    for (int k = 0; k < 3; k++) cx->W[6 + k] = 0;
    return true;
}

// Largest / smallest eigenvalue of a symmetric positive matrix (n <= 7) by Jacobi rotations.
static double cond_sym(const double *m, int n)
{
    double a[49];
    memcpy(a, m, sizeof *a * (size_t)(n * n));
    model_sym_eigen(n, a, NULL);
    double lo = INFINITY, hi = 0;
    for (int i = 0; i < n; i++) {
        lo = fmin(lo, a[i * n + i]);
        hi = fmax(hi, a[i * n + i]);
    }
    return lo > 0 ? hi / lo : INFINITY;
}

bool calib_lamps_bundle(const calib_lamps_obs_t *obs, int nobs, int nl, const calib_lamps_bundle_setup_t *S,
                        double *x_mm, double *cov_mm2, double *obs_angle, calib_lamps_bundle_t *out)
{
    memset(out, 0, sizeof *out);
    if (nl < 1 || nl > 64) {
        model_error_set(NULL, 0, "the joint fit takes 1 to 64 lamps (%d given)", nl);
        return false;
    }
    int cnt[64] = { 0 };
    for (int i = 0; i < nobs; i++)
        if (obs[i].lamp >= 0 && obs[i].lamp < nl) cnt[obs[i].lamp]++;
    for (int l = 0; l < nl; l++)
        if (cnt[l] < 3) {
            model_error_set(NULL, 0, "lamp %d has %d rays in the joint fit: a position needs at least 3", l, cnt[l]);
            return false;
        }
    calib_lamps_bundle_ctx_t *ctx = calloc((size_t)nobs, sizeof *ctx);
    lsq_problem_t *pr = lsq_problem_new();
    double *g = out->sphere;
    bool ok = false;
    if (!ctx || !pr) {
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
    for (int l = 0; l < nl; l++)
        if (!lsq_add_parameters(pr, x_mm + 3 * l, 3)) goto fail;
    if (!lsq_add_parameters(pr, g, 7)) goto fail;
    bool fixed[7];
    double prior[7];
    for (int k = 0; k < 7; k++) {
        prior[k] = k < 3 ? S->offset_prior_mm : k < 5 ? S->shift_prior_mm : S->tilt_prior_mrad;
        fixed[k] = !(prior[k] > 0);
    }
    if (!lsq_set_fixed(pr, g, fixed)) goto fail;
    for (int k = 0; k < 7; k++)
        if (!fixed[k] && !lsq_add_prior(pr, g, k, k < 3 ? S->offset_prior_mean_mm[k] : 0, prior[k])) goto fail;
    for (int i = 0; i < nobs; i++) {
        ctx[i].setup = S;
        ctx[i].obs = obs[i];
        ctx[i].sigma_rad = 1e-3;
        for (int k = 0; k < 9; k++) ctx[i].W[k] = k % 4 == 0;
        if (S->image_weights && !calib_lamps_bundle_weight(&ctx[i], x_mm + 3 * obs[i].lamp, g)) {
            model_error_set(NULL, 0, "the joint fit: a highlight's camera ray misses the sphere");
            goto done;
        }
        double *blocks[2] = { x_mm + 3 * obs[i].lamp, g };
        if (!lsq_add_residual(pr, calib_lamps_bundle_residual, &ctx[i], 3, 2, blocks, LSQ_LOSS_NONE, 0)) goto fail;
    }
    // rounds: solve, then each lamp's angular sigma from its residuals (dof
    // 2 per ray less its 3 and its share of the sphere's), solve again
    for (int round = 0; round < 4; round++) {
        lsq_options_t fo = lsq_defaults();
        fo.threads = 1;
        lsq_summary_t sm;
        if (!lsq_solve(pr, &fo, &sm)) {
            model_error_set(NULL, 0, "the joint fit of lamps and sphere failed: %s", sm.message);
            goto done;
        }
        out->iterations += sm.iterations;
        double ss[64] = { 0 };
        for (int i = 0; i < nobs; i++) {
            double rr[3];
            const double *pb[2] = { x_mm + 3 * obs[i].lamp, g };
            if (!calib_lamps_bundle_residual(&ctx[i], pb, rr, NULL)) {
                model_error_set(NULL, 0, "the joint fit: a highlight's ray misses the fitted sphere");
                goto done;
            }
            double a2 = (rr[0] * rr[0] + rr[1] * rr[1] + rr[2] * rr[2]) * ctx[i].sigma_rad * ctx[i].sigma_rad;
            if (!S->image_weights) a2 *= 1;
            ss[obs[i].lamp] += a2;
            if (obs_angle) obs_angle[i] = sqrt(a2);
        }
        int nfree_g = 0;
        for (int k = 0; k < 7; k++) nfree_g += !fixed[k];
        double change = 0;
        for (int l = 0; l < nl; l++) {
            double dof = 2.0 * cnt[l] - 3 - (double)nfree_g * cnt[l] / nobs;
            double sg = sqrt(ss[l] / (dof > 1 ? dof : 1));
            out->rms_rad[l] = sqrt(ss[l] / cnt[l]);
            if (!(sg > 1e-7)) sg = 1e-7;
            change = fmax(change, fabs(log(sg / (out->sigma_rad[l] > 0 ? out->sigma_rad[l] : 1e-3))));
            out->sigma_rad[l] = sg;
        }
        for (int i = 0; i < nobs; i++) {
            ctx[i].sigma_rad = out->sigma_rad[obs[i].lamp];
            if (S->image_weights && !calib_lamps_bundle_weight(&ctx[i], x_mm + 3 * obs[i].lamp, g)) {
                model_error_set(NULL, 0, "the joint fit: a highlight's camera ray misses the fitted sphere");
                goto done;
            }
        }
        if (round > 0 && change < 0.01) break;
    }
    for (int l = 0; l < nl; l++)
        if (!lsq_covariance(pr, x_mm + 3 * l, cov_mm2 + 9 * l)) goto fail;
    if (!lsq_covariance(pr, g, out->sphere_cov)) goto fail;
    {
        // observability of the free sphere parameters: the condition of their covariance
        int idx[7], m = 0;
        for (int k = 0; k < 7; k++)
            if (!fixed[k]) idx[m++] = k;
        double sub[49];
        for (int i = 0; i < m; i++)
            for (int j = 0; j < m; j++) sub[i * m + j] = out->sphere_cov[idx[i] * 7 + idx[j]];
        out->cond = m ? cond_sym(sub, m) : 1;
    }
    ok = true;
    goto done;
fail:
    model_error_set(NULL, 0, "the joint fit of lamps and sphere: %s", model_last_error());
done:
    lsq_problem_free(pr);
    free(ctx);
    return ok;
}
