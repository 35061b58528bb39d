// fit/material/export.c — materials out: glTF 2.0, Mitsuba 3 and MERL from a
// priors file, each with its conversion error (Ngan et al. 2005) against
// refl's model (fit/material/export.h has the conversions and the metric).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fit/material/export.h"
#include "fit/brdf/brdf.h"
#include "model/base/report.h"

bool fit_export_format_from_name(const char *name, fit_export_format_t *out)
{
    static const char *const names[] = { "gltf", "mitsuba", "merl" };
    for (int k = 0; k < 3; k++)
        if (name && !strcmp(name, names[k])) {
            *out = (fit_export_format_t)k;
            return true;
        }
    return false;
}

// ---------------------------------------------------------------------------
// The metric's samples: theta_i, theta_o uniform in cos below 85 deg (uniform
// in solid angle), the light in the plane phi = 0 (the models are isotropic).

enum { NI = 16, NO = 32, NP = 64, NSAMPLES = NI * NO * NP };

typedef struct {
    int              n;
    model_cosines_t *c;
    double          *R;     // the model's f_r cos theta_i
    double           rms;   // of R
} ngan_t;

static void ngan_free(ngan_t *s)
{
    free(s->c);
    free(s->R);
}

static bool ngan_samples(model_brdf_t model, const double *p, ngan_t *s)
{
    const double cmin = cos(85 * M_PI / 180);
    s->n = 0;
    s->c = malloc(NSAMPLES * sizeof *s->c);
    s->R = malloc(NSAMPLES * sizeof *s->R);
    if (!s->c || !s->R) {
        ngan_free(s);
        model_error(NULL, 0, "out of memory");
        return false;
    }
    double ss = 0;
    for (int i = 0; i < NI; i++) {
        double ci = 1 - (i + 0.5) / NI * (1 - cmin), si = sqrt(1 - ci * ci);
        model_vec3_t n = { 0, 0, 1 }, l = { si, 0, ci };
        for (int o = 0; o < NO; o++) {
            double co = 1 - (o + 0.5) / NO * (1 - cmin), so = sqrt(1 - co * co);
            for (int k = 0; k < NP; k++) {
                double ph = 2 * M_PI * (k + 0.5) / NP;
                model_vec3_t v = { so * cos(ph), so * sin(ph), co };
                s->c[s->n] = model_cosines(n, l, v);
                double R = model_brdf_eval(model, p, &s->c[s->n], NULL);
                s->R[s->n++] = R;
                ss += R * R;
            }
        }
    }
    s->rms = sqrt(ss / s->n);
    return true;
}

// ---------------------------------------------------------------------------
// The targets' pieces

static double d_ggx(double nh, double a)
{
    double a2 = a * a, t = nh * nh * (a2 - 1) + 1;
    return nh > 0 ? a2 / (M_PI * t * t) : 0;
}

// Smith's G1 of GGX (Mitsuba's separable G = G1(l) G1(v)).
static double g1_ggx(double mu, double a)
{
    if (!(mu > 0)) return 0;
    double t2 = (1 - mu * mu) / (mu * mu);
    return 2 / (1 + sqrt(1 + a * a * t2));
}

// Unpolarised Fresnel reflectance of a dielectric interface of relative index
// eta, light arriving from outside at cosine ci.
static double fresnel_dielectric(double ci, double eta)
{
    ci = fmin(fmax(ci, 0), 1);
    double s2 = (1 - ci * ci) / (eta * eta);
    if (s2 >= 1) return 1;
    double ct = sqrt(1 - s2);
    double rs = (ci - eta * ct) / (ci + eta * ct), rp = (eta * ci - ct) / (eta * ci + ct);
    return 0.5 * (rs * rs + rp * rp);
}

static double f0_to_ior(double F0)
{
    double s = sqrt(fmin(fmax(F0, 0), 0.999999));
    return (1 + s) / (1 - s);
}

// glTF's specular lobe D V (height-correlated Smith) without Fresnel: refl's
// ggx with kd 0, ks 1, F0 1 is exactly that.
static double gltf_dv(const model_cosines_t *c, double alpha)
{
    double p[4] = { 0, 1, alpha, 1 };
    return c->nl > 0 ? model_brdf_eval(MODEL_BRDF_GGX, p, c, NULL) / c->nl : 0;
}

// glTF, metallic 0, KHR_materials_specular (+ ior): q = base, metallic,
// roughness, specularFactor, specularColorFactor, ior.
enum { G_BASE, G_METALLIC, G_ROUGH, G_SPEC, G_SPECCOL, G_IOR, G_NQ };
static double gltf_fresnel(const double *q, double vh)
{
    double f0ior = q[G_IOR] == 0 ? 1 : pow((q[G_IOR] - 1) / (q[G_IOR] + 1), 2);
    double F0 = fmin(f0ior * q[G_SPECCOL], 1);
    return q[G_SPEC] * (F0 + (1 - F0) * pow(1 - fmin(fmax(vh, 0), 1), 5));
}

static double gltf_f(const double *q, const model_cosines_t *c)
{
    if (!(c->nl > 0 && c->nv > 0)) return 0;
    double F = gltf_fresnel(q, c->vh);
    return (1 - F) * q[G_BASE] / M_PI + F * gltf_dv(c, q[G_ROUGH] * q[G_ROUGH]);
}

// Mitsuba: q = alpha, ior, specular_reflectance, diffuse_reflectance (plastic)
// and aux = t(mu) at NT + 1 cosines, then the internal reflectance.
enum { M_ALPHA, M_IOR, M_SPEC, M_DIFF, M_NQ };
enum { NT = 64 };

static double mitsuba_spec(const double *q, const model_cosines_t *c)
{
    if (!(c->nl > 0 && c->nv > 0)) return 0;
    double a = q[M_ALPHA];
    return fresnel_dielectric(c->vh, q[M_IOR]) * d_ggx(c->nh, a) * g1_ggx(c->nl, a) * g1_ggx(c->nv, a) /
           (4 * c->nl * c->nv);
}

// The rough interface's reflected albedo at cosine mu (its microfacet
// reflection alone), by quadrature over half vectors distributed as D cos.
static double rough_albedo(double mu, double a, double eta)
{
    enum { NU = 48, NPH = 24 };
    double sum = 0, wi[3] = { sqrt(1 - mu * mu), 0, mu };
    for (int i = 0; i < NU; i++) {
        double u = (i + 0.5) / NU, th = atan(a * sqrt(u / (1 - u)));
        for (int k = 0; k < NPH; k++) {
            double ph = M_PI * (k + 0.5) / NPH;   // symmetric about the plane of wi: half the circle
            double h[3] = { sin(th) * cos(ph), sin(th) * sin(ph), cos(th) };
            double wh = wi[0] * h[0] + wi[2] * h[2];
            if (wh <= 0) continue;
            double wo_z = 2 * wh * h[2] - wi[2];
            if (wo_z <= 0) continue;
            sum += fresnel_dielectric(wh, eta) * g1_ggx(mu, a) * g1_ggx(wo_z, a) * wh / (mu * cos(th));
        }
    }
    return sum / (NU * NPH);
}

static void plastic_tables(const double *q, double *aux)
{
    double tint = 0;
    for (int k = 0; k <= NT; k++) {
        double mu = fmax((double)k / NT, 1e-3);
        aux[k] = 1 - rough_albedo(mu, q[M_ALPHA], q[M_IOR]);
        double mu0 = (double)k / NT;
        tint += (k == 0 || k == NT ? 0.5 : 1) * aux[k] * 2 * mu0 / NT;   // trapezoid of t 2 mu
    }
    aux[NT + 1] = 1 - tint / (q[M_IOR] * q[M_IOR]);
}

static double lerp_t(const double *aux, double mu)
{
    double x = fmin(fmax(mu, 0), 1) * NT;
    int i = (int)x < NT ? (int)x : NT - 1;
    return aux[i] + (x - i) * (aux[i + 1] - aux[i]);
}

static double plastic_diffuse(const double *q, const double *aux, const model_cosines_t *c)
{
    if (!(c->nl > 0 && c->nv > 0)) return 0;
    return q[M_DIFF] / (1 - aux[NT + 1]) / (M_PI * q[M_IOR] * q[M_IOR]) * lerp_t(aux, c->nl) * lerp_t(aux, c->nv);
}

// ---------------------------------------------------------------------------
// Conversions

_Static_assert(NT + 2 == FIT_EXPORT_NAUX, "fit/material/export.h: FIT_EXPORT_NAUX");

double fit_export_eval(const fit_export_material_t *e, const model_cosines_t *c)
{
    if (!strcmp(e->target, "gltf")) return gltf_f(e->q, c);
    if (!strcmp(e->target, "mitsuba roughconductor")) return e->q[M_SPEC] * mitsuba_spec(e->q, c);
    if (!strcmp(e->target, "mitsuba diffuse")) return c->nl > 0 && c->nv > 0 ? e->q[0] / M_PI : 0;
    if (!strcmp(e->target, "mitsuba roughplastic"))
        return e->q[M_SPEC] * mitsuba_spec(e->q, c) + plastic_diffuse(e->q, e->aux, c);
    double R = model_brdf_eval(e->model, e->p, c, NULL);   // merl: the model at the cells
    return c->nl > 0 ? R / c->nl : 0;
}

// Ngan error of a target (f_r from fit_export_eval) against the samples.
static double target_error(const fit_export_material_t *e, const ngan_t *s)
{
    double ss = 0;
    for (int i = 0; i < s->n; i++) {
        double d = fit_export_eval(e, &s->c[i]) * s->c[i].nl - s->R[i];
        ss += d * d;
    }
    return sqrt(ss / s->n);
}

// The ggx the conversions start from.
static bool to_ggx(const verify_prior_t *m, const ngan_t *s, double ggx[4], double *err)
{
    *err = 0;
    if (m->model == MODEL_BRDF_GGX) {
        memcpy(ggx, m->mean, 4 * sizeof *ggx);
        return true;
    }
    if (m->model == MODEL_BRDF_LAMBERT) {
        ggx[0] = fmin(M_PI * m->mean[0], 1), ggx[1] = 0, ggx[2] = 0.5, ggx[3] = 0.04;
    } else {
        // every sample is in front of the surface: fit_samples_add fails only for a non-finite R (skipped)
        // or out of memory
        fit_samples_t *fs = fit_samples_new();
        bool grown = fs != NULL;
        for (int i = 0; grown && i < s->n; i++) grown = fit_samples_add(fs, &s->c[i], s->R[i], 1) || !isfinite(s->R[i]);
        if (!grown) {
            fit_samples_free(fs);
            model_error(NULL, 0, "out of memory");
            return false;
        }
        fit_brdf_options_t o = fit_brdf_defaults();
        fit_brdf_result_t r;
        bool ok = fit_brdf(fs, MODEL_BRDF_GGX, &o, &r);
        fit_samples_free(fs);
        if (!ok) {
            model_error(NULL, 0, "material %s: no ggx could be fitted to its %s: %s", m->name,
                        model_brdf_name(m->model), model_last_error());
            return false;
        }
        memcpy(ggx, r.p, 4 * sizeof *ggx);
    }
    double ss = 0;
    for (int i = 0; i < s->n; i++) {
        double d = model_brdf_eval(MODEL_BRDF_GGX, ggx, &s->c[i], NULL) - s->R[i];
        ss += d * d;
    }
    *err = sqrt(ss / s->n);
    return true;
}

// Least squares of y ~ a A + b B with a, b in [0, hi] (B NULL: a alone), by
// exact coordinate steps (two unknowns: converges in a few).
static void ls2(const double *A, const double *B, const double *y, int n, double hi, double *a, double *b)
{
    double AA = 0, BB = 0, AB = 0, Ay = 0, By = 0;
    for (int i = 0; i < n; i++) {
        AA += A[i] * A[i], Ay += A[i] * y[i];
        if (B) BB += B[i] * B[i], AB += A[i] * B[i], By += B[i] * y[i];
    }
    *a = 0;
    if (b) *b = 0;
    for (int it = 0; it < 100; it++) {
        *a = AA > 0 ? fmin(fmax((Ay - (B ? AB * *b : 0)) / AA, 0), hi) : 0;
        if (!B) break;
        *b = BB > 0 ? fmin(fmax((By - AB * *a) / BB, 0), hi) : 0;
    }
}

static void set_q(fit_export_material_t *e, const char *target, int nq, const char *const *names, const double *q)
{
    snprintf(e->target, sizeof e->target, "%s", target);
    e->nq = nq;
    for (int k = 0; k < nq; k++) e->qname[k] = names[k], e->q[k] = q[k];
}

// glTF: everything from the ggx but the base colour, which is fitted. false + message (out of memory).
static bool convert_gltf(fit_export_material_t *e, const ngan_t *s)
{
    static const char *const names[G_NQ] = { "baseColorFactor", "metallicFactor", "roughnessFactor",
                                             "specularFactor", "specularColorFactor", "ior" };
    double F0 = e->ggx[3], q[G_NQ] = { 0, 0, sqrt(e->ggx[2]), e->ggx[1], 1, 1.5 };
    if (F0 <= 0.04) q[G_SPECCOL] = F0 / 0.04;
    else q[G_IOR] = F0 >= 1 ? 0 : (1 + sqrt(F0)) / (1 - sqrt(F0));
    set_q(e, "gltf", G_NQ, names, q);
    // R = base A + (specular part): base by least squares
    double *A = malloc((size_t)s->n * sizeof *A), *y = malloc((size_t)s->n * sizeof *y);
    if (!A || !y) {
        free(A);
        free(y);
        model_error(NULL, 0, "out of memory");
        return false;
    }
    for (int i = 0; i < s->n; i++) {
        const model_cosines_t *c = &s->c[i];
        double F = gltf_fresnel(e->q, c->vh);
        A[i] = (1 - F) / M_PI * c->nl;
        y[i] = s->R[i] - F * gltf_dv(c, e->q[G_ROUGH] * e->q[G_ROUGH]) * c->nl;
    }
    ls2(A, NULL, y, s->n, 1, &e->q[G_BASE], NULL);
    free(A);
    free(y);
    e->error = target_error(e, s);
    return true;
}

// Mitsuba: one plugin's parameters for a given alpha and ior, the
// reflectances by least squares; its error.
typedef struct {
    const ngan_t          *s;
    int                    kind;   // 0 roughplastic, 1 roughconductor, 2 diffuse
    double                *A, *B;
    fit_export_material_t  e, best;
} mfit_t;

static double mitsuba_try(mfit_t *f, double alpha, double ior)
{
    static const char *const plastic[M_NQ] = { "alpha", "int_ior", "specular_reflectance", "diffuse_reflectance" };
    static const char *const conductor[M_NQ - 1] = { "alpha", "eta", "specular_reflectance" };
    static const char *const diffuse[1] = { "reflectance" };
    fit_export_material_t *e = &f->e;
    double q[M_NQ] = { alpha, ior, 1, 1 };
    if (f->kind == 2) {   // the diffuse plugin: roughplastic's formulas with no specular and a clear interface
        for (int i = 0; i < f->s->n; i++) f->A[i] = f->s->c[i].nl / M_PI;
        ls2(f->A, NULL, f->s->R, f->s->n, 1, &q[0], NULL);
        set_q(e, "mitsuba diffuse", 1, diffuse, q);
    } else {
        set_q(e, f->kind ? "mitsuba roughconductor" : "mitsuba roughplastic", f->kind ? M_NQ - 1 : M_NQ,
              f->kind ? conductor : plastic, q);
        if (!f->kind) plastic_tables(e->q, e->aux);
        for (int i = 0; i < f->s->n; i++) {
            f->A[i] = mitsuba_spec(q, &f->s->c[i]) * f->s->c[i].nl;
            f->B[i] = f->kind ? 0 : plastic_diffuse(q, e->aux, &f->s->c[i]) * f->s->c[i].nl;
        }
        ls2(f->A, f->kind ? NULL : f->B, f->s->R, f->s->n, 1, &e->q[M_SPEC], f->kind ? NULL : &e->q[M_DIFF]);
    }
    e->error = target_error(e, f->s);
    if (!(e->error >= f->best.error)) f->best = *e;
    return e->error;
}

// Golden-section search of one of (log alpha, log(ior - 1)) about the best so far.
static void mitsuba_line(mfit_t *f, int which, double lo, double hi)
{
    const double g = (sqrt(5) - 1) / 2;
    double a = lo, b = hi, x1 = b - g * (b - a), x2 = a + g * (b - a);
    double al = f->best.q[M_ALPHA], io = f->best.q[M_IOR];
#define TRY(x) (which ? mitsuba_try(f, al, 1 + exp(x)) : mitsuba_try(f, exp(x), io))
    double f1 = TRY(x1), f2 = TRY(x2);
    for (int it = 0; it < 16; it++) {
        if (f1 < f2) b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a), f1 = TRY(x1);
        else a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a), f2 = TRY(x2);
    }
#undef TRY
}

// Mitsuba: roughplastic and roughconductor from the ggx's alpha and F0, then
// alpha and the ior searched (Mitsuba's separable G and exact Fresnel differ
// from the ggx's), and the diffuse plugin: the closest is chosen. false +
// message (out of memory).
static bool convert_mitsuba(fit_export_material_t *e, const ngan_t *s)
{
    mfit_t f = { .s = s };
    f.A = malloc((size_t)s->n * sizeof *f.A);
    f.B = malloc((size_t)s->n * sizeof *f.B);
    if (!f.A || !f.B) {
        free(f.A);
        free(f.B);
        model_error(NULL, 0, "out of memory");
        return false;
    }
    fit_export_material_t cand[3];
    for (int k = 0; k < 3; k++) {
        f.kind = k;
        f.e = f.best = *e;
        f.best.error = INFINITY;
        mitsuba_try(&f, e->ggx[2], f0_to_ior(e->ggx[3]));
        for (int round = 0; k < 2 && round < 2; round++) {
            mitsuba_line(&f, 0, log(0.001), 0);
            mitsuba_line(&f, 1, log(0.01), log(50));
        }
        cand[k] = f.best;
    }
    free(f.A);
    free(f.B);
    int b = 0, o = -1;
    for (int k = 1; k < 3; k++)
        if (cand[k].error < cand[b].error) b = k;
    for (int k = 0; k < 3; k++)
        if (k != b && (o < 0 || cand[k].error < cand[o].error)) o = k;
    *e = cand[b];
    snprintf(e->alt_target, sizeof e->alt_target, "%s", cand[o].target);
    e->alt_error = cand[o].error;
    return true;
}

bool fit_export_convert(const verify_prior_t *m, fit_export_format_t fmt, fit_export_material_t *e)
{
    memset(e, 0, sizeof *e);
    snprintf(e->name, sizeof e->name, "%s", m->name);
    e->model = m->model;
    memcpy(e->p, m->mean, sizeof e->p);
    e->alt_error = NAN;
    ngan_t s;
    if (!ngan_samples(m->model, m->mean, &s)) return false;
    bool ok = to_ggx(m, &s, e->ggx, &e->ggx_error);
    if (ok && fmt == FIT_EXPORT_GLTF) ok = convert_gltf(e, &s);
    if (ok && fmt == FIT_EXPORT_MITSUBA) ok = convert_mitsuba(e, &s);
    if (ok && fmt == FIT_EXPORT_MERL) {
        snprintf(e->target, sizeof e->target, "merl");
        model_brdf_table_t *t = fit_export_tabulate(m);
        ok = t != NULL;
        double ss = 0;
        for (int i = 0; ok && i < s.n; i++) {
            double d = model_brdf_table_eval(t, &s.c[i]) - s.R[i];
            ss += d * d;
        }
        e->error = sqrt(ss / s.n);
        model_brdf_table_free(t);
    }
    e->rel_error = s.rms > 0 ? e->error / s.rms : 0;
    ngan_free(&s);
    return ok;
}

model_brdf_table_t *fit_export_tabulate(const verify_prior_t *m)
{
    model_brdf_table_t *t = model_brdf_table_new();
    if (!t) {
        model_error(NULL, 0, "out of memory");
        return NULL;
    }
    double *f = model_brdf_table_values(t);
    for (int i = 0; i < MODEL_MERL_TH; i++)
        for (int j = 0; j < MODEL_MERL_TD; j++)
            for (int k = 0; k < MODEL_MERL_PD; k++) {
                model_cosines_t c;
                model_brdf_table_cell(i, j, k, &c);
                double R = c.nl > 0 && c.nv > 0 ? model_brdf_eval(m->model, m->mean, &c, NULL) : 0;
                f[((size_t)i * MODEL_MERL_TD + j) * MODEL_MERL_PD + k] = R > 0 ? R / c.nl : 0;
            }
    return t;
}

// ---------------------------------------------------------------------------
// Files

static json_t *grey(double v, int n, double last)
{
    json_t *a = json_array();
    for (int k = 0; k < n; k++) json_array_append_new(a, json_real(v));
    if (last >= 0) json_array_append_new(a, json_real(last));
    return a;
}

// What every format states of a conversion (glTF's extras, the sidecar).
static json_t *conversion_json(const fit_export_material_t *e)
{
    json_t *o = json_object(), *p = json_object(), *g = json_object(), *q = json_object();
    json_object_set_new(o, "name", json_string(e->name));
    json_object_set_new(o, "model", json_string(model_brdf_name(e->model)));
    for (int k = 0; k < model_brdf_nparams(e->model); k++)
        json_object_set_new(p, model_brdf_param_name(e->model, k), json_real(e->p[k]));
    json_object_set_new(o, "parameters", p);
    static const char *const gn[4] = { "kd", "ks", "alpha", "F0" };
    for (int k = 0; k < 4; k++) json_object_set_new(g, gn[k], json_real(e->ggx[k]));
    json_object_set_new(g, "ngan_error", json_real(e->ggx_error));
    json_object_set_new(o, "via_ggx", g);
    json_object_set_new(o, "target", json_string(e->target));
    for (int k = 0; k < e->nq; k++) json_object_set_new(q, e->qname[k], json_real(e->q[k]));
    json_object_set_new(o, "target_parameters", q);
    json_object_set_new(o, "ngan_error", json_real(e->error));
    json_object_set_new(o, "ngan_error_relative", json_real(e->rel_error));
    if (e->alt_target[0]) {
        json_t *a = json_object();
        json_object_set_new(a, "target", json_string(e->alt_target));
        json_object_set_new(a, "ngan_error", json_real(e->alt_error));
        json_object_set_new(o, "not_chosen", a);
    }
    json_object_set_new(o, "metric", json_string("Ngan et al. 2005: RMS of (f_export - f_model) cos theta_i over "
                                                 "directions uniform in solid angle, theta below 85 deg; 1/sr"));
    return o;
}

static json_t *gltf_json(const fit_export_result_t *r)
{
    json_t *root = json_object(), *asset = json_object(), *mats = json_array(), *used = json_array();
    json_object_set_new(asset, "version", json_string("2.0"));
    json_object_set_new(asset, "generator", json_string("refl " REFL_VERSION " (refl export material)"));
    json_object_set_new(root, "asset", asset);
    bool any_ior = false;
    for (int i = 0; i < r->n; i++) {
        const fit_export_material_t *e = &r->m[i];
        json_t *m = json_object(), *pbr = json_object(), *ext = json_object(), *sp = json_object();
        json_object_set_new(m, "name", json_string(e->name));
        json_object_set_new(pbr, "baseColorFactor", grey(e->q[G_BASE], 3, 1));
        json_object_set_new(pbr, "metallicFactor", json_real(e->q[G_METALLIC]));
        json_object_set_new(pbr, "roughnessFactor", json_real(e->q[G_ROUGH]));
        json_object_set_new(m, "pbrMetallicRoughness", pbr);
        json_object_set_new(sp, "specularFactor", json_real(e->q[G_SPEC]));
        json_object_set_new(sp, "specularColorFactor", grey(e->q[G_SPECCOL], 3, -1));
        json_object_set_new(ext, "KHR_materials_specular", sp);
        if (e->q[G_IOR] != 1.5) {
            json_t *ior = json_object();
            json_object_set_new(ior, "ior", json_real(e->q[G_IOR]));
            json_object_set_new(ext, "KHR_materials_ior", ior);
            any_ior = true;
        }
        json_object_set_new(m, "extensions", ext);
        json_t *extras = json_object();
        json_object_set_new(extras, "refl_conversion", conversion_json(e));
        json_object_set_new(m, "extras", extras);
        json_array_append_new(mats, m);
    }
    json_array_append_new(used, json_string("KHR_materials_specular"));
    if (any_ior) json_array_append_new(used, json_string("KHR_materials_ior"));
    json_object_set_new(root, "extensionsUsed", used);
    json_object_set_new(root, "materials", mats);
    return root;
}

// XML-safe text of a name (priors names are short identifiers, but may hold anything).
static void xml_text(GString *g, const char *s)
{
    for (; *s; s++) {
        if (*s == '&') g_string_append(g, "&amp;");
        else if (*s == '<') g_string_append(g, "&lt;");
        else if (*s == '>') g_string_append(g, "&gt;");
        else if (*s == '"') g_string_append(g, "&quot;");
        else if (*s == '-' && s[1] == '-') g_string_append(g, "-&#45;");   // also safe in the comments
        else if ((unsigned char)*s >= 0x20) g_string_append_c(g, *s);
    }
}

static char *mitsuba_xml(const fit_export_result_t *r)
{
    GString *g = g_string_new("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    g_string_append_printf(g, "<!-- refl %s (refl export material): Mitsuba 3 BSDFs of refl's fitted materials -->\n"
                           "<scene version=\"3.0.0\">\n", REFL_VERSION);
    for (int i = 0; i < r->n; i++) {
        const fit_export_material_t *e = &r->m[i];
        bool plastic = !strcmp(e->target, "mitsuba roughplastic");
        g_string_append(g, "    <!-- ");
        xml_text(g, e->name);
        g_string_append_printf(g, ": refl %s; Ngan error %.4g 1/sr (%.2f %% of the model's RMS f cos theta_i); %s: "
                               "%.4g 1/sr -->\n", model_brdf_name(e->model), e->error, 100 * e->rel_error,
                               e->alt_target, e->alt_error);
        g_string_append_printf(g, "    <bsdf type=\"%s\" id=\"", e->target + strlen("mitsuba "));
        xml_text(g, e->name);
        if (!strcmp(e->target, "mitsuba diffuse")) {
            g_string_append_printf(g, "\">\n        <rgb name=\"reflectance\" value=\"%.9g, %.9g, %.9g\"/>\n"
                                   "    </bsdf>\n", e->q[0], e->q[0], e->q[0]);
            continue;
        }
        g_string_append_printf(g, "\">\n        <string name=\"distribution\" value=\"ggx\"/>\n"
                               "        <float name=\"alpha\" value=\"%.9g\"/>\n", e->q[M_ALPHA]);
        if (plastic)
            g_string_append_printf(g, "        <float name=\"int_ior\" value=\"%.9g\"/>\n"
                                   "        <float name=\"ext_ior\" value=\"1\"/>\n"
                                   "        <boolean name=\"nonlinear\" value=\"false\"/>\n"
                                   "        <rgb name=\"diffuse_reflectance\" value=\"%.9g, %.9g, %.9g\"/>\n",
                                   e->q[M_IOR], e->q[M_DIFF], e->q[M_DIFF], e->q[M_DIFF]);
        else
            g_string_append_printf(g, "        <float name=\"eta\" value=\"%.9g\"/>\n"
                                   "        <float name=\"k\" value=\"0\"/>\n", e->q[M_IOR]);
        g_string_append_printf(g, "        <rgb name=\"specular_reflectance\" value=\"%.9g, %.9g, %.9g\"/>\n"
                               "    </bsdf>\n", e->q[M_SPEC], e->q[M_SPEC], e->q[M_SPEC]);
    }
    g_string_append(g, "</scene>\n");
    return g_string_free(g, FALSE);
}

static bool write_target(const verify_priors_t *pr, fit_export_format_t fmt, const char *out,
                         const fit_export_result_t *r)
{
    if (fmt == FIT_EXPORT_GLTF) {
        json_t *j = gltf_json(r);
        bool ok = model_write_json(out, j);
        json_decref(j);
        return ok;
    }
    if (fmt == FIT_EXPORT_MITSUBA) {
        char *x = mitsuba_xml(r);
        bool ok = model_write_file_atomic(out, x);
        g_free(x);
        return ok;
    }
    const verify_prior_t *m = verify_priors_find(pr, r->m[0].name);
    model_brdf_table_t *t = fit_export_tabulate(m);
    bool ok = t && model_brdf_table_save(t, out);
    model_brdf_table_free(t);
    return ok;
}

bool fit_export_materials(const char *priors, const char *only, fit_export_format_t fmt, const char *out,
                          json_t *prov, fit_export_result_t *res)
{
    memset(res, 0, sizeof *res);
    verify_priors_t pr = { 0 };
    bool ok = verify_priors_load(&pr, priors);
    if (ok && only && !verify_priors_find(&pr, only)) {
        GString *names = g_string_new("");
        for (int i = 0; i < pr.n; i++) g_string_append_printf(names, "%s%s", i ? ", " : "", pr.m[i].name);
        model_error(priors, 0, "no material %s here (it has %s)", only, names->str);
        g_string_free(names, TRUE);
        ok = false;
    }
    if (ok && fmt == FIT_EXPORT_MERL && !only && pr.n > 1) {
        model_error(priors, 0, "%d materials: a MERL table holds one; choose it with --material NAME", pr.n);
        ok = false;
    }
    if (ok && !(res->m = calloc((size_t)pr.n, sizeof *res->m))) {
        model_error(NULL, 0, "out of memory");
        ok = false;
    }
    for (int i = 0; ok && i < pr.n; i++)
        if (!only || !strcmp(only, pr.m[i].name)) ok = fit_export_convert(&pr.m[i], fmt, &res->m[res->n++]);
    ok = ok && write_target(&pr, fmt, out, res);
    if (ok) {
        json_t *side = json_object(), *list = json_array();
        model_json_set_format(side, "refl-export", 1);
        json_object_set_new(side, "file", json_string(out));
        for (int i = 0; i < res->n; i++) json_array_append_new(list, conversion_json(&res->m[i]));
        json_object_set_new(side, "materials", list);
        if (prov) json_object_set(side, "provenance", prov);
        char *path = g_strdup_printf("%s.conversion.json", out);
        ok = model_write_json(path, side);
        g_free(path);
        json_decref(side);
    }
    verify_priors_free(&pr);
    return ok;
}
