// fit/priors.c — the priors file ("refl-priors", fit/priors.h): its one reader
// (the materials' priors for refl verify, refl plan lamps, refl export material,
// the studies), its writer (a material's entry from a BRDF fit) and the
// multivariate Gaussian a prior's covariance makes.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/priors.h"
#include "model/base/report.h"

// ---------------------------------------------------------------------------
// Priors

void verify_priors_free(verify_priors_t *pr)
{
    if (!pr) return;
    free(pr->m);
    pr->m = NULL;
    pr->n = 0;
}

const verify_prior_t *verify_priors_find(const verify_priors_t *pr, const char *name)
{
    for (int i = 0; i < pr->n; i++)
        if (!strcmp(pr->m[i].name, name)) return &pr->m[i];
    return NULL;
}

static verify_prior_t *priors_push(verify_priors_t *pr)
{
    verify_prior_t *m = realloc(pr->m, (size_t)(pr->n + 1) * sizeof *m);
    if (!m) return NULL;
    pr->m = m;
    memset(&m[pr->n], 0, sizeof *m);
    return &m[pr->n++];
}

static double jnum(json_t *o, const char *key, double def)
{
    json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : def;
}

static bool priors_from_json(verify_priors_t *pr, json_t *root, const char *path, const char *sha);

bool verify_priors_load(verify_priors_t *pr, const char *path)
{
    size_t len = 0;
    char *text = model_read_file(path, &len);
    if (!text) return false;
    bool ok = verify_priors_parse(pr, text, len, path);
    free(text);
    return ok;
}

bool verify_priors_parse(verify_priors_t *pr, const char *text, size_t len, const char *path)
{
    json_error_t je;
    json_t *root = json_loadb(text, len, 0, &je);
    if (!root) {
        model_error(path, je.line, "not a readable JSON priors file: %s", je.text);
        return false;
    }
    char sha[65] = "";
    model_sha256_hex(text, len, sha);
    bool ok = priors_from_json(pr, root, path, sha);
    json_decref(root);
    return ok;
}

// The entry's "prior_covariance" (absent: independent std): its parameters
// in the model's order and an np x np symmetric matrix of finite numbers with
// a non-negative diagonal. false + message.
static bool prior_cov_from_json(verify_prior_t *p, json_t *pc, const char *path)
{
    p->has_cov = false;
    if (!pc) return true;
    json_t *names = json_object_get(pc, "parameters"), *mat = json_object_get(pc, "matrix");
    int np = p->np;
    bool ok = json_is_array(names) && json_is_array(mat) && (int)json_array_size(names) == np &&
              (int)json_array_size(mat) == np;
    for (int a = 0; ok && a < np; a++) {
        const char *n = json_string_value(json_array_get(names, a));
        json_t *row = json_array_get(mat, a);
        ok = n && !strcmp(n, model_brdf_param_name(p->model, a)) && json_is_array(row) &&
             (int)json_array_size(row) == np;
        for (int b = 0; ok && b < np; b++) {
            json_t *v = json_array_get(row, b);
            ok = json_is_number(v) && isfinite(json_number_value(v));
            if (ok) p->cov[a * np + b] = json_number_value(v);
        }
    }
    for (int a = 0; ok && a < np; a++) {
        ok = p->cov[a * np + a] >= 0;
        for (int b = 0; ok && b < a; b++)
            ok = fabs(p->cov[a * np + b] - p->cov[b * np + a]) <=
                 1e-9 * (fabs(p->cov[a * np + b]) + fabs(p->cov[b * np + a])) + 1e-300;
    }
    if (!ok) {
        model_error(path, 0, "material %s: \"prior_covariance\" must hold \"parameters\" (the %s model's, in its order) "
                    "and \"matrix\", %d x %d symmetric finite numbers with a diagonal >= 0", p->name,
                    model_brdf_name(p->model), np, np);
        return false;
    }
    p->has_cov = true;
    return true;
}

bool verify_mvprior_make(const verify_prior_t *P, const bool *use, verify_mvprior_t *out)
{
    memset(out, 0, sizeof *out);
    if (!P->has_cov) return false;
    out->np = P->np;
    for (int j = 0; j < P->np; j++)
        if (use[j]) {
            out->idx[out->n] = j;
            out->mean[out->n++] = P->mean[j];
        }
    int n = out->n;
    if (n < 2) return false;
    // Cholesky of Sigma_S, then L^-1 by forward substitution
    double L[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS] = { 0 };
    for (int a = 0; a < n; a++)
        for (int b = 0; b <= a; b++) {
            double s = P->cov[out->idx[a] * P->np + out->idx[b]];
            for (int k = 0; k < b; k++) s -= L[a * n + k] * L[b * n + k];
            if (a == b) {
                if (!(s > 1e-12 * fmax(P->cov[out->idx[a] * P->np + out->idx[a]], 1e-300))) return false;
                L[a * n + a] = sqrt(s);
            } else {
                L[a * n + b] = s / L[b * n + b];
            }
        }
    for (int c = 0; c < n; c++)
        for (int a = c; a < n; a++) {
            double s = a == c ? 1 : 0;
            for (int k = c; k < a; k++) s -= L[a * n + k] * out->Linv[k * n + c];
            out->Linv[a * n + c] = s / L[a * n + a];
        }
    return true;
}

bool verify_mvprior_residual(void *ctx, const double *const *p, double *r, double **J)
{
    const verify_mvprior_t *m = ctx;
    for (int a = 0; a < m->n; a++) {
        double s = 0;
        for (int b = 0; b <= a; b++) s += m->Linv[a * m->n + b] * (p[0][m->idx[b]] - m->mean[b]);
        r[a] = s;
        if (J && J[0]) {
            for (int q = 0; q < m->np; q++) J[0][a * m->np + q] = 0;
            for (int b = 0; b <= a; b++) J[0][a * m->np + m->idx[b]] = m->Linv[a * m->n + b];
        }
    }
    return true;
}

bool fit_priors_check_format(const json_t *root, const char *path, int *version)
{
    const char *fmt = json_string_value(json_object_get(root, "format"));
    if (json_is_object(root) && fmt && !strcmp(fmt, FIT_PRIORS_FORMAT_V1_NAME)) {
        *version = 1;
        return true;
    }
    return model_json_format_check(root, path, FIT_PRIORS_FORMAT, FIT_PRIORS_VERSION, version);
}

static bool priors_version(const json_t *root, const char *path, int *version)
{
    if (!fit_priors_check_format(root, path, version)) {
        model_error(NULL, 0, "%s", model_last_error());
        return false;
    }
    return true;
}

static bool priors_from_json(verify_priors_t *pr, json_t *root, const char *path, const char *sha)
{
    bool ok = false;
    json_t *mats = json_object_get(root, "materials");
    int version = 0;
    if (!priors_version(root, path, &version)) goto done;
    if (!json_is_array(mats) || !json_array_size(mats)) {
        model_error(path, 0, "no \"materials\" list: not a refl priors file (refl fit material / refl fit brdf "
                    "write them)");
        goto done;
    }
    for (size_t i = 0; i < json_array_size(mats); i++) {
        json_t *m = json_array_get(mats, i);
        const char *name = json_string_value(json_object_get(m, "name"));
        const char *model = json_string_value(json_object_get(m, "model"));
        json_t *ps = json_object_get(m, "parameters");
        if (!name || !name[0] || strlen(name) >= 64 || !model || !json_is_array(ps)) {
            model_error(path, 0, "materials[%zu]: needs \"name\" (under 64 characters), \"model\" and \"parameters\"",
                        i);
            goto done;
        }
        int mi = model_brdf_from_name(model);
        if (mi < 0) {
            model_error(path, 0, "material %s: unknown model '%s'", name, model);
            goto done;
        }
        const verify_prior_t *old = verify_priors_find(pr, name);
        if (old) {
            model_error(path, 0, "material %s is also in %s: give each material's priors once", name, old->source);
            goto done;
        }
        verify_prior_t *p = priors_push(pr);
        if (!p) {
            model_error(path, 0, "out of memory");
            goto done;
        }
        snprintf(p->name, sizeof p->name, "%s", name);
        snprintf(p->source, sizeof p->source, "%s", path);
        snprintf(p->sha256, sizeof p->sha256, "%s", sha);
        p->version = version;
        p->model = (model_brdf_t)mi;
        p->np = model_brdf_nparams(p->model);
        for (int j = 0; j < p->np; j++) {
            const char *pn = model_brdf_param_name(p->model, j);
            json_t *e = NULL;
            for (size_t k = 0; k < json_array_size(ps); k++) {
                const char *n = json_string_value(json_object_get(json_array_get(ps, k), "name"));
                if (n && !strcmp(n, pn)) e = json_array_get(ps, k);
            }
            double lo, hi;
            model_brdf_param_range(p->model, j, &lo, &hi);
            if (!e || !json_is_number(json_object_get(e, "mean"))) {
                model_error(path, 0, "material %s (%s): parameter %s is missing or has no \"mean\"", name, model, pn);
                goto done;
            }
            double mean = jnum(e, "mean", NAN), sd = jnum(e, "std", INFINITY);
            double blo = jnum(e, "lo", lo), bhi = jnum(e, "hi", hi);
            if (!isfinite(mean) || mean < lo || mean > hi || !(sd >= 0) || !(blo <= mean && mean <= bhi)) {
                model_error(path, 0, "material %s: parameter %s: mean %g must lie in its bounds [%g, %g] and the "
                            "physical range [%g, %g], std %g >= 0", name, pn, mean, blo, bhi, lo, hi, sd);
                goto done;
            }
            p->mean[j] = mean;
            p->std[j] = sd;
            p->lo[j] = fmax(blo, lo);
            p->hi[j] = fmin(bhi, hi);
            // held: std 0, or a "held" note (a parameter the material's samples
            // could not measure, e.g. F0 known only to lie in [lo, hi])
            p->held[j] = sd == 0 || json_is_string(json_object_get(e, "held"));
        }
        if (!prior_cov_from_json(p, json_object_get(m, "prior_covariance"), path)) goto done;
        // a window's relative spread about the model (refl fit material; absent or null: not known)
        json_t *wr = json_object_get(m, "window_rel_std");
        p->window_rel = NAN;
        if (wr && !json_is_null(wr)) {
            if (!json_is_number(wr) || !(json_number_value(wr) >= 0) || json_number_value(wr) > 10) {
                model_error(path, 0, "material %s: window_rel_std must be a number in [0, 10] (a relative spread)",
                            name);
                goto done;
            }
            p->window_rel = json_number_value(wr);
        }
    }
    ok = true;
done:
    return ok;
}

bool verify_priors_add(verify_priors_t *pr, const model_material_t *mat, double rel, double abs_min, double k)
{
    if (verify_priors_find(pr, mat->name)) {
        model_error(NULL, 0, "priors: material %s given twice", mat->name);
        return false;
    }
    verify_prior_t *p = priors_push(pr);
    if (!p) {
        model_error(NULL, 0, "priors: out of memory");
        return false;
    }
    snprintf(p->name, sizeof p->name, "%s", mat->name);
    snprintf(p->source, sizeof p->source, "(known values, std %g %%)", rel * 100);
    p->model = mat->model;
    p->window_rel = NAN;
    p->np = model_brdf_nparams(mat->model);
    for (int j = 0; j < p->np; j++) {
        double lo, hi;
        model_brdf_param_range(mat->model, j, &lo, &hi);
        p->mean[j] = mat->p[j];
        p->std[j] = fmax(rel * fabs(mat->p[j]), abs_min);
        p->lo[j] = fmax(lo, mat->p[j] - k * p->std[j]);
        p->hi[j] = fmin(hi, mat->p[j] + k * p->std[j]);
    }
    return true;
}

bool verify_match_priors(const model_scene_t *scene, const verify_priors_t *pr, const verify_prior_t **out)
{
    for (int k = 0; k < scene->nmaterials; k++) {
        out[k] = verify_priors_find(pr, scene->material_names[k]);
        if (!out[k]) {
            char have[512] = "";
            for (int i = 0; i < pr->n; i++)
                snprintf(have + strlen(have), sizeof have - strlen(have), "%s%s", i ? ", " : "", pr->m[i].name);
            model_error(scene->path, 0, "the description's material '%s' has no priors (the priors hold: %s); fit "
                        "it with refl fit material, or name the faces' material as the priors do",
                        scene->material_names[k], have[0] ? have : "none");
            return false;
        }
    }
    return true;
}

bool verify_priors_means(const model_scene_t *scene, const verify_priors_t *pr, model_material_t *mm,
                         const model_material_t **mats)
{
    const verify_prior_t **pp = calloc((size_t)scene->nmaterials + 1, sizeof *pp);
    if (!pp) model_error(NULL, 0, "out of memory");
    bool ok = pp && verify_match_priors(scene, pr, pp);
    for (int k = 0; ok && k < scene->nmaterials; k++) {
        memset(&mm[k], 0, sizeof mm[k]);
        snprintf(mm[k].name, sizeof mm[k].name, "%s", pp[k]->name);
        mm[k].model = pp[k]->model;
        memcpy(mm[k].p, pp[k]->mean, sizeof mm[k].p);
        mats[k] = &mm[k];
    }
    free(pp);
    return ok;
}

// ---------------------------------------------------------------------------
// Units and conventions

const char *fit_param_unit(model_brdf_t m, int i)
{
    const char *p = model_brdf_param_name(m, i);
    if (!p) return "";
    bool phys = model_brdf_is_physical(m);
    if (!strcmp(p, "kd")) return phys ? "1 (albedo)" : "1/sr (albedo/pi)";
    if (!strcmp(p, "Rd")) return "1 (reflectance)";
    if (!strcmp(p, "ks") || !strcmp(p, "ks2")) return phys ? "1" : "1/sr";
    return "1";
}

const char *fit_param_convention(model_brdf_t m, int i)
{
    const char *p = model_brdf_param_name(m, i);
    if (!p) return "";
    bool phys = model_brdf_is_physical(m);
    if (!strcmp(p, "kd"))
        return phys ? "diffuse albedo (the model divides by pi)" : "thesis coefficient kd = albedo/pi";
    if (!strcmp(p, "ks"))
        return m == MODEL_BRDF_GGX2 ? "weight of the sharper specular lobe" : "weight of the specular lobe";
    if (!strcmp(p, "ks2")) return "weight of the broader specular lobe";
    if (!strcmp(p, "Rd")) return "diffuse reflectance (Ashikhmin-Shirley; the model divides by pi and scales by 1-Rs)";
    if (!strcmp(p, "Rs")) return "specular reflectance at normal incidence (Ashikhmin-Shirley; also Schlick's F0)";
    if (!strcmp(p, "ns"))
        return m == MODEL_BRDF_ASHIKHMIN_SHIRLEY ? "Phong exponent of (n.h), normalised by (ns+1)/(8 pi)"
                                                 : "Blinn cosine exponent of (n.h)";
    if (!strcmp(p, "alpha2")) return "GGX alpha of the broader lobe (alpha2 >= alpha; not perceptual roughness)";
    if (!strcmp(p, "F0")) return "Schlick Fresnel reflectance at normal incidence";
    if (!strcmp(p, "m")) return "Beckmann rms microfacet slope";
    if (!strcmp(p, "alpha")) return "GGX alpha (not perceptual roughness; alpha = r^2)";
    return "";
}

// ---------------------------------------------------------------------------
// Writing: the document, and a material's entry from a BRDF fit

json_t *fit_priors_document(void)
{
    json_t *top = json_object();
    model_json_set_format(top, FIT_PRIORS_FORMAT, FIT_PRIORS_VERSION);
    json_object_set_new(top, "units", json_string("R = f_r cos(theta_i) in 1/sr; parameter units per parameter"));
    return top;
}

// A parameter the photometric scale multiplies (R linear in it): kd, ks, ks2, Rd.
static bool amplitude_param(const char *n)
{
    return !strcmp(n, "kd") || !strcmp(n, "ks") || !strcmp(n, "ks2") || !strcmp(n, "Rd");
}

void fit_prior_covariance(const fit_brdf_result_t *best, double sys_rel, double *C)
{
    model_brdf_t m = best->model;
    int np = best->nparams;
    for (int a = 0; a < np; a++)
        for (int b = 0; b < np; b++) {
            const char *na = model_brdf_param_name(m, a), *nb = model_brdf_param_name(m, b);
            bool fa = (best->f0_unmeasured && !strcmp(na, "F0")) || best->held_free[a];
            bool fb = (best->f0_unmeasured && !strcmp(nb, "F0")) || best->held_free[b];
            bool ha = best->fixed[a] && !fa, hb = best->fixed[b] && !fb;
            double c = ha || hb ? 0 : best->cov[a * np + b];
            if (!ha && !hb && !fa && !fb) {
                double ma = best->p[a], mb = best->p[b];
                if (a == b) c += sys_rel * sys_rel * ma * ma;
                else if (amplitude_param(na) && amplitude_param(nb)) c += sys_rel * sys_rel * ma * mb;
            }
            if (!ha && !hb && best->groups_ok) c += best->cov_groups[a * np + b];
            C[a * np + b] = c;
        }
}

double fit_prior_std(const fit_brdf_result_t *best, double sys_rel, int j)
{
    model_brdf_t m = best->model;
    int np = best->nparams;
    bool f0u = best->f0_unmeasured && !strcmp(model_brdf_param_name(m, j), "F0"), hf = best->held_free[j];
    if (best->fixed[j] && !f0u && !hf) return 0;
    double sd_stat = best->std[j], mean = best->p[j];
    double var_lamps = best->groups_ok ? best->cov_groups[j * np + j] : 0;
    double shared = f0u || hf ? 0 : sys_rel * mean;
    return sqrt(sd_stat * sd_stat + shared * shared + var_lamps);
}

static json_t *prior_covariance_json(const fit_brdf_result_t *best, double sys_rel)
{
    int np = best->nparams;
    double C[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    fit_prior_covariance(best, sys_rel, C);
    for (int a = 0; a < np * np; a++)
        if (!isfinite(C[a])) return NULL;   // no covariance from the fit: the std alone (independent)
    json_t *o = json_object(), *names = json_array(), *mat = json_array();
    for (int a = 0; a < np; a++) {
        json_array_append_new(names, json_string(model_brdf_param_name(best->model, a)));
        json_t *row = json_array();
        for (int b = 0; b < np; b++) json_array_append_new(row, json_real(C[a * np + b]));
        json_array_append_new(mat, row);
    }
    json_object_set_new(o, "parameters", names);
    json_object_set_new(o, "matrix", mat);
    json_object_set_new(o, "model", json_string(
        "the fit's covariance (\"covariance\", statistical) plus the systematic part: one photometric scale "
        "(kc*I, the white) shared by every sample multiplies R, so the parameters R is linear in (kd, ks, ks2, Rd) "
        "move together: systematic_rel^2 mean_a mean_b between them (fully correlated); every other parameter "
        "gets (systematic_rel mean)^2 on its diagonal alone (geometric errors: pose, lamp positions); with "
        "lamp_systematic, each lamp's own photometric scale (its kc*I, emission pattern and position) of relative "
        "std lamp_systematic.rel carried through the fit (sum over the lamps of dp dp^T, dp the parameters' change "
        "when that lamp's samples alone scale by rel). A held parameter has 0 rows and columns; F0 held over its "
        "interval keeps its uniform's variance along ks*F0 = const. The diagonal is each parameter's std^2"));
    return o;
}

json_t *fit_priors_material(const char *name, const fit_brdf_result_t *best, const fit_brdf_result_t *cand,
                            int ncand, double k_sigma, double sys_rel)
{
    model_brdf_t m = best->model;
    int np = best->nparams;
    json_t *o = json_object();
    json_object_set_new(o, "name", json_string(name));
    json_object_set_new(o, "model", json_string(model_brdf_name(m)));
    json_object_set_new(o, "convention", json_string(model_brdf_convention(m)));
    json_t *ps = json_array();
    for (int j = 0; j < np; j++) {
        json_t *p = json_object();
        bool f0u = best->f0_unmeasured && !strcmp(model_brdf_param_name(m, j), "F0"), hf = best->held_free[j];
        double lo, hi, mean = best->p[j], sd_stat = best->fixed[j] && !f0u && !hf ? 0 : best->std[j];
        double var_lamps = best->groups_ok && !(best->fixed[j] && !f0u && !hf) ? best->cov_groups[j * np + j] : 0;
        double sd = fit_prior_std(best, sys_rel, j);
        model_brdf_param_range(m, j, &lo, &hi);
        if (f0u) lo = best->f0_lo, hi = best->f0_hi;
        if (hf) lo = best->free_lo[j], hi = best->free_hi[j];
        double blo = isfinite(sd) ? fmax(lo, mean - k_sigma * sd) : lo;
        double bhi = isfinite(sd) ? fmin(hi, mean + k_sigma * sd) : hi;
        json_object_set_new(p, "name", json_string(model_brdf_param_name(m, j)));
        json_object_set_new(p, "unit", json_string(fit_param_unit(m, j)));
        json_object_set_new(p, "convention", json_string(fit_param_convention(m, j)));
        json_object_set_new(p, "mean", json_real(mean));
        json_object_set_new(p, "std", isfinite(sd) ? json_real(sd) : json_null());
        json_object_set_new(p, "std_statistical", isfinite(sd_stat) ? json_real(sd_stat) : json_null());
        if (best->shared_done || best->groups_ok) {
            // sd^2 = the parts' squares summed
            json_t *parts = json_object();
            bool held = best->fixed[j] && !f0u && !hf;
            json_object_set_new(parts, "statistical", isfinite(sd_stat) ? json_real(sd_stat) : json_null());
            json_object_set_new(parts, "lamps", json_real(sqrt(var_lamps)));
            json_object_set_new(parts, "shared", json_real(held || f0u || hf ? 0 : fabs(sys_rel * mean)));
            if (best->shared_done)
                json_object_set_new(parts, "statistical_chi2_scaled",
                                    isfinite(best->std_chi2[j]) && !held ? json_real(best->std_chi2[j]) : json_null());
            json_object_set_new(p, "std_parts", parts);
        }
        json_object_set_new(p, "lo", json_real(blo));
        json_object_set_new(p, "hi", isfinite(bhi) ? json_real(bhi) : json_null());
        json_object_set_new(p, "barely_constrained",
                            json_boolean(fit_priors_barely_constrained(mean, sd, blo, bhi, NULL, NULL)));
        if (f0u)
            json_object_set_new(p, "held", json_string("not measured: the samples never see Schlick's F change "
                                                       "enough (too far from grazing) and only ks*F0 is measured; "
                                                       "F0 lies in [lo, hi] (ks at most its maximum), mean and "
                                                       "std are a uniform's over it, ks = ks*F0 / F0; a fitter "
                                                       "holds it at mean"));
        else if (hf)
            json_object_set_new(p, "held", json_string("no effect on R over these samples (as ggx2's alpha2 when "
                                                       "ks2 is 0): any value in [lo, hi] fits alike; mean and std "
                                                       "are a uniform's over it; a fitter holds it at mean"));
        else if (best->fixed[j])
            json_object_set_new(p, "held", json_string("not separable from the other parameters by these samples; "
                                                       "held at its best value (std 0)"));
        json_array_append_new(ps, p);
    }
    json_object_set_new(o, "parameters", ps);
    json_t *cov = json_array();
    for (int a = 0; a < np; a++) {
        json_t *row = json_array();
        for (int b = 0; b < np; b++) {
            double c = best->cov[a * np + b];
            json_array_append_new(row, isfinite(c) ? json_real(c) : json_null());
        }
        json_array_append_new(cov, row);
    }
    json_object_set_new(o, "covariance", cov);
    json_t *pc = prior_covariance_json(best, sys_rel);
    if (pc) json_object_set_new(o, "prior_covariance", pc);
    json_object_set_new(o, "bounds_k_sigma", json_real(k_sigma));
    json_object_set_new(o, "systematic_rel", json_real(sys_rel));
    int jF = model_brdf_param_index(m, "F0"), jk = model_brdf_param_index(m, "ks");
    if (jF >= 0 && jk >= 0) json_object_set_new(o, "ks_times_F0", json_real(best->p[jk] * best->p[jF]));
    int jk2 = model_brdf_param_index(m, "ks2");
    if (jF >= 0 && jk2 >= 0) json_object_set_new(o, "ks2_times_F0", json_real(best->p[jk2] * best->p[jF]));
    json_object_set_new(o, "rms", json_real(best->rms));
    json_object_set_new(o, "rms_unit", json_string("1/sr, of R = f_r cos(theta_i)"));
    json_object_set_new(o, "ngan_error", json_real(best->ngan_error));
    json_object_set_new(o, "rms_fr", json_real(best->rms_fr));
    json_object_set_new(o, "aic", json_real(best->aic));
    json_object_set_new(o, "bic", json_real(best->bic));
    json_object_set_new(o, "cv_rms", isfinite(best->cv_rms) ? json_real(best->cv_rms) : json_null());
    json_object_set_new(o, "cv_rms_se", isfinite(best->cv_se) ? json_real(best->cv_se) : json_null());
    json_object_set_new(o, "n_samples", json_integer(best->n));
    json_object_set_new(o, "iterations", json_integer(best->summary.iterations));
    json_object_set_new(o, "termination", json_string(best->summary.termination));
    if (cand && ncand > 0) {
        json_t *arr = json_array();
        for (int c = 0; c < ncand; c++) {
            json_t *e = json_object();
            json_object_set_new(e, "model", json_string(model_brdf_name(cand[c].model)));
            json_object_set_new(e, "rms", json_real(cand[c].rms));
            json_object_set_new(e, "aic", json_real(cand[c].aic));
            json_object_set_new(e, "bic", json_real(cand[c].bic));
            json_object_set_new(e, "cv_rms", isfinite(cand[c].cv_rms) ? json_real(cand[c].cv_rms) : json_null());
            json_object_set_new(e, "cv_rms_se", isfinite(cand[c].cv_se) ? json_real(cand[c].cv_se) : json_null());
            json_t *pv = json_object();
            for (int j = 0; j < cand[c].nparams; j++)
                json_object_set_new(pv, model_brdf_param_name(cand[c].model, j), json_real(cand[c].p[j]));
            json_object_set_new(e, "parameters", pv);
            json_array_append_new(arr, e);
        }
        json_object_set_new(o, "candidates", arr);
    }
    return o;
}

bool fit_priors_barely_constrained(double mean, double sd, double lo, double hi, double *of_value, double *of_width)
{
    double w = hi - lo;
    if (of_value) *of_value = mean != 0 && isfinite(sd) ? sd / fabs(mean) : NAN;
    if (of_width) *of_width = w > 0 && isfinite(w) && isfinite(sd) ? sd / w : NAN;
    return isfinite(sd) && sd > 0 &&
           (sd > FIT_PRIORS_LOOSE_SHARE * fabs(mean) || (w > 0 && isfinite(w) && sd > FIT_PRIORS_LOOSE_SHARE * w));
}
