// fit/verify_study.c — `refl verify --study`: how well does verification
// separate right from wrong descriptions on the virtual rig?
//
// Images: the T-stiffener of the truth file from four turntable angles (0, 90,
// 180, 270 deg), every lamp of the truth on, 6 ms. Each case draws its own sensor noise,
// lamp intensities (each lamp x U(0.9, 1.1): drift of +-10 %) and camera
// sensitivity (x U(0.95, 1.05): gain drift), and is verified against the
// correct description and every corruption: I-stiffener, stiffener missing,
// shifted 1/2/5/10 mm (across the web), rotated 1/2/5 deg, height +-5/10 %.
// Configurations: with the priors (truth +- 10 %, bounds 3 sigma) or the
// thesis's unbounded fit (no priors, lamps fixed, kc free); with or without
// the per-pixel gain calibration (offset map, flat field, linearisation).
// Writes study.csv (one row per case, description and configuration) and
// study.json, then scripts/verify_study_report.py adds ROC AUC, the detection
// rate at 1 % false alarms and the figures (index.html).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "fit/verify.h"
#include "fit/verify_lab.h"
#include "model/report.h"
#include "model/vec.h"

#define NANG 4
#define NCONF 4

typedef struct {
    const char *label;
    model_stiffener_t d;
} desc_t;

typedef struct {
    verify_lab_t *lab;
    int ndesc;
    desc_t *desc;
    model_scene_t **scenes;
    verify_view_t **views;        // ndesc * NANG
    verify_priors_t *pr;
    verify_options_t opt[NCONF];
    const char *conf_name[NCONF];
    int cases;
    // results: [case][conf][desc]
    double *score, *secs;
    bool *correct;
    bool failed;
    char err[512];
    int done;
    pthread_mutex_t lock;
    double t0;
} study_t;

static const double angles[NANG] = { 0, 90, 180, 270 };

static void case_rows(void *vctx, int begin, int end, int thread)
{
    (void)thread;
    study_t *S = vctx;
    // a failed case's message is kept (S->err) and reported once by verify_study_run
    bool quiet = model_error_quiet_thread(true);
    int W = verify_lab_width(S->lab), H = verify_lab_height(S->lab), nl = verify_lab_nlamps(S->lab);
    float *img[NANG] = { 0 };
    for (int a = 0; a < NANG; a++) img[a] = malloc((size_t)W * H * sizeof(float));
    for (int c = begin; c < end; c++) {
        if (S->failed) break;
        model_rng_t rng = model_rng(20261121, (uint64_t)c);
        double ls[32];
        for (int i = 0; i < nl && i < 32; i++) ls[i] = 0.9 + 0.2 * model_rng_uniform(&rng);
        double kc = 0.95 + 0.1 * model_rng_uniform(&rng);
        verify_image_t im[NANG];
        bool ok = true;
        for (int a = 0; a < NANG; a++) {
            ok = ok && img[a] && verify_lab_image(S->lab, a, (1u << nl) - 1, ls, kc, 1000003ull * (uint64_t)c + a, img[a]);
            memset(&im[a], 0, sizeof im[a]);
            snprintf(im[a].name, sizeof im[a].name, "case%d_view%d", c, a);
            im[a].P = img[a];
            im[a].W = W;
            im[a].H = H;
            im[a].angle_deg = angles[a];
            im[a].lamps_on = (1u << nl) - 1;
            im[a].exposure_us = 6000;
        }
        for (int k = 0; k < NCONF && ok; k++)
            for (int d = 0; d < S->ndesc && ok; d++) {
                verify_result_t r;
                double t0 = model_now_s();
                ok = verify_run(S->scenes[d], S->pr, verify_lab_camera(S->lab), 1, verify_lab_lamps(S->lab),
                                verify_lab_A(S->lab), im, NANG, &S->views[d * NANG], &S->opt[k], &r);
                size_t at = ((size_t)c * NCONF + k) * S->ndesc + d;
                if (ok) {
                    S->score[at] = r.score;
                    S->correct[at] = r.correct;
                    S->secs[at] = model_now_s() - t0;
                }
                verify_result_free(&r);
            }
        pthread_mutex_lock(&S->lock);
        if (!ok && !S->failed) {
            S->failed = true;
            snprintf(S->err, sizeof S->err, "case %d: %s", c, model_last_error());
        }
        S->done++;
        double el = model_now_s() - S->t0;
        fprintf(stderr, "\rrefl verify --study: case %d/%d (%.0f s, ETA %.0f s)   ", S->done, S->cases, el,
                el / S->done * (S->cases - S->done));
        pthread_mutex_unlock(&S->lock);
    }
    for (int a = 0; a < NANG; a++) free(img[a]);
    model_error_quiet_thread(quiet);
}

// The descriptions: the correct one and its corruptions (D: room for 16). Returns their count.
static int study_descriptions(desc_t *D)
{
    int nd = 0;
    model_stiffener_t d0 = model_stiffener_default();
    D[nd++] = (desc_t){ "none", d0 };
    D[nd] = (desc_t){ "I-stiffener", d0 };
    D[nd++].d.kind = MODEL_STIFFENER_I;
    D[nd] = (desc_t){ "missing", d0 };
    D[nd++].d.kind = MODEL_STIFFENER_NONE;
    static const double shifts[4] = { 1, 2, 5, 10 }, rots[3] = { 1, 2, 5 }, hs[4] = { 5, -5, 10, -10 };
    static const char *shl[4] = { "shift 1 mm", "shift 2 mm", "shift 5 mm", "shift 10 mm" };
    static const char *rol[3] = { "rotate 1 deg", "rotate 2 deg", "rotate 5 deg" };
    static const char *hl[4] = { "height +5 %", "height -5 %", "height +10 %", "height -10 %" };
    for (int k = 0; k < 4; k++) {
        D[nd] = (desc_t){ shl[k], d0 };
        D[nd++].d.shift_mm[0] = shifts[k];
    }
    for (int k = 0; k < 3; k++) {
        D[nd] = (desc_t){ rol[k], d0 };
        D[nd++].d.rotate_deg = rots[k];
    }
    for (int k = 0; k < 4; k++) {
        D[nd] = (desc_t){ hl[k], d0 };
        D[nd++].d.height_scale = 1 + hs[k] / 100;
    }
    return nd;
}

// The configurations: with or without priors, with or without the gain maps.
static void study_configurations(study_t *S, const verify_options_t *opt)
{
    for (int k = 0; k < NCONF; k++) {
        S->opt[k] = *opt;
        S->opt[k].threads = 1;
        S->opt[k].no_covariance = true;
        S->opt[k].max_iterations = 30;
        S->opt[k].verbose = false;
        S->opt[k].use_priors = k < 2;
        S->opt[k].use_flat = k % 2 == 0;
    }
    S->conf_name[0] = "priors+maps";
    S->conf_name[1] = "priors";
    S->conf_name[2] = "no-priors+maps";
    S->conf_name[3] = "no-priors";
}

// The priors (the truth's materials +- 10 %), the scenes and their views, the result arrays.
static bool study_setup(study_t *S, const verify_study_opts_t *o)
{
    const int nd = S->ndesc, cases = o->cases;
    const model_materials_t *mm = verify_lab_materials(S->lab);
    const model_material_t *ply = model_materials_find(mm, "plywood"), *st = model_materials_find(mm, "painted_steel");
    if (!ply || !st || !verify_priors_add(S->pr, ply, 0.1, 1e-4, 3) || !verify_priors_add(S->pr, st, 0.1, 1e-4, 3)) {
        model_error(o->truth, 0, "the study needs the materials plywood and painted_steel");
        return false;
    }
    S->scenes = calloc((size_t)nd, sizeof *S->scenes);
    S->views = calloc((size_t)nd * NANG, sizeof *S->views);
    S->score = calloc((size_t)cases * NCONF * nd, sizeof *S->score);
    S->secs = calloc((size_t)cases * NCONF * nd, sizeof *S->secs);
    S->correct = calloc((size_t)cases * NCONF * nd, sizeof *S->correct);
    if (!S->scenes || !S->views || !S->score || !S->secs || !S->correct) return false;
    study_configurations(S, &o->opt);
    model_material_t mean[2] = { *ply, *st };
    for (int d = 0; d < nd; d++) {
        if (!(S->scenes[d] = model_stiffener_scene(&S->desc[d].d, S->desc[d].label))) return false;
        const model_material_t *mats[2];
        for (int k = 0; k < S->scenes[d]->nmaterials; k++)
            mats[k] = !strcmp(S->scenes[d]->material_names[k], "plywood") ? &mean[0] : &mean[1];
        for (int a = 0; a < NANG; a++) {
            verify_options_t vo = o->opt;
            if (!(S->views[d * NANG + a] = verify_view_new(S->scenes[d], verify_lab_camera(S->lab), angles[a],
                                                           verify_lab_lamps(S->lab), mats, &vo)))
                return false;
        }
        fprintf(stderr, "\rrefl verify --study: views of description %d/%d   ", d + 1, nd);
    }
    fprintf(stderr, "\n");
    return true;
}

// study.csv and study.json in o->out.
static bool study_write(const study_t *S, const verify_study_opts_t *o)
{
    const int nd = S->ndesc, cases = o->cases;
    char *cp = g_strdup_printf("%s/study.csv", o->out), *tmp = g_strdup_printf("%s/study.csv.tmp", o->out);
    FILE *f = fopen(tmp, "w");
    if (f) {
        fprintf(f, "config,corruption,case,score,verdict_correct,seconds\n");
        for (int k = 0; k < NCONF; k++)
            for (int d = 0; d < nd; d++)
                for (int c = 0; c < cases; c++) {
                    size_t at = ((size_t)c * NCONF + k) * nd + d;
                    fprintf(f, "%s,%s,%d,%.6g,%d,%.4f\n", S->conf_name[k], S->desc[d].label, c, S->score[at],
                            S->correct[at], S->secs[at]);
                }
    }
    bool ok = f && fclose(f) == 0 && rename(tmp, cp) == 0;
    if (!ok) model_error(cp, 0, "cannot write the study table");
    g_free(cp);
    g_free(tmp);
    if (!ok) return false;
    json_t *doc = json_object();
    json_object_set_new(doc, "conditions",
                        json_string("virtual rig (truth file in provenance): T-stiffener, turntable 0/90/180/270 deg, "
                                    "every lamp on, 6000 us, 0 dB, 12-bit sensor with its noise; per case: each "
                                    "lamp's intensity x U(0.9, 1.1), the camera's sensitivity x U(0.95, 1.05), new "
                                    "sensor noise; priors: the truth's material parameters +- 10 % (bounds 3 sigma); "
                                    "no-priors: the thesis's fit (physical bounds only, lamps fixed, kc free); "
                                    "+maps: the offset map, flat field and linearisation of the gain calibration"));
    json_object_set_new(doc, "cases_per_condition", json_integer(cases));
    json_object_set_new(doc, "score_threshold", json_real(o->opt.score_threshold));
    model_provenance_input(o->provenance, "truth", o->truth);
    json_object_set_new(doc, "provenance", json_incref(o->provenance));
    char *jp = g_strdup_printf("%s/study.json", o->out);
    ok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    return ok;
}

bool verify_study_run(const verify_study_opts_t *o, verify_study_result_t *r)
{
    memset(r, 0, sizeof *r);
    study_t S = { 0 };
    verify_priors_t pr = { 0 };
    desc_t D[16];
    bool ok = false;
    pthread_mutex_init(&S.lock, NULL);
    S.cases = o->cases;
    S.pr = &pr;
    S.desc = D;
    S.ndesc = study_descriptions(D);
    if (!model_mkdir_p(o->out)) goto done;
    fprintf(stderr, "refl verify --study: rendering the T-stiffener at 4 angles x each lamp on the virtual rig (%s)\n",
            o->truth);
    if (!(S.lab = verify_lab_open(o->truth, "t_stiffener", angles, NANG, 6000, 0, true))) goto done;
    if (!study_setup(&S, o)) goto done;
    S.t0 = model_now_s();
    int threads = o->opt.threads > 0 ? o->opt.threads : model_default_threads();
    model_parallel_for(o->cases, 1, threads, case_rows, &S);
    fprintf(stderr, "\n");
    if (S.failed) {
        model_error(NULL, 0, "verify study: %s", S.err);
        goto done;
    }
    if (!study_write(&S, o)) goto done;
    r->cases = o->cases;
    r->ndescriptions = S.ndesc;
    r->nconfigurations = NCONF;
    ok = true;
done:
    verify_priors_free(&pr);
    if (S.views)
        for (int k = 0; k < S.ndesc * NANG; k++) verify_view_free(S.views[k]);
    if (S.scenes)
        for (int k = 0; k < S.ndesc; k++) model_scene_free(S.scenes[k]);
    free(S.views);
    free(S.scenes);
    free(S.score);
    free(S.secs);
    free(S.correct);
    verify_lab_free(S.lab);
    pthread_mutex_destroy(&S.lock);
    return ok;
}
