// fit/cmd_verify.c — `refl verify`: does a scene description match images?
//
//   refl verify SCENE --images IMG... --priors PRIORS.json... -o DIR
//               [--calib DIR] [--camera-model CAM...] [--lamps-file LAMPS] [--gain-calib DIR...]
//               [--white WHITE.json | --kc-per-us X] [options]
//   refl verify --study -o DIR [--truth FILE] [--calib CAL --priors P...] [--cases N] [--shard K/N]
//   refl verify --study-merge DIR... -o OUT                      (fit/eval/study.c)
//
// Parses the arguments (model/base/opts.h), calls verify_files_run or
// eval_study_run (fit/eval/study.h) and prints the residue table and verdict.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/eval/study.h"
#include "fit/verify/verify.h"
#include "model/base/opts.h"
#include "model/base/report.h"

static const char about[] =
    "Fits the imaging model of the description SCENE (D3D, OBJ, STL or PLY; rig frame, mm unless --units) to\n"
    "reference points of the images, within the materials' priors, and judges whether the description is right.\n"
    "--no-priors: the thesis's fit instead (physical bounds only, lamps fixed, kc free); --priors still gives\n"
    "the materials' models and starting values (their means).\n"
    "Images: 16-bit PNG frames as refl capture and refl rig snap write them (their text chunks give the\n"
    "turntable angle, the lamps that were on, the exposure and the gain; --angle-deg, --lamps-on,\n"
    "--exposure-us, --gain-db override for every image), or float TIFFs with those options.\n"
    "With --calib DIR of several cameras (DIR/NAME.cameramodel, DIR/NAME/gain.json, DIR/NAME/white.json) and\n"
    "no --camera-model, each frame goes to the camera its text names (camera_name) with that camera's calibrations.\n"
    "\n"
    "       refl verify --study -o DIR [--truth TRUTH.ini] [--calib CAL --priors P...] [--cases N] [--shard K/N]\n"
    "       refl verify --study-merge DIR... -o OUT\n"
    "run the detection study on the virtual rig instead (make study), through the chain's calibrations and\n"
    "priors when given, or one shard of it; --study-merge joins the shards' directories into one study.";

static const char epilog[] =
    "Outputs in DIR: verify.json (verdict, score, residue, change regions, parameters against their\n"
    "priors, provenance), points.csv, imgN_actual.tiff / imgN_synthetic.tiff (float DN), and index.html\n"
    "with the figures (scripts/verify_report.py). Prints the residue table in the thesis's form.\n"
    "With --fail-on-incorrect the exit status is 4 when the verdict is incorrect (0 when correct).";

// --fix lamps,cameras,offset,rho,materials
static int parse_fix(model_cli_t *cli, const char *list, verify_options_t *opt)
{
    char *dup = strdup(list), *save = NULL;
    if (!dup) {
        fprintf(stderr, "refl verify: out of memory\n");
        return 1;
    }
    int rc = MODEL_CLI_OK;
    for (char *t = strtok_r(dup, ",", &save); t && rc == MODEL_CLI_OK; t = strtok_r(NULL, ",", &save)) {
        if (!strcmp(t, "lamps")) opt->fix_lamps = true;
        else if (!strcmp(t, "cameras")) opt->fix_cameras = true;
        else if (!strcmp(t, "offset")) opt->fix_pa = true;
        else if (!strcmp(t, "rho")) opt->fix_rho = true;
        else if (!strcmp(t, "materials")) opt->fix_materials = true;
        else rc = model_cli_error(cli, "--fix: '%s' is not lamps, cameras, offset, rho or materials", t);
    }
    free(dup);
    return rc;
}

// The truth file of the study: --truth, else refl's examples/virtual-truth.ini
// (model_share_path: a build tree's or an installation's; g_free; NULL: none).
static char *study_truth(const char *truth)
{
    if (truth) return g_strdup(truth);
    bool q = model_error_quiet_thread(true);
    char *path = model_share_path("examples", "virtual-truth.ini");
    model_error_quiet_thread(q);
    return path;
}

// --study: the study (or one shard of it), then its report when every case is in.
static int study(eval_study_opts_t *so, const char *truth, bool no_report, int argc, char **argv)
{
    char *truth_path = study_truth(truth);
    if (!truth_path) {
        fprintf(stderr, "refl verify --study: cannot find examples/virtual-truth.ini: give --truth FILE\n");
        return 2;
    }
    so->truth = truth_path;
    so->provenance = model_provenance(argc, argv);
    eval_study_result_t sr;
    int rc = 1;
    if (eval_study_run(so, &sr)) {
        rc = 0;
        if (!sr.complete)
            printf("refl verify --study: shard %d/%d: %d of %d cases x %d descriptions x %d configurations in %s; "
                   "merge the shards with refl verify --study-merge DIR... -o OUT\n", so->shard_k, so->shard_n,
                   sr.cases_run, sr.cases, sr.ndescriptions, sr.nconfigurations, so->out);
        else if (no_report || model_run_script("verify_study_report.py", so->out, NULL) == 0)
            printf("refl verify --study: %d cases x %d descriptions x %d configurations in %s%s\n", sr.cases,
                   sr.ndescriptions, sr.nconfigurations, so->out, no_report ? "" : " (report: index.html)");
        else
            rc = 1;
    }
    json_decref(so->provenance);
    g_free(truth_path);
    return rc;
}

// --study-merge DIR...: the shards' tables into one study, then its report.
static int study_merge(const char *const *dirs, int n, const char *out, bool no_report, int argc, char **argv)
{
    json_t *prov = model_provenance(argc, argv);
    eval_study_result_t sr;
    int rc = 1;
    if (!eval_study_merge(dirs, n, out, prov, &sr)) rc = 1;   // the library printed why
    else if (no_report || model_run_script("verify_study_report.py", out, NULL) == 0) {
        printf("refl verify --study-merge: %d shard(s), %d cases x %d descriptions x %d configurations%s%s%s\n", n,
               sr.cases, sr.ndescriptions, sr.nconfigurations, no_report ? "" : "; report: ", no_report ? "" : out,
               no_report ? "" : "/index.html");
        rc = 0;
    }
    json_decref(prov);
    return rc;
}

// --shard K/N
static int parse_shard(model_cli_t *cli, const char *s, int *k, int *n)
{
    char tail;
    if (sscanf(s, "%d/%d%c", k, n, &tail) != 2 || *n < 1 || *k < 1 || *k > *n)
        return model_cli_error(cli, "--shard '%s': give K/N with 1 <= K <= N (the K-th of N slices of the cases)", s);
    return MODEL_CLI_OK;
}

// The thesis's table: the residue per image and over all, change regions, pinned parameters, the verdict.
static void print_result(const verify_files_opts_t *o, const verify_files_result_t *r)
{
    const verify_result_t *res = &r->fit;
    printf("refl verify: %s against %d image(s)\n", o->scene, r->nimages);
    const verify_placement_t *p = &r->placement;
    if (o->placement_tol_mm > 0 || o->placement_tol_deg > 0)
        printf("placement: (%.2f, %.2f) mm, %.2f deg about (%.1f, %.1f) mm (registered within %g mm, %g deg; edge "
               "agreement %.3f, %.3f as described)\n", p->dx_mm, p->dy_mm, p->turn_deg, p->centre_mm[0],
               p->centre_mm[1], o->placement_tol_mm, o->placement_tol_deg, p->score, p->score_nominal);
    else
        printf("placement: as described (--placement-tolerance-mm 0 --placement-tolerance-deg 0)\n");
    printf("%-28s %8s %10s %10s %10s %10s %8s\n", "image", "points", "max|diff|", "mean|diff|", "std|diff|",
           "robust s", "rms z");
    for (int m = 0; m <= r->nimages; m++) {
        const verify_stats_t *s = m < r->nimages ? &res->per_image[m] : &res->all;
        const char *nm = m < r->nimages ? r->images[m].name : "all";
        const char *base_nm = strrchr(nm, '/') ? strrchr(nm, '/') + 1 : nm;
        printf("%-28.28s %8d %10.1f %10.2f %10.2f %10.2f %8.2f\n", base_nm, s->npoints, s->max_abs, s->mean_abs,
               s->std_abs, s->robust_sigma, s->rms_z);
    }
    int nreg = 0;
    for (int k = 0; k < res->nregions; k++) nreg += res->regions[k].counts;
    printf("change regions: %d; pinned parameters: %d\n", nreg, res->npinned);
    for (int k = 0; k < res->nwarnings; k++) printf("  warning: %s\n", res->warnings[k]);
    printf("verdict: description %s (score %.1f, threshold %.1f)\n", res->correct ? "CORRECT" : "INCORRECT",
           res->score, o->opt.score_threshold);
}

// refl verify's arguments, as parsed.
typedef struct {
    verify_files_opts_t o;
    const char         *fixed, *truth, *shard, *configs;
    bool                no_report, fail_on_incorrect, do_study, do_merge;
    int                 cases;
    model_opt_list_t    images, priors, cameras, gains;
} verify_args_t;

// After parsing: the lists' counts, the flags that turn defaults off, the
// checks every mode shares. MODEL_CLI_OK or the exit status (usage said).
static int verify_settle(model_cli_t *cli, verify_args_t *a)
{
    verify_files_opts_t *o = &a->o;
    verify_options_t *op = &o->opt;
    int rc;
    if ((rc = model_cli_units(cli, &o->scene_unit_mm)) || (rc = model_cli_channel(cli))) return rc;
    o->nimages = a->images.n;
    o->npriors = a->priors.n;
    o->ncameras = a->cameras.n;
    o->ngain = a->gains.n;
    // the flags that turn defaults off
    op->use_priors = !model_cli_opt(cli, "--no-priors")->given;
    op->use_flat = !model_cli_opt(cli, "--no-gain-maps")->given;
    op->edge_windows = !model_cli_opt(cli, "--skip-edge-windows")->given;
    op->model_rel_given = model_cli_opt(cli, "--model-rel")->given;
    o->have_angle = model_cli_opt(cli, "--angle-deg")->given;
    o->have_exposure = model_cli_opt(cli, "--exposure-us")->given;
    o->have_gain = model_cli_opt(cli, "--gain-db")->given;
    o->scene = cli->npositional ? cli->positional[0] : NULL;
    if (op->window_px % 2 == 0) return model_cli_error(cli, "--window-px must be odd");
    if (!o->out) return model_cli_error(cli, "missing -o DIR");
    return MODEL_CLI_OK;
}

// --study: the study's options from the arguments, then the study.
static int verify_study_cmd(model_cli_t *cli, verify_args_t *a, int argc, char **argv)
{
    const verify_files_opts_t *o = &a->o;
    eval_study_opts_t so = { .out = o->out, .cases = a->cases, .opt = o->opt, .calib = o->calib,
                             .priors = (const char *const *)o->priors, .npriors = o->npriors,
                             .configs = a->configs };
    // the study registers only when asked (each case's descriptions then get their own views: slower)
    if (model_cli_opt(cli, "--placement-tolerance-mm")->given || model_cli_opt(cli, "--placement-tolerance-deg")->given) {
        so.placement_tol_mm = o->placement_tol_mm;
        so.placement_tol_deg = o->placement_tol_deg;
    }
    if (cli->npositional) return model_cli_error(cli, "--study takes no SCENE (its scenes are the truth's)");
    int rc;
    if (a->shard && (rc = parse_shard(cli, a->shard, &so.shard_k, &so.shard_n)) != MODEL_CLI_OK) return rc;
    if (so.shard_n > a->cases)
        return model_cli_error(cli, "--shard %s: more shards than the %d cases", a->shard, a->cases);
    return study(&so, a->truth, a->no_report, argc, argv);
}

// The verification of SCENE against the images: the checks, the run, the
// printed table and the report. The exit status.
static int verify_files_cmd(model_cli_t *cli, verify_args_t *a, int argc, char **argv)
{
    verify_files_opts_t *o = &a->o;
    int rc;
    if (!o->scene) return model_cli_error(cli, "missing SCENE");
    if (cli->npositional > 1) return model_cli_error(cli, "one SCENE, not %d", cli->npositional);
    if (!o->nimages) return model_cli_error(cli, "missing --images IMG...");
    if (!o->npriors)
        return model_cli_error(cli, o->opt.use_priors ? "missing --priors PRIORS.json"
                                                      : "missing --priors PRIORS.json (with --no-priors too: the "
                                                        "materials' models and starting values)");
    if (!o->calib && !o->ncameras) return model_cli_error(cli, "missing --camera-model (or --calib DIR)");
    if (!o->calib && !o->lamps) return model_cli_error(cli, "missing --lamps-file (or --calib DIR)");
    if (o->ncameras > 1 && o->ncameras != o->nimages)
        return model_cli_error(cli, "%d cameras for %d images: give one camera, or one per image", o->ncameras,
                               o->nimages);
    if (a->fixed && (rc = parse_fix(cli, a->fixed, &o->opt)) != MODEL_CLI_OK) return rc;

    o->provenance = model_provenance(argc, argv);
    verify_files_result_t r;
    int exit_code = 1;
    if (verify_files_run(o, &r)) {
        print_result(o, &r);
        exit_code = a->fail_on_incorrect && !r.fit.correct ? MODEL_EXIT_INCORRECT : 0;
        if (!a->no_report) {
            if (model_run_script("verify_report.py", o->out, NULL) != 0) {
                fprintf(stderr, "refl verify: the report failed (the JSON, CSV and TIFF outputs are written)\n");
                exit_code = 1;
            } else {
                printf("report: %s/index.html\n", o->out);
            }
        }
    }
    verify_files_result_free(&r);
    json_decref(o->provenance);
    return exit_code;
}

int verify_cmd(int argc, char **argv)
{
    // the placement tolerance of a part laid on the turntable by hand against a stop (README: refl verify)
    verify_args_t a = { .o = { .opt = verify_defaults(), .placement_tol_mm = 3, .placement_tol_deg = 2,
                               .psf_sigma_px = NAN, .pixel_fill = NAN },
                        .cases = 200 };
    a.images = (model_opt_list_t){ a.o.images, 0, VERIFY_FILES_MAX };
    a.priors = (model_opt_list_t){ a.o.priors, 0, VERIFY_FILES_MAX };
    a.cameras = (model_opt_list_t){ a.o.cameras, 0, VERIFY_FILES_MAX };
    a.gains = (model_opt_list_t){ a.o.gain, 0, VERIFY_FILES_MAX };
    model_opt_t opts[] = {
        MODEL_OPT_LIST("--images", "IMG...", "16-bit PNG frames of refl capture / refl rig snap (angle, lamps, "
                       "exposure and gain from their text chunks), or float TIFFs (give the options below)", &a.images,
                       true, false),
        MODEL_OPT_LIST("--priors", "FILE...", "priors files of refl fit material / refl fit brdf (every material "
                       "of SCENE)", &a.priors, true, false),
        MODEL_OPT_OUT("DIR", "the output directory", &a.o.out, false),
        MODEL_OPT_STRING("--calib", "DIR", "a calibration directory: camera.cameramodel, lamps.json, gain.json + "
                         "maps, white.json (or in geometry/ lamps/ gain/ white/); the options below override",
                         &a.o.calib, false),
        MODEL_OPT_LIST("--camera-model", "CAM...", "camera models (mrcal, extrinsics in the rig frame): one, or one "
                       "per image", &a.cameras, true, false, .old = "--cameras"),
        MODEL_OPT_STRING("--lamps-file", "FILE", "lamps.json of refl calib lamps, or a lamps INI ([lamp NAME] "
                         "position_mm, intensity: then kc*I = X * intensity with --kc-per-us X)", &a.o.lamps, false,
                         .old = "--lamps"),
        MODEL_OPT_LIST("--gain-calib", "DIR...", "gain calibrations (gain.json, offset_dn.tiff, prnu_gain.tiff): "
                       "one per camera", &a.gains, true, false),
        MODEL_OPT_STRING("--white", "FILE", "white.json of refl calib white: kc*I per lamp per us at 0 dB",
                         &a.o.white, false),
        MODEL_OPT_DOUBLE("--kc-per-us", "X", "without a white calibration: kc per us of exposure (lamps INI "
                         "intensities)", &a.o.kc_per_us, 1e-300, 1e300),
        MODEL_OPT_DOUBLE("--angle-deg", "A", "turntable angle of every image (over the metadata)", &a.o.angle_deg,
                         -1e4, 1e4),
        MODEL_OPT_STRING("--lamps-on", "NAMES", "lamps on in every image (east+west, all)", &a.o.lamps_on, false),
        MODEL_OPT_DOUBLE("--exposure-us", "T", "exposure of every image", &a.o.exposure_us, 1e-3, 1e9),
        MODEL_OPT_DOUBLE("--gain-db", "G", "gain of every image, dB (taken relative to the gain calibration's)",
                         &a.o.gain_db, 0, 60),
        MODEL_OPT_UNITS,
        MODEL_OPT_CHANNEL,
        MODEL_OPT_DOUBLE("--placement-tolerance-mm", "D", "the part's placement is registered to the images "
                         "within +-D mm in x and y before the fit (3; 0 with --placement-tolerance-deg 0: as "
                         "described)", &a.o.placement_tol_mm, 0, 50),
        MODEL_OPT_DOUBLE("--placement-tolerance-deg", "A", "and within +-A deg about the part's centre (2)",
                         &a.o.placement_tol_deg, 0, 30),
        MODEL_OPT_INT("--spacing-px", "N", "grid step of the reference points (8)", &a.o.opt.spacing_px, 1, 1000),
        MODEL_OPT_INT("--window-px", "N", "window side, odd (5)", &a.o.opt.window_px, 1, 99),
        MODEL_OPT_DOUBLE("--edge-margin-px", "D", "skip windows this close to predicted edges (2)",
                         &a.o.opt.edge_margin_px, 0, 100),
        MODEL_OPT_DOUBLE("--boundary-margin-px", "D", "and face/shadow changes this far beyond the window (4)",
                         &a.o.opt.boundary_margin_px, 0, 100),
        MODEL_OPT_DOUBLE("--edge-k", "K", "a window whose std exceeds sqrt(K^2 var_noise + (R S)^2) holds an edge "
                         "the description does not predict (S: its signal; 3)", &a.o.opt.edge_k, 0.1, 1e6),
        MODEL_OPT_DOUBLE("--edge-rel", "R", "the relative part R of that test: texture and shading across the "
                         "window (0.05)", &a.o.opt.edge_rel, 0, 10),
        MODEL_OPT_FLAG("--skip-edge-windows", NULL, "skip the windows near edges (default: modelled with the "
                       "pixels' footprint and the blur)", NULL),
        MODEL_OPT_INT("--edge-subsamples", "N", "sub-cells per px side of a window's cells that see two faces "
                      "(5; odd)", &a.o.opt.edge_subsamples, 1, 15),
        MODEL_OPT_DOUBLE("--edge-position-sigma-px", "S", "1-sigma of where an edge lies in the image (0.1 px)",
                         &a.o.opt.edge_position_sigma_px, 0, 100),
        MODEL_OPT_DOUBLE("--psf-sigma-px", "S", "the optics' blur, a Gaussian's sigma in px (default: the "
                         "calibration's, else 0)", &a.o.psf_sigma_px, 0, 10),
        MODEL_OPT_DOUBLE("--pixel-fill", "F", "the pixel's footprint, a square of F px (default: the "
                         "calibration's, else 1: the whole pixel)", &a.o.pixel_fill, 0, 1),
        MODEL_OPT_INT("--interreflection-samples", "N", "interreflection rays per reference point (64; 0: no "
                      "interreflection)", &a.o.opt.ir_samples, 0, 1024),
        MODEL_OPT_DOUBLE("--model-rel", "R", "relative model error of every window, over the priors' "
                         "window_rel_std (default: the priors', else 0.04)", &a.o.opt.model_rel, 0, 10),
        MODEL_OPT_DOUBLE("--robust-scale", "Z", "Cauchy loss scale in z (3; 0 plain least squares)",
                         &a.o.opt.robust_scale, 0, 1e6),
        MODEL_OPT_DOUBLE("--lamp-sigma", "S", "prior std of the lamps' intensities (0.1)", &a.o.opt.lamp_sigma, 1e-6,
                         10),
        MODEL_OPT_DOUBLE("--camera-sigma", "S", "prior std of the cameras' sensitivities (0.1)", &a.o.opt.camera_sigma,
                         1e-6, 10),
        MODEL_OPT_DOUBLE("--pa-sigma-dn", "S", "prior std of the offset left after the offset map (5: ambient "
                         "light)", &a.o.opt.pa_sigma_dn, 1e-6, 1e6),
        MODEL_OPT_DOUBLE("--z-flag", "Z", "a reference point whose |z| = |measured - model| / sigma exceeds Z is "
                         "flagged as a change (4)", &a.o.opt.z_flag, 0.1, 1e6),
        MODEL_OPT_INT("--min-region", "N", "a region of flags (8-connected on an image's grid) counts toward the "
                      "score from N points (3)", &a.o.opt.min_region, 1, 1000000),
        MODEL_OPT_DOUBLE("--score-threshold", "T", "the verdict is incorrect when the score, the counted regions' "
                         "excess chi^2 sum(min(z^2, 25 Z^2) - Z^2), exceeds T (400)", &a.o.opt.score_threshold, 0,
                         1e300),
        MODEL_OPT_FLAG("--no-priors", NULL, "the thesis's fit: physical bounds only, lamps fixed, kc free (--priors "
                       "still gives the materials' models and starting values)", NULL),
        MODEL_OPT_FLAG("--no-gain-maps", NULL, "ignore the offset maps and flat fields", NULL),
        MODEL_OPT_STRING("--fix", "NAMES", "hold parameters: comma list of lamps, cameras, offset, rho, materials",
                         &a.fixed, false),
        MODEL_OPT_INT("--threads", "N", "worker threads (default 0: REFL_THREADS, else every online CPU)",
                      &a.o.opt.threads, 0, 1024),
        MODEL_OPT_FLAG("--verbose", NULL, "the solver's progress", &a.o.opt.verbose),
        MODEL_OPT_FLAG("--no-report", NULL, "no index.html", &a.no_report),
        MODEL_OPT_FLAG("--fail-on-incorrect", NULL, "exit 4 when the verdict is incorrect", &a.fail_on_incorrect),
        MODEL_OPT_FLAG("--study", NULL, "the detection study on the virtual rig (no SCENE)", &a.do_study),
        MODEL_OPT_STRING("--truth", "TRUTH.ini", "--study: the virtual rig's truth (default "
                         "examples/virtual-truth.ini)", &a.truth, false),
        MODEL_OPT_INT("--cases", "N", "--study: cases per condition (200)", &a.cases, 1, 100000),
        MODEL_OPT_STRING("--shard", "K/N", "--study: run the K-th of N disjoint slices of the cases (the cases c "
                         "with c mod N = K - 1, each with its own seeds as in the whole study)", &a.shard, false),
        MODEL_OPT_STRING("--configs", "NAMES", "--study: the configurations, comma-separated (priors+maps, "
                         "priors, no-priors+maps, no-priors; default all)", &a.configs, false),
        MODEL_OPT_FLAG("--study-merge", NULL, "merge the output directories DIR... of a study's shards into -o OUT "
                       "(equal to the unsharded run)", &a.do_merge),
    };
    model_cli_t cli = { .cmd = "verify", .synopsis = "SCENE", .about = about, .epilog = epilog, .opts = opts,
                        .nopts = MODEL_NOPTS(opts), .min_positional = 0, .max_positional = MODEL_CLI_POSITIONAL_MAX, .repeat_ok = true };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = verify_settle(&cli, &a)) != MODEL_CLI_OK) return rc;
    if (a.do_merge) {
        if (!cli.npositional) return model_cli_error(&cli, "--study-merge: give the shards' directories DIR...");
        return study_merge((const char *const *)cli.positional, cli.npositional, a.o.out, a.no_report, argc, argv);
    }
    if (a.do_study) return verify_study_cmd(&cli, &a, argc, argv);
    return verify_files_cmd(&cli, &a, argc, argv);
}
