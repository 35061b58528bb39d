// calib/cmd_calib.c — `refl calib geometry|lamps|pattern|gain|white`: dispatches to the
// calibrations (calib/geometry/geometry.c, calib/lamps/lamps.c, calib/gain/gain.c, calib/white.c).
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/export.h"
#include "model/model.h"
#include "model/base/opts.h"

static const struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} subs[] = {
    { "geometry", calib_cmd_geometry, "camera model (mrgingham + mrcal) and turntable axis from chessboard views" },
    { "lamps",    calib_cmd_lamps,    "lamp positions from mirror-sphere highlights, with uncertainty in mm" },
    { "pattern",  calib_cmd_pattern,  "each lamp's emission pattern (cos power, axis) from a reference-white session" },
    { "white",    calib_cmd_white,      "kc*I per lamp from a reference-white session" },
    { "gain",     calib_cmd_gain,     "sensitivity (EMVA 1288): dark, photon transfer, linearity, PRNU/DSNU maps" },
    { "export",   calib_cmd_export,   "a camera model as OpenCV FileStorage YAML or ROS camera_info YAML" },
};

static void usage(FILE *f)
{
    fprintf(f, "usage: refl calib geometry|lamps|pattern|gain|white|export [ARGS...]   (refl calib NAME --help for its options)\n\n");
    for (size_t i = 0; i < sizeof subs / sizeof subs[0]; i++) fprintf(f, "  %-9s %s\n", subs[i].name, subs[i].summary);
    fprintf(f, "\n");
    model_cli_exit_status(f);
    fprintf(f, "\nrefl %s\n", REFL_VERSION);
}

int calib_cmd(int argc, char **argv)
{
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        usage(stdout);
        return 0;
    }
    for (size_t i = 0; i < sizeof subs / sizeof subs[0]; i++)
        if (!strcmp(argv[1], subs[i].name)) return subs[i].run(argc - 1, argv + 1);
    fprintf(stderr, "refl calib: unknown calibration '%s'\n", argv[1]);
    usage(stderr);
    return 2;
}

// ---------------------------------------------------------------------------
// refl calib white

int calib_cli_window_step(model_cli_t *cli, int *window, int *step)
{
    static const char *const px[] = { "--window", "--step" };
    for (int k = 0; k < 2; k++) {
        const char *v = model_cli_value(cli, px[k]);
        long n;
        if (v && (!model_parse_int(v, &n) || n < 1 || n > 64))
            return model_cli_error(cli, "%s needs a whole number of pixels 1..64, not '%s'", px[k], v);
        if (v) *(k ? step : window) = (int)n;
    }
    return MODEL_CLI_OK;
}

// Each lamp's kc*I with its 1-sigma, one line each.
static void print_white(const calib_white_lamp_t *wl, int n, const calib_white_table_t *table)
{
    for (int l = 0; l < n; l++) {
        const calib_white_lamp_t *w = &wl[l];
        printf("  %-12s kc*I = %.6g DN/us per (1/sr)/mm^2 +- %.3f %% (statistical %.3f %%; spread %.2f %%, %d "
               "windows)", w->name, w->kcI_per_us, 100 * w->std_rel, 100 * w->part_rel[CALIB_WHITE_STAT],
               100 * w->spread_rel, w->n);
        if (table)
            printf("; Lambertian at %.4g: %+.2f %%", table->f[0], 100 * (w->kcI_lambertian_per_us / w->kcI_per_us - 1));
        printf("\n");
    }
}

int calib_cmd_white(int argc, char **argv)
{
    const char *calib_dir = NULL, *out = NULL, *camera = NULL, *table_path = NULL;
    calib_observe_options_t o = calib_observe_defaults();
    double albedo = 0.99;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--calib", "DIR", "the calibrations: camera.cameramodel, lamps.json, optionally gain.json "
                         "and its maps (DIR or DIR/geometry, DIR/lamps, DIR/gain)", &calib_dir, true),
        MODEL_OPT_OUT("WHITE.json", "the output (put it in DIR or DIR/white/ for refl fit material)", &out,
                         true),
        MODEL_OPT_STRING("--camera", "NAME", "camera NAME's frames with its calibrations (a directory of several "
                         "cameras: NAME.cameramodel, NAME/gain.json; write -o DIR/NAME/white.json)", &camera, false),
        MODEL_OPT_VALUE("--albedo", "A", "a Lambertian standard's albedo (default 0.99)", false),
        MODEL_OPT_STRING("--reflectance-table", "CSV", "the standard's reflectance factor by incidence and viewing "
                         "angle (its certificate; columns theta_i_deg,theta_r_deg,factor[,factor_std], a full grid) "
                         "instead of --albedo", &table_path, false),
        MODEL_OPT_VALUE("--albedo-std", "S", "the certificate's 1-sigma of the albedo (or of every factor of a "
                        "table without factor_std): the albedo's part of kc*I's uncertainty (default: not stated)",
                        false),
        MODEL_OPT_STRING("--scene", "FILE", "the standard's scene, D3D, OBJ, STL or PLY (needed: a session records "
                         "no scene)", &o.scene_path, false),
        MODEL_OPT_UNITS,
        MODEL_OPT_STRING("--material", "NAME", "its material in the scene (default: the scene's only material)",
                         &o.material, false),
        MODEL_OPT_VALUE("--window", "N", "windows of N x N pixels (default 5)", false),
        MODEL_OPT_VALUE("--step", "N", "on a grid of N pixels (default 8)", false),
        MODEL_OPT_FLAG("-v", "--verbose", "print every frame", &o.verbose),
    };
    model_cli_t cli = {
        .cmd = "calib white", .synopsis = "SESSION", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "The absolute scale kc*I of each lamp from a session of the reference white (a Lambertian standard\n"
                 "of albedo A, default 0.99): every lit window of the standard gives (P - Pa) d^2 / (g t kd n.l),\n"
                 "kd = A/pi; the median per lamp is written. Windows lie wholly on one face of the material.\n"
                 "With --reflectance-table the standard's BRDF is its reflectance factor at each window's\n"
                 "incidence and viewing angles over pi, and white.json states its departure from Lambertian.\n"
                 "Each kc*I carries its 1-sigma and its parts (statistical, lamp position, emission pattern,\n"
                 "albedo, flat field) and the irradiance's 1-sigma over the samples' region.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = calib_cli_window_step(&cli, &o.window, &o.step)) != MODEL_CLI_OK) return rc;
    if ((rc = model_cli_units(&cli, &o.scene_unit_mm))) return rc;
    const char *av = model_cli_value(&cli, "--albedo");
    if (av && !(model_parse_double(av, &albedo) && albedo > 0))
        return model_cli_error(&cli, "--albedo needs a number > 0, not '%s'", av);
    if (albedo > 1) return model_cli_error(&cli, "--albedo %g: an albedo is at most 1", albedo);
    if (av && table_path) return model_cli_error(&cli, "give --albedo or --reflectance-table, not both");
    calib_white_options_t wo = calib_white_defaults();
    const char *as = model_cli_value(&cli, "--albedo-std");
    if (as && !(model_parse_double(as, &wo.albedo_std) && wo.albedo_std >= 0 && wo.albedo_std < 1))
        return model_cli_error(&cli, "--albedo-std needs the albedo's 1-sigma, a number in [0, 1), not '%s'", as);
    calib_white_table_t *table = NULL;
    if (table_path) {
        bool q0 = model_error_quiet_thread(true);
        table = calib_white_table_load(table_path);
        model_error_quiet_thread(q0);
        if (!table) return model_error_report("calib white");
    }

    const char *session = cli.positional[0];
    calib_set_t *cal = NULL;
    calib_obs_set_t obs;
    json_t *prov = NULL;
    calib_white_lamp_t wl[32];
    bool q = model_error_quiet_thread(true);
    bool ok = calib_observe_session(session, calib_dir, camera, false, &o, &cal, &obs);
    if (ok) {
        printf("refl calib white: %d observations of %s in %d frames (%d skipped)\n", obs.n, obs.material,
               obs.frames_used, obs.frames_skipped);
        prov = calib_observe_provenance(argc + 1, argv - 1, session, cal);
        ok = calib_white(&obs, cal, albedo, table, &wo, out, prov, wl);
    }
    model_error_quiet_thread(q);
    if (ok) print_white(wl, cal->lamps->n, table);
    if (ok) printf("%s\n", out);
    rc = ok ? 0 : model_error_report("calib white");
    json_decref(prov);
    calib_obs_free(&obs);
    calib_set_free(cal);
    calib_white_table_free(table);
    return rc;
}

// ---------------------------------------------------------------------------
// refl calib export

int calib_cmd_export(int argc, char **argv)
{
    const char *format = NULL, *out = NULL, *name = NULL;
    bool approximate = false;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--format", "opencv|ros", "OpenCV FileStorage YAML (cv::FileStorage, cv2.FileStorage) or "
                         "ROS camera_info YAML (camera_calibration_parsers)", &format, true),
        MODEL_OPT_OUT("FILE", "the output file", &out, true),
        MODEL_OPT_STRING("--camera-name", "NAME", "ROS camera_name (default: the model file's name without "
                         "extension)", &name, false),
        MODEL_OPT_FLAG("--approximate", NULL, "a model OpenCV cannot hold (splined, ...): export LENSMODEL_OPENCV8 "
                       "fitted to it over the imager,\n                             its error stated (FILE.approx.cameramodel, "
                       "FILE.approx.json)", &approximate),
    };
    model_cli_t cli = {
        .cmd = "calib export", .synopsis = "CAMERA.cameramodel", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "Writes a camera model (refl calib geometry's camera.cameramodel, or any mrcal model) for OpenCV\n"
                 "or ROS: camera_matrix K = [fx 0 cx; 0 fy cy; 0 0 1], the image size and the distortion\n"
                 "coefficients in OpenCV's order k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4]]], which is mrcal's\n"
                 "for LENSMODEL_OPENCV4/5/8/12 (a pinhole: 5 zeros). ROS: distortion_model plumb_bob (OPENCV4,\n"
                 "OPENCV5, pinhole: 5 coefficients) or rational_polynomial (OPENCV8), rectification identity,\n"
                 "projection_matrix [K | 0]; OPENCV12 only as OpenCV. Splined and other models are refused,\n"
                 "or with --approximate replaced by LENSMODEL_OPENCV8 fitted to them over the imager (the\n"
                 "reprojection error's RMS and maximum printed and written in the file). The extrinsics\n"
                 "are not exported.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    calib_export_format_t f;
    if (!calib_export_format_from_name(format, &f))
        return model_cli_error(&cli, "--format %s: give opencv or ros", format);
    bool q = model_error_quiet_thread(true);
    double rms = 0, mx = 0;
    bool ok = approximate ? calib_export_camera_approx(cli.positional[0], f, name, out, &rms, &mx)
                          : calib_export_camera(cli.positional[0], f, name, out);
    model_error_quiet_thread(q);
    if (!ok) return model_error_report("calib export");
    if (rms > 0 || mx > 0)
        printf("refl calib export: LENSMODEL_OPENCV8 fitted to %s: reprojection error over the imager RMS %.4g px, "
               "max %.4g px (%s.approx.json)\n", cli.positional[0], rms, mx, out);
    printf("%s\n", out);
    return 0;
}
