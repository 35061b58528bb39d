// fit/verify/selfcheck.c — the fit's residual Jacobian against central differences,
// for every reflection model (tests).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

// Parameters of model m for the Jacobian check: its defaults, moved off the bounds.
static void check_params(model_brdf_t m, double *mp)
{
    for (int j = 0; j < model_brdf_nparams(m); j++) {
        double lo, hi;
        model_brdf_param_range(m, j, &lo, &hi);
        double dflt = model_brdf_param_default(m, j);
        const char *pn = model_brdf_param_name(m, j);
        mp[j] = isfinite(dflt) ? dflt : 0.3;
        if (mp[j] <= lo) mp[j] = lo + 0.1;
        if (!strcmp(pn, "ns")) mp[j] = 12;
        if (!strcmp(pn, "alpha") || !strcmp(pn, "m")) mp[j] = 0.3;
        if (!strcmp(pn, "F0")) mp[j] = 0.05;
    }
}

// For every model: a plain point (3 lamps) and a window near an edge with a
// second material (the next model; two parts, so each lamp twice).
bool verify_check_jacobian(double *max_abs_err)
{
    model_rng_t rng = model_rng(77, 1);
    bool ok = true;
    if (max_abs_err) *max_abs_err = 0;
    for (int m = 0; m < MODEL_BRDF_COUNT; m++)
        for (int mixed = 0; mixed < 2; mixed++) {
            const int nl = 3, nt = mixed ? 2 * nl : nl;
            model_brdf_t m1 = (model_brdf_t)m, m2 = (model_brdf_t)((m + 1) % MODEL_BRDF_COUNT);
            pt_t p = { .meas = 900, .sigma = 3, .Eg = 6000 * 1.02, .mat = 0, .mat2 = mixed ? 1 : -1, .nl = nt,
                       .first = 0, .r_last = NAN };
            model_brdf_prep_t cs[6];
            double w[6], b[6];
            int lamp[6] = { 0, 1, 2, 0, 1, 2 };
            uint8_t sec[6] = { 0, 0, 0, 1, 1, 1 };
            for (int i = 0; i < nt; i++) {
                model_vec3_t n = i < nl ? v3(0, 0, 1) : v3_unit(v3(0.2, 0, 1));
                double a = 2 * M_PI * model_rng_uniform(&rng), t = 0.1 + 1.2 * model_rng_uniform(&rng);
                model_vec3_t l = v3(sin(t) * cos(a), sin(t) * sin(a), cos(t)), v = v3_unit(v3(0.3, -0.2, 0.9));
                model_cosines_t c = model_cosines(n, l, v);
                cs[i] = model_brdf_prepare(&c);
                w[i] = 3e5 * 1e-6 * (0.5 + model_rng_uniform(&rng)) * (mixed ? 0.5 : 1);
                b[i] = 0.02 * model_rng_uniform(&rng);
            }
            res_ctx_t rc = { .pt = &p, .cs = cs, .w = w, .b = b, .lamp = lamp, .sec = sec, .model = m1,
                             .np = model_brdf_nparams(m1), .nl_all = nl };
            res_ctx_t rc2 = rc;
            rc2.model = m2;
            rc2.np = model_brdf_nparams(m2);
            int k[1] = { 0 };
            res_group_t g = { .rc = &rc, .rc2 = mixed ? &rc2 : NULL, .k = k, .n = 1, .b = 9 };
            double kc = 0.97, s[3] = { 1.02, 0.95, 1.1 }, Pa = 3, rho = 0.8;
            double mp[MODEL_BRDF_MAX_PARAMS], mp2[MODEL_BRDF_MAX_PARAMS];
            check_params(m1, mp);
            check_params(m2, mp2);
            double *blocks[6] = { &kc, s, &Pa, mp, &rho, mp2 };
            int sizes[6] = { 1, nl, 1, rc.np, 1, rc2.np };
            double err = 0;
            ok = lsq_check_jacobian(verify_group_fn, &g, 1, mixed ? 6 : 5, sizes, blocks, 1e-6, 1e-6, 1e-4, &err) && ok;
            if (max_abs_err && err > *max_abs_err) *max_abs_err = err;
        }
    return ok;
}
