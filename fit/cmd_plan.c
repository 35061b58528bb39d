// fit/cmd_plan.c — `refl plan lamps`: choose lamps and exposure for one view
// or several (lightplan_lamps_run, fit/lightplan/lightplan.h), optionally checked on the
// virtual rig, and the capture plan of the views: arguments (model/base/opts.h),
// the library call, the printed lines.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/plan.h"
#include "fit/lightplan/lightplan.h"
#include "model/model.h"
#include "model/base/opts.h"
#include "rig/camera/pixfmt.h"
#include "rig/lab.h"

enum { MAX_MATERIAL_FILES = 8, MAX_EXPOSURES = 64, MAX_VIEWS = 360 };

// The numbers of a comma list, each in [lo, hi], at most max. false: not such a list.
static bool parse_list(const char *list, double *v, int *n, int max, double lo, double hi)
{
    char *dup = strdup(list), *save = NULL;
    bool ok = dup != NULL;
    *n = 0;
    for (char *t = ok ? strtok_r(dup, ", ", &save) : NULL; t && ok; t = strtok_r(NULL, ", ", &save)) {
        double x;
        ok = *n < max && model_parse_double(t, &x) && x >= lo && x <= hi;
        if (ok) v[(*n)++] = x;
    }
    free(dup);
    return ok && *n > 0;
}

static void print_view(const lightplan_lamps_opts_t *o, const lightplan_view_t *r)
{
    if (o->nangles > 0) printf("view %g deg (%s):\n", r->angle_deg, r->dir);
    if (r->check_started) fprintf(stderr, "refl plan lamps: checking on the virtual rig (%s)\n", o->check_truth);
    for (int k = 0; k < r->nchecks; k++) {
        const lightplan_check_t *c = &r->checks[k];
        printf("check: lamps %-28s agreement %5.1f %% (%d of %d segments)\n", c->lamps,
               100 * (isfinite(c->agreement) ? c->agreement : 0), c->agreeing, c->judged);
    }
    if (r->checked)
        printf("check: agreement %.1f %% over %ld segments (target 95 %%)\n", 100 * r->check_agreement,
               r->check_judged);
    if (r->threshold_near_noise)
        fprintf(stderr, "refl plan lamps: warning: the Sobel threshold %.0f DN is close to the detector's response "
                "to the sensor's noise alone (%.0f DN at the median signal %.0f DN): edges will be found in noise; "
                "raise --sobel-threshold\n", o->opt.sobel_threshold, r->sobel_noise_dn, r->median_signal_dn);
    if (!r->written) return;
    const lightplan_config_t *b = &r->res.configs[r->res.best];
    if (r->exposure_edge)
        fprintf(stderr, "refl plan lamps: warning: the chosen exposure %g us is the %s of those searched: a %s one "
                "may be better; add %s exposures to --exposures-us\n", b->exposure_us,
                r->exposure_edge > 0 ? "longest" : "shortest", r->exposure_edge > 0 ? "longer" : "shorter",
                r->exposure_edge > 0 ? "longer" : "shorter");
    printf("refl plan lamps: %s at %g deg: chosen lamps %s at %g us%s: %d of %d edge segments detectable (%.0f px), "
           "%.0f usable reference points, %d glare and %d saturated pixels (step-2 grid)\n",
           o->scene, r->angle_deg, r->chosen, b->exposure_us, b->feasible ? "" : " (no configuration is free of glare and saturation)",
           b->n_detectable, b->n_segments, b->detectable_length_px, b->usable_points, b->glare_pix, b->saturated_pix);
}

static void print_plan(const lightplan_lamps_opts_t *o, const lightplan_lamps_result_t *r)
{
    if (r->ncandidates) {
        fprintf(stderr, "refl plan lamps: %d candidate lamps, %d exposures, %d view%s\n", r->ncandidates, o->nexp,
                o->nangles > 0 ? o->nangles : 1, o->nangles > 1 ? "s" : "");
        fprintf(stderr, "refl plan lamps: edges blurred by a Gaussian PSF of sigma %.3g px (from %s) and the "
                "pixel's 1 px footprint\n", r->psf_sigma_px, r->psf_source);
    }
    for (int k = 0; k < r->nviews; k++) print_view(o, &r->views[k]);
    if (r->capture_plan)
        printf("capture plan: %s%s\n", r->capture_plan,
               r->plan_bound ? " (binds to the virtual rig)" : "");
}

static int plan_lamps(int argc, char **argv)
{
    lightplan_lamps_opts_t o = lightplan_lamps_defaults();
    o.angle_deg = NAN;   // given or not
    lightplan_options_t *op = &o.opt;
    const char *matfiles[MAX_MATERIAL_FILES], *exposures = "500,1000,2000,4000,8000,16000", *angles = NULL;
    model_opt_list_t materials = { matfiles, 0, MAX_MATERIAL_FILES };
    bool no_report = false;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--camera-model", "CAM", "camera model (mrcal; extrinsics in the rig frame)", &o.camera,
                         true, .old = "--camera"),
        MODEL_OPT_STRING("--lamps-file", "FILE", "candidates: a lamps INI with --kc-per-us, or lamps.json with "
                         "--white", &o.lamps, true, .old = "--lamps"),
        MODEL_OPT_LIST("--materials", "FILE...", "a materials INI, or priors JSON files (their means)", &materials,
                       true, true),
        MODEL_OPT_DOUBLE("--kc-per-us", "X", "kc*I = X * a lamps INI's intensity (DN/us)", &o.kc_per_us, 1e-300,
                         1e300),
        MODEL_OPT_STRING("--white", "WHITE.json", "kc*I per lamp (refl calib white), with a lamps.json", &o.white,
                         false),
        MODEL_OPT_STRING("--gain-calib", "DIR", "gain.json (K, read noise, saturation), offset_dn.tiff, "
                         "prnu_gain.tiff", &o.gain_dir, false),
        MODEL_OPT_OUT("DIR", "the output directory", &o.out, true),
        MODEL_OPT_DOUBLE("--angle-deg", "A", "turntable angle of the one view (0)", &o.angle_deg, -1e4, 1e4),
        MODEL_OPT_STRING("--angles-deg", "LIST", "several views: their turntable angles (comma list), each planned "
                         "on its own", &angles, false),
        MODEL_OPT_STRING("--exposures-us", "LIST", "comma list to try (500,1000,2000,4000,8000,16000)", &exposures,
                         false),
        MODEL_OPT_DOUBLE("--saturation-dn", "S", "saturation without a gain calibration (4095)", &o.saturation_dn, 1,
                         1e9),
        MODEL_OPT_DOUBLE("--offset-dn", "O", "dark offset without a gain calibration (0)", &o.offset_dn, -1e9, 1e9),
        MODEL_OPT_DOUBLE("--glare-cone-deg", "G", "glare cone around the mirror direction (15)", &op->glare_cone_deg, 0,
                         90),
        MODEL_OPT_DOUBLE("--sobel-threshold", "T", "the edge detector's threshold, DN (250)", &op->sobel_threshold, 0,
                         1e9),
        MODEL_OPT_DOUBLE("--floor-snr", "S", "usable signal: at least S x the temporal noise (10)", &op->floor_snr, 0,
                         1e6),
        MODEL_OPT_DOUBLE("--floor-dn", "D", "and at least D DN (20)", &op->floor_dn, 0, 1e9),
        MODEL_OPT_DOUBLE("--saturation-frac", "F", "usable below F x saturation (0.95)", &op->saturation_frac, 0.01,
                         1),
        MODEL_OPT_DOUBLE("--max-bad-frac", "F", "feasible: glare and saturated pixels at most F of the object's "
                         "(0.001)", &op->max_bad_frac, 0, 1),
        MODEL_OPT_INT("--max-lamps", "N", "lamps in a set at most (all)", &op->max_lamps, 1, MAXL_PLAN),
        MODEL_OPT_INT("--spacing-px", "N", "the verification grid, for the usable reference points (8)",
                      &op->spacing_px, 1, 1000),
        MODEL_OPT_STRING("--check-virtual", "TRUTH.ini", "check the plan on the virtual rig of this truth file",
                         &o.check_truth, false),
        MODEL_OPT_STRING("--sample", "NAME", "the sample: the capture plan's and the virtual rig's for the check "
                         "(the scene file's name)", &o.sample, false),
        MODEL_OPT_STRING("--pixel-format", "FMT", "the capture plan's pixel format (Mono12)", &o.pixel_format, false),
        MODEL_OPT_DOUBLE("--psf-sigma-px", "S", "the optics' Gaussian blur (px) of the edges' predicted Sobel "
                         "response (default: the geometry calibration's, geometry.json beside --camera; else 0)",
                         &op->psf_sigma_px, 0, 10),
        MODEL_OPT_INT("--threads", "N", "worker threads (default 0: REFL_THREADS, else every online CPU)",
                      &op->threads, 0, 1024),
        MODEL_OPT_FLAG("--no-report", NULL, "no index.html", &no_report),
        MODEL_OPT_UNITS,
    };
    model_cli_t cli = {
        .cmd = "plan lamps", .synopsis = "SCENE", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "Predicts, for every set of the candidate lamps and every exposure, the grey values of each face\n"
                 "against the camera's usable range, the specular glare and the contrast across every visible scene\n"
                 "edge, and chooses the set and exposure that make the most edge length detectable by a Sobel\n"
                 "detector and leave the most usable reference points, without glare or saturation.",
        .epilog = "SCENE: a D3D, OBJ, STL or PLY description (rig frame, mm unless --units m|in). The candidates' kc*I: a lamps INI ([lamp NAME]\n"
                  "position_mm, intensity) with --kc-per-us X (kc*I = X * intensity), or lamps.json with --white.\n"
                  "Without --gain-calib: --saturation-dn S (4095), --offset-dn O (0), the SNR floor off.\n"
                  "--check-virtual renders the chosen configuration and each single lamp at its exposure on the\n"
                  "virtual rig (in process) and compares a Sobel detector with the prediction.\n\n"
                  "Outputs in DIR: plan.json (every configuration, the chosen one, faces, edge segments; the check),\n"
                  "predicted.tiff (DN, direct light), glare.tiff (where each candidate would glare), index.html\n"
                  "(scripts/plan_lamps_report.py), and capture_plan.ini: a capture plan refl capture takes as it is\n"
                  "(refl capture DIR/capture_plan.ini --rig RIG -o SESSION): [sample] --sample (kind workpiece), the\n"
                  "views' angles, a [view N] section per view with its chosen lamps and exposure (fixed, gain 0,\n"
                  "--pixel-format), a dark frame after the views; the command and inputs (sha256) in its comments.\n"
                  "With --check-virtual the capture plan is also bound to that virtual rig (lamps, exposures, sample).\n"
                  "--angles-deg A,B,...: each view is planned on its own into DIR/view_A/ ... (the outputs above and\n"
                  "a report each); DIR/plan.json then lists the views and DIR/index.html links their reports.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = model_cli_units(&cli, &o.scene_unit_mm))) return rc;
    if (!o.white && !(o.kc_per_us > 0)) return model_cli_error(&cli, "give --kc-per-us X (lamps INI) or --white WHITE.json");
    double exps[MAX_EXPOSURES], angs[MAX_VIEWS];
    if (!parse_list(exposures, exps, &o.nexp, MAX_EXPOSURES, 1e-300, 1e300))
        return model_cli_error(&cli, "--exposures-us: '%s' is not a list of up to %d positive exposures in us",
                               exposures, MAX_EXPOSURES);
    if (angles && !parse_list(angles, angs, &o.nangles, MAX_VIEWS, -1e4, 1e4))
        return model_cli_error(&cli, "--angles-deg: '%s' is not a list of up to %d angles in deg (-10000..10000)",
                               angles, MAX_VIEWS);
    if (angles && !isnan(o.angle_deg))
        return model_cli_error(&cli, "give --angle-deg (one view) or --angles-deg (several), not both");
    if (isnan(o.angle_deg)) o.angle_deg = 0;
    rig_pixfmt_t pf;
    if (o.pixel_format && !rig_pixfmt_from_name(o.pixel_format, &pf))
        return model_cli_error(&cli, "--pixel-format %s: write Mono8, Mono12 or Mono16 (or Mono10, Mono10p, Mono12p, "
                               "Mono10Packed, Mono12Packed)", o.pixel_format);
    o.angles_deg = angles ? angs : NULL;
    o.nmaterials = materials.n;
    o.scene = cli.positional[0];
    o.materials = matfiles;
    o.exposures_us = exps;
    o.report = !no_report;
    o.argc = argc + 1;   // the provenance's command: refl plan lamps ...
    o.argv = argv - 1;
    lightplan_lamps_result_t *r = malloc(sizeof *r);
    if (!r) {
        model_error_set(NULL, 0, "out of memory");
        return model_error_report("plan lamps");
    }
    bool ok = lightplan_lamps_run(&o, r);
    print_plan(&o, r);
    if (ok && o.report) printf("report: %s/index.html\n", o.out);
    rc = ok ? 0 : model_error_report("plan lamps");
    lightplan_lamps_result_free(r);
    free(r);
    return rc;
}

int lightplan_cmd(int argc, char **argv)
{
    if (argc >= 2 && !strcmp(argv[1], "lamps")) return plan_lamps(argc - 1, argv + 1);
    if (argc >= 2 && !strcmp(argv[1], "geometry")) return calib_cmd_plan_geometry(argc - 1, argv + 1);
    if (argc >= 2 && !strcmp(argv[1], "day")) return rig_cmd_plan_day(argc - 1, argv + 1);
    if (argc >= 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("usage: refl plan lamps SCENE --camera-model CAM.cameramodel --lamps-file CANDIDATES --materials MATS\n"
               "                       (--kc-per-us X | --white WHITE.json) [options] -o DIR   (refl plan lamps --help)\n"
               "       refl plan geometry [--rig RIG.ini] --camera-model M [...] [options]   (the board's poses)\n"
               "       refl plan day --rig RIG.ini --lab LAB.ini -o DIR   (a lab day's plans)\n"
               "\n");
        model_cli_exit_status(stdout);
        printf("\nrefl %s\n", REFL_VERSION);
        return 0;
    }
    fprintf(stderr, "usage: refl plan lamps|geometry|day ... (refl plan --help)\n");
    return 2;
}
