// fit/verify/verify.c — the verification fitter (see verify.h for the model): the
// fit's state, its parameters and priors, residual blocks, solve and verdict.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

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
    if (!F->prior) {
        model_error(NULL, 0, "out of memory");
        return false;
    }
    if (!verify_match_priors(F->scene, pr, F->prior)) return false;
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
    if (!mat_used) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    for (int k = 0; k < F->nfit; k++)
        if (F->pt[k].mat >= 0 && F->pt[k].mat < F->nm && out->points[F->ptidx[k]].status == VERIFY_PT_USED) {
            mat_used[F->pt[k].mat] = true;
            if (F->pt[k].mat2 >= 0 && F->pt[k].mat2 < F->nm) mat_used[F->pt[k].mat2] = true;
        }
    bool ok = true;
    F->mvp = calloc((size_t)F->nm + 1, sizeof *F->mvp);
    F->mvp_pd = calloc((size_t)F->nm + 1, sizeof *F->mvp_pd);
    if (!F->mvp || !F->mvp_pd) {
        model_error_set(NULL, 0, "out of memory");
        ok = false;
    }
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
int verify_fit_blocks(const fit_t *F, int m, int mat, int mat2, double *blocks[6])
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
        int nb = verify_fit_blocks(F, F->out->points[F->ptidx[F->groups[gi].k[0]]].image, q->mat, q->mat2, blocks);
        if (!lsq_add_residual(F->prob, verify_group_fn, &F->groups[gi], F->groups[gi].n, nb, blocks, LSQ_LOSS_NONE, 0))
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
    fo.normal_equations = !opt->reference_eval;   // the reference: QR on the residuals
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
    if (!out->params) {
        model_error(NULL, 0, "out of memory for %d parameters", F->npd);
        return false;
    }
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
// in every image are held, not fitted: fixed, no warning). false + message: out of memory.
static bool fit_warnings(fit_t *F)
{
    verify_result_t *out = F->out;
    out->warnings = calloc((size_t)out->nparams + 1, sizeof *out->warnings);
    if (!out->warnings) {
        model_error(NULL, 0, "out of memory for the warnings");
        return false;
    }
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
    if (!fit_check(&F, pr) || !fit_alloc(&F) || !verify_fit_measure(&F)) goto done;
    if (!fit_parameters(&F) || !fit_bounds_and_masks(&F) || !fit_residuals(&F)) {
        model_error(NULL, 0, "verify: setting up the fit failed: %s", model_last_error());
        goto done;
    }
    if (!fit_solve(&F) || !fit_collect_params(&F)) goto done;
    if ((!opt->no_covariance && !verify_fit_covariance(&F)) || !fit_warnings(&F)) goto done;
    for (int k = 0; k < F.nm; k++) memcpy(out->mats[k].p, &F.mp[k * MODEL_BRDF_MAX_PARAMS], sizeof out->mats[k].p);
    if (!verify_fit_residue(&F) || !verify_fit_regions(&F)) goto done;
    // the verdict
    out->correct = out->score <= opt->score_threshold;
    out->time_fit_s = model_now_s() - t0;
    ok = true;
done:
    fit_free(&F);
    return ok;
}
