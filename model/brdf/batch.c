// model/brdf/batch.c — model_brdf_eval_n: the reflection models of
// model/brdf/brdf.c for many samples at once. GGX has its own branch-free loop
// (the same formulas as brdf.c's d_ggx, g_smith_ggx and f_schlick, every
// quantity computed and then selected) that the compiler vectorises; this
// file is built with -fno-math-errno -fno-trapping-math (Makefile) so sqrt
// and the selects vectorise, and cloned for AVX-512, AVX2 and the baseline
// where the compiler supports it. Tests compare it with model_brdf_eval.
#include <math.h>
#include <stddef.h>

#include "model/model.h"

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define REFL_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define REFL_CLONES
#endif

// GGX: R = kd/pi n.l + ks D G2 F / (4 n.v), 0 where n.l <= 0 or n.v <= 0;
// D = 0 where n.h <= 0, G2 = 0 where v.h <= 0. want: the 4 derivatives too.
static inline __attribute__((always_inline)) void ggx_loop(const double *p, const model_cosines_t *c, int n,
                                                            double *restrict R, double *restrict g, int want)
{
    const double kd = p[0], ks = p[1], a = p[2], F0 = p[3], a2 = a * a, ip = 1 / M_PI;
    for (int i = 0; i < n; i++) {
        double nl = c[i].nl, nv = c[i].nv, nh = c[i].nh, vh = c[i].vh;
        int ok = (nl > 0) & (nv > 0);
        // distribution
        double c2 = nh * nh, q = c2 * (a2 - 1) + 1, iq = 1 / q;
        double D0 = a2 * ip * iq * iq, dD0 = 2 * a * (q - 2 * a2 * c2) * ip * iq * iq * iq;
        double D = nh > 0 ? D0 : 0, dD = nh > 0 ? dD0 : 0;
        // height-correlated Smith masking-shadowing
        double nl2 = nl * nl, nv2 = nv * nv, tl0 = (1 - nl2) / nl2, tv0 = (1 - nv2) / nv2;
        double tl = tl0 > 0 ? tl0 : 0, tv = tv0 > 0 ? tv0 : 0;
        double sl = sqrt(1 + a2 * tl), sv = sqrt(1 + a2 * tv);
        double G0 = 1 / (1 + (sl - 1) / 2 + (sv - 1) / 2);
        double dG0 = -G0 * G0 * (tl / (4 * sl) + tv / (4 * sv)) * 2 * a;
        double G = vh > 0 ? G0 : 0, dG = vh > 0 ? dG0 : 0;
        // Schlick Fresnel
        double x = 1 - vh, x5 = x * x * x * x * x, F = F0 + (1 - F0) * x5;
        double s = 1 / (4 * nv);
        double r = kd * ip * nl + ks * D * G * F * s;
        double g0 = nl * ip, g1 = D * G * F * s, g2 = ks * (dD * G + D * dG) * F * s, g3 = ks * D * G * (1 - x5) * s;
        R[i] = ok ? r : 0;
        if (want) {
            g[4 * i + 0] = ok ? g0 : 0;
            g[4 * i + 1] = ok ? g1 : 0;
            g[4 * i + 2] = ok ? g2 : 0;
            g[4 * i + 3] = ok ? g3 : 0;
        }
    }
}

REFL_CLONES static void ggx_values(const double *p, const model_cosines_t *c, int n, double *R)
{
    ggx_loop(p, c, n, R, NULL, 0);
}

REFL_CLONES static void ggx_values_derivatives(const double *p, const model_cosines_t *c, int n, double *R, double *g)
{
    ggx_loop(p, c, n, R, g, 1);
}

void model_brdf_eval_n(model_brdf_t m, const double *p, const model_cosines_t *c, int n, double *R, double *dR_dp)
{
    if (m == MODEL_BRDF_GGX) {
        if (dR_dp) ggx_values_derivatives(p, c, n, R, dR_dp);
        else ggx_values(p, c, n, R);
        return;
    }
    int np = model_brdf_nparams(m);
    for (int i = 0; i < n; i++) R[i] = model_brdf_eval(m, p, &c[i], dR_dp ? dR_dp + (size_t)i * np : NULL);
}
