// calib/cmd_lamps.c — `refl calib lamps`: parses its options (model/base/opts.h)
// into a calib_lamps_opts_t, runs calib_lamps_run (calib/lamps/lamps.c) and prints
// the lamps' table.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/lamps/lamps.h"
#include "model/model.h"
#include "model/base/opts.h"

static const char ABOUT[] =
    "Lamp positions from the highlights of a mirror (chrome) sphere of known radius carried round by the\n"
    "turntable: each lamp alone at several angles, its highlight found to sub-pixel, reflected off the\n"
    "sphere into a ray toward the lamp, the rays triangulated (least squares, outliers dropped).\n"
    "Either --rig RIG.ini (capture into DIR/capture) or --session DIR (a session captured elsewhere).";

static const char EPILOG[] =
    "The sphere's facts (--sphere-centre-mm, --sphere-radius-mm) are required, on a virtual rig too (a\n"
    "measurement never reads the virtual rig's truth; refl chain compares the lamps with it). The centre typed is\n"
    "a prior (std --sphere-offset-prior-mm, default 3 mm) and a check: the joint fit finds the centre from the\n"
    "highlights across the turntable's angles, and while it moves by more than 0.2 mm the highlights are found\n"
    "again at the moved centre (at most 3 rounds); lamps.json's sphere.centre_found_mm and its std, and a note\n"
    "when the typed centre is more than twice its std away.\n\n"
    "Output lamps.json: units mm, rig frame; per lamp position_mm, std_mm, rms_ray_distance_mm, n_frames,\n"
    "frames_missing, radius_mm (the emitting radius the highlights were modelled with). A lamp whose\n"
    "highlight is missing in some frames is named with those frames and fitted\n"
    "from the rest (>= 3 needed, else an error).\n\n"
    "With --rig the session begins with an operator step (place the chrome ball at the table centre,\n"
    "its centre as given): Enter on a terminal, --yes or --operator-input FILE answers it; with stdin\n"
    "not a terminal and neither option the command pauses there (exit 3; run it again to continue).\n"
    "Exit: 0 done, 1 error, 2 usage, 3 paused.";

// The indentation of an option's help continued on the next line.
#define IND "                             "

// A list of numbers "A,B,C" (commas or spaces) into v (at most max). 0 or a usage error.
static int number_list(model_cli_t *cli, const char *name, double *v, int max, int *n)
{
    const char *s = model_cli_value(cli, name);
    if (!s) return 0;
    *n = 0;
    char *dup = g_strdup(s);
    int rc = 0;
    for (char *save = NULL, *tok = strtok_r(dup, ", ", &save); tok && !rc; tok = strtok_r(NULL, ", ", &save)) {
        if (*n >= max) rc = model_cli_error(cli, "%s '%s': at most %d values", name, s, max);
        else if (!model_parse_double(tok, &v[(*n)++]))
            rc = model_cli_error(cli, "%s '%s': '%s' is not a number", name, s, tok);
    }
    g_free(dup);
    return rc;
}

// A number option, at least lo (more than lo when lo_open), kept when absent;
// why: the hint of the message "NAME 'V': why".
static int number_opt(model_cli_t *cli, const char *name, double *out, double lo, bool lo_open, const char *why)
{
    const char *s = model_cli_value(cli, name);
    double v;
    if (!s) return 0;
    if (!model_parse_double(s, &v) || !(lo_open ? v > lo : v >= lo))
        return model_cli_error(cli, "%s '%s': %s", name, s, why);
    *out = v;
    return 0;
}

// A word option: the index of its value in words (NULL-terminated), kept when absent.
static int word_opt(model_cli_t *cli, const char *name, const char *const *words, int *out, const char *why)
{
    const char *s = model_cli_value(cli, name);
    if (!s) return 0;
    for (int k = 0; words[k]; k++)
        if (!strcmp(s, words[k])) {
            *out = k;
            return 0;
        }
    return model_cli_error(cli, "%s '%s': %s", name, s, why);
}

// The options after parsing: numbers, lists, words and the checks between them.
static int read_options(model_cli_t *cli, calib_lamps_opts_t *o, char ***lamps)
{
    static const char *const progress[] = { "lines", "bar", NULL };
    static const char *const method[] = { "centroid", "gauss", "model", NULL };
    static const char *const path[] = { "fixed", "fit", NULL };
    static const char *const prior[] = { "--sphere-offset-prior-mm", "--sphere-shift-prior-mm",
                                         "--sphere-tilt-prior-mrad" };
    double *prior_dest[] = { &o->offset_prior_mm, &o->shift_prior_mm, &o->tilt_prior_mrad };
    int joint = o->joint, meth = (int)o->method, n = 0, rc;
    if ((rc = word_opt(cli, "--progress", progress, &o->progress, "write lines or bar")) ||
        (rc = word_opt(cli, "--highlight", method, &meth, "write model, gauss or centroid")) ||
        (rc = word_opt(cli, "--sphere-path", path, &joint, "write fit or fixed")) ||
        (rc = number_opt(cli, "--lamp-radius-mm", &o->lamp_radius_mm, 0, false,
                         "give the lamps' radius in mm (>= 0)")) ||
        (rc = number_opt(cli, "--min-snr", &o->min_snr, 3, false, "give a number >= 3")))
        return rc;
    for (int k = 0; k < 3; k++)
        if ((rc = number_opt(cli, prior[k], prior_dest[k], 0, false, "give a std >= 0 (0 holds it at 0)"))) return rc;
    o->method = (calib_lamps_method_t)meth;
    o->joint = joint;
    const char *c = model_cli_value(cli, "--sphere-centre-mm");
    if ((rc = number_list(cli, "--sphere-centre-mm", o->sphere_centre_mm, 3, &n))) return rc;
    if (c && n != 3) return model_cli_error(cli, "--sphere-centre-mm '%s': give X,Y,Z (mm, rig frame, angle 0)", c);
    if ((rc = number_opt(cli, "--sphere-radius-mm", &o->sphere_radius_mm, 0, true, "give the radius in mm (> 0)")))
        return rc;
    o->sphere_given = c && model_cli_value(cli, "--sphere-radius-mm");
    if (!o->out) return model_cli_error(cli, "-o DIR is required");
    if (!o->camera) return model_cli_error(cli, "--camera-model CAMERA.cameramodel is required");
    if (!o->rig == !o->session)
        return model_cli_error(cli, o->rig ? "give --rig or --session, not both"
                                           : "give --rig RIG.ini (capture) or --session DIR");
    const char *a = model_cli_value(cli, "--angles-deg");
    if (a && o->session) return model_cli_error(cli, "--angles-deg is for a capture (--rig); a session has its own");
    if ((rc = number_list(cli, "--angles-deg", o->angles_deg, CALIB_LAMPS_MAX_ANGLES, &o->nangles))) return rc;
    if (a && o->nangles < 3)
        return model_cli_error(cli, "--angles-deg '%s': at least 3 angles are needed to triangulate", a);
    if ((rc = number_list(cli, "--exposures-us", o->exposures_us, CALIB_LAMPS_MAX_EXPOSURES, &o->nexposures)))
        return rc;
    if (o->nexposures < 1) return model_cli_error(cli, "--exposures-us: give at least one exposure");
    const char *l = model_cli_value(cli, "--lamps-on");
    if (l) {
        GPtrArray *v = g_ptr_array_new();
        char **parts = g_strsplit(l, ",", -1);
        for (char **p = parts; *p; p++)
            if (*g_strstrip(*p)) g_ptr_array_add(v, g_strdup(*p));
        g_strfreev(parts);
        g_ptr_array_add(v, NULL);
        *lamps = (char **)g_ptr_array_free(v, FALSE);
        o->lamps = *lamps;
    }
    return 0;
}

// The lamps' table on stdout.
static void print_lamps(const calib_lamps_result_t *r)
{
    printf("lamp       x_mm      y_mm      z_mm    std_x  std_y  std_z  rms_mm  frames\n");
    for (int l = 0; l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
        printf("%-8s %9.2f %9.2f %9.2f  %6.2f %6.2f %6.2f  %6.2f  %2d/%d\n", lp->name, x[0], x[1], x[2], sqrt(cv[0]),
               sqrt(cv[4]), sqrt(cv[8]), lp->fit.rms_mm, lp->fit.n_used, r->nangles);
    }
    if (r->have_joint && r->have_typed) {
        const double *f = r->found_mm, *t = r->typed_mm, *c = r->found_cov_mm2;
        printf("sphere centre at angle 0 from the highlights: %.2f %.2f %.2f mm (std %.2f %.2f %.2f), typed %g %g %g "
               "(%.2f mm off; %d round%s)\n", f[0], f[1], f[2], sqrt(c[0]), sqrt(c[4]), sqrt(c[8]), t[0], t[1], t[2],
               sqrt(pow(f[0] - t[0], 2) + pow(f[1] - t[1], 2) + pow(f[2] - t[2], 2)), r->rounds,
               r->rounds == 1 ? "" : "s");
    }
}

int calib_cmd_lamps(int argc, char **argv)
{
    calib_lamps_opts_t o = calib_lamps_defaults();
    bool yes = false;
    const char *operator_input = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG.ini", "capture on this rig into DIR/capture (a complete session there is "
                         "reused)", &o.rig, false),
        MODEL_OPT_STRING("--session", "DIR", "analyse a session captured elsewhere (its plan: the sphere, each lamp "
                         "alone)", &o.session, false),
        MODEL_OPT_STRING("--camera-model", "FILE", "the camera model (mrcal .cameramodel, extrinsics in the rig "
                         "frame)", &o.camera, false, .old = "--camera"),
        MODEL_OPT_OUT("DIR", "output: lamps.json, report.html, plots", &o.out, false),
        MODEL_OPT_VALUE("--sphere-centre-mm", "X,Y,Z", "the sphere's centre at turntable angle 0 as measured (rig "
                        "frame,\n" IND "mm; required): where the highlights are looked for first, and the prior of "
                        "the\n" IND "centre the joint fit finds from them", false),
        MODEL_OPT_VALUE("--sphere-radius-mm", "R", "the sphere's radius (mm; required)", false),
        MODEL_OPT_STRING("--sample", "NAME", "the sample of the plan (default mirror_sphere)", &o.sample, false),
        MODEL_OPT_VALUE("--angles-deg", "DEG,DEG,...", "turntable angles (default 24: 0,15,...,345)", false,
                        .old = "--angles"),
        MODEL_OPT_VALUE("--lamps-on", "NAME,...", "the lamps (default every lamp of the rig file, or every lamp"
                        "\n" IND "alone of the session's plan)", false, .old = "--lamps"),
        MODEL_OPT_VALUE("--exposures-us", "US,...", "auto-bracketing ladder, longest first (default 40,20,10)", false),
        MODEL_OPT_VALUE("--min-snr", "X", "a highlight's peak / noise at least (default 12)", false),
        MODEL_OPT_VALUE("--lamp-radius-mm", "R", "the lamps' emitting radius, modelled in the highlight (default 0 "
                        "= point lamps)", false),
        MODEL_OPT_VALUE("--highlight", "model|gauss|centroid", "how a highlight is located: model (default) fits "
                        "the lamp's disk seen\n" IND "in the mirror in direction space; gauss a 2-D Gaussian in the "
                        "image;\n" IND "centroid the intensity-weighted centroid", false),
        MODEL_OPT_VALUE("--sphere-path", "fit|fixed", "fit (default): the lamps and the sphere's path jointly over "
                        "every\n" IND "highlight (the path: the given centre plus an offset that turns with the\n"
                        IND "table, a shift and a tilt that do not: what the camera model's extrinsics\n" IND
                        "error moves); fixed: each lamp alone with the sphere where the facts put it", false),
        MODEL_OPT_VALUE("--sphere-offset-prior-mm", "S", "std of the typed sphere centre (default 3): the centre "
                        "is\n" IND "found from the highlights across angles, the typed one its prior and check",
                        false),
        MODEL_OPT_VALUE("--sphere-shift-prior-mm", "S", "std of the path's shift across the axis (default 0.1: a "
                        "calibrated camera)", false),
        MODEL_OPT_VALUE("--sphere-tilt-prior-mrad", "S", "std of the path's tilt (default 1); 0 holds a part at 0",
                        false),
        MODEL_OPT_VALUE("--progress", "lines|bar", "capture progress (default: bar on a terminal)", false),
        RIG_OPERATOR_OPTS(&yes, &operator_input),
    };
    model_cli_t cli = { .cmd = "calib lamps", .synopsis = "", .about = ABOUT, .epilog = EPILOG, .opts = opts,
                        .nopts = MODEL_NOPTS(opts), .repeat_ok = true };
    char **lamps = NULL;
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = read_options(&cli, &o, &lamps))) goto done;
    // the command as typed (refl calib lamps ...) for the provenance
    o.argc = argc + 1;
    o.argv = argv - 1;
    if (!(o.op = rig_operator_open(yes, operator_input))) {
        rc = yes ? model_cli_error(&cli, "give --yes or --operator-input FILE, not both")
                 : model_error_report("calib lamps");
        goto done;
    }
    calib_lamps_result_t r;
    bool q = model_error_quiet_thread(true);   // one message, printed here
    bool ok = calib_lamps_run(&o, &r);
    model_error_quiet_thread(q);
    if (ok) print_lamps(&r);
    else model_error_report("calib lamps");
    calib_lamps_result_free(&r);
    rc = ok ? 0 : rig_operator_paused(o.op) ? 3 : 1;
    rig_operator_close(o.op);
done:
    g_strfreev(lamps);
    return rc;
}

// ---------------------------------------------------------------------------
// refl calib pattern

static const char PATTERN_ABOUT[] =
    "Each lamp's emission pattern from a session of a flat Lambertian target of albedo A (the reference white,\n"
    "default 0.99) lit by each lamp alone, at one or more turntable angles (examples/plans/reference_white_lamps.ini):\n"
    "every window's irradiance s d^2 / (kd n.l) against its direction u from the lamp, fitted per lamp with\n"
    "kcI max(0, a.u)^n (n the cos power, a the axis). Writes the lamps.json of DIR with each lamp's\n"
    "emission_cos_power, emission_axis and their uncertainties; every later use of that lamps.json (refl calib\n"
    "white, refl fit material, refl verify, refl plan lamps) applies the pattern.";

static const char PATTERN_EPILOG[] =
    "Order on a lab day: refl calib lamps (positions), refl calib gain (its flat field corrects the vignetting that\n"
    "would otherwise read as a pattern), then this, then refl calib white (kc*I becomes the on-axis intensity's).\n"
    "The pattern is measured over the directions of the target's windows (a cone printed per lamp); beyond it it\n"
    "is extrapolated: make the target cover the samples' region (the 150 mm white at the table centre does).\n"
    "Output (-o, may be DIR's lamps.json itself, written atomically): lamps.json as read, plus per lamp\n"
    "emission_cos_power (n, 0 = isotropic), emission_axis ([x, y, z], unit, rig frame) and emission (the figures:\n"
    "cos_power_std, axis_std_deg, tilt_from_origin_deg, the measured cone, rms_residual_pct, irradiance_std_pct).";

int calib_cmd_pattern(int argc, char **argv)
{
    const char *calib_dir = NULL, *out = NULL, *camera = NULL, *report = NULL;
    bool no_report = false;
    calib_observe_options_t o = calib_observe_defaults();
    double albedo = 0.99;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--calib", "DIR", "the calibrations: camera.cameramodel, lamps.json (positions), optionally "
                         "gain.json and its maps", &calib_dir, true),
        MODEL_OPT_OUT("LAMPS.json", "the output: DIR's lamps.json with the patterns (it may be that file)",
                         &out, true),
        MODEL_OPT_STRING("--camera", "NAME", "camera NAME's frames with its calibrations (a directory of several "
                         "cameras)", &camera, false),
        MODEL_OPT_VALUE("--albedo", "A", "the target's albedo (default 0.99)", false),
        MODEL_OPT_STRING("--scene", "FILE", "the target's scene, D3D or OBJ (needed: a session records no scene)",
                         &o.scene_path, false),
        MODEL_OPT_STRING("--material", "NAME", "its material in the scene (default: the scene's only material)",
                         &o.material, false),
        MODEL_OPT_VALUE("--window", "N", "windows of N x N pixels (default 5)", false),
        MODEL_OPT_VALUE("--step", "N", "on a grid of N pixels (default 8)", false),
        MODEL_OPT_STRING("--report", "DIR", "the report's directory (default: pattern/ beside the -o file): "
                         "report.html, pattern.png, pattern_windows.csv", &report, false),
        MODEL_OPT_FLAG("--no-report", NULL, "skip the report", &no_report),
        MODEL_OPT_FLAG("-v", "--verbose", "print every frame", &o.verbose),
    };
    model_cli_t cli = { .cmd = "calib pattern", .synopsis = "SESSION", .about = PATTERN_ABOUT,
                        .epilog = PATTERN_EPILOG, .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 1,
                        .max_positional = 1 };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = calib_cli_window_step(&cli, &o.window, &o.step)) != MODEL_CLI_OK) return rc;
    const char *av = model_cli_value(&cli, "--albedo");
    if (av && !(model_parse_double(av, &albedo) && albedo > 0 && albedo <= 1))
        return model_cli_error(&cli, "--albedo needs a number in (0, 1], not '%s'", av);

    const char *session = cli.positional[0];
    calib_set_t *cal = NULL;
    calib_obs_set_t obs;
    json_t *prov = NULL;
    calib_lamps_pattern_t *pat = NULL;
    bool q = model_error_quiet_thread(true);
    bool ok = calib_observe_session(session, calib_dir, camera, false, &o, &cal, &obs);
    if (ok) {
        printf("refl calib pattern: %d observations of %s in %d frames (%d skipped)\n", obs.n, obs.material,
               obs.frames_used, obs.frames_skipped);
        ok = (pat = calloc((size_t)cal->lamps->n, sizeof *pat)) != NULL;
        if (!ok) model_error_set(NULL, 0, "out of memory");
    }
    ok = ok && calib_lamps_pattern_fit(&obs, cal, albedo, pat);
    if (ok) {
        prov = calib_observe_provenance(argc + 1, argv - 1, session, cal);
        ok = calib_lamps_pattern_write(cal, pat, session, out, prov);
    }
    char *rdir = NULL;
    if (ok && !no_report) {
        char *od = g_path_get_dirname(out);
        rdir = report ? g_strdup(report) : g_build_filename(od, "pattern", NULL);
        g_free(od);
        ok = calib_lamps_pattern_report(&obs, cal, albedo, pat, rdir, prov);
    }
    model_error_quiet_thread(q);
    if (ok) {
        printf("%-8s %6s %6s %9s %8s %8s %6s %7s %7s\n", "lamp", "n", "n_std", "tilt_deg", "axis_std", "cone_deg",
               "rms_%", "irr_std%", "windows");
        for (int l = 0; l < cal->lamps->n; l++) {
            const calib_lamps_pattern_t *P = &pat[l];
            if (!P->fitted) {
                printf("%-8s not measured: %d windows (need 20); its lamps.json entry is unchanged\n", P->name,
                       P->nwindows);
                continue;
            }
            printf("%-8s %6.2f %6.2f %9.2f %8.2f %8.2f %6.2f %7.2f %7d\n", P->name, P->n, P->n_std, P->tilt_deg,
                   P->axis_std_deg, P->cone_half_angle_deg, 100 * P->rms_rel, 100 * P->irradiance_std_rel,
                   P->nwindows);
        }
        printf("%s\n", out);
        if (rdir) printf("%s/report.html\n", rdir);
    }
    g_free(rdir);
    rc = ok ? 0 : model_error_report("calib pattern");
    free(pat);
    json_decref(prov);
    calib_obs_free(&obs);
    calib_set_free(cal);
    return rc;
}
