// model/brdf/gen.c — reflection models that are none of refl's fitted ones,
// for tabulated materials (model/brdf/table.c): a recipe "NAME key=value ..."
// (refl brdf tabulate, [material NAME] generate = ...) evaluates f_r from the
// cosines and fills a MERL table. Every model here is reciprocal and, within
// its parameter ranges, energy conserving (directional albedo <= 1; the tests
// check both on the tables).
//
//   oren-nayar  albedo, sigma (rad): Oren & Nayar, "Generalization of Lambert's
//               reflectance model", SIGGRAPH 1994, their qualitative model
//               f = albedo/pi (A + B max(0, cos dphi) sin(alpha) tan(beta)).
//   ggx2        albedo, ks1, alpha1, ks2, alpha2, F0: a Lambertian base and two
//               GGX lobes (Walter et al., "Microfacet models for refraction
//               through rough surfaces", EGSR 2007; height-correlated Smith,
//               Schlick Fresnel), as two-layer clear coats show
//               (albedo + ks1 + ks2 <= 1).
//   retro       albedo, kr, n: a Lambertian base and a retro-reflective lobe
//               kr (n+2)/(2 pi) (l.v)^n, a normalised Phong lobe about the
//               lamp direction (Lafortune & Willems, "Using the modified Phong
//               reflectance model for physically based rendering", 1994); its
//               directional albedo is <= kr (albedo + kr <= 1).
//   ggx-ms      alpha, ks: GGX (F = 1) plus the multiple-scattering term of
//               Kulla & Conty, "Revisiting physically based shading at
//               Imageworks" (SIGGRAPH 2017 course):
//               f_ms = (1 - E(mu_i))(1 - E(mu_o)) / (pi (1 - E_avg)), E the
//               single-scattering directional albedo (computed here
//               numerically), E_avg = 2 int E(mu) mu dmu; the sum reflects ks
//               at every incidence (a white furnace).
//   ptfe        albedo, drop: a pressed-PTFE-like reference white,
//               f = albedo/pi g(theta_i) g(theta_o), g(theta) = 1 - drop
//               (1 - cos theta)/(1 - cos 75 deg): the reflectance factor
//               falls by `drop` from normal to 75 deg incidence (reciprocal).
//   ggx         kd, ks, alpha, F0: refl's own ggx model (model/brdf/brdf.c), to
//               check the table against the analytic model.
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

typedef struct {
    const char *key;
    double      def, lo, hi;
} gen_param_t;

typedef struct {
    const char *name;
    int         np;
    gen_param_t p[MODEL_BRDF_RECIPE_MAX];
    double      sum_max;      // the first sum_n parameters must add up to at most this (0: no check)
    int         sum_idx[3];
    int         sum_n;
} gen_model_t;

static const gen_model_t gen_models[] = {
    { "oren-nayar", 2, { { "albedo", 0.5, 0, 1 }, { "sigma", 0.3, 0, 1.0 } }, 0, { 0 }, 0 },
    { "ggx2", 6,
      { { "albedo", 0.3, 0, 1 }, { "ks1", 0.3, 0, 1 }, { "alpha1", 0.05, 0.01, 1 }, { "ks2", 0.3, 0, 1 },
        { "alpha2", 0.3, 0.01, 1 }, { "F0", 0.04, 0, 1 } },
      1, { 0, 1, 3 }, 3 },
    { "retro", 3, { { "albedo", 0.5, 0, 1 }, { "kr", 0.2, 0, 1 }, { "n", 10, 0, 1000 } }, 1, { 0, 1 }, 2 },
    { "ggx-ms", 2, { { "alpha", 0.5, 0.05, 1 }, { "ks", 1, 0, 1 } }, 0, { 0 }, 0 },
    { "ptfe", 2, { { "albedo", 0.99, 0, 1 }, { "drop", 0.03, 0, 0.5 } }, 0, { 0 }, 0 },
    { "ggx", 4, { { "kd", 0, 0, 1 }, { "ks", 1, 0, 1 }, { "alpha", 0.3, 0.01, 1 }, { "F0", 1, 0, 1 } }, 1, { 0, 1 },
      2 },
};
#define NGEN ((int)(sizeof gen_models / sizeof gen_models[0]))

const char *model_brdf_recipe_models(void)
{
    return "oren-nayar (albedo=0.5 sigma=0.3 rad), ggx2 (albedo=0.3 ks1=0.3 alpha1=0.05 ks2=0.3 alpha2=0.3 "
           "F0=0.04), retro (albedo=0.5 kr=0.2 n=10), ggx-ms (alpha=0.5 ks=1), ptfe (albedo=0.99 drop=0.03), "
           "ggx (kd=0 ks=1 alpha=0.3 F0=1)";
}

// GGX pieces (as model/brdf/brdf.c's, without derivatives).
static double ggx_d(double nh, double a2)
{
    if (!(nh > 0)) return 0;
    double q = nh * nh * (a2 - 1) + 1;
    return a2 / (M_PI * q * q);
}
static double ggx_lambda(double c, double a2)
{
    double t2 = fmax(0.0, (1 - c * c) / (c * c));
    return (sqrt(1 + a2 * t2) - 1) / 2;
}
static double ggx_f(const model_cosines_t *c, double a, double F0)
{
    if (!(c->vh > 0)) return 0;
    double a2 = a * a, G = 1 / (1 + ggx_lambda(c->nl, a2) + ggx_lambda(c->nv, a2));
    double x = 1 - c->vh, F = F0 + (1 - F0) * x * x * x * x * x;
    return ggx_d(c->nh, a2) * G * F / (4 * c->nl * c->nv);
}

// cos of the azimuth between l and v (about n) from the cosines.
static double cos_dphi(const model_cosines_t *c)
{
    double lv = 2 * c->vh * c->vh - 1, sl = sqrt(fmax(0, 1 - c->nl * c->nl)), sv = sqrt(fmax(0, 1 - c->nv * c->nv));
    return sl * sv > 1e-12 ? fmin(1, fmax(-1, (lv - c->nl * c->nv) / (sl * sv))) : 0;
}

static double ms_E(const model_brdf_recipe_t *r, double mu)
{
    double x = fmin(1, fmax(0, mu)) * (MODEL_BRDF_RECIPE_NE - 1);
    int i = (int)x;
    if (i >= MODEL_BRDF_RECIPE_NE - 1) return r->E[MODEL_BRDF_RECIPE_NE - 1];
    return r->E[i] + (x - i) * (r->E[i + 1] - r->E[i]);
}

double model_brdf_recipe_f(const model_brdf_recipe_t *r, const model_cosines_t *c)
{
    if (!(c->nl > 0) || !(c->nv > 0)) return 0;
    const double *p = r->p;
    switch (r->model) {
    case 0: {   // oren-nayar
        double s2 = p[1] * p[1], A = 1 - 0.5 * s2 / (s2 + 0.33), B = 0.45 * s2 / (s2 + 0.09);
        double ti = acos(fmin(1, c->nl)), to = acos(fmin(1, c->nv));
        double al = fmax(ti, to), be = fmin(ti, to);
        return p[0] / M_PI * (A + B * fmax(0, cos_dphi(c)) * sin(al) * tan(be));
    }
    case 1:     // ggx2
        return p[0] / M_PI + p[1] * ggx_f(c, p[2], p[5]) + p[3] * ggx_f(c, p[4], p[5]);
    case 2: {   // retro
        double lv = fmax(0, 2 * c->vh * c->vh - 1);
        return p[0] / M_PI + p[1] * (p[2] + 2) / (2 * M_PI) * pow(lv, p[2]);
    }
    case 3: {   // ggx-ms
        double ms = (1 - ms_E(r, c->nl)) * (1 - ms_E(r, c->nv)) / (M_PI * (1 - r->Eavg));
        return p[1] * (ggx_f(c, p[0], 1.0) + ms);
    }
    case 4: {   // ptfe
        double k = p[1] / (1 - cos(75 * M_PI / 180));
        return p[0] / M_PI * (1 - k * (1 - c->nl)) * (1 - k * (1 - c->nv));
    }
    case 5:     // ggx
        return model_brdf_eval(MODEL_BRDF_GGX, p, c, NULL) / c->nl;
    default:
        return NAN;
    }
}

static double ss_cb(const void *ctx, const model_cosines_t *c)
{
    return ggx_f(c, *(const double *)ctx, 1.0);
}

// ggx-ms: E(mu) of single-scattering GGX (F = 1) on NE points and E_avg.
static void precompute_ms(model_brdf_recipe_t *r)
{
    double a = r->p[0], avg = 0;
    for (int i = 0; i < MODEL_BRDF_RECIPE_NE; i++) {
        double mu = fmax(1e-3, (double)i / (MODEL_BRDF_RECIPE_NE - 1));
        r->E[i] = fmin(1, model_brdf_directional_albedo(ss_cb, &a, acos(mu), 256));
    }
    for (int i = 0; i < 256; i++) {   // E_avg = 2 int_0^1 E(mu) mu dmu (midpoint)
        double mu = (i + 0.5) / 256;
        avg += 2 * ms_E(r, mu) * mu / 256;
    }
    r->Eavg = fmin(avg, 0.999);
}

bool model_brdf_recipe_parse(const char *text, const char *file, int line, model_brdf_recipe_t *r)
{
    memset(r, 0, sizeof *r);
    char buf[512];
    snprintf(buf, sizeof buf, "%s", text ? text : "");
    char *save = NULL, *tok = strtok_r(buf, " \t", &save);
    int m = -1;
    for (int k = 0; tok && k < NGEN; k++)
        if (!strcmp(tok, gen_models[k].name)) m = k;
    if (m < 0) {
        model_error(file, line, "unknown BRDF generator '%s'; models and their defaults: %s", tok ? tok : "",
                    model_brdf_recipe_models());
        return false;
    }
    const gen_model_t *g = &gen_models[m];
    r->model = m;
    snprintf(r->name, sizeof r->name, "%s", g->name);
    r->np = g->np;
    for (int i = 0; i < g->np; i++) r->p[i] = g->p[i].def;
    while ((tok = strtok_r(NULL, " \t", &save))) {
        char *eq = strchr(tok, '=');
        int i = -1;
        if (eq) {
            *eq = 0;
            for (int k = 0; k < g->np; k++)
                if (!strcmp(tok, g->p[k].key)) i = k;
        }
        double v;
        if (i < 0) {
            model_error(file, line, "BRDF generator %s: '%s' is not KEY=VALUE with a key of %s", g->name, tok,
                        model_brdf_recipe_models());
            return false;
        }
        if (!model_parse_double(eq + 1, &v) || !(v >= g->p[i].lo && v <= g->p[i].hi)) {
            model_error(file, line, "BRDF generator %s: %s = '%s' is not a number in [%g, %g]", g->name, tok, eq + 1,
                        g->p[i].lo, g->p[i].hi);
            return false;
        }
        r->p[i] = v;
    }
    double sum = 0;
    for (int k = 0; k < g->sum_n; k++) sum += r->p[g->sum_idx[k]];
    if (g->sum_n && sum > g->sum_max + 1e-12) {
        model_error(file, line, "BRDF generator %s: its weights add up to %g > %g, more light than comes in "
                    "(lower them)", g->name, sum, g->sum_max);
        return false;
    }
    if (!strcmp(g->name, "ggx-ms")) precompute_ms(r);
    return true;
}

typedef struct {
    const model_brdf_recipe_t *r;
    double *f;
} gen_job_t;

static void gen_rows(void *ctx, int begin, int end, int thread)
{
    (void)thread;
    const gen_job_t *J = ctx;
    for (int i = begin; i < end; i++)
        for (int j = 0; j < MODEL_MERL_TD; j++)
            for (int k = 0; k < MODEL_MERL_PD; k++) {
                model_cosines_t c;
                model_brdf_table_cell(i, j, k, &c);
                // Below the horizon a table holds 0 (the renderer never looks there).
                J->f[((size_t)i * MODEL_MERL_TD + j) * MODEL_MERL_PD + k] = model_brdf_recipe_f(J->r, &c);
            }
}

model_brdf_table_t *model_brdf_tabulate(const model_brdf_recipe_t *r)
{
    model_brdf_table_t *t = model_brdf_table_new();
    if (!t) return NULL;
    gen_job_t J = { r, model_brdf_table_values(t) };
    model_parallel_for(MODEL_MERL_TH, 1, model_default_threads(), gen_rows, &J);
    return t;
}
