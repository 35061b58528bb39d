// calib/cmd_plan_geometry.c — `refl plan geometry`: the options, the geometry plan
// (calib_geometry_plan, calib/geometry/plan.h) and the lab file's [geometry] section it prints.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/plan.h"
#include "model/base/opts.h"
#include "model/base/report.h"
#include "model/model.h"
#include "rig/lab.h"
#include "rig/rig.h"

#define ABOUT                                                                                                  \
    "Proposes the board poses of refl calib geometry for one's own camera(s): the board flat and on each\n"   \
    "wedge (--wedges-deg) with its hinge at each azimuth (--azimuths-deg), at turntable angles every\n"      \
    "--angle-step-deg; a pose counts for a camera whose imager holds the board's inner corners and half\n" \
    "a square beyond them with --margin-px to spare (mrgingham finds the whole grid or none; the margin\n"   \
    "is for the board's placement on its wedge), its squares at least\n"                                    \
    "--min-square-px and its obliquity at most --max-obliquity-deg. The poses\n"                             \
    "are chosen greedily for the imager's coverage by the corners, the orientations kept spread (head-on,\n"  \
    "tilted left, right, up, down in the image), as mrcal's guidance for a calibration dance asks: many\n"   \
    "views, close, tilted, corners over the whole imager. Prints the lab file's [geometry] section (paste it\n" \
    "into LAB.ini; -o FILE writes it there) with the coverage, the views and their orientations in its\n"    \
    "comments. --check-tilts SPEC: the same figures of tilts at hand (e.g. the lab file's).\n"            \
    "The cameras: --camera-model FILE (an mrcal model with its pose in the rig frame: a calibration, or a\n" \
    "datasheet guess) or --camera-guess 'W,H,F,X,Y,Z' (a pinhole of W x H px, focal length F px = the\n"    \
    "lens's focal length / the pixel pitch, centre at X,Y,Z mm in the rig frame, looking at the turntable's\n" \
    "top centre), one per camera of --rig in its order. The board: --lab's [geometry] board_scene,\n"       \
    "board_corners, board_square_mm, else --board-scene (default examples/samples/calib_board.d3d: 390 x 390\n" \
    "mm, 10 x 10 inner corners 30 mm apart, centred 130 mm off the axis)."
#define EPILOG                                                                                                 \
    "Rig frame: origin at the turntable's top centre, z up; angles deg, lengths mm, pixels px.\n"          \
    "Exit: 0 done (a coverage under 90 % is a warning in the output), 1 error, 2 usage."

enum { MAX_CAMS = CALIB_PLAN_MAX_CAMERAS };

// A comma list of numbers within [lo, hi] into v (at most max). 0 or a usage error.
static int numbers(model_cli_t *c, const char *name, double *v, int *n, int max, double lo, double hi)
{
    const char *s = model_cli_value(c, name);
    if (!s) return 0;
    int k = model_parse_doubles(s, ", ", lo, hi, v, max);
    if (k < 0) return model_cli_error(c, "%s %s: give up to %d numbers %g..%g separated by commas", name, s, max,
                                          lo, hi);
    *n = k;
    return 0;
}

typedef struct {
    model_opt_list_t models, guesses;
    const char      *rig, *lab, *board, *out, *check;
} args_t;

// The cameras of the options, checked against the rig's. 0, 1 (error printed) or 2 (usage).
static int cameras(model_cli_t *c, const args_t *a, calib_geometry_plan_opts_t *o, char names[][64])
{
    int nrig = -1;
    char **rn = NULL;
    if (a->rig && !rig_file_camera_names(a->rig, &rn, &nrig)) return model_error_report("plan geometry");
    if (a->models.n + a->guesses.n == 0)
        return model_cli_error(c, "give --camera-model FILE or --camera-guess 'W,H,F,X,Y,Z' for each camera");
    if (a->models.n && a->guesses.n) return model_cli_error(c, "give --camera-model or --camera-guess, not both");
    int n = a->models.n + a->guesses.n;
    if (nrig >= 0 && nrig != n) {
        g_strfreev(rn);
        return model_cli_error(c, "the rig %s has %d camera%s: give one camera model or guess each, in its order", a->rig,
                               nrig, nrig == 1 ? "" : "s");
    }
    for (int k = 0; k < n; k++) {
        if (rn) snprintf(names[k], 64, "%s", rn[k]);
        else if (n == 1) snprintf(names[k], 64, "camera");
        else snprintf(names[k], 64, "camera%d", k + 1);
        if (a->models.n) {
            o->cams[k] = model_camera_load(a->models.v[k]);
        } else {
            double v[6];
            int m = 0;
            gchar **w = g_strsplit_set(a->guesses.v[k], ", ", -1);
            for (int i = 0; w[i] && m <= 6; i++)
                if (w[i][0] && (m == 6 || !model_parse_double(w[i], &v[m++]))) m = 7;
            g_strfreev(w);
            if (m != 6) {
                g_strfreev(rn);
                return model_cli_error(c, "--camera-guess %s: give W,H,F,X,Y,Z (px, px, px, mm, mm, mm)",
                                       a->guesses.v[k]);
            }
            o->cams[k] = calib_geometry_plan_guess_camera((int)v[0], (int)v[1], v[2], v + 3);
        }
        if (!o->cams[k]) {
            g_strfreev(rn);
            return model_error_report("plan geometry");
        }
        o->ncams = k + 1;
    }
    g_strfreev(rn);
    return 0;
}

// The board: the lab file's [geometry], else the options (the example board by default).
static int board(model_cli_t *c, const args_t *a, calib_geometry_plan_opts_t *o, char **scene_path)
{
    double cw[2];
    int n = 0, rc;
    if (a->lab) {
        rig_lab_t *L = rig_lab_load(a->lab);
        if (!L) return model_error_report("plan geometry");
        o->corners_w = L->geometry.corners_w, o->corners_h = L->geometry.corners_h;
        o->square_mm = L->geometry.square_mm;
        *scene_path = L->geometry.board_scene ? g_strdup(L->geometry.board_scene) : NULL;
        rig_lab_free(L);
    }
    if ((rc = numbers(c, "--board-corners", cw, &n, 2, 2, 100))) return rc;
    if (n == 1 || (n == 2 && (cw[0] != floor(cw[0]) || cw[1] != floor(cw[1]))))
        return model_cli_error(c, "--board-corners: give W,H inner corners (whole numbers)");
    if (n == 2) o->corners_w = (int)cw[0], o->corners_h = (int)cw[1];
    if ((rc = model_cli_double(c, "--board-square-mm", &o->square_mm, 0, true, 1e4, NULL))) return rc;
    if (a->board) {
        g_free(*scene_path);
        *scene_path = g_strdup(a->board);
    }
    if (!*scene_path && !(*scene_path = model_share_path("examples", "samples/calib_board.d3d")))
        return model_error_report("plan geometry");
    if (!(o->board = model_scene_load(*scene_path, NULL))) return model_error_report("plan geometry");
    return 0;
}

static int options(model_cli_t *c, calib_geometry_plan_opts_t *o)
{
    int rc;
    double mv = o->max_views;
    if ((rc = numbers(c, "--wedges-deg", o->wedges_deg, &o->nwedges, CALIB_PLAN_MAX_WEDGES, 1, 80)) ||
        (rc = numbers(c, "--azimuths-deg", o->azimuths_deg, &o->nazimuths, CALIB_PLAN_MAX_WEDGES, -360, 360)) ||
        (rc = model_cli_double(c, "--angle-step-deg", &o->angle_step_deg, 0.5, false, 180, NULL)) ||
        (rc = model_cli_double(c, "--max-obliquity-deg", &o->max_obliquity_deg, 0, true, 89, NULL)) ||
        (rc = model_cli_double(c, "--margin-px", &o->margin_px, 0, false, 1e4, NULL)) ||
        (rc = model_cli_double(c, "--min-square-px", &o->min_square_px, 0, false, 1e4, NULL)) ||
        (rc = model_cli_double(c, "--max-views", &mv, 1, false, 1000, NULL)))
        return rc;
    o->max_views = (int)mv;
    return 0;
}

// The [geometry] section with the plan's figures in its comments.
static char *section(const calib_geometry_plan_opts_t *o, const calib_geometry_plan_t *p, char names[][64],
                     const char *board_scene, const args_t *a)
{
    GString *c = g_string_new("");
    g_string_append_printf(c, "refl plan geometry: %d board poses (of %d candidates, %d usable), the board %d x %d "
                           "inner corners of %g mm (%s)\n", p->nviews, p->ncandidates, p->nusable, o->corners_w,
                           o->corners_h, o->square_mm, board_scene);
    for (int k = 0; k < o->ncams; k++) {
        g_string_append_printf(c, "camera %s (%s): corners over %.1f %% of the imager (%.1f %% with every usable "
                               "pose), %d views", names[k], a->models.n ? a->models.v[k] : a->guesses.v[k],
                               100 * p->coverage[k], 100 * p->coverage_all[k], p->views[k]);
        if (k > 0) g_string_append_printf(c, " (%d shared with %s)", p->shared[k], names[0]);
        g_string_append(c, "\n  orientations:");
        for (int j = 0; j < 5; j++)
            g_string_append_printf(c, " %s %d%s", calib_geometry_plan_class_name(j), p->classes[k][j], j < 4 ? "," : "");
        g_string_append_printf(c, "; obliquity %.0f..%.0f deg; board centre %.0f..%.0f mm from the camera\n",
                               p->obliquity_min_deg[k], p->obliquity_max_deg[k], p->range_min_mm[k],
                               p->range_max_mm[k]);
        if (p->coverage[k] < 0.9)
            g_string_append_printf(c, "  WARNING: under 90 %% of the imager: bring the board closer (a larger "
                                   "board, the camera nearer), add wedges or allow more obliquity\n");
    }
    g_string_append(c, "Paste into the lab file (LAB.ini); refl calib geometry --tilts takes the tilts as they are.");
    rig_lab_geometry_t g = { .tilts = p->tilts, .corners_w = o->corners_w, .corners_h = o->corners_h,
                             .square_mm = o->square_mm, .height_mm = NAN, .exposure_us = NAN };
    double top = -INFINITY;
    for (int i = 0; i < o->board->nvertices; i++) top = fmax(top, o->board->vertices[i].z);
    g.height_mm = top;
    char *text = rig_lab_geometry_text(&g, c->str);
    g_string_free(c, TRUE);
    return text;
}

int calib_cmd_plan_geometry(int argc, char **argv)
{
    calib_geometry_plan_opts_t o = calib_geometry_plan_defaults();
    const char *mv[MAX_CAMS], *gv[MAX_CAMS];
    args_t a = { .models = { mv, 0, MAX_CAMS }, .guesses = { gv, 0, MAX_CAMS } };
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG.ini", "the rig file: its cameras (a model or guess each, in its order)",
                         &a.rig, false),
        MODEL_OPT_LIST("--camera-model", "FILE", "a camera's mrcal model (rig frame extrinsics); repeat per camera",
                       &a.models, false, false),
        MODEL_OPT_LIST("--camera-guess", "W,H,F,X,Y,Z", "a camera guessed: W x H px, focal length F px, centre X,Y,Z "
                       "mm (rig frame), looking at the turntable's top centre; repeat per camera", &a.guesses, false,
                       false),
        MODEL_OPT_STRING("--lab", "LAB.ini", "take the board's facts from this lab file's [geometry]", &a.lab, false),
        MODEL_OPT_STRING("--board-scene", "FILE", "the board's scene at angle 0, flat (default "
                         "examples/samples/calib_board.d3d)", &a.board, false),
        MODEL_OPT_VALUE("--board-corners", "W,H", "inner corners (default 10,10)", false),
        MODEL_OPT_VALUE("--board-square-mm", "S", "corner spacing (default 30)", false),
        MODEL_OPT_VALUE("--wedges-deg", "T,T,...", "the wedges' tilts at hand (default 20,35,50; flat is always tried)",
                        false),
        MODEL_OPT_VALUE("--azimuths-deg", "A,A,...", "hinge azimuths tried on each wedge (default 0,90,180,270)",
                        false),
        MODEL_OPT_VALUE("--angle-step-deg", "S", "turntable angles tried: every S deg (default 10)", false),
        MODEL_OPT_VALUE("--max-obliquity-deg", "D", "the board's normal at most D from the camera (default 60)",
                        false),
        MODEL_OPT_VALUE("--margin-px", "M", "the corners and half a square beyond them at least M px inside the "
                        "imager (default 10)", false),
        MODEL_OPT_VALUE("--min-square-px", "S", "its smallest square at least S px (default 12)", false),
        MODEL_OPT_VALUE("--max-views", "N", "views chosen per camera at most (default 30)", false),
        MODEL_OPT_STRING("--check-tilts", "SPEC", "instead: the coverage of these tilts ('T[@AZ]:A,A,... ...', as "
                         "calib geometry --tilts; each entry with its angles) and the views seen whole", &a.check,
                         false),
        MODEL_OPT_OUT("FILE", "write the [geometry] section to FILE (default: stdout)", &a.out, false),
    };
    model_cli_t cli = { .cmd = "plan geometry", .synopsis = "", .about = ABOUT, .epilog = EPILOG, .opts = opts,
                        .nopts = MODEL_NOPTS(opts) };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    char names[MAX_CAMS][64], *scene = NULL;
    bool q = model_error_quiet_thread(true);
    rc = options(&cli, &o);
    if (!rc) rc = cameras(&cli, &a, &o, names);
    if (!rc) rc = board(&cli, &a, &o, &scene);
    calib_geometry_plan_t p = { 0 };
    if (!rc && a.check) {
        double cov[MAX_CAMS];
        int views[MAX_CAMS];
        rc = calib_geometry_plan_coverage(&o, a.check, cov, views) ? 0 : model_error_report("plan geometry");
        for (int k = 0; !rc && k < o.ncams; k++)
            printf("camera %s: corners over %.1f %% of the imager, %d views seen whole\n", names[k], 100 * cov[k],
                   views[k]);
        a.check = rc ? a.check : NULL;
        rc = rc ? rc : -1;
    }
    if (!rc && !calib_geometry_plan(&o, &p)) rc = model_error_report("plan geometry");
    model_error_quiet_thread(q);
    if (rc < 0) rc = 0;
    else if (!rc) {
        char *text = section(&o, &p, names, scene, &a);
        if (a.out) {
            if (!model_write_file_atomic(a.out, text)) rc = model_error_report("plan geometry");
            else printf("refl plan geometry: %d poses, the [geometry] section in %s\n", p.nviews, a.out);
        } else {
            fputs(text, stdout);
        }
        g_free(text);
        for (int k = 0; k < o.ncams; k++)
            if (p.coverage[k] < 0.9)
                fprintf(stderr, "refl plan geometry: warning: camera %s: corners over %.1f %% of the imager, under "
                        "90 %%\n", names[k], 100 * p.coverage[k]);
    }
    calib_geometry_plan_free(&p);
    for (int k = 0; k < o.ncams; k++) model_camera_free((model_camera_t *)o.cams[k]);
    model_scene_free((model_scene_t *)o.board);
    g_free(scene);
    return rc;
}
