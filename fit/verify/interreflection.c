// fit/verify/interreflection.c — one diffuse bounce of each lamp's light at a set of
// points: the fit's interreflection basis B and its Monte Carlo error.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

typedef struct {
    const model_tracer_t *t;
    const model_lamps_t *lamps;
    const model_material_t *const *mats;
    int N;
    const model_pixel_info_t *pi;
    const int *idx;   // indices into pi (NULL: 0..n-1)
    float *B;         // per index into pi: nl values
    uint64_t seed;
    float *Bsd;       // as B: the estimate's standard error (NULL: not wanted)
} ir_ctx_t;

static double radical_inverse2(uint32_t i)
{
    i = (i << 16) | (i >> 16);
    i = ((i & 0x55555555u) << 1) | ((i & 0xAAAAAAAAu) >> 1);
    i = ((i & 0x33333333u) << 2) | ((i & 0xCCCCCCCCu) >> 2);
    i = ((i & 0x0F0F0F0Fu) << 4) | ((i & 0xF0F0F0F0u) >> 4);
    i = ((i & 0x00FF00FFu) << 8) | ((i & 0xFF00FF00u) >> 8);
    return i * 0x1p-32;
}

// B_ik = (pi / N) sum_j f_x(w_j, v) sum over lamp i: V_yi R_y(l_yi, -w_j) E_i(y) / d_yi^2, w_j cosine-weighted
// (E_i: lamp i's emission pattern, model_lamp_emission).
static void ir_rows(void *vctx, int begin, int end, int thread)
{
    (void)thread;
    ir_ctx_t *c = vctx;
    const int nl = c->lamps->n, N = c->N;
    double eps = 4 * model_tracer_epsilon_mm(c->t);
    for (int k = begin; k < end; k++) {
        int g = c->idx ? c->idx[k] : k;
        const model_pixel_info_t *pi = &c->pi[g];
        float *B = &c->B[(size_t)g * nl], *Bsd = c->Bsd ? &c->Bsd[(size_t)g * nl] : NULL;
        for (int i = 0; i < nl; i++) B[i] = 0;
        for (int i = 0; Bsd && i < nl; i++) Bsd[i] = 0;
        if (pi->face < 0 || pi->material < 0) continue;
        const model_material_t *mx = c->mats[pi->material];
        model_vec3_t n = pi->n, a = fabs(n.x) < 0.9 ? v3(1, 0, 0) : v3(0, 1, 0);
        a = v3_unit(v3_sub(a, v3_scale(n, v3_dot(a, n))));
        model_vec3_t b = v3_cross(n, a);
        model_rng_t rng = model_rng(c->seed, (uint64_t)g);
        double rot = model_rng_uniform(&rng);
        double acc[MAX_LAMPS] = { 0 }, acc2[MAX_LAMPS] = { 0 };
        model_vec3_t org = v3_add(pi->p_mm, v3_scale(n, eps));
        for (int j = 0; j < N; j++) {
            double u = (j + 0.5) / N, ph = 2 * M_PI * (radical_inverse2((uint32_t)j) + rot);
            double r = sqrt(u), cz = sqrt(1 - u);
            model_vec3_t w = v3_add(v3_add(v3_scale(a, r * cos(ph)), v3_scale(b, r * sin(ph))), v3_scale(n, cz));
            model_pixel_info_t y;
            model_tracer_cast(c->t, org, w, &y);
            if (y.face < 0 || y.material < 0) continue;
            model_cosines_t cx = model_cosines(n, w, pi->v);
            if (cx.nl <= 0 || cx.nv <= 0) continue;
            double fx = model_brdf_eval(mx->model, mx->p, &cx, NULL) / cx.nl;
            const model_material_t *my = c->mats[y.material];
            model_vec3_t vy = v3_scale(w, -1);
            for (int i = 0; i < nl; i++) {
                model_vec3_t d = v3_sub(c->lamps->lamps[i].position_mm, y.p_mm);
                double dd = v3_norm(d);
                model_vec3_t l = v3_scale(d, 1 / dd);
                model_cosines_t cy = model_cosines(y.n, l, vy);
                if (cy.nl <= 0 || cy.nv <= 0) continue;
                if (!model_tracer_visible_from(c->t, y.p_mm, y.n, c->lamps->lamps[i].position_mm)) continue;
                double t = fx * model_brdf_eval(my->model, my->p, &cy, NULL) / (dd * dd) *
                           model_lamp_emission(&c->lamps->lamps[i], y.p_mm);
                acc[i] += t;
                acc2[i] += t * t;
            }
        }
        for (int i = 0; i < nl; i++) B[i] = (float)(M_PI / N * acc[i]);
        // the mean's standard error over the rays: pi sqrt((mean a^2 - mean^2) / (N - 1))
        for (int i = 0; Bsd && N > 1 && i < nl; i++)
            Bsd[i] = (float)(M_PI * sqrt(fmax(acc2[i] / N - (acc[i] / N) * (acc[i] / N), 0) / (N - 1)));
    }
}

void verify_interreflection(const model_tracer_t *t, const model_lamps_t *lamps, const model_material_t *const *mats,
                            const model_pixel_info_t *pi, int n, int samples, int threads, float *B)
{
    verify_interreflection_sd(t, lamps, mats, pi, n, samples, threads, B, NULL);
}

void verify_interreflection_sd(const model_tracer_t *t, const model_lamps_t *lamps,
                               const model_material_t *const *mats, const model_pixel_info_t *pi, int n, int samples,
                               int threads, float *B, float *Bsd)
{
    verify_interreflection_at(t, lamps, mats, pi, NULL, n, samples, threads, B, Bsd);
}

void verify_interreflection_at(const model_tracer_t *t, const model_lamps_t *lamps, const model_material_t *const *mats,
                               const model_pixel_info_t *pi, const int *idx, int n, int samples, int threads, float *B,
                               float *Bsd)
{
    ir_ctx_t ic = { t, lamps, mats, samples, pi, idx, B, 0x1e5f, Bsd };
    model_parallel_for(n, 64, threads > 0 ? threads : model_default_threads(), ir_rows, &ic);
}
