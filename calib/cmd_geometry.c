// calib/cmd_geometry.c — `refl calib geometry`: parses the options
// (model/base/opts.h), runs calib_geometry_run (calib/geometry/geometry.h) and prints the
// outputs. Exit: 0 done, 1 error (the library's message, printed once here),
// 2 usage.
#include <math.h>
#include <mrcal/mrcal.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/geometry/geometry.h"
#include "model/model.h"
#include "model/base/opts.h"

#define ABOUT                                                                                                  \
    "Camera model by mrgingham (corners) and mrcal (mrcal-calibrate-cameras), the turntable axis\n"             \
    "from the board poses across angles, and the extrinsics in the rig frame. Writes\n"                         \
    "DIR/camera.cameramodel, DIR/geometry.json, DIR/report.html (and DIR/capture/, DIR/images/,\n"              \
    "DIR/corners.vnl, DIR/mrcal/). The views come from one of:\n"                                               \
    "  --rig RIG.ini -o DIR                    capture here, one session per tilt\n"                           \
    "  --session DIR1 [--session DIR2 ...]     capture sessions made elsewhere\n"                               \
    "  --images 'GLOB'|DIR                     images captured elsewhere (PNG, JPEG, TIFF; others skipped)\n"   \
    "  --corners CORNERS.vnl --imagersize W H  corners found elsewhere (mrgingham's format, as mrcal reads it)\n"  \
    "The board: a chessboard of W x H inner corners (--object-width-n, --object-height-n; --gridn N:\n"      \
    "N x N), found by mrgingham when square, else by OpenCV (findChessboardCornersSB, the whole board);\n"  \
    "or a ChArUco board (--board charuco: OpenCV's, W x H inner corners, markers of --charuco-dict),\n"      \
    "found by OpenCV in part too (a corner not seen is '- -' in DIR/corners.vnl, as mrcal takes it)."

#define EPILOG                                                                                                 \
    "Rig frame: z along the fitted turntable axis (counter-clockwise angles positive seen from\n"              \
    "+z); origin on the axis at the table top (--board-height-mm below the board's corner plane\n"             \
    "at tilt 0); x: the board grid direction at angle 0, tilt 0 closest to the image's +x\n"                   \
    "(lay the board square to the turntable's home orientation). Units mm, deg, px.\n"                         \
    "Several cameras (a rig or sessions of several, no --camera): one mrcal solve of every camera and\n"     \
    "its pose relative to the first (corner order made to agree across the cameras); DIR/NAME.cameramodel\n" \
    "per camera, DIR/camera.cameramodel the first's; the rig frame from the first camera's views; every\n"  \
    "camera needs the board in enough views (give --tilts that show it to all; --tilts 2cam-example:\n"     \
    "those of examples/virtual-rig-2cam.ini, 111 poses).\n"                                                  \
    "With --rig, each tilt's session begins with an operator step (mount the board on the wedge,\n"         \
    "facing the camera): Enter on a terminal, --yes or --operator-input FILE answers it; with stdin\n"      \
    "not a terminal and neither option the command pauses there (exit 3; run it again to continue).\n"     \
    "mrcal-calibrate-cameras' names are accepted: --object-spacing (metres unless a unit is given),\n"  \
    "--object-width-n (--gridn), --object-height-n, --corners-cache (--corners), --focal (--focal-px).\n" \
    "A view with fewer than --min-corners corners (a ChArUco board mostly out of view) is left out\n"     \
    "with the reason, as a view without a board is. The camera\n"                                        \
    "models keep mrcal's optimization_inputs with refl's extrinsics: mrcal's tools run on them.\n"      \
    "Cross-validation (every run): the views split into two halves (alternate frames), each solved\n"        \
    "alone; their projections differ over the imager by D against the predicted s0 + s1 (mrcal's\n"         \
    "projection uncertainty of each half); the model fails when the RMS of D / (s0 + s1) where both\n"      \
    "halves saw corners exceeds 1.5. --lensmodel auto: OPENCV8, cross-validated and compared the same\n"  \
    "way with a splined fit of the same views (a bias both halves share shows there); when it fails\n"     \
    "either, LENSMODEL_SPLINED_STEREOGRAPHIC (order 3, ~70 px per knot, the knots covering the\n"          \
    "imager with 10 % margin) is cross-validated and kept when it passes. geometry.json's\n"              \
    "cross_validation has the figures and the choice; the report says which and why.\n"                   \
    "The axis: fitted with the board poses as turns of one pose per tilt about it, to the corners;\n"    \
    "a frame those turns do not explain is left out and named; its 1-sigma and the rig frame's\n"         \
    "(axis.rig_frame_sigma) in geometry.json.\n"                                                          \
    "Exit: 0 done, 1 error, 2 usage, 3 paused."

// A number option within [lo, hi] (whole when integer), with the command's own message.
static int number(model_cli_t *c, const char *name, double lo, double hi, bool integer, const char *what, double *out)
{
    const char *v = model_cli_value(c, name);
    double d;
    if (!v) return 0;
    if (!model_parse_double(v, &d) || !(d >= lo && d <= hi) || (integer && d != floor(d)))
        return model_cli_error(c, "%s %s: %s", name, v, what);
    *out = d;
    return 0;
}

// --imagersize W H (a list option of two values).
static int imagersize(model_cli_t *c, const model_opt_list_t *l, calib_geometry_opts_t *o)
{
    double w = 0, h = 0;
    if (!l->n) return 0;
    if (l->n != 2 || !model_parse_double(l->v[0], &w) || !model_parse_double(l->v[1], &h) || !(w >= 1 && w <= 1e5) ||
        !(h >= 1 && h <= 1e5))
        return model_cli_error(c, "--imagersize needs W H in pixels");
    o->imager_w = (int)w;
    o->imager_h = (int)h;
    return 0;
}

// --object-spacing (mrcal-calibrate-cameras' name): metres, or a length with
// its unit m, cm or mm; the same as --square-mm, which it excludes.
static int object_spacing(model_cli_t *c, calib_geometry_opts_t *o)
{
    const char *v = model_cli_value(c, "--object-spacing");
    if (!v) return 0;
    if (model_cli_value(c, "--square-mm"))
        return model_cli_error(c, "give --square-mm or --object-spacing, not both (the same corner spacing)");
    static const struct { const char *unit; double mm; } units[] = { { "mm", 1 }, { "cm", 10 }, { "m", 1000 } };
    char num[64];
    double scale = 1000, d;
    snprintf(num, sizeof num, "%s", v);
    size_t n = strlen(num);
    for (size_t k = 0; k < sizeof units / sizeof units[0]; k++) {
        size_t u = strlen(units[k].unit);
        if (n > u && !strcmp(num + n - u, units[k].unit)) {
            num[n - u] = 0;
            scale = units[k].mm;
            break;
        }
    }
    if (!model_parse_double(num, &d) || !(d * scale >= 1e-3 && d * scale <= 1e4))
        return model_cli_error(c, "--object-spacing %s: give the corner spacing in metres (as mrcal does, e.g. "
                               "0.03) or with its unit (30mm, 3cm, 0.03m), 0.001 mm .. 10 m", v);
    o->board.spacing_mm = d * scale;
    return 0;
}

// --board, --charuco-dict, --detector (words).
static int board_options(model_cli_t *c, calib_geometry_opts_t *o)
{
    const char *v;
    if ((v = model_cli_value(c, "--board")) && !calib_board_kind_parse(v, &o->board.kind))
        return model_cli_error(c, "--board %s: give chessboard or charuco", v);
    if ((v = model_cli_value(c, "--charuco-dict"))) {
        if (strlen(v) >= sizeof o->board.dict || !calib_board_dict_size(v))
            return model_cli_error(c, "--charuco-dict %s: give one of OpenCV's predefined dictionaries (DICT_4X4_50 "
                                   ".. DICT_7X7_1000, DICT_ARUCO_ORIGINAL, DICT_APRILTAG_16h5 .. DICT_APRILTAG_36h11)", v);
        snprintf(o->board.dict, sizeof o->board.dict, "%s", v);
    }
    if (o->board.kind != CALIB_BOARD_CHARUCO && (model_cli_value(c, "--charuco-dict") ||
                                                 model_cli_value(c, "--charuco-marker-mm")))
        return model_cli_error(c, "--charuco-dict and --charuco-marker-mm describe a ChArUco board: give --board "
                               "charuco");
    static const struct { const char *word; calib_detector_t d; } dets[] = {
        { "auto", CALIB_DETECTOR_AUTO }, { "mrgingham", CALIB_DETECTOR_MRGINGHAM }, { "opencv", CALIB_DETECTOR_OPENCV }
    };
    if ((v = model_cli_value(c, "--detector"))) {
        size_t k = 0;
        while (k < sizeof dets / sizeof dets[0] && strcmp(dets[k].word, v)) k++;
        if (k == sizeof dets / sizeof dets[0]) return model_cli_error(c, "--detector %s: give auto, mrgingham or opencv", v);
        o->detector = dets[k].d;
    }
    return 0;
}

// The numbers, then the checks of the whole (one source, its needs).
static int check_options(model_cli_t *c, const model_opt_list_t *imsize, calib_geometry_opts_t *o)
{
    double width_n = o->board.width_n, height_n = NAN, min_views = 0, min_corners = 0, marker_mm = NAN;
    int rc;
    if ((rc = number(c, "--gridn", 2, 100, true, "give an integer 2..100", &width_n)) ||
        (rc = number(c, "--object-height-n", 2, 100, true, "give an integer 2..100", &height_n)) ||
        (rc = number(c, "--charuco-marker-mm", 1e-3, 1e4, false, "give a length in mm > 0", &marker_mm)) ||
        (rc = number(c, "--min-corners", 4, 1e5, true, "give an integer >= 4", &min_corners)) ||
        (rc = number(c, "--square-mm", 1e-3, 1e4, false, "give a length in mm > 0", &o->board.spacing_mm)) ||
        (rc = number(c, "--board-height-mm", -1e4, 1e4, false, "give a length in mm", &o->board_height_mm)) ||
        (rc = number(c, "--exposure-us", 1, 1e8, false, "give microseconds > 0", &o->exposure_us)) ||
        (rc = number(c, "--focal-px", 1, 1e6, false, "give a focal length in px > 0", &o->focal_px)) ||
        (rc = number(c, "--distance-mm", 1, 1e7, false, "give a distance in mm > 0", &o->distance_mm)) ||
        (rc = number(c, "--min-views", 1, 1e5, true, "give an integer >= 1", &min_views)) ||
        (rc = imagersize(c, imsize, o)))
        return rc;
    if ((rc = object_spacing(c, o)) || (rc = board_options(c, o))) return rc;
    o->board.width_n = (int)width_n;
    o->board.height_n = isfinite(height_n) ? (int)height_n : (int)width_n;   // mrcal's default: square
    o->board.marker_mm = isfinite(marker_mm) ? marker_mm : CALIB_BOARD_DEFAULT_MARKER_RATIO * o->board.spacing_mm;
    o->min_views = (int)min_views;
    o->min_corners = (int)min_corners;
    if (!calib_board_check(&o->board)) return model_cli_error(c, "%s", model_last_error());
    if (o->detector == CALIB_DETECTOR_MRGINGHAM &&
        (o->board.kind != CALIB_BOARD_CHESSBOARD || o->board.width_n != o->board.height_n))
        return model_cli_error(c, "--detector mrgingham finds square chessboards only (--gridn N); a %dx%d %s needs "
                               "--detector opencv (the default for it)", o->board.width_n, o->board.height_n,
                               calib_board_kind_name(o->board.kind));
    int nsrc = (o->rig != NULL) + (o->nsessions > 0) + (o->images != NULL) + (o->corners != NULL);
    if (nsrc != 1)
        return model_cli_error(c, "%s", nsrc ? "give only one of --rig, --session, --images, --corners"
                                             : "say where the views come from: --rig, --session, --images or "
                                               "--corners");
    if (!o->out) return model_cli_error(c, "give the output directory: -o DIR");
    if (o->corners && !o->imager_w)
        return model_cli_error(c, "--corners needs --imagersize W H (no images to read it from)");
    mrcal_lensmodel_t lm;
    if (!calib_geometry_is_auto(o->lensmodel) && !mrcal_lensmodel_from_name(&lm, o->lensmodel))
        return model_cli_error(c, "--lensmodel %s: not a lens model mrcal knows nor auto (e.g. LENSMODEL_OPENCV8, "
                               "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=50)", o->lensmodel);
    if (o->rig && access(o->rig, R_OK) != 0) return model_cli_error(c, "--rig %s: cannot read the rig file", o->rig);
    if (o->corners && access(o->corners, R_OK) != 0)
        return model_cli_error(c, "--corners %s: cannot read the corners file", o->corners);
    return 0;
}

int calib_cmd_geometry(int argc, char **argv)
{
    calib_geometry_opts_t o = calib_geometry_defaults();
    const char **session_v = calloc((size_t)argc + 1, sizeof *session_v);
    model_opt_list_t sessions = { session_v, 0, argc + 1 };
    const char *imsize_v[2];
    model_opt_list_t imsize = { imsize_v, 0, 2 };
    if (!session_v) return model_error_report("calib geometry");
    bool yes = false;
    const char *operator_input = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG.ini", "capture: one session per tilt (DIR/capture/tiltT_azA), all lamps on",
                         &o.rig, false),
        MODEL_OPT_OUT("DIR", "the output directory", &o.out, false),
        MODEL_OPT_STRING("--tilts", "SPEC", "tilts for --rig: 'T[@AZ][:A,A,...] ...' (tilt deg, hinge azimuth deg, "
                         "turntable angles deg; default: the example rig's\n                             '"
                         CALIB_GEOMETRY_DEFAULT_TILTS "')", &o.tilts, false),
        MODEL_OPT_STRING("--angles-deg", "A,A,...", "turntable angles for tilts given without their own (default '"
                         CALIB_GEOMETRY_DEFAULT_ANGLES "')", &o.angles, false, .old = "--angles"),
        MODEL_OPT_STRING("--sample", "NAME", "the board sample (default calib_board)", &o.sample, false),
        MODEL_OPT_STRING("--camera", "NAME", "--rig, --session: calibrate only this camera (its rig file "
                         "name; default: every camera together)", &o.camera, false),
        MODEL_OPT_VALUE("--exposure-us", "US", "the capture's exposure (default 6000)", false),
        MODEL_OPT_LIST("--session", "DIR", "use a capture session (angles from its journal, tilt from its plan); "
                       "repeat it for more", &sessions, false, false),
        MODEL_OPT_STRING("--images", "'GLOB'|DIR", "use images captured elsewhere (no angles: no axis, no rig "
                         "frame); files that are no image are skipped with the reason", &o.images, false),
        MODEL_OPT_CHANNEL,
        { "--corners", "--corners-cache", "FILE.vnl", "use mrgingham's corners (no images needed; needs "
          "--imagersize)", MODEL_OPT_KIND_STRING, &o.corners, 0, 0, false, false, NULL, NULL, 0 },
        MODEL_OPT_STRING("--lensmodel", "NAME", "LENSMODEL_OPENCV8 (default), LENSMODEL_OPENCV4, ..., "
                         "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=50, or auto (the lean "
                         "OPENCV8 unless it fails the checks below, then the splined model)", &o.lensmodel, false),
        MODEL_OPT_VALUE("--board", "KIND", "chessboard (default) or charuco (OpenCV's ChArUco board)", false),
        { "--gridn", "--object-width-n", "W", "inner corners along the board's x (default 10; with --gridn and no\n"
          "                             --object-height-n also along y: a square board)", MODEL_OPT_KIND_STRING, NULL,
          0, 0, false, false, NULL, NULL, 0 },
        MODEL_OPT_VALUE("--object-height-n", "H", "inner corners along the board's y (default: the same as along x)",
                        false),
        MODEL_OPT_VALUE("--square-mm", "S", "corner spacing, a square's side (default 30)", false),
        MODEL_OPT_VALUE("--object-spacing", "S[m|cm|mm]", "corner spacing as mrcal-calibrate-cameras takes it: in "
                        "metres,\n                             or with a unit (0.03, 0.03m, 3cm, 30mm)", false),
        MODEL_OPT_VALUE("--charuco-dict", "NAME", "ChArUco: the markers' dictionary, OpenCV's name (default "
                        CALIB_BOARD_DEFAULT_DICT ")", false),
        MODEL_OPT_VALUE("--charuco-marker-mm", "M", "ChArUco: a marker's side (default 0.75 x the square's)", false),
        MODEL_OPT_VALUE("--detector", "NAME", "who finds the corners: auto (default: mrgingham for a square "
                        "chessboard,\n                             else OpenCV), mrgingham or opencv (a chessboard: findChessboardCornersSB, "
                        "then the\n                             classic detector on the image and on a contrast-normalised "
                        "copy;\n                             geometry.json names each view's)", false),
        MODEL_OPT_VALUE("--min-corners", "N", "a view with fewer corners is left out, with the reason (default 12, "
                        "at most\n                             the board's)", false),
        MODEL_OPT_VALUE("--board-height-mm", "H", "height of the corner plane above the table top at tilt 0 "
                        "(default 5)", false),
        { "--focal-px", "--focal", "F", "seed focal length for mrcal in px (default 1.4 x imager width)",
          MODEL_OPT_KIND_STRING, NULL, 0, 0, false, false, NULL, NULL, 0 },
        MODEL_OPT_LIST("--imagersize", "W H", "imager size (needed with --corners)", &imsize, true, false),
        MODEL_OPT_VALUE("--distance-mm", "D", "distance of the projection-uncertainty figure (default 900)", false),
        MODEL_OPT_VALUE("--min-views", "N", "views with a board the solve needs (default by lens model)", false),
        RIG_OPERATOR_OPTS(&yes, &operator_input),
    };
    model_cli_t cli = { .cmd = "calib geometry", .synopsis = "", .about = ABOUT, .epilog = EPILOG, .opts = opts,
                        .nopts = MODEL_NOPTS(opts), .min_positional = 0, .max_positional = 0, .repeat_ok = true };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) {
        free(session_v);
        return rc;
    }
    o.sessions = session_v;
    o.nsessions = sessions.n;
    o.argc = argc;
    o.argv = argv;
    if ((rc = check_options(&cli, &imsize, &o)) || (rc = model_cli_channel(&cli))) {
        free(session_v);
        return rc;
    }
    if (!(o.op = rig_operator_open(yes, operator_input))) {
        free(session_v);
        return yes ? model_cli_error(&cli, "give --yes or --operator-input FILE, not both")
                   : model_error_report("calib geometry");
    }
    calib_geometry_result_t r;
    bool q = model_error_quiet_thread(true);   // the library's message is printed once, here
    bool ok = calib_geometry_run(&o, &r);
    model_error_quiet_thread(q);
    if (ok) {
        printf("refl calib geometry: %s (RMS %.4f px), %s/geometry.json, %s/report.html\n", r.camera_model, r.rms_px,
               r.outdir, r.outdir);
        rc = 0;
    } else {
        model_error_report("calib geometry");
        if (r.usage) model_cli_usage(&cli, stderr);
        rc = r.usage ? 2 : rig_operator_paused(o.op) ? 3 : 1;
    }
    rig_operator_close(o.op);
    calib_geometry_result_free(&r);
    free(session_v);
    return rc;
}
