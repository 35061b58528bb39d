// fit/verify/verify.c — the verification fitter (see verify.h for the model).
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/brdf.h"
#include "fit/verify/verify.h"
#include "fit/verify/footprint.h"
#include "model/base/vec.h"

#define MAX_LAMPS 32

verify_options_t verify_defaults(void)
{
    return (verify_options_t){
        .spacing_px = 8,
        .window_px = 5,
        .edge_margin_px = 2,
        .boundary_margin_px = 4,
        .edge_k = 3,
        .edge_rel = 0.05,
        .edge_windows = true,
        .edge_subsamples = 5,
        .edge_position_sigma_px = 0.1,
        .ir_samples = 64,
        .use_priors = true,
        .use_flat = true,
        .model_rel = 0.04,
        .lamp_sigma = 0.1,
        .camera_sigma = 0.1,
        .pa_sigma_dn = 5,
        .robust_scale = 3,
        .z_flag = 4,
        .min_region = 3,
        .score_threshold = 400,
        .max_iterations = 100,
    };
}

const char *verify_pt_status_name(verify_pt_status_t s)
{
    static const char *names[] = { "used", "background", "near_edge", "boundary", "saturated", "edge_measured" };
    return (unsigned)s < VERIFY_PT_NSTATUS ? names[s] : "?";
}

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

// The entry's "prior_covariance" (absent: independent std, as files before
// it): its parameters in the model's order and an np x np symmetric matrix
// of finite numbers with a non-negative diagonal. false + message.
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

static bool priors_from_json(verify_priors_t *pr, json_t *root, const char *path, const char *sha)
{
    bool ok = false;
    json_t *mats = json_object_get(root, "materials");
    const char *fmt = json_string_value(json_object_get(root, "format"));
    if (fmt && strcmp(fmt, "refl priors 1")) {
        model_error(path, 0, "format '%s' is not 'refl priors 1'", fmt);
        goto done;
    }
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
    if (!p) return false;
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

// ---------------------------------------------------------------------------
// Views

struct verify_view {
    int W, H, gw, gh, sp, x0, y0, nl;
    model_scene_t *rot;
    model_tracer_t *t;
    model_pixel_info_t *pi;     // gw*gh
    model_lamp_sample_t *ls;    // gw*gh*nl
    uint8_t *status;            // geometric status (USED, BACKGROUND, NEAR_EDGE, BOUNDARY)
    float *B;                   // gw*gh*nl: interreflection basis per unit A_i
    float *Bsd;                 // gw*gh*nl: its Monte Carlo estimate's standard error
    verify_footprints_t fp;     // the windows near edges modelled with footprint and blur (USED, fp.first >= 0)
    int nusable;
    double time_s;
};

int    verify_view_npoints(const verify_view_t *v) { return v ? v->nusable : 0; }
double verify_view_time_s(const verify_view_t *v) { return v ? v->time_s : 0; }

void verify_view_free(verify_view_t *v)
{
    if (!v) return;
    model_tracer_free(v->t);
    model_scene_free(v->rot);
    free(v->pi);
    free(v->ls);
    free(v->status);
    free(v->B);
    free(v->Bsd);
    verify_footprints_free(&v->fp);
    free(v);
}

static uint32_t lit_bits(const model_lamp_sample_t *ls, int nl)
{
    uint32_t b = 0;
    for (int i = 0; i < nl; i++)
        if (ls[i].V > 0.5) b |= 1u << i;
    return b;
}

static double seg_dist(double px, double py, const double a[2], const double b[2])
{
    double dx = b[0] - a[0], dy = b[1] - a[1], L2 = dx * dx + dy * dy;
    double t = L2 > 0 ? ((px - a[0]) * dx + (py - a[1]) * dy) / L2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = a[0] + t * dx - px, ey = a[1] + t * dy - py;
    return sqrt(ex * ex + ey * ey);
}

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
    ir_ctx_t ic = { t, lamps, mats, samples, pi, NULL, B, 0x1e5f, Bsd };
    model_parallel_for(n, 64, threads > 0 ? threads : model_default_threads(), ir_rows, &ic);
}

// Grid points within reach (px) of a predicted edge (model_edges_predict):
// USED -> NEAR_EDGE. q: the points' pixel coordinates. false + message.
static bool view_near_edges(verify_view_t *v, const verify_camera_t *cam, const model_lamps_t *lamps,
                            const model_material_t *const *mats, const double *q, double reach, int threads)
{
    model_shading_t sh = model_shading_default();
    sh.nthreads = threads;
    model_edges_t *ed = model_edges_predict(v->rot, v->t, cam->cam, lamps, mats, &sh, 1.0);
    if (!ed) return false;
    for (int e = 0; e < ed->nedges; e++)
        for (int s = 0; s < ed->edges[e].nsegments; s++) {
            const model_edge_segment_t *sg = &ed->edges[e].segments[s];
            double xa = fmin(sg->q0[0], sg->q1[0]) - reach, xb = fmax(sg->q0[0], sg->q1[0]) + reach;
            double ya = fmin(sg->q0[1], sg->q1[1]) - reach, yb = fmax(sg->q0[1], sg->q1[1]) + reach;
            int i0 = (int)floor((xa - v->x0) / v->sp), i1 = (int)ceil((xb - v->x0) / v->sp);
            int j0 = (int)floor((ya - v->y0) / v->sp), j1 = (int)ceil((yb - v->y0) / v->sp);
            if (i0 < 0) i0 = 0;
            if (j0 < 0) j0 = 0;
            if (i1 > v->gw - 1) i1 = v->gw - 1;
            if (j1 > v->gh - 1) j1 = v->gh - 1;
            for (int j = j0; j <= j1; j++)
                for (int i = i0; i <= i1; i++) {
                    int g = j * v->gw + i;
                    if (v->status[g] == VERIFY_PT_USED &&
                        seg_dist(q[2 * g], q[2 * g + 1], sg->q0, sg->q1) <= reach)
                        v->status[g] = VERIFY_PT_NEAR_EDGE;
                }
        }
    model_edges_free(ed);
    return true;
}

// Face or shadow changes within the window (+ margin, c px from its centre):
// where a neighbour differs, look at the window's corners and edge midpoints;
// USED -> BOUNDARY. cand: room for the grid's points. false + message.
static bool view_boundaries(verify_view_t *v, const verify_camera_t *cam, const model_lamps_t *lamps,
                            const double *q, int c, int threads, int *cand)
{
    const int nl = v->nl;
    int ncand = 0;
    for (int j = 0; j < v->gh; j++)
        for (int i = 0; i < v->gw; i++) {
            int g = j * v->gw + i;
            if (v->status[g] != VERIFY_PT_USED) continue;
            uint32_t bits = lit_bits(&v->ls[(size_t)g * nl], nl);
            bool diff = false;
            for (int dj = -1; dj <= 1 && !diff; dj++)
                for (int di = -1; di <= 1 && !diff; di++) {
                    int ii = i + di, jj = j + dj;
                    if ((!di && !dj) || ii < 0 || jj < 0 || ii >= v->gw || jj >= v->gh) continue;
                    int g2 = jj * v->gw + ii;
                    diff = v->pi[g2].face != v->pi[g].face || lit_bits(&v->ls[(size_t)g2 * nl], nl) != bits;
                }
            if (diff) cand[ncand++] = g;
        }
    if (!ncand) return true;
    const int NC = 8;
    double *qc = malloc((size_t)ncand * NC * 2 * sizeof *qc);
    model_pixel_info_t *pc = malloc((size_t)ncand * NC * sizeof *pc);
    model_lamp_sample_t *lc = malloc((size_t)ncand * NC * (nl ? nl : 1) * sizeof *lc);
    bool ok = qc && pc && lc;
    if (ok) {
        static const int off[8][2] = { { -1, -1 }, { 1, -1 }, { -1, 1 }, { 1, 1 },
                                       { 0, -1 }, { 0, 1 }, { -1, 0 }, { 1, 0 } };
        for (int k = 0; k < ncand; k++)
            for (int m = 0; m < NC; m++) {
                qc[2 * (k * NC + m)] = q[2 * cand[k]] + off[m][0] * c;
                qc[2 * (k * NC + m) + 1] = q[2 * cand[k] + 1] + off[m][1] * c;
            }
        ok = model_pixel_info_table(v->t, cam->cam, lamps, qc, ncand * NC, pc, lc, threads);
    }
    if (ok)
        for (int k = 0; k < ncand; k++) {
            int g = cand[k];
            uint32_t bits = lit_bits(&v->ls[(size_t)g * nl], nl);
            for (int m = 0; m < NC; m++) {
                int km = k * NC + m;
                if (pc[km].face != v->pi[g].face || lit_bits(&lc[(size_t)km * nl], nl) != bits) {
                    v->status[g] = VERIFY_PT_BOUNDARY;
                    break;
                }
            }
        }
    free(qc);
    free(pc);
    free(lc);
    return ok;
}

// A view's grid (x0, y0, gw, gh) for the image size and options; false + message when it has no points.
static bool view_grid(verify_view_t *v, const verify_options_t *opt, int *c)
{
    int h = opt->window_px / 2;
    *c = h + (int)ceil(opt->boundary_margin_px);
    v->x0 = v->y0 = *c > v->sp / 2 ? *c : v->sp / 2;
    v->gw = v->W - 1 - *c >= v->x0 ? (v->W - 1 - *c - v->x0) / v->sp + 1 : 0;
    v->gh = v->H - 1 - *c >= v->y0 ? (v->H - 1 - *c - v->y0) / v->sp + 1 : 0;
    if (v->gw * v->gh <= 0) {
        model_error(NULL, 0, "verify: a %dx%d image has no room for reference points", v->W, v->H);
        return false;
    }
    return true;
}

verify_view_t *verify_view_new(const model_scene_t *scene, const verify_camera_t *cam, double angle_deg,
                               const model_lamps_t *lamps, const model_material_t *const *mats,
                               const verify_options_t *opt)
{
    double t0 = model_now_s();
    if (lamps->n > MAX_LAMPS) {
        model_error(lamps->path, 0, "%d lamps: verification handles at most %d", lamps->n, MAX_LAMPS);
        return NULL;
    }
    if (opt->window_px < 1 || opt->window_px % 2 == 0 || opt->spacing_px < 1) {
        model_error(NULL, 0, "verify: the window (%d px) must be odd and >= 1, the spacing (%d px) >= 1",
                    opt->window_px, opt->spacing_px);
        return NULL;
    }
    verify_view_t *v = calloc(1, sizeof *v);
    if (!v) return NULL;
    v->W = model_camera_width(cam->cam);
    v->H = model_camera_height(cam->cam);
    v->sp = opt->spacing_px;
    v->nl = lamps->n;
    int c;
    if (!view_grid(v, opt, &c)) {
        free(v);
        return NULL;
    }
    int n = v->gw * v->gh, nl = v->nl;
    int threads = opt->threads > 0 ? opt->threads : model_default_threads();
    v->rot = model_scene_rotated_z(scene, angle_deg);
    v->t = v->rot ? model_tracer_new(v->rot) : NULL;
    v->pi = malloc((size_t)n * sizeof *v->pi);
    v->ls = malloc((size_t)n * (nl ? nl : 1) * sizeof *v->ls);
    v->status = calloc((size_t)n, 1);
    v->B = calloc((size_t)n * (nl ? nl : 1), sizeof *v->B);
    v->Bsd = calloc((size_t)n * (nl ? nl : 1), sizeof *v->Bsd);
    double *q = malloc((size_t)n * 2 * sizeof *q);
    int *cand = malloc((size_t)n * sizeof *cand);
    if (!v->t || !v->pi || !v->ls || !v->status || !v->B || !v->Bsd || !q || !cand) {
        if (v->t) model_error(NULL, 0, "out of memory for %d reference points", n);
        goto fail;
    }
    // the grid's pixel_info: face, position, normal, lamp samples (background where the ray misses)
    for (int j = 0; j < v->gh; j++)
        for (int i = 0; i < v->gw; i++) {
            q[2 * (j * v->gw + i)] = v->x0 + i * v->sp;
            q[2 * (j * v->gw + i) + 1] = v->y0 + j * v->sp;
        }
    if (!model_pixel_info_table(v->t, cam->cam, lamps, q, n, v->pi, v->ls, threads)) goto fail;
    for (int g = 0; g < n; g++)
        if (v->pi[g].face < 0) v->status[g] = VERIFY_PT_BACKGROUND;
    // a blurred edge reaches 3 sigma further
    double sigma_px = cam->psf_sigma_px > 0 ? cam->psf_sigma_px : 0;
    double reach = (opt->window_px / 2) * M_SQRT2 + opt->edge_margin_px + 3 * sigma_px;
    if (!view_near_edges(v, cam, lamps, mats, q, reach, threads) ||
        !view_boundaries(v, cam, lamps, q, c + (int)ceil(3 * sigma_px), threads, cand))
        goto fail;
    // the windows near edges: modelled with the pixels' footprint and the blur where they see only the description
    if (opt->edge_windows) {
        bool *want = calloc((size_t)n, sizeof *want);
        if (!want) goto fail;
        for (int g = 0; g < n; g++)
            want[g] = v->status[g] == VERIFY_PT_NEAR_EDGE || v->status[g] == VERIFY_PT_BOUNDARY;
        bool fok = verify_footprints_make(v->t, cam->cam, lamps, mats, q, want, n, opt->window_px,
                                          fmin(fmax(cam->pixel_fill, 0), 1), sigma_px,
                                          opt->edge_subsamples, opt->ir_samples, threads, &v->fp);
        free(want);
        if (!fok) goto fail;
        for (int g = 0; g < n; g++)
            if (v->fp.first[g] >= 0) v->status[g] = VERIFY_PT_USED;
    }
    // the interreflection basis at the usable points
    int ncand = 0;
    v->nusable = 0;
    for (int g = 0; g < n; g++) {
        if (v->status[g] != VERIFY_PT_USED) continue;
        v->nusable++;
        if (!(v->fp.first && v->fp.first[g] >= 0)) cand[ncand++] = g;   // (a window's parts have their own)
    }
    if (opt->ir_samples > 0 && ncand && nl) {
        ir_ctx_t ic = { v->t, lamps, mats, opt->ir_samples, v->pi, cand, v->B, 0x1e5f, v->Bsd };
        model_parallel_for(ncand, 64, threads, ir_rows, &ic);
    }
    free(cand);
    free(q);
    v->time_s = model_now_s() - t0;
    return v;
fail:
    free(cand);
    free(q);
    verify_view_free(v);
    return NULL;
}

// ---------------------------------------------------------------------------
// The fit

typedef struct {
    double meas, sigma, Eg;   // measured DN (after the offset map), sigma DN, E * g
    int    mat, mat2;         // scene material; a window near an edge may see a second one (else -1)
    int    nl;                // its terms: (lamp on) for a plain point, (part, lamp on) for a window near an edge
    int    first;             // into the lamp arrays
    double r_last, rr_last;   // the robust transform's last residual and its image (group_fn; NAN: none)
} pt_t;

typedef struct {
    pt_t         *pt;            // (r_last, rr_last change in group_fn)
    model_brdf_prep_t *cs;       // per (point, lamp on): the geometry's terms (kept factors change)
    const double *w;             // A_i V / d^2
    const double *b;             // A_i B_i
    const int    *lamp;          // lamp index
    const uint8_t *sec;          // 1: the term is of the point's second material (mat2)
    model_brdf_t  model;         // of the point's material
    int           np, nl_all;
    bool          reference;     // model_brdf_eval on cs[].c, no kept robust images (reference_eval)
} res_ctx_t;

typedef struct {
    res_ctx_t *rc, *rc2;         // the point's material's and its second's (NULL: none)
    int        k;
} res_item_t;

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

static bool residual_fn(void *vctx, const double *const *par, double *res, double **jac)
{
    const res_item_t *it = vctx;
    res[0] = point_eval(it->rc, it->rc2, it->k, par, jac);
    return isfinite(res[0]);
}

// A group of points of one image and material: one residual block. The
// robust (Cauchy) loss is applied to each point's residual inside:
// r' = sign(r) sqrt(b ln(1 + r^2/b)), so its Gauss-Newton step is the
// loss's iteratively reweighted one (b = robust_scale^2; 0: plain).
typedef struct {
    res_ctx_t *rc, *rc2;   // the points' material's and their second material's (NULL: none; 6 blocks)
    const int *k;
    int        n;
    double     b;
} res_group_t;

static bool group_fn(void *vctx, const double *const *par, double *res, double **jac)
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

void verify_result_free(verify_result_t *r)
{
    if (!r) return;
    free(r->points);
    free(r->per_image);
    free(r->regions);
    free(r->params);
    free(r->kc);
    free(r->s);
    free(r->Pa);
    free(r->mats);
    free(r->warnings);
    memset(r, 0, sizeof *r);
}

static void stats_of(const verify_point_t *pts, int n, int image, verify_stats_t *st)
{
    memset(st, 0, sizeof *st);
    double *d = malloc((size_t)(n ? n : 1) * sizeof *d), *z = malloc((size_t)(n ? n : 1) * sizeof *z);
    double s1 = 0, s2 = 0, zz = 0;
    int m = 0;
    for (int k = 0; k < n; k++) {
        const verify_point_t *p = &pts[k];
        if (p->status != VERIFY_PT_USED || (image >= 0 && p->image != image)) continue;
        double diff = p->meas - p->model, a = fabs(diff);
        if (d) d[m] = diff;
        if (z) z[m] = fabs(p->z);
        m++;
        s1 += a;
        s2 += a * a;
        zz += (double)p->z * p->z;
        if (a > st->max_abs) st->max_abs = a;
    }
    st->npoints = m;
    if (m && d && z) {
        st->mean_abs = s1 / m;
        st->std_abs = sqrt(fmax(s2 / m - st->mean_abs * st->mean_abs, 0));
        st->rms_z = sqrt(zz / m);
        st->median_abs_z = model_median(z, m);
        double med = model_median(d, m);
        for (int k = 0; k < m; k++) d[k] = fabs(d[k] - med);
        st->robust_sigma = 1.4826 * model_median(d, m);
    }
    free(d);
    free(z);
}

// A parameter of the fit: x[i], its prior and bounds.
typedef struct {
    char   name[96];
    double *x;
    int    i;
    double prior_mean, prior_std, lo, hi;
    bool   fixed;
    bool   mv;      // its prior is in a material's multivariate prior (F->mvp), not alone
} pdesc_t;

// The working state that verify_run's stages share. The inputs are borrowed;
// every array below is owned and freed by fit_free (out's arrays go to the
// caller).
typedef struct {
    // in
    const model_scene_t    *scene;
    const verify_camera_t  *cams;
    int                     ncams;
    const model_lamps_t    *lamps;
    const double           *A;          // kc*I per us, per lamp
    const verify_image_t   *imgs;
    int                     nimgs;
    verify_view_t *const   *views;
    const verify_options_t *opt;
    int                     nl, nm;     // lamps, scene materials
    const verify_prior_t  **prior;      // nm: each material's prior
    int                     npts;       // grid points of every image
    // the fit's points: those used and those with an unexpected edge (predicted, not fitted)
    pt_t            *pt;                // nfit
    int             *ptidx;             // nfit: point -> index in out->points
    int              nfit;
    model_brdf_prep_t *cs;              // per (fit point, lamp on)
    double          *wv, *bv;           // A_i V / d^2 and A_i B_i, per (fit point, lamp on)
    int             *lampv;             // lamp index, per (fit point, lamp on)
    uint8_t         *secv;              // per (fit point, lamp on): the term is of the point's second material
    double          *mp;                // nm x MODEL_BRDF_MAX_PARAMS: the materials' parameters
    res_ctx_t       *rcs;               // nm
    res_group_t     *groups;            // ngroups residual blocks; their indices in gidx
    int             *gidx;
    int              ngroups, nused;
    pdesc_t         *pd;                // npd parameters
    int              npd;
    verify_mvprior_t *mvp;              // nm: the materials' multivariate priors (n 0: none)
    int              *mvp_pd;           // nm: the index in pd of each material's first parameter
    lsq_problem_t   *prob;
    verify_result_t *out;
} fit_t;

static void fit_free(fit_t *F)
{
    lsq_problem_free(F->prob);
    free(F->prior);
    free(F->pt);
    free(F->ptidx);
    free(F->cs);
    free(F->wv);
    free(F->bv);
    free(F->lampv);
    free(F->secv);
    free(F->mp);
    free(F->rcs);
    free(F->groups);
    free(F->gidx);
    free(F->pd);
    free(F->mvp);
    free(F->mvp_pd);
}

// The inputs agree (priors for every material, image sizes, cameras, lamp
// masks); counts the grid points. false + message.
static bool fit_check(fit_t *F, const verify_priors_t *pr)
{
    if (F->nl > MAX_LAMPS) {
        model_error(F->lamps->path, 0, "%d lamps: verification handles at most %d", F->nl, MAX_LAMPS);
        return false;
    }
    F->prior = calloc((size_t)(F->nm ? F->nm : 1), sizeof *F->prior);
    if (!F->prior || !verify_match_priors(F->scene, pr, F->prior)) return false;
    F->npts = 0;
    for (int m = 0; m < F->nimgs; m++) {
        const verify_view_t *v = F->views[m];
        const verify_image_t *im = &F->imgs[m];
        if (im->W != v->W || im->H != v->H || im->camera < 0 || im->camera >= F->ncams) {
            model_error(im->name, 0, "the image is %dx%d but its camera model (%s) is %dx%d: give the camera "
                        "model calibrated for this image size", im->W, im->H,
                        im->camera >= 0 && im->camera < F->ncams ? F->cams[im->camera].name : "?", v->W, v->H);
            return false;
        }
        if (im->lamps_on >> F->nl && F->nl < 32) {
            model_error(im->name, 0, "lamp mask 0x%x names lamps beyond the %d given", im->lamps_on, F->nl);
            return false;
        }
        double gf;
        if (!model_gain_factor(im->gain_db, "dB", 0, "dB", im->name, &gf)) {
            model_error(NULL, 0, "%s", model_last_error());
            return false;
        }
        F->npts += v->gw * v->gh;
    }
    return true;
}

// The result's arrays and the fit's, the parameters at their starts (kc = s
// = 1, rho 1 with interreflections, the materials at the priors' means).
static bool fit_alloc(fit_t *F)
{
    verify_result_t *out = F->out;
    const int npts = F->npts, nimgs = F->nimgs, nm = F->nm, nl = F->nl, ncams = F->ncams;
    size_t n1 = (size_t)(npts ? npts : 1), nle = 0;
    for (int m = 0; m < nimgs; m++) {
        const verify_view_t *v = F->views[m];
        size_t terms = (size_t)v->gw * v->gh;   // a plain point's: one per lamp on; a window's near an edge: per part
        for (int g = 0; v->fp.first && g < v->gw * v->gh; g++)
            if (v->fp.first[g] >= 0) terms += (size_t)v->fp.nparts[g] - 1;
        nle += terms * (size_t)__builtin_popcount(F->imgs[m].lamps_on);
    }
    if (!nle) nle = 1;
    out->points = calloc(n1, sizeof *out->points);
    out->per_image = calloc((size_t)(nimgs ? nimgs : 1), sizeof *out->per_image);
    out->nimages = nimgs;
    out->kc = calloc((size_t)(ncams ? ncams : 1), sizeof(double));
    out->s = calloc((size_t)(nl ? nl : 1), sizeof(double));
    out->Pa = calloc((size_t)(nimgs ? nimgs : 1), sizeof(double));
    out->mats = calloc((size_t)(nm ? nm : 1), sizeof *out->mats);
    F->pt = malloc(n1 * sizeof *F->pt);
    F->ptidx = malloc(n1 * sizeof *F->ptidx);
    F->cs = malloc(nle * sizeof *F->cs);
    F->wv = malloc(nle * sizeof *F->wv);
    F->bv = malloc(nle * sizeof *F->bv);
    F->lampv = malloc(nle * sizeof *F->lampv);
    F->secv = calloc(nle, sizeof *F->secv);
    F->mp = calloc((size_t)(nm ? nm : 1) * MODEL_BRDF_MAX_PARAMS, sizeof *F->mp);
    F->rcs = calloc((size_t)(nm ? nm : 1), sizeof *F->rcs);
    F->groups = malloc(n1 * sizeof *F->groups);
    F->gidx = malloc(n1 * sizeof *F->gidx);
    F->pd = calloc((size_t)(ncams + nl + nimgs + 1 + nm * MODEL_BRDF_MAX_PARAMS), sizeof *F->pd);
    F->prob = lsq_problem_new();
    if (!out->points || !out->per_image || !out->kc || !out->s || !out->Pa || !out->mats || !F->pt || !F->ptidx ||
        !F->cs || !F->wv || !F->bv || !F->lampv || !F->secv || !F->mp || !F->rcs || !F->groups || !F->gidx || !F->pd ||
        !F->prob) {
        model_error(NULL, 0, "out of memory for %d reference points", npts);
        return false;
    }
    for (int c = 0; c < ncams; c++) out->kc[c] = 1;
    for (int i = 0; i < nl; i++) out->s[i] = 1;
    out->rho = F->opt->ir_samples > 0 ? 1 : 0;
    for (int k = 0; k < nm; k++) {
        snprintf(out->mats[k].name, sizeof out->mats[k].name, "%s", F->scene->material_names[k]);
        out->mats[k].model = F->prior[k]->model;
        memcpy(out->mats[k].p, F->prior[k]->mean, sizeof F->prior[k]->mean);
        memcpy(&F->mp[k * MODEL_BRDF_MAX_PARAMS], F->prior[k]->mean, sizeof F->prior[k]->mean);
    }
    return true;
}

// An image's gain as a factor: verify_image_t.gain_db is in dB relative to the
// calibration (the readers convert a camera's own unit, model_gain_factor);
// fit_check checked it.
static double image_gain_factor(const verify_image_t *im)
{
    double gf = 1;
    model_gain_factor(im->gain_db, "dB", 0, "dB", im->name, &gf);
    return gf;
}

// A window's sums: of P - offset, its square, the flat field, and the largest raw P.
typedef struct {
    double s1, s2, gs, mx;
} wsum_t;

#define WINDOWS_KEPT 2   // with and without the maps
struct verify_windows {
    struct {
        const float *P, *off, *flat;
        int          w, sp, x0, y0, gw, gh;
        wsum_t      *s;
    } e[WINDOWS_KEPT];
    int next;
};

verify_windows_t *verify_windows_new(void) { return calloc(1, sizeof(verify_windows_t)); }

void verify_windows_clear(verify_windows_t *W)
{
    if (!W) return;
    for (int k = 0; k < WINDOWS_KEPT; k++) free(W->e[k].s);
    memset(W, 0, sizeof *W);
}

void verify_windows_free(verify_windows_t *W)
{
    verify_windows_clear(W);
    free(W);
}

// The sums of every window of view v's grid on image im (w x w, offset map
// off and flat field flat or NULL): kept in im->windows when given (*owned
// false), else made for this fit (*owned true: the caller frees). NULL: out of memory.
static const wsum_t *window_sums(const verify_image_t *im, const verify_view_t *v, int w, const float *off,
                                 const float *flat, bool *owned)
{
    verify_windows_t *W = im->windows;
    *owned = W == NULL;
    for (int k = 0; W && k < WINDOWS_KEPT; k++)
        if (W->e[k].s && W->e[k].P == im->P && W->e[k].off == off && W->e[k].flat == flat && W->e[k].w == w &&
            W->e[k].sp == v->sp && W->e[k].x0 == v->x0 && W->e[k].y0 == v->y0 && W->e[k].gw == v->gw &&
            W->e[k].gh == v->gh)
            return W->e[k].s;
    const int h = w / 2, n = v->gw * v->gh;
    wsum_t *S = malloc((size_t)n * sizeof *S);
    if (!S) return NULL;
    for (int g = 0; g < n; g++) {
        int gx = v->x0 + (g % v->gw) * v->sp, gy = v->y0 + (g / v->gw) * v->sp;
        double s1 = 0, s2 = 0, gs = 0, mx = 0;
        for (int y = gy - h; y <= gy + h; y++)
            for (int x = gx - h; x <= gx + h; x++) {
                size_t o = (size_t)y * v->W + x;
                double P = im->P[o];
                if (P > mx) mx = P;
                if (off) P -= off[o];
                s1 += P;
                s2 += P * P;
                gs += flat ? flat[o] : 1;
            }
        S[g] = (wsum_t){ s1, s2, gs, mx };
    }
    if (W) {
        int k = W->next;
        W->next = (k + 1) % WINDOWS_KEPT;
        free(W->e[k].s);
        W->e[k].P = im->P;
        W->e[k].off = off;
        W->e[k].flat = flat;
        W->e[k].w = w;
        W->e[k].sp = v->sp;
        W->e[k].x0 = v->x0;
        W->e[k].y0 = v->y0;
        W->e[k].gw = v->gw;
        W->e[k].gh = v->gh;
        W->e[k].s = S;
    }
    return S;
}

// Image m's reference points from first_pt on: the windows' means (after the
// offset map, linearised), their spread (in sigma for now) and mean flat
// field (in model for now), saturation. *Pa0: the offset's start (0 with the
// offset map; else the median of the background windows, or the darkest
// usable one); *var_px_fallback: without K, the pixel noise as the median
// window variance of the usable points. false: out of memory.
static bool measure_windows(fit_t *F, int m, int first_pt, double *Pa0, double *var_px_fallback)
{
    const verify_options_t *opt = F->opt;
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_camera_t *cm = &F->cams[im->camera];
    const int w = opt->window_px, n = v->gw * v->gh;
    const float *off = opt->use_flat ? cm->offset_dn : NULL, *flat = opt->use_flat ? cm->flat : NULL;
    double gf = image_gain_factor(im), Kg = cm->K_dn_per_e * gf;
    double sat = cm->saturation_dn > 0 ? cm->saturation_dn : INFINITY;
    bool owned;
    const wsum_t *ws = window_sums(im, v, w, off, flat, &owned);
    double *tmp = malloc((size_t)n * sizeof *tmp);
    int nt = 0;
    if (!tmp || !ws) {
        free(tmp);
        if (owned) free((void *)ws);
        return false;
    }
    for (int g = 0; g < n; g++) {
        verify_point_t *p = &F->out->points[first_pt + g];
        int gx = v->x0 + (g % v->gw) * v->sp, gy = v->y0 + (g / v->gw) * v->sp;
        p->image = m;
        p->q[0] = (float)gx;
        p->q[1] = (float)gy;
        p->face = v->pi[g].face;
        p->status = v->status[g];
        p->region = -1;
        double s1 = ws[g].s1, s2 = ws[g].s2, gs = ws[g].gs, mx = ws[g].mx;
        double N = (double)w * w, mean = s1 / N;
        if (cm->lin && off) {
            // linearise the window (mean and spread) with the gain calibration's linearisation
            double slope, lin = model_linearise(cm->lin, mean, gf, &slope);
            double var = fmax(s2 / N - mean * mean, 0) * slope * slope;
            mean = lin;
            s1 = mean * N;
            s2 = (var + mean * mean) * N;
        }
        p->meas = (float)mean;
        p->sigma = (float)sqrt(fmax(s2 / N - mean * mean, 0) * N / (N > 1 ? N - 1 : 1));   // window std for now
        p->model = (float)(gs / N);   // g for now
        if (p->status == VERIFY_PT_USED && mx >= sat - 0.5) p->status = VERIFY_PT_SATURATED;
        if (!off && p->status == VERIFY_PT_BACKGROUND) tmp[nt++] = mean;
    }
    *Pa0 = 0;
    if (!off) {
        if (nt >= 10) {
            *Pa0 = model_median(tmp, nt);
        } else {
            *Pa0 = INFINITY;
            for (int k = first_pt; k < first_pt + n; k++)
                if (F->out->points[k].status == VERIFY_PT_USED) *Pa0 = fmin(*Pa0, F->out->points[k].meas);
            if (!isfinite(*Pa0)) *Pa0 = 0;
        }
    }
    *var_px_fallback = 0;
    if (!(Kg > 0)) {
        nt = 0;
        for (int k = first_pt; k < first_pt + n; k++)
            if (F->out->points[k].status == VERIFY_PT_USED)
                tmp[nt++] = (double)F->out->points[k].sigma * F->out->points[k].sigma;
        *var_px_fallback = nt ? model_median(tmp, nt) : 1;
        if (!(*var_px_fallback > 0)) *var_px_fallback = 1;
    }
    free(tmp);
    if (owned) free((void *)ws);
    return true;
}

// A point's relative model error: its material's window spread (the priors'
// window_rel_std) unless model_rel is given or the priors state none; of two
// materials the larger.
static double point_model_rel(const fit_t *F, const pt_t *q)
{
    double rel = 0;
    for (int k = 0; k < 2; k++) {
        int mat = k ? q->mat2 : q->mat;
        if (mat < 0) continue;
        double wr = F->prior[mat]->window_rel;
        rel = fmax(rel, F->opt->model_rel_given || !isfinite(wr) ? F->opt->model_rel : wr);
    }
    return rel;
}

// The terms of grid point g of image m's window near an edge (its parts,
// verify_footprint.h) from *e on, into q (mat, mat2, nl); *gx, *gy: the
// model's slope per unit E g across the window's centre (per px) at the
// priors' means (kc = s = 1; the direct light); *bsd += its interreflection
// basis's Monte Carlo error per unit E g. false (nothing written) when the
// window sees more than two materials.
static bool footprint_terms(fit_t *F, int m, int g, pt_t *q, size_t *e, double *gx, double *gy, double *bsd)
{
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_footprints_t *fp = &v->fp;
    const int P0 = fp->first[g], np = fp->nparts[g], nl = fp->nl;
    int mat = fp->parts[P0].material, mat2 = -1;
    for (int j = 1; j < np; j++) {
        int mj = fp->parts[P0 + j].material;
        if (mj == mat || mj == mat2) continue;
        if (mat2 >= 0) return false;
        mat2 = mj;
    }
    q->mat = mat;
    q->mat2 = mat2;
    *gx = *gy = 0;
    for (int j = 0; j < np; j++) {
        const verify_part_t *P = &fp->parts[P0 + j];
        const float *wl = &fp->wl[(size_t)(P0 + j) * nl * 3];
        const float *B = &fp->B[(size_t)(P0 + j) * nl], *Bsd = &fp->Bsd[(size_t)(P0 + j) * nl];
        const int pm = P->material;
        const double *mp = &F->mp[pm * MODEL_BRDF_MAX_PARAMS];
        for (int i = 0; i < F->nl; i++) {
            if (!((im->lamps_on >> i) & 1)) continue;
            if (!(wl[3 * i] > 0) && !(B[i] > 0)) continue;
            model_vec3_t d = v3_sub(F->lamps->lamps[i].position_mm, P->p_mm);
            model_vec3_t l = v3_unit(d);
            model_cosines_t c = model_cosines(P->n, l, P->v);
            double em = model_lamp_emission(&F->lamps->lamps[i], P->p_mm);
            F->cs[*e] = model_brdf_prepare(&c);
            F->wv[*e] = F->A[i] * em * wl[3 * i];
            F->bv[*e] = F->A[i] * P->W * B[i];
            F->lampv[*e] = i;
            F->secv[*e] = mat2 >= 0 && pm == mat2;
            double R = model_brdf_eval(F->prior[pm]->model, mp, &c, NULL);
            *bsd += F->A[i] * P->W * Bsd[i];
            *gx += F->A[i] * em * wl[3 * i + 1] * R;
            *gy += F->A[i] * em * wl[3 * i + 2] * R;
            (*e)++;
            q->nl++;
        }
    }
    return true;
}

// Image m's usable points after measure_windows: the measured-edge test,
// sigma, and the fit's points with their per-lamp terms (from *e on).
static void image_fit_points(fit_t *F, int m, int first_pt, double Pa0, double var_px_fallback, size_t *e)
{
    const verify_options_t *opt = F->opt;
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_camera_t *cm = &F->cams[im->camera];
    const int w = opt->window_px;
    double gf = image_gain_factor(im), Kg = cm->K_dn_per_e * gf;
    double E = im->exposure_us * gf * (cm->kc_rel > 0 ? cm->kc_rel : 1);   // the camera's own sensitivity
    for (int g = 0; g < v->gw * v->gh; g++) {
        int k = first_pt + g;
        verify_point_t *p = &F->out->points[k];
        if (p->status != VERIFY_PT_USED) continue;
        double S = fmax(p->meas - Pa0, 0), wstd = p->sigma, gmean = p->model;
        double var_px = Kg > 0 ? Kg * S + Kg * Kg * cm->read_noise_e * cm->read_noise_e + 1.0 / 12
                               : var_px_fallback;
        bool foot = v->fp.first && v->fp.first[g] >= 0;
        double thr2 = opt->edge_k * opt->edge_k * var_px + (opt->edge_rel * S) * (opt->edge_rel * S);
        if (!foot && wstd * wstd > thr2) {   // (a window near an edge has its spread from the edge)
            p->status = VERIFY_PT_EDGE_MEASURED;
            p->z = (float)(opt->z_flag * wstd / sqrt(thr2));
        }
        double sig2 = var_px / ((double)w * w);
        // the fit's point (edge-measured ones are predicted too, not fitted)
        pt_t *q = &F->pt[F->nfit];
        q->meas = p->meas;
        q->Eg = E * gmean;
        q->mat = v->pi[g].material;
        q->mat2 = -1;
        q->first = (int)*e;
        q->nl = 0;
        q->r_last = q->rr_last = NAN;
        double bsd = 0;   // the interreflection basis's Monte Carlo error, per unit E g
        if (foot) {
            double gx, gy;
            if (!footprint_terms(F, m, g, q, e, &gx, &gy, &bsd)) {   // more than two materials in the window
                p->status = VERIFY_PT_NEAR_EDGE;
                continue;
            }
            p->footprint = true;
            // where the edge lies is known to edge_position_sigma_px: the model's slope across it
            double se = opt->edge_position_sigma_px * q->Eg * hypot(gx, gy);
            sig2 += se * se;
        } else {
            const model_lamp_sample_t *ls = &v->ls[(size_t)g * v->nl];
            for (int i = 0; i < F->nl; i++) {
                if (!((im->lamps_on >> i) & 1)) continue;
                model_cosines_t c = model_cosines(v->pi[g].n, ls[i].l, v->pi[g].v);
                F->cs[*e] = model_brdf_prepare(&c);
                // the lamp's emission pattern toward the point (exactly 1 for an isotropic lamp)
                F->wv[*e] = ls[i].d_mm > 0 ? F->A[i] * ls[i].V / (ls[i].d_mm * ls[i].d_mm) *
                                                 model_lamp_emission(&F->lamps->lamps[i], v->pi[g].p_mm)
                                           : 0;
                F->bv[*e] = F->A[i] * v->B[(size_t)g * v->nl + i];
                F->lampv[*e] = i;
                F->secv[*e] = 0;
                bsd += F->A[i] * v->Bsd[(size_t)g * v->nl + i];
                (*e)++;
                q->nl++;
            }
        }
        // what the model lacks: the material's window spread (its priors' window_rel_std, else model_rel;
        // a window of two materials the larger), and the interreflection basis's Monte Carlo error
        double rel = point_model_rel(F, q);
        double sb = opt->ir_samples > 0 ? q->Eg * bsd : 0;
        sig2 += (rel * S) * (rel * S) + sb * sb;
        q->sigma = sqrt(sig2);
        p->sigma = (float)q->sigma;
        p->model = 0;
        F->ptidx[F->nfit] = k;
        F->nfit++;
    }
}

// Every image's reference points and windows. false: out of memory.
static bool fit_measure(fit_t *F)
{
    int np = 0;
    size_t e = 0;
    for (int m = 0; m < F->nimgs; m++) {
        double Pa0, var_px_fallback;
        if (!measure_windows(F, m, np, &Pa0, &var_px_fallback)) return false;
        F->out->Pa[m] = Pa0;
        image_fit_points(F, m, np, Pa0, var_px_fallback, &e);
        np += F->views[m]->gw * F->views[m]->gh;
    }
    return true;
}

// A parameter's description (the next of F->pd).
static pdesc_t *fit_param(fit_t *F, double *x, int i, double prior_mean, double prior_std, double lo, double hi,
                          bool fixed)
{
    pdesc_t *d = &F->pd[F->npd++];
    d->x = x;
    d->i = i;
    d->prior_mean = prior_mean;
    d->prior_std = prior_std;
    d->lo = lo;
    d->hi = hi;
    d->fixed = fixed;
    return d;
}

// Lamp i is on in at least one image (else its scale is held: no data).
static bool lamp_lit(const fit_t *F, int i)
{
    for (int m = 0; m < F->nimgs; m++)
        if ((F->imgs[m].lamps_on >> i) & 1) return true;
    return false;
}

// The parameters within the priors (verify.h): kc per camera, s per lamp, Pa
// per image, rho, the materials'. false + message (kept) from the solver.
static bool fit_parameters(fit_t *F)
{
    const verify_options_t *opt = F->opt;
    verify_result_t *out = F->out;
    const bool up = opt->use_priors;
    for (int c = 0; c < F->ncams; c++) {
        pdesc_t *d = fit_param(F, &out->kc[c], 0, 1, up ? opt->camera_sigma : 0,
                               up ? fmax(0.2, 1 - 5 * opt->camera_sigma) : 0, up ? 1 + 5 * opt->camera_sigma : INFINITY,
                               opt->fix_cameras);
        snprintf(d->name, sizeof d->name, "kc[%s]", F->cams[c].name);
        if (!lsq_add_parameters(F->prob, d->x, 1)) return false;
    }
    if (!lsq_add_parameters(F->prob, out->s, F->nl ? F->nl : 1)) return false;
    for (int i = 0; i < F->nl; i++) {
        // the thesis's fit (no priors): lamps fixed, kc free
        pdesc_t *d = fit_param(F, out->s, i, 1, up ? opt->lamp_sigma : 0, fmax(0.2, 1 - 5 * opt->lamp_sigma),
                               1 + 5 * opt->lamp_sigma, opt->fix_lamps || !up || !lamp_lit(F, i));
        snprintf(d->name, sizeof d->name, "lamp[%s]", F->lamps->lamps[i].name);
    }
    for (int m = 0; m < F->nimgs; m++) {
        bool have_map = opt->use_flat && F->cams[F->imgs[m].camera].offset_dn;
        pdesc_t *d = fit_param(F, &out->Pa[m], 0, out->Pa[m], up && have_map ? opt->pa_sigma_dn : 0, -INFINITY,
                               INFINITY, opt->fix_pa);
        snprintf(d->name, sizeof d->name, "Pa[%d]", m);
        if (!lsq_add_parameters(F->prob, d->x, 1)) return false;
    }
    pdesc_t *d = fit_param(F, &out->rho, 0, 1, up ? 0.5 : 0, 0, up ? 3 : INFINITY,
                           opt->fix_rho || opt->ir_samples <= 0);
    snprintf(d->name, sizeof d->name, "rho");
    if (!lsq_add_parameters(F->prob, d->x, 1)) return false;
    bool *mat_used = calloc((size_t)F->nm + 1, sizeof *mat_used);
    if (!mat_used) return false;
    for (int k = 0; k < F->nfit; k++)
        if (F->pt[k].mat >= 0 && F->pt[k].mat < F->nm && out->points[F->ptidx[k]].status == VERIFY_PT_USED) {
            mat_used[F->pt[k].mat] = true;
            if (F->pt[k].mat2 >= 0 && F->pt[k].mat2 < F->nm) mat_used[F->pt[k].mat2] = true;
        }
    bool ok = true;
    F->mvp = calloc((size_t)F->nm + 1, sizeof *F->mvp);
    F->mvp_pd = calloc((size_t)F->nm + 1, sizeof *F->mvp_pd);
    if (!F->mvp || !F->mvp_pd) ok = false;
    for (int k = 0; k < F->nm && ok; k++) {
        const verify_prior_t *P = F->prior[k];
        double *x = &F->mp[k * MODEL_BRDF_MAX_PARAMS];
        F->mvp_pd[k] = F->npd;
        if (!(ok = lsq_add_parameters(F->prob, x, P->np))) break;
        for (int j = 0; j < P->np; j++) {
            double lo, hi;
            model_brdf_param_range(P->model, j, &lo, &hi);
            const char *pn = model_brdf_param_name(P->model, j);
            bool fixed = opt->fix_materials || (up && P->held[j]) || !mat_used[k] || (!up && !strcmp(pn, "F0"));
            d = fit_param(F, x, j, P->mean[j], up && isfinite(P->std[j]) ? P->std[j] : 0, up ? P->lo[j] : lo,
                          up ? P->hi[j] : hi, fixed);
            snprintf(d->name, sizeof d->name, "%s.%s", P->name, pn);
        }
        // with the priors' covariance: one multivariate Gaussian over the free ones
        bool use[MODEL_BRDF_MAX_PARAMS] = { 0 };
        for (int j = 0; j < P->np; j++) use[j] = !F->pd[F->mvp_pd[k] + j].fixed && F->pd[F->mvp_pd[k] + j].prior_std > 0;
        if (up && verify_mvprior_make(P, use, &F->mvp[k]))
            for (int j = 0; j < P->np; j++) F->pd[F->mvp_pd[k] + j].mv = use[j];
        F->rcs[k] = (res_ctx_t){ .pt = F->pt, .cs = F->cs, .w = F->wv, .b = F->bv, .lamp = F->lampv, .sec = F->secv,
                                 .model = P->model, .np = P->np, .nl_all = F->nl ? F->nl : 1,
                                 .reference = opt->reference_eval };
    }
    free(mat_used);
    return ok;
}

// Bounds and priors of the free parameters, the fixed ones' masks.
static bool fit_bounds_and_masks(fit_t *F)
{
    const verify_options_t *opt = F->opt;
    lsq_problem_t *prob = F->prob;
    const pdesc_t *pd = F->pd;
    const int npd = F->npd;
    for (int k = 0; k < npd; k++) {
        const pdesc_t *d = &pd[k];
        if (d->fixed) continue;
        if ((isfinite(d->lo) || isfinite(d->hi)) && !lsq_set_bounds(prob, d->x, d->i, d->lo, d->hi)) return false;
        if (d->prior_std > 0 && !d->mv && !lsq_add_prior(prob, d->x, d->i, d->prior_mean, d->prior_std)) return false;
    }
    for (int k = 0; k < F->nm; k++) {   // the materials' multivariate priors
        double *x = &F->mp[k * MODEL_BRDF_MAX_PARAMS];
        if (F->mvp[k].n > 0 &&
            !lsq_add_residual(prob, verify_mvprior_residual, &F->mvp[k], F->mvp[k].n, 1, &x, LSQ_LOSS_NONE, 0))
            return false;
    }
    // masks per block
    bool fx[MAX_LAMPS];
    for (int i = 0; i < F->nl; i++) fx[i] = opt->fix_lamps || !opt->use_priors || !lamp_lit(F, i);
    if (F->nl && !lsq_set_fixed(prob, F->out->s, fx)) return false;
    if (!F->nl) lsq_set_fixed(prob, F->out->s, NULL);
    for (int k = 0; k < npd; k++) {
        const pdesc_t *d = &pd[k];
        if (d->x == F->out->s) continue;
        bool f[MODEL_BRDF_MAX_PARAMS] = { 0 };
        int size = 1;
        for (int q = 0; q < npd; q++)
            if (pd[q].x == d->x) {
                f[pd[q].i] = pd[q].fixed;
                if (pd[q].i + 1 > size) size = pd[q].i + 1;
            }
        bool any = false;
        for (int q = 0; q < size; q++) any |= f[q];
        if (any && d->i == 0 && !lsq_set_fixed(prob, d->x, f)) return false;
    }
    return true;
}

// The parameter blocks of a point of image m and material mat: kc, s, Pa, p,
// rho, and with a second material mat2 (>= 0) its p. Returns their number.
static int fit_blocks(const fit_t *F, int m, int mat, int mat2, double *blocks[6])
{
    blocks[0] = &F->out->kc[F->imgs[m].camera];
    blocks[1] = F->out->s;
    blocks[2] = &F->out->Pa[m];
    blocks[3] = &F->mp[mat * MODEL_BRDF_MAX_PARAMS];
    blocks[4] = &F->out->rho;
    blocks[5] = mat2 >= 0 ? &F->mp[mat2 * MODEL_BRDF_MAX_PARAMS] : NULL;
    return mat2 >= 0 ? 6 : 5;
}

// The residual blocks: groups of up to 64 used points of one image and material.
static bool fit_residuals(fit_t *F)
{
    const verify_options_t *opt = F->opt;
    int gpos = 0;
    F->nused = F->ngroups = 0;
    for (int m = 0; m < F->nimgs; m++)
        for (int mat = 0; mat < F->nm; mat++)
            for (int mat2 = -1; mat2 < F->nm; mat2++) {
                int cur = -1;
                for (int k = 0; k < F->nfit; k++) {
                    const verify_point_t *p = &F->out->points[F->ptidx[k]];
                    if (p->image != m || F->pt[k].mat != mat || F->pt[k].mat2 != mat2 || p->status != VERIFY_PT_USED)
                        continue;
                    F->nused++;
                    if (cur < 0 || F->groups[cur].n == 64) {
                        cur = F->ngroups++;
                        F->groups[cur].rc = &F->rcs[mat];
                        F->groups[cur].rc2 = mat2 >= 0 ? &F->rcs[mat2] : NULL;
                        F->groups[cur].k = &F->gidx[gpos];
                        F->groups[cur].n = 0;
                        F->groups[cur].b = opt->robust_scale > 0 ? opt->robust_scale * opt->robust_scale : 0;
                    }
                    F->gidx[gpos++] = k;   // a group's indices are contiguous in gidx
                    F->groups[cur].n++;
                }
            }
    for (int gi = 0; gi < F->ngroups; gi++) {
        const pt_t *q = &F->pt[F->groups[gi].k[0]];
        double *blocks[6];
        int nb = fit_blocks(F, F->out->points[F->ptidx[F->groups[gi].k[0]]].image, q->mat, q->mat2, blocks);
        if (!lsq_add_residual(F->prob, group_fn, &F->groups[gi], F->groups[gi].n, nb, blocks, LSQ_LOSS_NONE, 0))
            return false;
    }
    return true;
}

// Solve (at least 10 usable points). false + message.
static bool fit_solve(fit_t *F)
{
    const verify_options_t *opt = F->opt;
    if (F->nused < 10) {
        model_error(NULL, 0, "verify: only %d usable reference points in %d image(s): the description's surfaces "
                    "are not in view, or the images are saturated", F->nused, F->nimgs);
        return false;
    }
    lsq_options_t fo = lsq_defaults();
    fo.threads = opt->threads;
    fo.max_iterations = opt->max_iterations > 0 ? opt->max_iterations : 100;
    fo.function_tolerance = 1e-8;
    fo.parameter_tolerance = 1e-8;
    fo.verbose = opt->verbose;
    fo.normal_equations = !opt->reference_eval;   // the reference: QR, as before the speed work
    if (!lsq_solve(F->prob, &fo, &F->out->summary)) {
        model_error(NULL, 0, "verify: the fit failed: %s (%s)", F->out->summary.termination, F->out->summary.message);
        return false;
    }
    return true;
}

// The fitted parameters with their priors and bounds; those at a bound are pinned.
static bool fit_collect_params(fit_t *F)
{
    verify_result_t *out = F->out;
    out->params = calloc((size_t)F->npd, sizeof *out->params);
    if (!out->params) return false;
    out->nparams = F->npd;
    for (int k = 0; k < F->npd; k++) {
        const pdesc_t *d = &F->pd[k];
        verify_param_t *o = &out->params[k];
        snprintf(o->name, sizeof o->name, "%s", d->name);
        o->value = d->x[d->i];
        o->std = NAN;
        o->prior_mean = d->prior_mean;
        o->prior_std = d->prior_std;
        o->lo = d->lo;
        o->hi = d->hi;
        o->fixed = d->fixed;
        if (!d->fixed && isfinite(d->lo) && isfinite(d->hi) && d->hi > d->lo) {
            double tol = 1e-3 * (d->hi - d->lo);
            o->pinned = o->value <= d->lo + tol || o->value >= d->hi - tol;
        } else if (!d->fixed && isfinite(d->lo) && o->value <= d->lo + 1e-9 * fmax(1, fabs(d->lo)) &&
                   d->lo > -INFINITY && F->opt->use_priors) {
            o->pinned = true;
        }
        if (o->pinned) out->npinned++;
    }
    return true;
}

// Add residual group g's J^T J to JtJ (nf x nf; col: parameter -> column or -1).
static bool covariance_add_group(const fit_t *F, const res_group_t *g, const int *col, int nf, double *jb,
                                 double *JtJ)
{
    const pdesc_t *pd = F->pd;
    const verify_point_t *p = &F->out->points[F->ptidx[g->k[0]]];
    int mat = F->pt[g->k[0]].mat, mat2 = F->pt[g->k[0]].mat2;
    double *blocks[6], rbuf[64];
    const int nb = fit_blocks(F, p->image, mat, mat2, blocks);
    const int size[6] = { 1, F->nl ? F->nl : 1, 1, F->rcs[mat].np, 1, mat2 >= 0 ? F->rcs[mat2].np : 0 };
    double *jac[6] = { NULL };
    int off = 0, gcol[6][MAX_LAMPS];
    for (int b = 0; b < nb; b++) {
        jac[b] = jb + (size_t)off * 64;
        off += size[b];
        for (int q = 0; q < size[b]; q++) {
            gcol[b][q] = -1;
            for (int k = 0; k < F->npd; k++)
                if (pd[k].x == blocks[b] && pd[k].i == q) gcol[b][q] = col[k];
        }
    }
    if (!group_fn((void *)g, (const double *const *)blocks, rbuf, jac)) return false;
    for (int t = 0; t < g->n; t++) {
        double row[64];
        int rc_[64], nr = 0;
        for (int b = 0; b < nb; b++)
            for (int q = 0; q < size[b]; q++)
                if (gcol[b][q] >= 0 && nr < 64) {
                    row[nr] = jac[b][(size_t)t * size[b] + q];
                    rc_[nr++] = gcol[b][q];
                }
        for (int u = 0; u < nr; u++)
            for (int v2 = 0; v2 < nr; v2++) JtJ[(size_t)rc_[u] * nf + rc_[v2]] += row[u] * row[v2];
    }
    return true;
}

// The parameters' standard deviations: (J^T J + priors)^-1 over the free
// parameters at the solution, J of the loss-scaled residuals (as Ceres's).
// They stay NAN when it cannot be had.
static void fit_covariance(fit_t *F)
{
    const int npd = F->npd, nl = F->nl;
    const pdesc_t *pd = F->pd;
    int nf = 0, *col = malloc((size_t)npd * sizeof *col);
    for (int k = 0; col && k < npd; k++) col[k] = pd[k].fixed ? -1 : nf++;
    double *JtJ = calloc((size_t)nf * nf + 1, sizeof *JtJ), *inv = calloc((size_t)nf * nf + 1, sizeof *inv);
    double *ev = malloc(((size_t)nf + 1) * sizeof *ev);
    double *jb = malloc((size_t)64 * (3 + nl + 2 * MODEL_BRDF_MAX_PARAMS) * sizeof *jb);
    bool cok = col && JtJ && inv && ev && jb && nf > 0;
    for (int gi = 0; gi < F->ngroups && cok; gi++) cok = covariance_add_group(F, &F->groups[gi], col, nf, jb, JtJ);
    for (int k = 0; k < npd && cok; k++)
        if (col[k] >= 0 && pd[k].prior_std > 0 && !pd[k].mv)
            JtJ[(size_t)col[k] * nf + col[k]] += 1 / (pd[k].prior_std * pd[k].prior_std);
    for (int m = 0; m < F->nm && cok; m++) {   // multivariate priors: Sigma_S^-1 = L^-T L^-1
        const verify_mvprior_t *v = &F->mvp[m];
        for (int a = 0; a < v->n; a++)
            for (int b = 0; b < v->n; b++) {
                int ca = col[F->mvp_pd[m] + v->idx[a]], cb = col[F->mvp_pd[m] + v->idx[b]];
                double s = 0;
                for (int r = 0; r < v->n; r++) s += v->Linv[r * v->n + a] * v->Linv[r * v->n + b];
                if (ca >= 0 && cb >= 0) JtJ[(size_t)ca * nf + cb] += s;
            }
    }
    for (int c = 0; c < nf && cok; c++) {
        double *A2 = malloc((size_t)nf * nf * sizeof *A2);
        if (!A2) {
            cok = false;
            break;
        }
        memcpy(A2, JtJ, (size_t)nf * nf * sizeof *A2);
        for (int q = 0; q < nf; q++) ev[q] = q == c;
        cok = model_solve_linear(A2, ev, nf);
        free(A2);
        for (int q = 0; q < nf && cok; q++) inv[(size_t)q * nf + c] = ev[q];
    }
    if (cok)
        for (int k = 0; k < npd; k++)
            if (col[k] >= 0) F->out->params[k].std = sqrt(fmax(inv[(size_t)col[k] * nf + col[k]], 0));
    free(col);
    free(JtJ);
    free(inv);
    free(ev);
    free(jb);
}

// The residue: the fitted model at every measured point (used and
// edge-measured), z and the flags; the status counts and the statistics.
static void fit_residue(fit_t *F)
{
    verify_result_t *out = F->out;
    for (int k = 0; k < F->nfit; k++) {
        verify_point_t *p = &out->points[F->ptidx[k]];
        double r, *blocks[6];
        res_item_t it = { &F->rcs[F->pt[k].mat], F->pt[k].mat2 >= 0 ? &F->rcs[F->pt[k].mat2] : NULL, k };
        fit_blocks(F, p->image, F->pt[k].mat, F->pt[k].mat2, blocks);
        residual_fn(&it, (const double *const *)blocks, &r, NULL);
        p->model = (float)(F->pt[k].meas + r * F->pt[k].sigma);
        if (p->status == VERIFY_PT_USED) {
            p->z = (float)-r;   // (measured - model) / sigma, the sign of the difference images
            p->flag = fabs(r) > F->opt->z_flag;
        } else {
            p->flag = true;   // an unexpected edge: z holds z_flag * its std ratio
        }
    }
    for (int k = 0; k < F->npts; k++) out->nstatus[out->points[k].status]++;
    out->npoints = F->npts;
    stats_of(out->points, F->npts, -1, &out->all);
    for (int m = 0; m < F->nimgs; m++) stats_of(out->points, F->npts, m, &out->per_image[m]);
}

// Grow region rid from grid point g0 of image m (points from base on) over
// 8-connected flags; stack: room for the image's points.
static void grow_region(verify_result_t *out, const verify_view_t *v, int m, int base, int g0, int rid, int *stack,
                        const verify_options_t *opt)
{
    verify_region_t *R = &out->regions[rid];
    memset(R, 0, sizeof *R);
    R->image = m;
    R->bbox[0] = R->bbox[1] = INFINITY;
    R->bbox[2] = R->bbox[3] = -INFINITY;
    int fc[64], fn[64], nf = 0;
    int top = 0;
    stack[top++] = g0;
    out->points[base + g0].region = rid;
    const double cap2 = 25 * opt->z_flag * opt->z_flag;
    while (top) {
        int g = stack[--top];
        verify_point_t *p = &out->points[base + g];
        R->npoints++;
        double z2 = fmin((double)p->z * p->z, cap2);
        R->excess_chi2 += fmax(z2 - opt->z_flag * opt->z_flag, 0);
        R->max_abs_z = fmax(R->max_abs_z, fabs(p->z));
        R->bbox[0] = fmin(R->bbox[0], p->q[0] - v->sp / 2.0);
        R->bbox[1] = fmin(R->bbox[1], p->q[1] - v->sp / 2.0);
        R->bbox[2] = fmax(R->bbox[2], p->q[0] + v->sp / 2.0);
        R->bbox[3] = fmax(R->bbox[3], p->q[1] + v->sp / 2.0);
        int f;
        for (f = 0; f < nf; f++)
            if (fc[f] == p->face) break;
        if (f == nf && nf < 64) {
            fc[nf] = p->face;
            fn[nf++] = 0;
        }
        if (f < 64) fn[f]++;
        int gi = g % v->gw, gj = g / v->gw;
        for (int dj = -1; dj <= 1; dj++)
            for (int di = -1; di <= 1; di++) {
                int ii = gi + di, jj = gj + dj;
                if (ii < 0 || jj < 0 || ii >= v->gw || jj >= v->gh) continue;
                verify_point_t *q2 = &out->points[base + jj * v->gw + ii];
                if (q2->flag && q2->region < 0) {
                    q2->region = rid;
                    stack[top++] = jj * v->gw + ii;
                }
            }
    }
    R->area_px = (double)R->npoints * v->sp * v->sp;
    R->counts = R->npoints >= opt->min_region;
    for (int t = 0; t < 4; t++) {
        int best = -1;
        for (int f = 0; f < nf; f++)
            if (fn[f] > 0 && (best < 0 || fn[f] > fn[best])) best = f;
        R->faces[t] = best >= 0 ? fc[best] : -1;
        R->face_points[t] = best >= 0 ? fn[best] : 0;
        if (best >= 0) fn[best] = 0;
    }
}

// Change detection: 8-connected flags on each image's grid are regions; the
// score sums the excess chi^2 of those of at least min_region points.
static void fit_regions(fit_t *F)
{
    verify_result_t *out = F->out;
    int base = 0, cap = 0;
    int *stack = malloc((size_t)(F->npts ? F->npts : 1) * sizeof *stack);
    for (int m = 0; m < F->nimgs && stack; m++) {
        const verify_view_t *v = F->views[m];
        int n = v->gw * v->gh;
        for (int g0 = 0; g0 < n; g0++) {
            const verify_point_t *p0 = &out->points[base + g0];
            if (!p0->flag || p0->region >= 0) continue;
            if (out->nregions == cap) {
                cap = cap ? 2 * cap : 64;
                verify_region_t *nr = realloc(out->regions, (size_t)cap * sizeof *nr);
                if (!nr) break;
                out->regions = nr;
            }
            int rid = out->nregions++;
            grow_region(out, v, m, base, g0, rid, stack, F->opt);
            if (out->regions[rid].counts) out->score += out->regions[rid].excess_chi2;
        }
        base += n;
    }
    free(stack);
}

bool verify_param_warning(const verify_param_t *p, char *buf, size_t n)
{
    if (p->fixed) return false;
    if (p->pinned) {
        snprintf(buf, n, "%s = %.6g is pinned at its bound [%.6g, %.6g]: its prior may be wrong (swapped or "
                 "mislabelled materials, a changed lamp or camera)", p->name, p->value, p->lo, p->hi);
        return true;
    }
    double z = p->prior_std > 0 ? (p->value - p->prior_mean) / p->prior_std : 0;
    if (fabs(z) > 3) {
        snprintf(buf, n, "%s = %.6g is %.1f sigma from its prior %.6g +- %.3g: the prior does not hold for these "
                 "images (a changed lamp, camera, offset or material)", p->name, p->value, z, p->prior_mean,
                 p->prior_std);
        return true;
    }
    return false;
}

// The fit's warnings: its parameters' (verify_param_warning; the lamps off
// in every image are held, not fitted: fixed, no warning). false: out of memory.
static bool fit_warnings(fit_t *F)
{
    verify_result_t *out = F->out;
    out->warnings = calloc((size_t)out->nparams + 1, sizeof *out->warnings);
    if (!out->warnings) return false;
    for (int k = 0; k < out->nparams; k++)
        if (verify_param_warning(&out->params[k], out->warnings[out->nwarnings], sizeof out->warnings[0]))
            out->nwarnings++;
    return true;
}

bool verify_run(const model_scene_t *scene, const verify_priors_t *pr, const verify_camera_t *cams, int ncams,
                const model_lamps_t *lamps, const double *A, const verify_image_t *imgs, int nimgs,
                verify_view_t *const *views, const verify_options_t *opt, verify_result_t *out)
{
    memset(out, 0, sizeof *out);
    double t0 = model_now_s();
    fit_t F = { .scene = scene, .cams = cams, .ncams = ncams, .lamps = lamps, .A = A, .imgs = imgs, .nimgs = nimgs,
                .views = views, .opt = opt, .nl = lamps->n, .nm = scene->nmaterials, .out = out };
    bool ok = false;
    if (!fit_check(&F, pr) || !fit_alloc(&F) || !fit_measure(&F)) goto done;
    if (!fit_parameters(&F) || !fit_bounds_and_masks(&F) || !fit_residuals(&F)) {
        model_error(NULL, 0, "verify: setting up the fit failed: %s", model_last_error());
        goto done;
    }
    if (!fit_solve(&F) || !fit_collect_params(&F)) goto done;
    if (!opt->no_covariance) fit_covariance(&F);
    if (!fit_warnings(&F)) goto done;
    for (int k = 0; k < F.nm; k++) memcpy(out->mats[k].p, &F.mp[k * MODEL_BRDF_MAX_PARAMS], sizeof out->mats[k].p);
    fit_residue(&F);
    fit_regions(&F);
    // the verdict
    out->correct = out->score <= opt->score_threshold;
    out->time_fit_s = model_now_s() - t0;
    ok = true;
done:
    fit_free(&F);
    return ok;
}

// ---------------------------------------------------------------------------
// JSON

static json_t *jreal(double x) { return isfinite(x) ? json_real(x) : json_null(); }

static json_t *stats_json(const verify_stats_t *s)
{
    json_t *o = json_object();
    json_object_set_new(o, "n_points", json_integer(s->npoints));
    json_object_set_new(o, "max_abs_diff_dn", jreal(s->max_abs));
    json_object_set_new(o, "mean_abs_diff_dn", jreal(s->mean_abs));
    json_object_set_new(o, "std_abs_diff_dn", jreal(s->std_abs));
    json_object_set_new(o, "robust_sigma_dn", jreal(s->robust_sigma));
    json_object_set_new(o, "rms_z", jreal(s->rms_z));
    json_object_set_new(o, "median_abs_z", jreal(s->median_abs_z));
    return o;
}

json_t *verify_result_json(const verify_result_t *r, const model_scene_t *scene, const verify_image_t *imgs,
                           const model_lamps_t *lamps, const verify_options_t *opt)
{
    (void)lamps;
    json_t *o = json_object();
    json_object_set_new(o, "verdict", json_string(r->correct ? "correct" : "incorrect"));
    json_object_set_new(o, "description_correct", json_boolean(r->correct));
    json_object_set_new(o, "score", jreal(r->score));
    json_object_set_new(o, "score_threshold", jreal(opt->score_threshold));
    json_object_set_new(o, "score_definition",
                        json_string("sum over change regions of at least min_region flagged grid points of "
                                    "sum(min(z^2, (5 z_flag)^2) - z_flag^2); z = (measured - model)/sigma per "
                                    "reference point; an unexpected edge counts as z_flag x its window-std ratio"));
    json_object_set_new(o, "n_pinned_parameters", json_integer(r->npinned));
    json_t *warn = json_array();
    for (int k = 0; k < r->nwarnings; k++) json_array_append_new(warn, json_string(r->warnings[k]));
    json_object_set_new(o, "warnings", warn);
    json_object_set_new(o, "residue", stats_json(&r->all));
    json_object_set_new(o, "residue_units", json_string("DN of the images' pixel format; difference = measured - "
                                                        "model at each reference point (window mean)"));
    json_t *pi = json_array();
    for (int m = 0; m < r->nimages; m++) {
        json_t *s = stats_json(&r->per_image[m]);
        json_object_set_new(s, "image", json_string(imgs[m].name));
        json_object_set_new(s, "turntable_deg", json_real(imgs[m].angle_deg));
        json_array_append_new(pi, s);
    }
    json_object_set_new(o, "residue_per_image", pi);
    json_t *st = json_object();
    for (int s = 0; s < VERIFY_PT_NSTATUS; s++)
        json_object_set_new(st, verify_pt_status_name((verify_pt_status_t)s), json_integer(r->nstatus[s]));
    json_object_set_new(o, "reference_points", st);
    json_t *rg = json_array();
    for (int k = 0; k < r->nregions; k++) {
        const verify_region_t *R = &r->regions[k];
        if (!R->counts) continue;
        json_t *e = json_object();
        json_object_set_new(e, "index", json_integer(k));
        json_object_set_new(e, "image", json_string(imgs[R->image].name));
        json_object_set_new(e, "image_index", json_integer(R->image));
        json_object_set_new(e, "n_points", json_integer(R->npoints));
        json_object_set_new(e, "area_px", json_real(R->area_px));
        json_object_set_new(e, "excess_chi2", json_real(R->excess_chi2));
        json_object_set_new(e, "max_abs_z", json_real(R->max_abs_z));
        json_object_set_new(e, "bbox_px", json_pack("[f,f,f,f]", R->bbox[0], R->bbox[1], R->bbox[2], R->bbox[3]));
        json_t *fa = json_array();
        for (int t = 0; t < 4; t++) {
            if (R->face_points[t] <= 0) continue;
            int f = R->faces[t];
            json_t *fe = json_object();
            if (f < 0) json_object_set_new(fe, "face", json_string("background"));
            else if (f < scene->nfaces) {
                json_object_set_new(fe, "face", json_integer(scene->faces[f].number));
                json_object_set_new(fe, "line", json_integer(scene->faces[f].line));
                json_object_set_new(fe, "material",
                                    json_string(scene->material_names[scene->faces[f].material]));
            } else {
                json_object_set_new(fe, "sphere", json_integer(f - scene->nfaces));
            }
            json_object_set_new(fe, "n_points", json_integer(R->face_points[t]));
            json_array_append_new(fa, fe);
        }
        json_object_set_new(e, "faces", fa);
        json_array_append_new(rg, e);
    }
    json_object_set_new(o, "change_regions", rg);
    json_t *ps = json_array();
    for (int k = 0; k < r->nparams; k++) {
        const verify_param_t *p = &r->params[k];
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(p->name));
        json_object_set_new(e, "value", jreal(p->value));
        json_object_set_new(e, "std", jreal(p->std));
        json_object_set_new(e, "prior_mean", jreal(p->prior_mean));
        json_object_set_new(e, "prior_std", p->prior_std > 0 ? json_real(p->prior_std) : json_null());
        json_object_set_new(e, "lo", jreal(p->lo));
        json_object_set_new(e, "hi", jreal(p->hi));
        json_object_set_new(e, "fixed", json_boolean(p->fixed));
        json_object_set_new(e, "pinned", json_boolean(p->pinned));
        json_array_append_new(ps, e);
    }
    json_object_set_new(o, "parameters", ps);
    json_object_set_new(o, "parameter_conventions",
                        json_string("kc[camera]: the camera's sensitivity relative to the white calibration; "
                                    "lamp[name]: the lamp's intensity relative to it; Pa[image]: offset left after "
                                    "the offset map, DN (the dark level itself without one); rho: weight of the "
                                    "one-bounce diffuse interreflection (1 = physical); material.parameter: see "
                                    "the priors' conventions"));
    json_t *fs = json_object();
    json_object_set_new(fs, "iterations", json_integer(r->summary.iterations));
    json_object_set_new(fs, "initial_cost", jreal(r->summary.initial_cost));
    json_object_set_new(fs, "final_cost", jreal(r->summary.final_cost));
    json_object_set_new(fs, "termination", json_string(r->summary.termination));
    json_object_set_new(fs, "n_residuals", json_integer(r->summary.nresiduals));
    json_object_set_new(fs, "n_free_parameters", json_integer(r->summary.nfree));
    json_object_set_new(fs, "time_s", jreal(r->time_fit_s));
    json_object_set_new(o, "fit", fs);
    json_t *op = json_object();
    json_object_set_new(op, "spacing_px", json_integer(opt->spacing_px));
    json_object_set_new(op, "window_px", json_integer(opt->window_px));
    json_object_set_new(op, "edge_margin_px", json_real(opt->edge_margin_px));
    json_object_set_new(op, "boundary_margin_px", json_real(opt->boundary_margin_px));
    json_object_set_new(op, "edge_k", json_real(opt->edge_k));
    json_object_set_new(op, "edge_rel", json_real(opt->edge_rel));
    json_object_set_new(op, "interreflection_samples", json_integer(opt->ir_samples));
    json_object_set_new(op, "priors", json_boolean(opt->use_priors));
    json_object_set_new(op, "gain_maps", json_boolean(opt->use_flat));
    json_object_set_new(op, "model_rel", json_real(opt->model_rel));
    json_object_set_new(op, "model_rel_source",
                        json_string(opt->model_rel_given ? "model_rel for every material (--model-rel)"
                                                         : "each material's priors' window_rel_std; model_rel for "
                                                           "materials whose priors state none"));
    json_object_set_new(op, "edge_windows", json_boolean(opt->edge_windows));
    json_object_set_new(op, "edge_subsamples", json_integer(opt->edge_subsamples));
    json_object_set_new(op, "edge_position_sigma_px", json_real(opt->edge_position_sigma_px));
    json_object_set_new(op, "lamp_sigma", json_real(opt->lamp_sigma));
    json_object_set_new(op, "camera_sigma", json_real(opt->camera_sigma));
    json_object_set_new(op, "robust_scale", json_real(opt->robust_scale));
    json_object_set_new(op, "z_flag", json_real(opt->z_flag));
    json_object_set_new(op, "min_region", json_integer(opt->min_region));
    json_object_set_new(o, "options", op);
    return o;
}

// ---------------------------------------------------------------------------
// Self check of the residual's Jacobian (tests)

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
            ok = lsq_check_jacobian(group_fn, &g, 1, mixed ? 6 : 5, sizes, blocks, 1e-6, 1e-6, 1e-4, &err) && ok;
            if (max_abs_err && err > *max_abs_err) *max_abs_err = err;
        }
    return ok;
}
