// fit/eval/study.c — `refl verify --study` and `--study-merge`: how well does
// verification separate right from wrong descriptions on the virtual rig?
// The one owner of study.csv, timing.csv and study.json.
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
#include "fit/eval/lab.h"
#include "model/base/report.h"
#include "model/base/vec.h"

#define NANG 4
#define NCONF 4
#define NDESC 14
#define NPLACE 3
#define NCOND (NDESC + NPLACE)

// A condition of the study: a description verified against images of the
// part as placed (place 0) or placed off (place > 0).
typedef struct {
    char label[48];
    char expected[16];   // "correct", "wrong", "placed" (the correct description, the part placed off)
    int  desc;           // the description's index (its scene and views)
    int  place;          // the lab's placement set
} study_cond_t;

// The study's table: one row per (case, configuration, condition).
typedef struct {
    int     cases, nconf, ncond;
    char    conf[NCONF][32];
    study_cond_t  cond[NCOND];
    double *score;       // [case][conf][cond]
    signed char *verdict;   // 1: verdict correct, 0: incorrect, -1: not run here (another shard)
    double *secs;        // wall time of the fit (timing.csv; not part of the results)
    int    *iters;
    double *rmsz, *medz; // the fit's RMS z and median |z| over its used points (the z calibration)
    bool    reg;         // the placement registered (placement.csv)
    float  *pose;        // [case][cond][4]: dx mm, dy mm, turn deg, edge agreement (NAN: not here)
} study_table_t;

static size_t study_row(const study_table_t *T, int c, int k, int d)
{
    return ((size_t)c * T->nconf + k) * T->ncond + d;
}

static bool study_table_alloc(study_table_t *T)
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

static void study_table_free(study_table_t *T)
{
    free(T->score);
    free(T->verdict);
    free(T->secs);
    free(T->iters);
    free(T->rmsz);
    free(T->medz);
    free(T->pose);
}

static float *study_pose(const study_table_t *T, int c, int d) { return T->pose + ((size_t)c * T->ncond + d) * 4; }

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
    for (int a = 0; a < NANG; a++) {
        img[a] = malloc(npx * sizeof(float));
        win[a] = verify_windows_new();
    }
    for (int j = begin; j < end; j++) {
        if (S->failed) break;
        int c = S->shard_k - 1 + j * S->shard_n;
        bool ok = run_case(S, c, img, win);
        pthread_mutex_lock(&S->lock);
        if (!ok && !S->failed) {
            S->failed = true;
            snprintf(S->err, sizeof S->err, "case %d: %s", c, model_last_error());
        }
        S->done++;
        double el = model_now_s() - S->t0;
        fprintf(stderr, "\rrefl verify --study: case %d/%d (%.0f s, ETA %.0f s)   ", S->done, S->ncases_here, el,
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
        fprintf(stderr, "\rrefl verify --study: views of description %d/%d   ", d + 1, NDESC);
    }
    fprintf(stderr, "\n");
    return true;
}

// ---------------------------------------------------------------------------
// The summary (study.json "results"), from the table alone

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

// Mann-Whitney AUC: P(pos > neg) + P(pos == neg) / 2 (neg sorted).
static double auc_mw(const double *neg, int nn, const double *pos, int np)
{
    double s = 0;
    for (int i = 0; i < np; i++) {
        int lo = 0, hi = nn;   // first neg >= pos[i]
        while (lo < hi) {
            int m = (lo + hi) / 2;
            if (neg[m] < pos[i]) lo = m + 1;
            else hi = m;
        }
        int lt = lo, le = lo;
        while (le < nn && neg[le] == pos[i]) le++;
        s += lt + 0.5 * (le - lt);
    }
    return s / ((double)np * nn);
}

static json_t *jnum(double x) { return isfinite(x) ? json_real(x) : json_null(); }

// The ROC of the rule score >= t over every distinct score, from (0, 0) to (1, 1) (both sorted).
static json_t *roc_json(const double *neg, int nn, const double *pos, int np)
{
    json_t *fa = json_array(), *tp = json_array(), *th = json_array();
    json_array_append_new(fa, json_real(0));
    json_array_append_new(tp, json_real(0));
    json_array_append_new(th, json_null());
    int i = nn, j = np;   // scores >= t: neg[i..], pos[j..]
    while (i > 0 || j > 0) {
        double t = fmax(i > 0 ? neg[i - 1] : -INFINITY, j > 0 ? pos[j - 1] : -INFINITY);
        while (i > 0 && neg[i - 1] >= t) i--;
        while (j > 0 && pos[j - 1] >= t) j--;
        json_array_append_new(fa, json_real((double)(nn - i) / nn));
        json_array_append_new(tp, json_real((double)(np - j) / np));
        json_array_append_new(th, json_real(t));
    }
    json_t *o = json_object();
    json_object_set_new(o, "false_alarm", fa);
    json_object_set_new(o, "detection", tp);
    json_object_set_new(o, "threshold", th);
    return o;
}

// The scores and flags of condition d under configuration k (sorted scores; n rows).
static int cond_scores(const study_table_t *T, int k, int d, double *sc, int *flagged)
{
    int n = 0;
    *flagged = 0;
    for (int c = 0; c < T->cases; c++) {
        size_t i = study_row(T, c, k, d);
        if (T->verdict[i] < 0) continue;
        sc[n++] = T->score[i];
        *flagged += T->verdict[i] == 0;
    }
    qsort(sc, (size_t)n, sizeof *sc, cmp_d);
    return n;
}

static json_t *config_summary(const study_table_t *T, int k, double *neg, double *pos, json_t *roc)
{
    int nfl, nn = cond_scores(T, k, 0, neg, &nfl);
    double thr = nn ? neg[nn - 1 - nn / 100] : NAN;
    json_t *rows = json_array();
    for (int d = 1; d < T->ncond; d++) {
        int pfl, np = cond_scores(T, k, d, pos, &pfl);
        if (!np) continue;
        int above = 0;
        for (int i = 0; i < np; i++) above += pos[i] > thr;
        json_t *s = json_object();
        bool placed = !strcmp(T->cond[d].expected, "placed");
        json_object_set_new(s, "config", json_string(T->conf[k]));
        json_object_set_new(s, "description", json_string(T->cond[d].label));
        json_object_set_new(s, "expected", json_string(T->cond[d].expected));
        json_object_set_new(s, "n_correct", json_integer(nn));
        json_object_set_new(s, "n", json_integer(np));
        json_object_set_new(s, "auc", nn ? jnum(auc_mw(neg, nn, pos, np)) : json_null());
        json_object_set_new(s, "threshold_1pct", jnum(thr));
        json_object_set_new(s, placed ? "flagged_at_1pct_fa" : "det_at_1pct_fa",
                            nn ? json_real((double)above / np) : json_null());
        json_object_set_new(s, placed ? "flagged_verdict" : "det_verdict", json_real((double)pfl / np));
        json_object_set_new(s, "fa_verdict", nn ? json_real((double)nfl / nn) : json_null());
        json_array_append_new(rows, s);
        if (nn) {
            json_t *r = roc_json(neg, nn, pos, np);
            json_object_set_new(r, "config", json_string(T->conf[k]));
            json_object_set_new(r, "description", json_string(T->cond[d].label));
            json_array_append_new(roc, r);
        }
    }
    return rows;
}

// The z calibration: per configuration, over the cases of the correct
// description (and of the part placed off when the study registers), the
// mean and range of each fit's RMS z and median |z| (N(0, 1): 1 and 0.674).
static json_t *z_calibration(const study_table_t *T)
{
    json_t *a = json_array();
    for (int k = 0; k < T->nconf; k++)
        for (int d = 0; d < T->ncond; d++) {
            bool placed = !strcmp(T->cond[d].expected, "placed");
            if (strcmp(T->cond[d].expected, "correct") && !(placed && T->reg)) continue;
            double sr = 0, sm = 0, rlo = INFINITY, rhi = -INFINITY, mlo = INFINITY, mhi = -INFINITY;
            int n = 0;
            for (int c = 0; c < T->cases; c++) {
                size_t i = study_row(T, c, k, d);
                if (T->verdict[i] < 0 || !isfinite(T->rmsz[i]) || !isfinite(T->medz[i])) continue;
                sr += T->rmsz[i], sm += T->medz[i], n++;
                rlo = fmin(rlo, T->rmsz[i]), rhi = fmax(rhi, T->rmsz[i]);
                mlo = fmin(mlo, T->medz[i]), mhi = fmax(mhi, T->medz[i]);
            }
            if (!n) continue;
            json_array_append_new(a, json_pack("{s:s, s:s, s:i, s:f, s:[f,f], s:f, s:[f,f]}", "config", T->conf[k],
                                               "description", T->cond[d].label, "n", n, "rms_z_mean", sr / n,
                                               "rms_z_range", rlo, rhi, "median_abs_z_mean", sm / n,
                                               "median_abs_z_range", mlo, mhi));
        }
    return a;
}

// {"summary": [...], "roc": [...]}: per configuration and condition other than
// the correct description (negatives: the correct description's rows of the
// same configuration).
static json_t *study_results(const study_table_t *T)
{
    double *neg = malloc((size_t)(T->cases ? T->cases : 1) * sizeof *neg);
    double *pos = malloc((size_t)(T->cases ? T->cases : 1) * sizeof *pos);
    if (!neg || !pos) {
        free(neg);
        free(pos);
        return NULL;
    }
    json_t *summ = json_array(), *roc = json_array();
    for (int k = 0; k < T->nconf; k++) {
        json_t *rows = config_summary(T, k, neg, pos, roc);
        json_array_extend(summ, rows);
        json_decref(rows);
    }
    free(neg);
    free(pos);
    json_t *o = json_object();
    json_object_set_new(o, "summary", summ);
    json_object_set_new(o, "roc", roc);
    json_object_set_new(o, "z_calibration", z_calibration(T));
    return o;
}

// ---------------------------------------------------------------------------
// The files: study.csv, timing.csv, study.json

static const char units[] =
    "score: refl verify's score of the fit (dimensionless, >= 0; higher = more likely wrong; the verdict calls a "
    "description incorrect above score_threshold); rms_z, median_abs_z: over the fit's used reference points, z = "
    "(measured - model) / sigma (for N(0, 1) 1 and 0.674: the stated sigma calibrated); rates: fractions 0..1 of the rows of a configuration and "
    "description; seconds: wall time of one fit on one thread; angles deg, lengths mm";

static const char conditions[] =
    "virtual rig (truth file in design.inputs): T-stiffener, turntable 0/90/180/270 deg, every lamp on, 6000 us, "
    "0 dB, 12-bit sensor with its noise; per case (seeds of the case number only): each lamp's intensity x U(0.9, "
    "1.1), the camera's sensitivity x U(0.95, 1.05), new sensor noise; descriptions: the correct one and 13 "
    "corruptions on the part as placed, and the correct one on the part placed off by 1 mm / 0.5 deg, 2 mm / 1 deg "
    "and 3 mm / 2 deg (shift along 30 deg from x, turn about the part's centre, same drifts, new noise; a truth "
    "with [placement] adds a draw of its own to each placement: design.descriptions[].truth_placement_error; "
    "expected 'placed': a rightly made part, to pass when registration finds it within the tolerance); priors: the chain's (--priors) or the truth's "
    "materials +- 10 %, bounds 3 sigma; no-priors: the thesis's fit (physical bounds only, lamps fixed, kc free); "
    "+maps: the offset map, flat field and linearisation of the gain calibration; calibrations: the chain's "
    "(--calib) or the lab's (the truth's camera, lamps and kc*I, maps measured noise-free)";

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

// study.csv and timing.csv: the rows run here, configuration by configuration, description by description, case by case.
static bool study_write_tables(const char *out, const study_table_t *T)
{
    GString *st = g_string_new("config,description,expected,case,score,verdict_correct,rms_z,median_abs_z\n");
    GString *tm = g_string_new("config,description,case,seconds,iterations\n");
    for (int k = 0; k < T->nconf; k++)
        for (int d = 0; d < T->ncond; d++)
            for (int c = 0; c < T->cases; c++) {
                size_t i = study_row(T, c, k, d);
                if (T->verdict[i] < 0) continue;
                g_string_append_printf(st, "%s,%s,%s,%d,%.17g,%d,%.17g,%.17g\n", T->conf[k], T->cond[d].label,
                                       T->cond[d].expected, c, T->score[i], T->verdict[i], T->rmsz[i], T->medz[i]);
                g_string_append_printf(tm, "%s,%s,%d,%.4f,%d\n", T->conf[k], T->cond[d].label, c, T->secs[i],
                                       T->iters[i]);
            }
    char *sp = g_strdup_printf("%s/study.csv", out), *tp = g_strdup_printf("%s/timing.csv", out);
    bool ok = model_write_file_atomic(sp, st->str) && model_write_file_atomic(tp, tm->str);
    g_free(sp);
    g_free(tp);
    if (ok && T->reg) {
        // each case's registered placement of each description (the same for every configuration)
        GString *pl = g_string_new("description,case,dx_mm,dy_mm,turn_deg,edge_agreement\n");
        for (int d = 0; d < T->ncond; d++)
            for (int c = 0; c < T->cases; c++) {
                const float *q = study_pose(T, c, d);
                if (isfinite(q[3]))
                    g_string_append_printf(pl, "%s,%d,%.9g,%.9g,%.9g,%.9g\n", T->cond[d].label, c, q[0], q[1], q[2],
                                           q[3]);
            }
        char *pp = g_strdup_printf("%s/placement.csv", out);
        ok = model_write_file_atomic(pp, pl->str);
        g_free(pp);
        g_string_free(pl, TRUE);
    }
    g_string_free(st, TRUE);
    g_string_free(tm, TRUE);
    return ok;
}

static bool study_table_complete(const study_table_t *T)
{
    size_t n = (size_t)T->cases * T->nconf * T->ncond;
    for (size_t i = 0; i < n; i++)
        if (T->verdict[i] < 0) return false;
    return true;
}

// study.json: units, conditions, design, the shard (when one), the results (when complete), timing, provenance.
static bool study_write_json(const char *out, const study_table_t *T, json_t *design, json_t *shard,
                             json_t *provenance)
{
    json_t *doc = json_object();
    json_object_set_new(doc, "units", json_string(units));
    json_object_set_new(doc, "conditions", json_string(conditions));
    json_object_set(doc, "design", design);
    if (shard) json_object_set(doc, "shard", shard);
    bool complete = study_table_complete(T);
    json_object_set_new(doc, "complete", json_boolean(complete));
    if (complete) {
        json_t *res = study_results(T);
        if (!res) {
            json_decref(doc);
            model_error(NULL, 0, "verify study: out of memory for the summary");
            return false;
        }
        json_object_set_new(doc, "results", res);
    }
    double sum = 0;
    long nf = 0, it = 0;
    for (size_t i = 0; i < (size_t)T->cases * T->nconf * T->ncond; i++)
        if (T->verdict[i] >= 0) sum += T->secs[i], it += T->iters[i], nf++;
    json_object_set_new(doc, "timing", json_pack("{s:I, s:f, s:f}", "fits", (json_int_t)nf, "fit_seconds_sum", sum,
                                                  "mean_iterations", nf ? (double)it / nf : 0.0));
    json_object_set(doc, "provenance", provenance);
    char *jp = g_strdup_printf("%s/study.json", out);
    bool ok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    return ok;
}

// ---------------------------------------------------------------------------
// The run

// The lab, its placed-off sets, the calibrations, priors, views and table. false + message.
static bool study_setup(study_t *S, const eval_study_opts_t *o, const model_stiffener_t *D, const int *which)
{
    fprintf(stderr, "refl verify --study: rendering the T-stiffener at 4 angles x each lamp on the virtual rig (%s)\n",
            o->truth);
    if (!(S->lab = eval_lab_open(o->truth, "t_stiffener", angles, NANG, 6000, 0, true))) return false;
    for (int p = 0; p < NPLACE; p++) {
        double az = PLACE_AZIMUTH_DEG * M_PI / 180;
        fprintf(stderr, "refl verify --study: the part placed off by %g mm, %g deg\n", place_mm[p], place_deg[p]);
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
    fprintf(stderr, "\n");
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

// ---------------------------------------------------------------------------
// Merging shards

// The table's shape from a shard's design. false + message.
static bool table_from_design(study_table_t *T, const json_t *design, const char *path)
{
    json_t *cf = json_object_get(design, "configurations"), *cd = json_object_get(design, "descriptions");
    json_int_t cases = json_integer_value(json_object_get(design, "cases"));
    if (!json_is_array(cf) || !json_is_array(cd) || cases < 1 || cases > 10000000 || json_array_size(cf) < 1 ||
        json_array_size(cf) > NCONF || json_array_size(cd) < 2 || json_array_size(cd) > NCOND) {
        model_error(path, 0, "its design (cases, configurations, descriptions) is not one of refl verify --study's");
        return false;
    }
    T->cases = (int)cases;
    T->nconf = (int)json_array_size(cf);
    T->ncond = (int)json_array_size(cd);
    for (int k = 0; k < T->nconf; k++) {
        const char *s = json_string_value(json_array_get(cf, k));
        if (!s || strlen(s) >= sizeof T->conf[k]) {
            model_error(path, 0, "design: configuration %d is not a short string", k);
            return false;
        }
        snprintf(T->conf[k], sizeof T->conf[k], "%s", s);
    }
    for (int k = 0; k < T->ncond; k++) {
        json_t *e = json_array_get(cd, k);
        const char *l = json_string_value(json_object_get(e, "description")),
                   *x = json_string_value(json_object_get(e, "expected"));
        if (!l || !x || strlen(l) >= sizeof T->cond[k].label || strlen(x) >= sizeof T->cond[k].expected ||
            (k == 0) != !strcmp(x, "correct")) {
            model_error(path, 0, "design: description %d is not {description, expected} (the first, and only "
                        "the first, the correct one)", k);
            return false;
        }
        snprintf(T->cond[k].label, sizeof T->cond[k].label, "%s", l);
        snprintf(T->cond[k].expected, sizeof T->cond[k].expected, "%s", x);
    }
    T->reg = json_object_get(design, "placement_tolerance") != NULL;
    return study_table_alloc(T);
}

static int find_label(const char *s, const char *base, int n, size_t stride);

// DIR/placement.csv (a study that registers) into the table. false + message naming the file and line.
static bool study_read_placement(const char *dir, study_table_t *T)
{
    static const char *h = "description,case,dx_mm,dy_mm,turn_deg,edge_agreement";
    char *path = g_strdup_printf("%s/placement.csv", dir), *text = NULL;
    GError *ge = NULL;
    bool ok = g_file_get_contents(path, &text, NULL, &ge);
    if (!ok) model_error(path, 0, "cannot read: %s (the study registered the placement)", ge->message);
    g_clear_error(&ge);
    char **lines = ok ? g_strsplit(text, "\n", -1) : NULL;
    if (ok && strcmp(lines[0], h)) ok = false, model_error(path, 1, "the header is not '%s'", h);
    for (int ln = 1; ok && lines[ln]; ln++) {
        if (!lines[ln][0] && !lines[ln + 1]) break;
        char **f = g_strsplit(lines[ln], ",", -1);
        int d = g_strv_length(f) == 6 ? find_label(f[0], T->cond[0].label, T->ncond, sizeof T->cond[0]) : -1;
        long c = -1;
        double v[4];
        char *end = NULL;
        bool good = d >= 0 && model_parse_int(f[1], &c) && c >= 0 && c < T->cases;
        for (int k = 0; good && k < 4; k++) good = (v[k] = strtod(f[2 + k], &end), !*end && isfinite(v[k]));
        if (!good) {
            ok = false;
            model_error(path, ln + 1, "a bad row (%s): want description,case,dx_mm,dy_mm,turn_deg,edge_agreement",
                        lines[ln]);
        } else {
            float *q = study_pose(T, (int)c, d);
            for (int k = 0; k < 4; k++) q[k] = (float)v[k];
        }
        g_strfreev(f);
    }
    g_strfreev(lines);
    g_free(text);
    g_free(path);
    return ok;
}

// The index of label s among n strings stored stride bytes apart from base (-1: none).
static int find_label(const char *s, const char *base, int n, size_t stride)
{
    for (int k = 0; k < n; k++)
        if (!strcmp(s, base + (size_t)k * stride)) return k;
    return -1;
}

// A row's configuration, description and case (the first three of f, case at f[ci]). false + message (path:line).
static bool row_key(const study_table_t *T, char **f, int ci, const char *path, int line, int *k, int *d, int *c)
{
    long cv;
    *k = find_label(f[0], T->conf[0], T->nconf, sizeof T->conf[0]);
    *d = find_label(f[1], T->cond[0].label, T->ncond, sizeof T->cond[0]);
    if (*k < 0 || *d < 0) {
        model_error(path, line, "configuration '%s' or description '%s' is not in the study's design", f[0], f[1]);
        return false;
    }
    if (!model_parse_int(f[ci], &cv) || cv < 0 || cv >= T->cases) {
        model_error(path, line, "case '%s' is not a case number 0..%d", f[ci], T->cases - 1);
        return false;
    }
    *c = (int)cv;
    return true;
}

// DIR/study.csv (required) or DIR/timing.csv into the table. false + message naming the file and line.
static bool study_read_rows(const char *dir, study_table_t *T, bool timing)
{
    static const char *hs = "config,description,expected,case,score,verdict_correct,rms_z,median_abs_z",
                      *ht = "config,description,case,seconds,iterations";
    char *path = g_strdup_printf("%s/%s", dir, timing ? "timing.csv" : "study.csv"), *text = NULL;
    GError *ge = NULL;
    bool ok = g_file_get_contents(path, &text, NULL, &ge);
    if (!ok) model_error(path, 0, "cannot read: %s", ge->message);
    g_clear_error(&ge);
    char **lines = ok ? g_strsplit(text, "\n", -1) : NULL;
    if (ok && strcmp(lines[0], timing ? ht : hs)) ok = false, model_error(path, 1, "the header is not '%s'", timing ? ht : hs);
    for (int ln = 1; ok && lines[ln]; ln++) {
        if (!lines[ln][0] && !lines[ln + 1]) break;
        char **f = g_strsplit(lines[ln], ",", -1);
        int k, d, c, nf = (int)g_strv_length(f);
        if (nf != (timing ? 5 : 8)) {
            ok = false;
            model_error(path, ln + 1, "%d fields: want %d", nf, timing ? 5 : 8);
        } else if ((ok = row_key(T, f, timing ? 2 : 3, path, ln + 1, &k, &d, &c))) {
            size_t i = study_row(T, c, k, d);
            char *end;
            double v = strtod(f[timing ? 3 : 4], &end);
            if (*end || !isfinite(v) || (!timing && (strcmp(f[2], T->cond[d].expected) ||
                                                     (strcmp(f[5], "0") && strcmp(f[5], "1"))))) {
                ok = false;
                model_error(path, ln + 1, "a bad value (%s: expected, score or verdict_correct 0/1)", lines[ln]);
            } else if (timing) {
                long it = 0;
                model_parse_int(f[4], &it);
                T->secs[i] = v;
                T->iters[i] = (int)it;
            } else if (T->verdict[i] >= 0) {
                ok = false;
                model_error(path, ln + 1, "%s, %s, case %d: already in another shard (the same shard given twice?)",
                            f[0], f[1], c);
            } else {
                double rz = strtod(f[6], &end);
                char *end2;
                double mz = strtod(f[7], &end2);
                if (*end || *end2) {
                    ok = false;
                    model_error(path, ln + 1, "a bad value (%s: rms_z and median_abs_z are numbers)", lines[ln]);
                }
                T->score[i] = v;
                T->verdict[i] = (signed char)(f[5][0] - '0');
                T->rmsz[i] = rz;
                T->medz[i] = mz;
            }
        }
        g_strfreev(f);
    }
    g_strfreev(lines);
    g_free(text);
    g_free(path);
    return ok;
}

// The first case (configuration, description) no shard has: false + message.
static bool check_complete(const study_table_t *T)
{
    for (int c = 0; c < T->cases; c++)
        for (int k = 0; k < T->nconf; k++)
            for (int d = 0; d < T->ncond; d++)
                if (T->verdict[study_row(T, c, k, d)] < 0) {
                    model_error(NULL, 0, "verify study merge: case %d (%s, %s) is in none of the shards given: "
                                "give every shard K/N of the study", c, T->conf[k], T->cond[d].label);
                    return false;
                }
    return true;
}

bool eval_study_merge(const char *const *dirs, int ndirs, const char *out, json_t *provenance,
                      eval_study_result_t *r)
{
    memset(r, 0, sizeof *r);
    study_table_t T = { 0 };
    json_t *design = NULL, *from = json_array();
    bool ok = ndirs > 0;
    if (!ok) model_error(NULL, 0, "verify study merge: no shard directory given");
    for (int s = 0; ok && s < ndirs; s++) {
        char *jp = g_strdup_printf("%s/study.json", dirs[s]);
        json_error_t je;
        json_t *doc = json_load_file(jp, 0, &je), *d = json_object_get(doc, "design");
        if (!doc) {
            ok = false;
            model_error(jp, je.line, "%s", je.text);
        } else if (!json_is_object(d)) {
            ok = false;
            model_error(jp, 0, "no design: not a study of refl verify --study");
        } else if (!design) {
            design = json_incref(d);
            ok = table_from_design(&T, d, jp);
        } else if (!json_equal(design, d)) {
            ok = false;
            model_error(jp, 0, "its design (cases, configurations, descriptions, threshold or the inputs' hashes) "
                        "differs from that of %s: shards of different studies", dirs[0]);
        }
        if (ok) {
            model_provenance_input(provenance, "shard", jp);
            json_array_append_new(from, json_pack("{s:s, s:O?, s:O?}", "dir", dirs[s], "shard",
                                                  json_object_get(doc, "shard"), "provenance",
                                                  json_object_get(doc, "provenance")));
            ok = study_read_rows(dirs[s], &T, false);
            char *tp = g_strdup_printf("%s/timing.csv", dirs[s]);
            if (ok && g_file_test(tp, G_FILE_TEST_EXISTS)) ok = study_read_rows(dirs[s], &T, true);
            g_free(tp);
            if (ok && T.reg) ok = study_read_placement(dirs[s], &T);
        }
        json_decref(doc);
        g_free(jp);
    }
    ok = ok && check_complete(&T) && model_mkdir_p(out);
    if (ok) {
        json_object_set_new(provenance, "merged_from", json_incref(from));
        ok = study_write_tables(out, &T) && study_write_json(out, &T, design, NULL, provenance);
    }
    if (ok) {
        r->cases = r->cases_run = T.cases;
        r->ndescriptions = T.ncond;
        r->nconfigurations = T.nconf;
        r->complete = true;
    }
    json_decref(from);
    json_decref(design);
    study_table_free(&T);
    return ok;
}
