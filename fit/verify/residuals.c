// fit/verify/residuals.c — a reference point's residual and its Jacobian, one at a
// time and in groups with the robust (Cauchy) transform.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

// One point's residual and its Jacobian rows (each jac[b] may be NULL).
// blocks: kc (1), s (nl_all), Pa (1), p (np), rho (1), and with a second
// material (rc2) its p2 (rc2->np).
static double point_eval(const res_ctx_t *rc, const res_ctx_t *rc2, int k, const double *const *par,
                         double *const *jac)
{
    const pt_t *p = &rc->pt[k];
    double kc = par[0][0], Pa = par[2][0], rho = par[4][0];
    const double *s = par[1], *mp = par[3], *mp2 = rc2 ? par[5] : NULL;
    double *j3 = jac ? jac[3] : NULL, *j5 = jac && rc2 ? jac[5] : NULL;
    double S = 0, T = 0, dS_dp[MODEL_BRDF_MAX_PARAMS] = { 0 }, dS_dp2[MODEL_BRDF_MAX_PARAMS] = { 0 };
    double dR[MODEL_BRDF_MAX_PARAMS], dS_ds[MAX_LAMPS] = { 0 };
    for (int j = 0; j < p->nl; j++) {
        int e = p->first + j, i = rc->lamp[e];
        bool second = rc2 && rc->sec[e];
        const res_ctx_t *r = second ? rc2 : rc;
        double *dsp = second ? dS_dp2 : dS_dp;
        bool want = second ? j5 != NULL : j3 != NULL;
        double R = rc->reference ? model_brdf_eval(r->model, second ? mp2 : mp, &rc->cs[e].c, want ? dR : NULL)
                                  : model_brdf_eval_prepared(r->model, second ? mp2 : mp, &rc->cs[e], want ? dR : NULL);
        double wr = rc->w[e] * R;
        S += s[i] * wr;
        T += s[i] * rc->b[e];
        dS_ds[i] += wr + rho * rc->b[e];
        if (want)
            for (int q = 0; q < r->np; q++) dsp[q] += s[i] * rc->w[e] * dR[q];
    }
    double inv = 1 / p->sigma, ec = p->Eg * kc;
    if (jac && jac[0]) jac[0][0] = p->Eg * (S + rho * T) * inv;
    if (jac && jac[1])
        for (int i = 0; i < rc->nl_all; i++) jac[1][i] = ec * dS_ds[i] * inv;
    if (jac && jac[2]) jac[2][0] = inv;
    if (j3)
        for (int q = 0; q < rc->np; q++) j3[q] = ec * dS_dp[q] * inv;
    if (jac && jac[4]) jac[4][0] = ec * T * inv;
    if (j5)
        for (int q = 0; q < rc2->np; q++) j5[q] = ec * dS_dp2[q] * inv;
    return (Pa + ec * (S + rho * T) - p->meas) * inv;
}

bool verify_residual_fn(void *vctx, const double *const *par, double *res, double **jac)
{
    const res_item_t *it = vctx;
    res[0] = point_eval(it->rc, it->rc2, it->k, par, jac);
    return isfinite(res[0]);
}

bool verify_group_fn(void *vctx, const double *const *par, double *res, double **jac)
{
    const res_group_t *g = vctx;
    const int nl = g->rc->nl_all, np = g->rc->np, nb = g->rc2 ? 6 : 5;
    const int size[6] = { 1, nl, 1, np, 1, g->rc2 ? g->rc2->np : 0 };
    for (int t = 0; t < g->n; t++) {
        double *row[6] = { NULL };
        for (int b = 0; b < nb; b++) row[b] = jac && jac[b] ? jac[b] + (size_t)t * size[b] : NULL;
        double r = point_eval(g->rc, g->rc2, g->k[t], par, row);
        if (!isfinite(r)) return false;
        if (g->b > 0) {
            // the same r again (the solver's Jacobian at an accepted candidate): its image is kept
            pt_t *p = &g->rc->pt[g->k[t]];
            bool same = !g->rc->reference && r == p->r_last && signbit(r) == signbit(p->r_last);
            double s2 = r * r, rr = same ? p->rr_last : copysign(sqrt(g->b * log1p(s2 / g->b)), r);
            p->r_last = r;
            p->rr_last = rr;
            double f = fabs(r) > 1e-12 ? r / (1 + s2 / g->b) / rr : 1;
            for (int b = 0; b < nb; b++)
                if (row[b])
                    for (int q = 0; q < size[b]; q++) row[b][q] *= f;
            r = rr;
        }
        res[t] = r;
    }
    return true;
}
