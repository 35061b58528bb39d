// fit/material/material.c — the material fit (fit_material_run, see material.h):
// calibrated observations (calib_observe) to BRDF samples, every model
// fitted, priors and the report.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/material/internal.h"
#include "fit/material/material.h"
#include "fit/verify/verify.h"
#include "rig/session/session.h"
#include "model/base/report.h"
#include "model/base/vec.h"

// ---------------------------------------------------------------------------
// Albedo cells (--albedo-cells MM): a textured material (wood, a painted
// surface) varies its albedo from place to place, which one set of BRDF
// parameters cannot follow. The sample's surface is cut into cells of MM mm
// (by the observations' points at angle 0, which turn with the table, and
// their faces); each cell with at least CELL_MIN_OBS observations gets a
// factor c_j on its whole reflectance (the virtual rig's texture multiplies
// it so), and the fit becomes R_k = c_j(k) R(theta; geometry_k):
//   1. theta from the samples as they are (the model fit_brdf_models chose);
//   2. c_j = sum R_k f_k / sum f_k^2 over the cell (f = the model's R),
//      then the factors scaled to mean 1 over the observations (so kd & co
//      are the sample's mean);
//   3. theta again from R_k / c_j with weights c_j^2 (the same residuals
//      R_k - c_j f_k); repeat 2-3 until no factor moves by 1e-4 (at most 20).
// Every model is then fitted to the corrected samples. The residual's
// degrees of freedom lose one per cell (rms_over_noise uses N - k - cells).
enum { CELL_MIN_OBS = 4 };

typedef struct {
    int     n_cells, n_obs_in, iterations;
    int    *cell;       // per observation: its cell, -1 when its cell has too few
    double *factor;     // per cell
    double  rel_std;    // std of the factors over the observations (their mean is 1)
} albedo_cells_t;

static void cells_free(albedo_cells_t *ac)
{
    free(ac->cell);
    free(ac->factor);
    memset(ac, 0, sizeof *ac);
}

static bool cells_assign(const calib_obs_set_t *obs, double cell_mm, albedo_cells_t *ac)
{
    memset(ac, 0, sizeof *ac);
    GHashTable *h = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);
    int *raw = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *raw), nraw = 0;
    ac->cell = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *ac->cell);
    if (!h || !raw || !ac->cell) goto oom;
    for (int i = 0; i < obs->n; i++) {
        const calib_obs_t *o = &obs->o[i];
        char key[96];
        snprintf(key, sizeof key, "%d:%.0f:%.0f:%.0f", o->face, floor(o->p0_mm[0] / cell_mm),
                 floor(o->p0_mm[1] / cell_mm), floor(o->p0_mm[2] / cell_mm));
        gpointer v;
        if (g_hash_table_lookup_extended(h, key, NULL, &v)) {
            raw[i] = GPOINTER_TO_INT(v);
        } else {
            raw[i] = nraw;
            g_hash_table_insert(h, g_strdup(key), GINT_TO_POINTER(nraw));
            nraw++;
        }
    }
    int *count = calloc((size_t)(nraw ? nraw : 1), sizeof *count), *index = malloc((size_t)(nraw ? nraw : 1) * sizeof *index);
    if (!count || !index) {
        free(count);
        free(index);
        goto oom;
    }
    for (int i = 0; i < obs->n; i++) count[raw[i]]++;
    for (int j = 0; j < nraw; j++) index[j] = count[j] >= CELL_MIN_OBS ? ac->n_cells++ : -1;
    for (int i = 0; i < obs->n; i++) {
        ac->cell[i] = index[raw[i]];
        ac->n_obs_in += ac->cell[i] >= 0;
    }
    free(count);
    free(index);
    ac->factor = malloc((size_t)(ac->n_cells ? ac->n_cells : 1) * sizeof *ac->factor);
    if (!ac->factor) goto oom;
    for (int j = 0; j < ac->n_cells; j++) ac->factor[j] = 1;
    free(raw);
    g_hash_table_destroy(h);
    return true;
oom:
    free(raw);
    if (h) g_hash_table_destroy(h);
    cells_free(ac);
    model_error_set(NULL, 0, "out of memory for the albedo cells");
    return false;
}

// The samples corrected by the cells' factors: R_k / c, weight c^2.
static fit_samples_t *cells_samples(const fit_samples_t *smp, const albedo_cells_t *ac)
{
    fit_samples_t *out = fit_samples_new();
    if (!out) {
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    snprintf(out->source, sizeof out->source, "%s", smp->source);
    out->noise_weighted = smp->noise_weighted;   // R/c has the std sigma/c: weight c^2 / sigma^2
    for (int i = 0; i < smp->n; i++) {
        double c = ac->cell[i] >= 0 ? ac->factor[ac->cell[i]] : 1;
        const model_cosines_t *disc = smp->disc_at && smp->disc_at[i] >= 0 ? smp->disc + smp->disc_at[i] : NULL;
        if (!fit_samples_add_disc(out, &smp->c[i], disc, smp->R[i] / c, smp->w[i] * c * c)) {
            fit_samples_free(out);
            model_error_set(NULL, 0, "sample %d: albedo factor %g gives no usable sample", i, c);
            return NULL;
        }
    }
    return out;
}

// Steps 2-3 above from the fit *r (its model and parameters); *r is updated.
static bool cells_fit(const fit_samples_t *smp, albedo_cells_t *ac, fit_brdf_result_t *r)
{
    double *num = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *num);
    double *den = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *den);
    bool ok = num && den;
    if (!ok) model_error_set(NULL, 0, "out of memory for the albedo cells");
    ac->iterations = 0;
    for (int it = 0; ok && it < 20; it++) {
        ac->iterations = it + 1;   // rounds done (reported)
        memset(num, 0, (size_t)ac->n_cells * sizeof *num);
        memset(den, 0, (size_t)ac->n_cells * sizeof *den);
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j < 0) continue;
            double f = fit_samples_eval(smp, r->model, r->p, i);
            num[j] += smp->R[i] * f;
            den[j] += f * f;
        }
        double sum = 0, moved = 0;
        int n = 0;
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j >= 0 && den[j] > 0) {
                sum += num[j] / den[j];
                n++;
            }
        }
        double mean = n ? sum / n : 1;
        for (int j = 0; j < ac->n_cells; j++) {
            double c = den[j] > 0 && mean > 0 ? num[j] / den[j] / mean : 1;
            if (!(c > 0) || !isfinite(c)) c = 1;
            moved = fmax(moved, fabs(c - ac->factor[j]));
            ac->factor[j] = c;
        }
        fit_samples_t *cs = cells_samples(smp, ac);
        fit_brdf_result_t nr;
        double start[MODEL_BRDF_MAX_PARAMS];
        memcpy(start, r->p, sizeof start);
        ok = cs && fit_brdf_from(cs, r->model, NULL, start, &nr);
        fit_samples_free(cs);
        if (!ok) break;
        // alternating least squares: the residual only falls; stop when it
        // no longer does (or nothing moves)
        double before = r->rss;
        *r = nr;
        if (moved < 1e-4 || (it > 0 && before - nr.rss <= 1e-6 * before)) break;
    }
    if (ok) {
        double s1 = 0, s2 = 0;
        for (int i = 0; i < smp->n; i++)
            if (ac->cell[i] >= 0) {
                double c = ac->factor[ac->cell[i]];
                s1 += c;
                s2 += c * c;
            }
        int n = ac->n_obs_in;
        ac->rel_std = n > 1 ? sqrt(fmax(0.0, (s2 - s1 * s1 / n) / (n - 1))) : 0;
    }
    free(num);
    free(den);
    return ok;
}

// ---------------------------------------------------------------------------
// The material fit (fit_material_run): stages

fit_material_opts_t fit_material_defaults(void)
{
    return (fit_material_opts_t){ .model = "all", .k_sigma = 3, .sys_rel = 0.03, .lamp_rel = 0.03, .cv_folds = 5,
                                  .cv_seed = 1, .noise_weights = true, .loss = LSQ_LOSS_NONE, .loss_scale = 2 };
}

void fit_material_result_free(fit_material_result_t *r)
{
    if (r) memset(r, 0, sizeof *r);
}

// The cameras of o->session to observe: o->camera, else every camera of the
// session (names; NULL entries: a session of one camera, read with the
// calibration directory's plain layout). Their number, 0 on error.
static int material_cameras(const fit_material_opts_t *o, const char *names[8], char store[8][32])
{
    if (o->camera) {
        snprintf(store[0], 32, "%s", o->camera);
        names[0] = store[0];
        return 1;
    }
    rig_session_t *s = rig_session_open(o->session);
    if (!s) return 0;
    const char *nm[8];
    int nc = rig_session_cameras(s, nm, 8);
    if (nc > 8) {
        model_error_set(o->session, 0, "%d cameras: the fit takes at most 8 (give --camera NAME)", nc);
        nc = 0;
    }
    for (int k = 0; k < nc; k++) {
        snprintf(store[k], 32, "%s", nm[k]);
        names[k] = nc > 1 ? store[k] : NULL;
    }
    if (nc == 0 && s->n == 0) model_error_set(o->session, 0, "the session has no frames");
    if (nc == 1) names[0] = NULL;
    rig_session_free(s);
    return nc;
}

// One camera's observations (through c) as BRDF samples R = s d^2 / kcI into
// smp, each weighted by its noise: sigma_R = s_std d^2 / kcI, s_std the
// temporal noise calib_observe gives the window's mean (shot noise K S at its
// linearised signal S, read noise, quantisation, at the frame's exposure and
// gain, through the same flat field, emission and drift division as s), so
// w = 1 / sigma_R^2; *v2 += sigma_R^2, *missing += samples without a sigma
// (no gain calibration: weight 1).
static bool camera_samples(const calib_set_t *c, const calib_obs_set_t *ob, fit_samples_t *smp, double *v2,
                           int *missing)
{
    for (int i = 0; i < ob->n; i++) {
        const calib_obs_t *b = &ob->o[i];
        double sr = b->s_std * b->d_mm * b->d_mm / c->kcI_per_us[b->lamp];
        bool has = sr > 0 && isfinite(sr);
        *missing += !has;
        if (!fit_samples_add_disc(smp, &b->c, b->has_disc ? b->disc : NULL,
                                  b->s_dn_per_us * b->d_mm * b->d_mm / c->kcI_per_us[b->lamp], has ? 1 / (sr * sr) : 1)) {
            model_error_set(NULL, 0, "observation %d (step %d%s%s) gives no usable sample (kc*I of lamp %s is %g)",
                            i, b->step, c->camera[0] ? ", camera " : "", c->camera, c->lamps->lamps[b->lamp].name,
                            c->kcI_per_us[b->lamp]);
            return false;
        }
        *v2 += has ? sr * sr : 0;
    }
    return true;
}

// ob's observations appended to obs (ob emptied).
static bool obs_append(calib_obs_set_t *obs, calib_obs_set_t *ob)
{
    calib_obs_t *o2 = realloc(obs->o, sizeof *o2 * (size_t)(obs->n + ob->n + 1));
    if (!o2) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    obs->o = o2;
    memcpy(obs->o + obs->n, ob->o, sizeof *o2 * (size_t)ob->n);
    obs->n += ob->n;
    obs->cap = obs->n;
    obs->frames_used += ob->frames_used;
    obs->frames_skipped += ob->frames_skipped;
    snprintf(obs->sample, sizeof obs->sample, "%s", ob->sample);
    snprintf(obs->material, sizeof obs->material, "%s", ob->material);
    calib_obs_free(ob);
    return true;
}

// The observations of the session (calib_observe_session, each camera's
// through its calibrations) and their BRDF samples R = s d^2 / kcI; the
// expected noise RMS when every camera has a gain calibration. *cal: the
// first camera's set, its inputs listing every camera's files.
static bool material_samples(const fit_material_opts_t *o, calib_set_t **cal, calib_obs_set_t *obs,
                             fit_samples_t **smp, fit_material_result_t *r)
{
    calib_observe_options_t co = calib_observe_defaults();
    co.scene_path = o->scene;
    co.scene_unit_mm = o->scene_unit_mm;
    co.material = o->material;
    co.verbose = co.pose.verbose = o->verbose;
    co.fit_pose = !o->pose_nominal;
    if (o->pose_sigma_deg > 0) co.pose.sigma_deg = o->pose_sigma_deg;
    if (o->pose_sigma_mm > 0) co.pose.sigma_mm = o->pose_sigma_mm;
    if (o->window > 0) co.window = o->window;
    if (o->step > 0) co.step = o->step;
    memset(obs, 0, sizeof *obs);
    const char *names[8];
    char store[8][32];
    int nc = material_cameras(o, names, store);
    if (!nc) return false;
    if (!(*smp = fit_samples_new())) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    snprintf((*smp)->source, sizeof (*smp)->source, "%s", o->session);
    // every camera's calibrations first, so that one missing fails before the others' observations
    for (int k = 0; k < nc; k++)
        if (names[k] && !calib_set_has_camera(o->calib, names[k])) {
            calib_set_free(calib_set_load_camera(o->calib, names[k], true));   // its message: what is missing
            return false;
        }
    double v2 = 0;
    bool all_gain = true;
    int missing = 0;
    for (int k = 0; k < nc; k++) {
        calib_set_t *ck = NULL;
        calib_obs_set_t ob;
        bool ok = calib_observe_session(o->session, o->calib, names[k], true, &co, &ck, &ob) &&
                  camera_samples(ck, &ob, *smp, &v2, &missing);
        if (ok) {
            snprintf(r->cameras[k], sizeof r->cameras[k], "%s", store[k]);
            r->nobs_camera[k] = ob.n;
            r->ncameras = k + 1;
            all_gain &= ck->gain_dn_per_e > 0;
            if (k == 0) r->pose = ob.pose;
            ok = obs_append(obs, &ob);
        }
        calib_obs_free(&ob);
        if (ok && k == 0) *cal = ck;
        else if (ok) json_array_extend((*cal)->inputs, ck->inputs);
        if (k > 0 || !ok) calib_set_free(ck);
        if (!ok) return false;
    }
    const calib_set_t *c = *cal;
    r->observed = true;
    snprintf(r->sample, sizeof r->sample, "%s", obs->sample);
    snprintf(r->material, sizeof r->material, "%s", obs->material);
    r->nobs = obs->n;
    r->nsamples = (*smp)->n;
    r->frames_used = obs->frames_used;
    r->frames_skipped = obs->frames_skipped;
    // the residual RMS the sensor's temporal noise alone would give (with gain calibrations)
    if (all_gain && obs->n > 0) {
        r->have_gain = true;
        r->noise_rms = sqrt(v2 / obs->n);
        r->lin = c->lin;
    }
    // weighted by each sample's noise when every sample has one (and not --weights uniform)
    (*smp)->noise_weighted = o->noise_weights && missing == 0 && (*smp)->n > 0;
    r->noise_weighted = (*smp)->noise_weighted;
    if (!(*smp)->noise_weighted)
        for (int i = 0; i < (*smp)->n; i++) (*smp)->w[i] = 1;
    return true;
}

// The fits' options: the model choice by cross-validation over the frames
// (one turntable step lit by one lamp: the windows of a frame share its pose,
// lamp and exposure errors, so they are held out together). unit: per sample
// (= observation) its step.
static fit_brdf_options_t material_fit_options(const fit_material_opts_t *o, const calib_obs_set_t *obs, int *unit)
{
    fit_brdf_options_t fo = fit_brdf_defaults();
    fo.cv_folds = o->cv_folds;
    fo.cv_seed = o->cv_seed;
    fo.loss = o->loss;
    fo.loss_scale = o->loss_scale;
    if (unit) {
        for (int i = 0; i < obs->n; i++) unit[i] = obs->o[i].step;
        fo.cv_unit = unit;
        fo.cv_unit_name = "frame";
    }
    return fo;
}

// Albedo cells of o->cell_mm: the factors fitted with the first pass's best
// model, *csmp the corrected samples, and every model fitted to them into r->models.
static bool material_cells(const fit_material_opts_t *o, const calib_obs_set_t *obs, const fit_samples_t *smp,
                           const model_brdf_t *models, int nm, albedo_cells_t *ac, fit_samples_t **csmp,
                           fit_material_result_t *r, const fit_brdf_options_t *fo)
{
    fit_brdf_result_t b = r->first.res[r->first.best];
    if (!cells_assign(obs, o->cell_mm, ac) || !cells_fit(smp, ac, &b) || !(*csmp = cells_samples(smp, ac))) {
        char msg[1600];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error_set(NULL, 0, "albedo cells: %s", msg);
        return false;
    }
    r->cells_done = true;
    r->n_cells = ac->n_cells;
    r->n_obs_in_cells = ac->n_obs_in;
    r->cells_rel_std = ac->rel_std;
    r->cell_iterations = ac->iterations;
    r->cells_model = b.model;
    if (!fit_brdf_models(*csmp, models, nm, fo, &r->models)) {
        model_error_set(NULL, 0, "no model could be fitted to the samples with albedo cells");
        return false;
    }
    return true;
}

// The albedo cells' record in the priors entry.
static json_t *cells_json(const fit_material_opts_t *o, const fit_material_result_t *r)
{
    json_t *jc = json_object();
    json_object_set_new(jc, "cell_mm", json_real(o->cell_mm));
    json_object_set_new(jc, "cells", json_integer(r->n_cells));
    json_object_set_new(jc, "observations_in_cells", json_integer(r->n_obs_in_cells));
    json_object_set_new(jc, "observations", json_integer(r->nobs));
    json_object_set_new(jc, "factor_rel_std", json_real(r->cells_rel_std));
    json_object_set_new(jc, "iterations", json_integer(r->cell_iterations));
    json_object_set_new(jc, "convention", json_string(
        "each cell (MM mm of the sample's surface at angle 0, per face) scales the whole reflectance by its "
        "factor; the factors' mean over the observations is 1, so the parameters describe the mean material; "
        "factor_rel_std is the spread of the albedo from place to place"));
    return jc;
}

// What the samples of the chosen fit share (fit_brdf_shared_covariance; obs
// and smp sample for sample): frames (a camera's step), places (cells of
// r->place_mm of the sample's surface at angle 0) and each camera's lamps as
// photometric groups of relative std o->lamp_rel. The chosen result in
// r->models is updated; *out its record for the priors entry (the lamps'
// shifts dp, the clusters; a shared covariance that could not be computed
// leaves the fit's own, said in it). false + message: out of memory, or
// places too small for the sample.
static bool material_shared(const fit_material_opts_t *o, const calib_set_t *cal, const calib_obs_set_t *obs,
                            const fit_samples_t *smp, fit_material_result_t *r, json_t **out)
{
    fit_brdf_result_t *b = &r->models.res[r->models.best];
    int n = obs->n, nl = cal->lamps->n, nc = r->ncameras > 0 ? r->ncameras : 1, ng = nc * nl, np = b->nparams;
    int *frame = malloc((size_t)(n ? n : 1) * sizeof *frame), *place = malloc((size_t)(n ? n : 1) * sizeof *place);
    int *group = malloc((size_t)(n ? n : 1) * sizeof *group), *count = calloc((size_t)ng, sizeof *count);
    double *rel = malloc((size_t)ng * sizeof *rel), *dp = calloc((size_t)ng * np, sizeof *dp);
    json_t *j = NULL;
    *out = NULL;
    if (!frame || !place || !group || !count || !rel || !dp || n != smp->n) {
        model_error_set(NULL, 0, n != smp->n ? "%d observations for %d samples" : "out of memory", n, smp->n);
        goto done;
    }
    // the places: cells of the sample's surface at angle 0
    double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY }, ext = 0;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], obs->o[i].p0_mm[k]), hi[k] = fmax(hi[k], obs->o[i].p0_mm[k]);
    for (int k = 0; k < 3; k++) ext = fmax(ext, hi[k] - lo[k]);
    r->place_mm = o->place_mm > 0 ? o->place_mm : fmax(1.0, ext / 6);
    long long nxyz[3];
    for (int k = 0; k < 3; k++) nxyz[k] = n ? (long long)floor((hi[k] - lo[k]) / r->place_mm) + 1 : 1;
    if ((double)nxyz[0] * (double)nxyz[1] * (double)nxyz[2] > 1e9) {
        model_error_set(NULL, 0, "--place-mm %g: %lld x %lld x %lld places over the sample's %.0f mm; give a larger "
                        "--place-mm", r->place_mm, nxyz[0], nxyz[1], nxyz[2], ext);
        goto done;
    }
    for (int i = 0, cam = 0, left = r->nobs_camera[0]; i < n; i++) {
        while (left == 0 && cam + 1 < nc) left = r->nobs_camera[++cam];
        left--;
        const calib_obs_t *ob = &obs->o[i];
        frame[i] = cam * 1000000 + ob->step;
        long long c[3];
        for (int k = 0; k < 3; k++) c[k] = (long long)floor((ob->p0_mm[k] - lo[k]) / r->place_mm);
        place[i] = (int)((c[0] * nxyz[1] + c[1]) * nxyz[2] + c[2]);
        group[i] = ob->lamp >= 0 && ob->lamp < nl ? cam * nl + ob->lamp : -1;
        if (group[i] >= 0) count[group[i]]++;
    }
    for (int g = 0; g < ng; g++) rel[g] = o->lamp_rel;
    fit_shared_t sh = { .frame = frame, .place = place, .group = o->lamp_rel > 0 ? group : NULL, .ngroups = ng,
                        .group_rel = rel };
    bool ok = fit_brdf_shared_covariance(smp, &sh, b, dp);
    j = json_object();
    json_t *sc = json_object();
    json_object_set_new(sc, "method", json_string(
        !ok ? "the fit's own (chi^2/dof-scaled): the shared covariance could not be computed (see note)"
        : b->shared_done ? (b->clusters_frame && b->clusters_place
                                ? "cluster-robust, two-way by frames and places (V_frame + V_place - V_frame&place)"
                                : b->clusters_frame ? "cluster-robust by frames" : "cluster-robust by places")
                         : "the fit's own (chi^2/dof-scaled): too few frames and places to cluster, or a robust loss"));
    if (!ok) json_object_set_new(sc, "note", json_string(model_last_error()));
    json_object_set_new(sc, "frames", json_integer(b->clusters_frame));
    json_object_set_new(sc, "places", json_integer(b->clusters_place));
    json_object_set_new(sc, "place_mm", json_real(r->place_mm));
    json_object_set_new(sc, "convention", json_string(
        "std_statistical is the sandwich H^-1 M H^-1 over the free parameters (H = sum w J J^T, M = sum over "
        "clusters of u u^T with u = sum w (R_model - R) J over the cluster's samples, times G/(G-1)): residuals a "
        "frame (a camera's turntable step: exposure, lamp state, pose, and the model's misfit over its geometry) or "
        "a place on the sample (cubes of place_mm mm of the surface at angle 0: what the material does there) "
        "shares count once per cluster; std_parts.statistical_chi2_scaled is the covariance scaled by chi^2/dof "
        "it replaced. A way with fewer than 10 clusters is not used"));
    json_object_set_new(j, "statistical_covariance", sc);
    json_t *ls = json_object(), *arr = json_array();
    json_object_set_new(ls, "rel", json_real(o->lamp_rel));
    for (int g = 0; ok && b->groups_ok && g < ng; g++) {
        if (!count[g]) continue;
        json_t *e = json_object(), *d = json_object();
        if (r->ncameras > 1) json_object_set_new(e, "camera", json_string(r->cameras[g / nl]));
        json_object_set_new(e, "lamp", json_string(cal->lamps->lamps[g % nl].name));
        json_object_set_new(e, "samples", json_integer(count[g]));
        for (int k = 0; k < np; k++) json_object_set_new(d, model_brdf_param_name(b->model, k), json_real(dp[g * np + k]));
        json_object_set_new(e, "dp", d);
        json_array_append_new(arr, e);
    }
    json_object_set_new(ls, "lamps", arr);
    json_object_set_new(ls, "convention", json_string(
        "each lamp of each camera scales its samples alike (its kc*I from the white, its emission pattern and "
        "position over the sample), independently of the other lamps: dp is the parameters' change (their units) "
        "when that lamp's samples alone scale by 1 + rel (the linearised refit H^-1 sum w J R rel); the priors add "
        "sum dp dp^T to the covariance (std_parts.lamps). A parameter that one lamp alone measures (F0 through the "
        "rim lamp's highlights near grazing) carries that lamp's calibration in full"));
    json_object_set_new(j, "lamp_systematic", ls);
    r->shared_done = ok && b->shared_done;
    r->clusters_frame = b->clusters_frame;
    r->clusters_place = b->clusters_place;
    *out = j;
done:
    free(frame);
    free(place);
    free(group);
    free(count);
    free(rel);
    free(dp);
    return *out != NULL;
}

double fit_material_window_spread(const fit_samples_t *smp, model_brdf_t m, const double *p, double noise_rms,
                                  int *n)
{
    *n = 0;
    double *f = malloc((size_t)(smp->n ? smp->n : 1) * sizeof *f);
    double *e = malloc((size_t)(smp->n ? smp->n : 1) * sizeof *e);
    double *u = malloc((size_t)(smp->n ? smp->n : 1) * sizeof *u);
    double fmax_ = 0, rel = NAN;
    if (!f || !e || !u) {
        model_error_set(NULL, 0, "out of memory");
        *n = -1;
        goto done;
    }
    for (int i = 0; i < smp->n; i++) {
        f[i] = fit_samples_eval(smp, m, p, i);
        if (isfinite(f[i]) && f[i] > fmax_) fmax_ = f[i];
    }
    for (int i = 0; i < smp->n; i++) {
        double sig = smp->noise_weighted ? (smp->w[i] > 0 ? 1 / sqrt(smp->w[i]) : NAN) : noise_rms;
        if (!(f[i] >= 0.1 * fmax_) || !(fmax_ > 0) || !isfinite(sig)) continue;
        e[*n] = smp->R[i] / f[i] - 1;
        u[*n] = (sig / f[i]) * (sig / f[i]);
        (*n)++;
    }
    if (*n >= 20) {
        double med = model_median(e, *n);
        for (int k = 0; k < *n; k++) e[k] = fabs(e[k] - med);
        double mad = 1.4826 * model_median(e, *n), un = model_median(u, *n);
        rel = sqrt(fmax(mad * mad - un, 0));
    }
done:
    free(f);
    free(e);
    free(u);
    return rel;
}

// The priors document (fit_priors_document) of the final fits; *entry
// (borrowed) is its material's entry. Sets r->rms_over_noise.
static json_t *material_priors(const fit_material_opts_t *o, const calib_set_t *cal, fit_material_result_t *r,
                               json_t **entry)
{
    const fit_brdf_models_t *m = &r->models;
    const fit_brdf_result_t *best = &m->res[m->best];
    json_t *top = fit_priors_document();
    json_t *mats = json_array();
    json_t *e = fit_priors_material(o->name ? o->name : r->material, best, m->res, m->nres, o->k_sigma, o->sys_rel);
    json_object_set_new(e, "model_choice", fit_brdf_choice_json(m));
    json_object_set_new(e, "session", json_string(o->session));
    json_object_set_new(e, "sample", json_string(r->sample));
    json_object_set_new(e, "sample_pose", calib_sample_pose_json(&r->pose));
    json_object_set_new(e, "noise_rms_expected", model_json_number(r->noise_rms));
    // the residual per degree of freedom (the cells' factors take one each)
    double dof = (double)best->n - best->nfree - r->n_cells;
    double rms_dof = dof > 0 ? sqrt(best->rss / dof) : NAN;
    if (r->noise_weighted && isfinite(rms_dof)) {
        r->rms_over_noise = rms_dof;   // sqrt(chi^2 / dof): the weighted residuals are in sigma
        json_object_set_new(e, "rms_over_noise", json_real(r->rms_over_noise));
    } else if (isfinite(r->noise_rms) && r->noise_rms > 0 && isfinite(rms_dof)) {
        r->rms_over_noise = rms_dof / r->noise_rms;
        json_object_set_new(e, "rms_over_noise", json_real(r->rms_over_noise));
    }
    json_object_set_new(e, "weighting", json_string(
        r->noise_weighted ? "weighted by each sample's noise: w = 1/sigma_R^2, sigma_R from the gain calibration (K, "
                            "read noise, quantisation at the window's linearised signal, exposure and gain) carried "
                            "to R = f_r cos(theta_i) like the sample; rms and cv_rms are the weighted RMS of R, "
                            "rms_over_noise = sqrt(chi^2 / (N - parameters - cells))"
                          : "uniform (no gain calibration, or --weights uniform): rms_over_noise = residual per "
                            "degree of freedom over noise_rms_expected"));
    json_object_set_new(e, "loss", json_string(fit_loss_name(best->loss)));
    if (best->loss != LSQ_LOSS_NONE) {
        json_object_set_new(e, "loss_scale_sigma", json_real(o->loss_scale));
        json_object_set_new(e, "n_downweighted", json_integer(best->n_downweighted));
    }
    if (r->cells_done) json_object_set_new(e, "albedo_cells", cells_json(o, r));
    // how far a window of the material strays from the model beyond its noise (refl verify's sigma)
    json_object_set_new(e, "window_rel_std", model_json_number(r->window_rel_std));
    json_object_set_new(e, "window_rel_std_convention", json_string(
        "the relative spread of a window's R about the model (the final parameters, no albedo factors) beyond its "
        "temporal noise: over the samples whose model R is at least 10 % of the largest, sqrt((1.4826 MAD(R/R_model "
        "- 1))^2 - median((sigma_R/R_model)^2)), at least 0; texture from place to place and what the model lacks, "
        "at the session's window size; refl verify takes it as each window's relative model error"));
    json_object_set_new(e, "window_rel_std_samples", json_integer(r->window_rel_n));
    json_array_append_new(mats, e);
    json_object_set_new(top, "materials", mats);
    char *argv0[] = { "refl", NULL };
    json_object_set_new(top, "provenance", calib_observe_provenance(o->argc > 0 ? o->argc : 1,
                                                                    o->argc > 0 ? o->argv : argv0, o->session, cal));
    *entry = e;
    return top;
}

bool fit_material_run(const fit_material_opts_t *o, fit_material_result_t *r)
{
    memset(r, 0, sizeof *r);
    r->noise_rms = r->rms_over_noise = r->window_rel_std = NAN;
    r->first.best = r->models.best = -1;
    bool quiet = model_error_quiet_thread(true);   // the caller reports the message
    bool ok = false;
    calib_set_t *cal = NULL;
    calib_obs_set_t obs = { 0 };
    fit_samples_t *smp = NULL, *csmp = NULL;
    albedo_cells_t ac = { 0 };
    json_t *top = NULL, *entry = NULL;
    int *unit = NULL;
    model_brdf_t models[MODEL_BRDF_COUNT];
    int nm = 0;
    if (!fit_brdf_model_list(o->model ? o->model : "all", models, &nm)) {
        model_error_set(NULL, 0, "--model: unknown model %s", o->model);
        goto done;
    }
    if (!material_samples(o, &cal, &obs, &smp, r)) goto done;
    if (!(unit = malloc((size_t)(obs.n ? obs.n : 1) * sizeof *unit))) {
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
    fit_brdf_options_t fo = material_fit_options(o, &obs, obs.n == smp->n ? unit : NULL);
    if (!fit_brdf_models(smp, models, nm, &fo, &r->first)) goto done;
    if (o->cell_mm > 0) {
        if (!material_cells(o, &obs, smp, models, nm, &ac, &csmp, r, &fo)) goto done;
    } else {
        r->models = r->first;
    }
    json_t *shared = NULL;
    if (!material_shared(o, cal, &obs, csmp ? csmp : smp, r, &shared)) goto done;
    {
        const fit_brdf_result_t *b = &r->models.res[r->models.best];
        r->window_rel_std = fit_material_window_spread(smp, b->model, b->p, r->noise_rms, &r->window_rel_n);
    }
    if (r->window_rel_n < 0) {
        json_decref(shared);
        goto done;
    }
    top = material_priors(o, cal, r, &entry);
    json_object_update(entry, shared);
    json_decref(shared);
    char *od = g_path_get_dirname(o->out);
    bool made = model_mkdir_p(od);
    g_free(od);
    if (!made || !model_write_json(o->out, top)) goto done;
    r->written = true;
    if (o->report) {
        const fit_brdf_models_t *m = &r->models;
        if (!fit_material_report(o->report, &obs, csmp ? csmp : smp, m->res, m->nres, m->best, entry,
                                 json_object_get(top, "provenance"), cal, ac.n_cells > 0 ? ac.cell : NULL, ac.factor)) {
            char msg[1600];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error_set(NULL, 0, "the report: %s", msg);
            goto done;
        }
    }
    ok = true;
done:
    free(unit);
    json_decref(top);
    fit_samples_free(smp);
    fit_samples_free(csmp);
    cells_free(&ac);
    calib_obs_free(&obs);
    calib_set_free(cal);
    model_error_quiet_thread(quiet);
    return ok;
}
