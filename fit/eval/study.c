// fit/eval/study.c — `refl verify --study` and `--study-merge`: how well does
// verification separate right from wrong descriptions on the virtual rig?
// Its parts: the design and the run (here), the results (study_results.c),
// the files written and read back (study_files.c), the merge of shards
// (study_merge.c); what they share is in fit/eval/internal.h.
//
// Images: the T-stiffener of the truth file from four turntable angles (0, 90,
// 180, 270 deg), every lamp of the truth on, 6 ms. Each case draws its own
// sensor noise, lamp intensities (each lamp x U(0.9, 1.1): drift of +-10 %) and
// camera sensitivity (x U(0.95, 1.05): gain drift), from seeds of the case's
// number only, and is verified against the correct description and every
// corruption (I-stiffener, stiffener missing, shifted 1/2/5/10 mm across the
// web, rotated 1/2/5 deg, height +-5/10 %), and, with the same drifts and new
// noise, the correct description of the part placed off where it belongs
// (1 mm / 0.5 deg, 2 mm / 1 deg, 3 mm / 2 deg). Configurations: with the priors
// (bounds 3 sigma) or the thesis's unbounded fit (no priors, lamps fixed, kc
// free); with or without the per-pixel gain calibration (offset map, flat
// field, linearisation).
//
// The calibrations verification uses: with --calib, the chain's (camera model,
// lamps.json, gain calibration, white.json's kc*I); without, the lab's (the
// truth's camera and lamps, maps measured noise-free; fit/eval/lab.h). The
// priors: with --priors, the chain's; without, the truth's materials +- 10 %.
//
// Shards: --shard K/N runs the cases c with c mod N = K - 1 (the seeds are the
// case's, so a shard's rows are those of the unsharded run); --study-merge
// joins the shards' tables and computes the summary from them, exactly as the
// unsharded run computes it from its own (scores written with 17 digits read
// back to the same doubles).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "fit/eval/study.h"
#include "fit/verify/verify.h"
#include "fit/eval/internal.h"
#include "fit/eval/lab.h"
#include "model/base/report.h"
#include "model/base/vec.h"

bool study_table_alloc(study_table_t *T)
{
    size_t n = (size_t)T->cases * T->nconf * T->ncond;
    T->score = calloc(n, sizeof *T->score);
    T->verdict = malloc(n);
    T->secs = calloc(n, sizeof *T->secs);
    T->iters = calloc(n, sizeof *T->iters);
    T->rmsz = calloc(n, sizeof *T->rmsz);
    T->medz = calloc(n, sizeof *T->medz);
    size_t np = (size_t)T->cases * T->ncond * 4;
    T->pose = T->reg ? malloc(np * sizeof *T->pose) : NULL;
    for (size_t i = 0; T->pose && i < np; i++) T->pose[i] = NAN;
    if (!T->score || !T->verdict || !T->secs || !T->iters || !T->rmsz || !T->medz || (T->reg && !T->pose)) {
        model_error(NULL, 0, "verify study: out of memory for %d cases", T->cases);
        return false;
    }
    memset(T->verdict, -1, n);
    return true;
}

void study_table_free(study_table_t *T)
{
    free(T->score);
    free(T->verdict);
    free(T->secs);
    free(T->iters);
    free(T->rmsz);
    free(T->medz);
    free(T->pose);
}

static const double angles[NANG] = { 0, 90, 180, 270 };
// the placed-off cases: turn (deg) about the part's centre, shift (mm) along
// 30 deg from x (across and along the web at once)
static const double place_mm[NPLACE] = { 1, 2, 3 }, place_deg[NPLACE] = { 0.5, 1, 2 };
#define PLACE_AZIMUTH_DEG 30.0

// The descriptions (d: room for NDESC) and the conditions of the table.
static void study_design(study_table_t *T, model_stiffener_t *d)
{
    static const char *labels[NDESC] = { "correct", "I-stiffener", "missing", "shift 1 mm", "shift 2 mm",
                                         "shift 5 mm", "shift 10 mm", "rotate 1 deg", "rotate 2 deg", "rotate 5 deg",
                                         "height +5 %", "height -5 %", "height +10 %", "height -10 %" };
    static const double shifts[4] = { 1, 2, 5, 10 }, rots[3] = { 1, 2, 5 }, hs[4] = { 5, -5, 10, -10 };
    model_stiffener_t d0 = model_stiffener_default();
    for (int k = 0; k < NDESC; k++) d[k] = d0;
    d[1].kind = MODEL_STIFFENER_I;
    d[2].kind = MODEL_STIFFENER_NONE;
    for (int k = 0; k < 4; k++) d[3 + k].shift_mm[0] = shifts[k];
    for (int k = 0; k < 3; k++) d[7 + k].rotate_deg = rots[k];
    for (int k = 0; k < 4; k++) d[10 + k].height_scale = 1 + hs[k] / 100;
    T->ncond = NCOND;
    for (int k = 0; k < NDESC; k++) {
        study_cond_t *c = &T->cond[k];
        snprintf(c->label, sizeof c->label, "%s", labels[k]);
        snprintf(c->expected, sizeof c->expected, "%s", k ? "wrong" : "correct");
        c->desc = k;
        c->place = 0;
    }
    for (int p = 0; p < NPLACE; p++) {
        study_cond_t *c = &T->cond[NDESC + p];
        snprintf(c->label, sizeof c->label, "placed %g mm %g deg", place_mm[p], place_deg[p]);
        snprintf(c->expected, sizeof c->expected, "placed");
        c->desc = 0;
        c->place = 1 + p;
    }
}

// The configurations: with or without priors, with or without the gain maps.
static const struct {
    const char *name;
    bool        use_priors, use_flat;
} configs[NCONF] = { { "priors+maps", true, true }, { "priors", true, false }, { "no-priors+maps", false, true },
                     { "no-priors", false, false } };

// The configurations of the run: list (comma-separated names; NULL: all), in
// the canonical order. false + message naming the unknown one.
static bool study_configs(study_table_t *T, const char *list, int *which)
{
    T->nconf = 0;
    for (int k = 0; k < NCONF; k++) {
        bool on = !list;
        if (list) {
            char **v = g_strsplit(list, ",", -1);
            for (int i = 0; v[i]; i++) on |= !strcmp(g_strstrip(v[i]), configs[k].name);
            g_strfreev(v);
        }
        if (on) {
            which[T->nconf] = k;
            snprintf(T->conf[T->nconf++], sizeof T->conf[0], "%s", configs[k].name);
        }
    }
    char **v = list ? g_strsplit(list, ",", -1) : NULL;
    for (int i = 0; v && v[i]; i++) {
        bool known = false;
        for (int k = 0; k < NCONF; k++) known |= !strcmp(g_strstrip(v[i]), configs[k].name);
        if (!known) {
            model_error(NULL, 0, "verify study: configuration '%s' is not one of priors+maps, priors, "
                        "no-priors+maps, no-priors", v[i]);
            g_strfreev(v);
            return false;
        }
    }
    g_strfreev(v);
    if (!T->nconf) model_error(NULL, 0, "verify study: no configuration given");
    return T->nconf > 0;
}

// ---------------------------------------------------------------------------
// Running the cases

typedef struct {
    eval_lab_t     *lab;
    study_table_t          *T;
    model_scene_t    *scenes[NDESC];
    verify_view_t    *views[NDESC * NANG];
    verify_priors_t   pr;
    calib_set_t      *cal;              // --calib (NULL: the lab's calibrations)
    verify_camera_t   cam;              // the calibrations verification uses
    const model_lamps_t *lamps;
    const double     *A;
    uint32_t          lamps_on;         // in the calibration's indices
    double            gain_db;          // the lab's 0 dB relative to the gain calibration's gain
    verify_options_t  opt[NCONF];
    int               shard_k, shard_n; // this run's cases: c mod shard_n == shard_k - 1
    double            tol_mm, tol_deg;  // the placement tolerance (T->reg)
    int               ncases_here;
    bool              failed;
    char              err[512];
    int               done;
    pthread_mutex_t   lock;
    double            t0;
} study_t;

// Case c's images at placement place into img (and im; win: each image's
// window sums, cleared: new pixels).
static bool case_images(study_t *S, int c, int place, const double *ls, double kc, float **img,
                        verify_windows_t **win, verify_image_t *im)
{
    int W = eval_lab_width(S->lab), H = eval_lab_height(S->lab), nl = eval_lab_nlamps(S->lab);
    for (int a = 0; a < NANG; a++) {
        uint64_t seed = 1000003ull * (uint64_t)c + a + 7919ull * (uint64_t)place;
        if (!img[a] || !eval_lab_image_placed(S->lab, place, a, (1u << nl) - 1, ls, kc, seed, img[a])) return false;
        memset(&im[a], 0, sizeof im[a]);
        snprintf(im[a].name, sizeof im[a].name, "case%d_place%d_view%d", c, place, a);
        im[a].P = img[a];
        im[a].W = W;
        im[a].H = H;
        im[a].angle_deg = angles[a];
        im[a].lamps_on = S->lamps_on;
        im[a].exposure_us = 6000;
        im[a].gain_db = S->gain_db;
        verify_windows_clear(win[a]);
        im[a].windows = win[a];
    }
    return true;
}

// The views of description desc as registered to images im (placement p). false + message.
static bool registered_views(study_t *S, int desc, const verify_image_t *im, verify_placement_t *p,
                             model_scene_t **placed, verify_view_t **views)
{
    model_material_t mm[8];
    const model_material_t *mats[8];
    const model_scene_t *sc = S->scenes[desc];
    if (sc->nmaterials > 8 || !verify_priors_means(sc, &S->pr, mm, mats)) return false;
    if (!verify_register(sc, &S->cam, S->lamps, S->A, mats, im, NANG, S->tol_mm, S->tol_deg, p) ||
        !(*placed = verify_placed_scene(sc, p)))
        return false;
    verify_options_t vo = S->opt[0];
    for (int a = 0; a < NANG; a++)
        if (!(views[a] = verify_view_new(*placed, &S->cam, angles[a], S->lamps, mats, &vo))) return false;
    return true;
}

// Condition d of case c on its images im: every configuration (registered first when the study registers).
static bool run_condition(study_t *S, int c, int d, const verify_image_t *im)
{
    study_table_t *T = S->T;
    const study_cond_t *cd = &T->cond[d];
    verify_view_t *own[NANG] = { 0 }, **views = &S->views[cd->desc * NANG];
    model_scene_t *placed = NULL;
    const model_scene_t *scene = S->scenes[cd->desc];
    bool ok = true;
    if (T->reg) {
        verify_placement_t p;
        ok = registered_views(S, cd->desc, im, &p, &placed, own);
        if (ok) {
            float *q = study_pose(T, c, d);
            q[0] = (float)p.dx_mm, q[1] = (float)p.dy_mm, q[2] = (float)p.turn_deg, q[3] = (float)p.score;
        }
        views = own;
        scene = placed;
    }
    for (int k = 0; ok && k < T->nconf; k++) {
        verify_result_t r;
        double t0 = model_now_s();
        ok = verify_run(scene, &S->pr, &S->cam, 1, S->lamps, S->A, im, NANG, views, &S->opt[k], &r);
        size_t i = study_row(T, c, k, d);
        if (ok) {
            T->score[i] = r.score;
            T->verdict[i] = r.correct ? 1 : 0;
            T->secs[i] = model_now_s() - t0;
            T->iters[i] = r.summary.iterations;
            T->rmsz[i] = r.all.rms_z;
            T->medz[i] = r.all.median_abs_z;
        }
        verify_result_free(&r);
    }
    for (int a = 0; a < NANG; a++) verify_view_free(own[a]);
    model_scene_free(placed);
    return ok;
}

// Case c: its drifts, then its images at each placement and every fit on them.
static bool run_case(study_t *S, int c, float **img, verify_windows_t **win)
{
    study_table_t *T = S->T;
    int nl = eval_lab_nlamps(S->lab);
    model_rng_t rng = model_rng(20261121, (uint64_t)c);
    double ls[32];
    for (int i = 0; i < nl && i < 32; i++) ls[i] = 0.9 + 0.2 * model_rng_uniform(&rng);
    double kc = 0.95 + 0.1 * model_rng_uniform(&rng);
    verify_image_t im[NANG];
    for (int place = 0; place <= NPLACE; place++) {
        if (!case_images(S, c, place, ls, kc, img, win, im)) return false;
        for (int d = 0; d < T->ncond; d++) {
            const study_cond_t *cd = &T->cond[d];
            if (cd->place != place) continue;
            if (!run_condition(S, c, d, im)) return false;
        }
    }
    return true;
}


static void case_rows(void *vctx, int begin, int end, int thread)
{
    (void)thread;
    study_t *S = vctx;
    // a failed case's message is kept (S->err) and reported once by eval_study_run
    bool quiet = model_error_quiet_thread(true);
    size_t npx = (size_t)eval_lab_width(S->lab) * eval_lab_height(S->lab);
    float *img[NANG] = { 0 };
    verify_windows_t *win[NANG] = { 0 };
    bool have = true;
    for (int a = 0; a < NANG; a++) {
        img[a] = malloc(npx * sizeof(float));
        win[a] = verify_windows_new();
        have &= img[a] && win[a];
    }
    if (!have) model_error_set(NULL, 0, "out of memory for the case's images");
    for (int j = begin; j < end; j++) {
        if (S->failed) break;
        int c = S->shard_k - 1 + j * S->shard_n;
        bool ok = have && run_case(S, c, img, win);
        pthread_mutex_lock(&S->lock);
        if (!ok && !S->failed) {
            S->failed = true;
            snprintf(S->err, sizeof S->err, "case %d: %s", c, model_last_error());
        }
        S->done++;
        double el = model_now_s() - S->t0;
        model_progress("study: case %d/%d (%.0f s, ETA %.0f s)", S->done, S->ncases_here, el,
                       el / S->done * (S->ncases_here - S->done));
        pthread_mutex_unlock(&S->lock);
    }
    for (int a = 0; a < NANG; a++) {
        free(img[a]);
        verify_windows_free(win[a]);
    }
    model_error_quiet_thread(quiet);
}

// The options of each configuration of the run (which: their indices in configs).
static void study_configurations(study_t *S, const verify_options_t *opt, const int *which)
{
    for (int j = 0; j < S->T->nconf; j++) {
        int k = which[j];
        S->opt[j] = *opt;
        S->opt[j].threads = 1;
        S->opt[j].no_covariance = true;
        S->opt[j].max_iterations = 30;
        S->opt[j].verbose = false;
        S->opt[j].use_priors = configs[k].use_priors;
        S->opt[j].use_flat = configs[k].use_flat;
    }
}

// ---------------------------------------------------------------------------
// The calibrations and priors verification uses

// The lab's own: the truth's camera, lamps and kc*I, its noise-free maps.
static void calibs_of_lab(study_t *S)
{
    S->cam = *eval_lab_camera(S->lab);
    S->lamps = eval_lab_lamps(S->lab);
    S->A = eval_lab_A(S->lab);
    S->lamps_on = (1u << eval_lab_nlamps(S->lab)) - 1;
    S->gain_db = 0;
}

// The chain's calibration directory: its camera model, gain calibration and
// maps, lamps.json and white.json; every lamp of the truth must be in it.
static bool calibs_of_chain(study_t *S, const eval_study_opts_t *o)
{
    if (!(S->cal = calib_set_load(o->calib, true))) return false;
    const calib_set_t *cal = S->cal;
    if (cal->W != eval_lab_width(S->lab) || cal->H != eval_lab_height(S->lab)) {
        model_error(o->calib, 0, "its camera model is %dx%d but the truth's camera (%s) is %dx%d: give the "
                    "calibrations of this rig", cal->W, cal->H, o->truth, eval_lab_width(S->lab),
                    eval_lab_height(S->lab));
        return false;
    }
    const model_lamps_t *tl = eval_lab_lamps(S->lab);
    S->lamps_on = 0;
    for (int i = 0; i < tl->n; i++) {
        int j = model_lamps_find(cal->lamps, tl->lamps[i].name);
        if (j < 0 || j >= 32) {
            model_error(o->calib, 0, "its lamps.json has no lamp '%s' of the truth %s: give the calibrations of "
                        "this rig", tl->lamps[i].name, o->truth);
            return false;
        }
        S->lamps_on |= 1u << j;
    }
    S->cam = (verify_camera_t){ .cam = cal->cam, .offset_dn = cal->offset_dn, .flat = cal->flat,
                                .K_dn_per_e = cal->gain_dn_per_e, .read_noise_e = cal->read_noise_e,
                                .saturation_dn = cal->saturation_dn, .lin = &cal->lin,
                                .kc_rel = 1,
                                // the geometry calibration's pixel response, else the whole pixel, no blur
                                .psf_sigma_px = cal->have_psf ? cal->psf_sigma_px : 0,
                                .pixel_fill = cal->have_psf ? cal->psf_pixel_fill : 1 };
    snprintf(S->cam.name, sizeof S->cam.name, "%s", cal->camera[0] ? cal->camera : "camera");
    S->lamps = cal->lamps;
    S->A = cal->kcI_per_us;
    double f;
    if (!model_gain_factor(0, "dB", cal->cal_gain, cal->cal_gain_unit, o->calib, &f)) return false;
    S->gain_db = 20 * log10(f);
    return true;
}

// The priors: --priors files, else the truth's plywood and painted steel +- 10 % (bounds 3 sigma).
static bool study_priors(study_t *S, const eval_study_opts_t *o)
{
    for (int k = 0; k < o->npriors; k++)
        if (!verify_priors_load(&S->pr, o->priors[k])) return false;
    if (o->npriors) return true;
    const model_materials_t *mm = eval_lab_materials(S->lab);
    const model_material_t *ply = model_materials_find(mm, "plywood"), *st = model_materials_find(mm, "painted_steel");
    if (!ply || !st || !verify_priors_add(&S->pr, ply, 0.1, 1e-4, 3) || !verify_priors_add(&S->pr, st, 0.1, 1e-4, 3)) {
        model_error(o->truth, 0, "the study needs the materials plywood and painted_steel");
        return false;
    }
    return true;
}

// The descriptions' scenes and views (at the priors' means).
static bool study_views(study_t *S, const model_stiffener_t *D, const verify_options_t *opt)
{
    for (int d = 0; d < NDESC; d++) {
        if (!(S->scenes[d] = model_stiffener_scene(&D[d], S->T->cond[d].label))) return false;
        model_material_t mm[8];
        const model_material_t *mats[8];
        if (S->scenes[d]->nmaterials > 8 || !verify_priors_means(S->scenes[d], &S->pr, mm, mats)) return false;
        for (int a = 0; a < NANG; a++) {
            verify_options_t vo = *opt;
            if (!(S->views[d * NANG + a] = verify_view_new(S->scenes[d], &S->cam, angles[a], S->lamps, mats, &vo)))
                return false;
        }
        model_progress("study: views of description %d/%d", d + 1, NDESC);
    }
    model_progress_end();
    return true;
}

// The design (what a shard must share with the others to be merged): cases,
// configurations, conditions, threshold and the inputs' hashes (no paths: the
// shards may run on other machines).
static json_t *design_json(const study_table_t *T, const json_t *inputs, const eval_study_opts_t *o,
                           const eval_lab_t *lab)
{
    json_t *d = json_object(), *cf = json_array(), *cd = json_array(), *in = json_array();
    json_object_set_new(d, "cases", json_integer(T->cases));
    for (int k = 0; k < T->nconf; k++) json_array_append_new(cf, json_string(T->conf[k]));
    json_object_set_new(d, "configurations", cf);
    for (int k = 0; k < T->ncond; k++) {
        const study_cond_t *c = &T->cond[k];
        json_t *e = json_pack("{s:s, s:s}", "description", c->label, "expected", c->expected);
        if (c->place > 0) {
            double az = PLACE_AZIMUTH_DEG * M_PI / 180, mm = place_mm[c->place - 1];
            json_object_set_new(e, "placed_off", json_pack("{s:f, s:f, s:f}", "turn_deg", place_deg[c->place - 1],
                                                           "dx_mm", mm * cos(az), "dy_mm", mm * sin(az)));
        }
        // the truth's own placement error of the part in these images ([placement]: one draw per placement)
        double tu, dx, dy;
        if (lab && eval_lab_placement_draw(lab, c->place, &tu, &dx, &dy))
            json_object_set_new(e, "truth_placement_error", json_pack("{s:f, s:f, s:f}", "turn_deg", tu, "dx_mm", dx,
                                                                      "dy_mm", dy));
        json_array_append_new(cd, e);
    }
    json_object_set_new(d, "descriptions", cd);
    json_object_set_new(d, "score_threshold", json_real(o->opt.score_threshold));
    if (T->reg)
        json_object_set_new(d, "placement_tolerance", json_pack("{s:f, s:f}", "mm", o->placement_tol_mm, "deg",
                                                                o->placement_tol_deg));
    json_object_set_new(d, "calibrations", json_string(o->calib ? "the chain's (--calib)" : "the lab's (truth)"));
    json_object_set_new(d, "priors", json_string(o->npriors ? "the chain's (--priors)" : "truth +- 10 %"));
    size_t i;
    json_t *e;
    json_array_foreach(inputs, i, e)
        json_array_append_new(in, json_pack("{s:O, s:O}", "role", json_object_get(e, "role"), "sha256",
                                            json_object_get(e, "sha256")));
    json_object_set_new(d, "inputs", in);
    return d;
}

// ---------------------------------------------------------------------------
// The run

// The lab, its placed-off sets, the calibrations, priors, views and table. false + message.
static bool study_setup(study_t *S, const eval_study_opts_t *o, const model_stiffener_t *D, const int *which)
{
    model_note("study: rendering the T-stiffener at 4 angles x each lamp on the virtual rig (%s)", o->truth);
    if (!(S->lab = eval_lab_open(o->truth, "t_stiffener", angles, NANG, 6000, 0, true))) return false;
    for (int p = 0; p < NPLACE; p++) {
        double az = PLACE_AZIMUTH_DEG * M_PI / 180;
        model_note("study: the part placed off by %g mm, %g deg", place_mm[p], place_deg[p]);
        if (eval_lab_add_placement(S->lab, place_deg[p], place_mm[p] * cos(az), place_mm[p] * sin(az), true) < 0)
            return false;
    }
    if (o->calib ? !calibs_of_chain(S, o) : (calibs_of_lab(S), false)) return false;
    if (!study_priors(S, o) || !study_table_alloc(S->T)) return false;
    study_configurations(S, &o->opt, which);
    return study_views(S, D, &o->opt);
}

// The inputs (truth, calibration files, priors) into the provenance and a list for the design.
static json_t *study_inputs(const study_t *S, const eval_study_opts_t *o)
{
    json_t *in = json_array();
    model_inputs_add(in, "truth", o->truth);
    model_provenance_input(o->provenance, "truth", o->truth);
    size_t i;
    json_t *e;
    if (S->cal)
        json_array_foreach(S->cal->inputs, i, e) {
            json_array_append(in, e);
            model_provenance_input(o->provenance, json_string_value(json_object_get(e, "role")),
                                   json_string_value(json_object_get(e, "path")));
        }
    for (int k = 0; k < o->npriors; k++) {
        model_inputs_add(in, "priors", o->priors[k]);
        model_provenance_input(o->provenance, "priors", o->priors[k]);
    }
    return in;
}

static void study_free(study_t *S)
{
    verify_priors_free(&S->pr);
    for (int k = 0; k < NDESC * NANG; k++) verify_view_free(S->views[k]);
    for (int k = 0; k < NDESC; k++) model_scene_free(S->scenes[k]);
    calib_set_free(S->cal);
    eval_lab_free(S->lab);
    pthread_mutex_destroy(&S->lock);
}

bool eval_study_run(const eval_study_opts_t *o, eval_study_result_t *r)
{
    memset(r, 0, sizeof *r);
    study_table_t T = { .cases = o->cases, .reg = o->placement_tol_mm > 0 || o->placement_tol_deg > 0 };
    model_stiffener_t D[NDESC];
    int which[NCONF];
    study_design(&T, D);
    if (!study_configs(&T, o->configs, which)) return false;
    int sn = o->shard_n > 0 ? o->shard_n : 1, sk = o->shard_n > 0 ? o->shard_k : 1;
    if (sk < 1 || sk > sn || sn > o->cases) {
        model_error(NULL, 0, "verify study: shard %d/%d of %d cases: K must be 1..N and N at most the cases", sk, sn,
                    o->cases);
        return false;
    }
    study_t S = { .T = &T, .shard_k = sk, .shard_n = sn, .ncases_here = (o->cases - sk + sn) / sn,
                  .tol_mm = o->placement_tol_mm, .tol_deg = o->placement_tol_deg };
    pthread_mutex_init(&S.lock, NULL);
    bool ok = false;
    json_t *inputs = NULL, *design = NULL, *shard = NULL;
    if (!model_mkdir_p(o->out) || !study_setup(&S, o, D, which)) goto done;
    S.t0 = model_now_s();
    int threads = o->opt.threads > 0 ? o->opt.threads : model_default_threads();
    model_parallel_for(S.ncases_here, 1, threads, case_rows, &S);
    model_progress_end();
    if (S.failed) {
        model_error(NULL, 0, "verify study: %s", S.err);
        goto done;
    }
    inputs = study_inputs(&S, o);
    design = design_json(&T, inputs, o, S.lab);
    if (o->shard_n > 0)
        shard = json_pack("{s:i, s:i, s:s}", "k", sk, "n", sn, "cases", "c with c mod n = k - 1 (c from 0)");
    json_object_set_new(o->provenance, "wall_seconds", json_real(model_now_s() - S.t0));
    if (!study_write_tables(o->out, &T) || !study_write_json(o->out, &T, design, shard, o->provenance)) goto done;
    r->cases = o->cases;
    r->cases_run = S.ncases_here;
    r->ndescriptions = T.ncond;
    r->nconfigurations = T.nconf;
    r->complete = study_table_complete(&T);
    ok = true;
done:
    json_decref(inputs);
    json_decref(design);
    json_decref(shard);
    study_free(&S);
    study_table_free(&T);
    return ok;
}
