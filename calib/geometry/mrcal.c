// calib/geometry/mrcal.c — the solve: mrcal-calibrate-cameras on the corners (the
// corner order of several cameras made to agree first; a failed solve with
// partial views tried again), scripts/calib_geometry_report.py solution, and
// the solution's poses and camera into the state.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/geometry/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// Several cameras: mrgingham's corner order made to agree across the cameras
// of each frame (scripts/calib_geometry_report.py align) into
// DIR/corners-joint.vnl; views left out get their reason. false + message.
static bool align_corners(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **joint)
{
    char gn[32], sp[32], *spec[RIG_CAMERAS_MAX] = { 0 };
    snprintf(gn, sizeof gn, "%dx%d", o->board.width_n, o->board.height_n);
    snprintf(sp, sizeof sp, "%.9g", o->board.spacing_mm);
    for (int k = 0; k < RIG_CAMERAS_MAX; k++)
        if (k < s->ncams)
            spec[k] = g_strdup_printf("%s:%d:%d:%.6g", s->camnames[k], s->camw[k], s->camh[k],
                                      isfinite(o->focal_px) ? o->focal_px : 1.4 * s->camw[k]);
    *joint = g_strdup_printf("%s/corners-joint.vnl", s->outdir);
    char *ajson = g_strdup_printf("%s/align.json", s->mdir);
    model_note("making the corner order agree across the cameras");
    int e = model_run_script("calib_geometry_report.py", "align", s->cornpath, *joint, ajson, gn, sp, spec[0],
                             spec[1], spec[2], spec[3], spec[4], spec[5], spec[6], spec[7], NULL);
    for (int k = 0; k < RIG_CAMERAS_MAX; k++) g_free(spec[k]);
    json_error_t je;
    json_t *a = e == 0 ? json_load_file(ajson, 0, &je) : NULL;
    bool ok = a != NULL;
    if (e == 0 && !a) model_error_set(ajson, je.line, "cannot read: %s", je.text);
    else if (e != 0) model_error_set(s->cornpath, 0, "aligning the cameras' corner order failed (exit status %d)", e);
    if (ok && json_object_get(a, "error")) {
        model_error_set(s->cornpath, 0, "%s", json_string_value(json_object_get(a, "error")));
        ok = false;
    }
    const char *name;
    json_t *vj;
    json_object_foreach(ok ? json_object_get(a, "views") : NULL, name, vj) {
        calib_geometry_view_t *v = calib_geometry_view_find(&s->views, name);
        if (!v) continue;
        v->quarter_turns = (int)json_integer_value(json_object_get(vj, "quarter_turns"));
        if (json_is_true(json_object_get(vj, "dropped")))
            snprintf(v->why, sizeof v->why, "left out of the joint solve: no quarter turn of its corners agrees "
                     "with the other cameras' view of this board pose (%.1f deg off)",
                     json_real_value(json_object_get(vj, "mismatch_deg")));
    }
    json_decref(a);
    g_free(ajson);
    return ok;
}

bool calib_geometry_mrcal(const calib_geometry_opts_t *o, calib_geometry_state_t *s, const char *lensmodel,
                          const char *corners, const char *mdir, int nviews, json_t **sol)
{
    char focal[160], spacing[32], wn[16], hn[16], ws[16], hs[16];
    *sol = NULL;
    snprintf(focal, sizeof focal, "%.6g", isfinite(o->focal_px) ? o->focal_px : 1.4 * s->W);
    snprintf(spacing, sizeof spacing, "%.9g", o->board.spacing_mm);
    snprintf(wn, sizeof wn, "%d", o->board.width_n);
    snprintf(hn, sizeof hn, "%d", o->board.height_n);
    snprintf(ws, sizeof ws, "%d", s->W);
    snprintf(hs, sizeof hs, "%d", s->H);
    if (!model_mkdir_p(mdir)) return false;
    char *cwd = o->corners ? g_path_get_dirname(s->cornpath) : g_strdup(s->imgdir);
    char *argv_m[] = { "mrcal-calibrate-cameras", "--corners-cache", (char *)corners, "--lensmodel",
                       (char *)lensmodel, "--focal", focal, "--object-spacing", spacing, "--object-width-n", wn,
                       "--object-height-n", hn, "--imagersize", ws, hs, "--outdir", (char *)mdir, "*", NULL, NULL,
                       NULL, NULL, NULL, NULL, NULL, NULL };
    if (s->ncams > 1) {    // one glob and seed focal length per camera, each its own imager size
        GString *fl = g_string_new("");
        for (int k = 0; k < s->ncams; k++)
            g_string_append_printf(fl, "%s%.6g", k ? "," : "", isfinite(o->focal_px) ? o->focal_px : 1.4 * s->camw[k]);
        snprintf(focal, sizeof focal, "%s", fl->str);
        g_string_free(fl, TRUE);
        argv_m[13] = "--outdir";   // no --imagersize: each camera's own, from its images
        argv_m[14] = (char *)mdir;
        for (int k = 0; k < s->ncams; k++) argv_m[15 + k] = g_strdup_printf("%s/*.png", s->camnames[k]);
        argv_m[15 + s->ncams] = NULL;
    }
    if (s->no_outlier_rejection)   // after the globs: argparse takes options anywhere
        argv_m[s->ncams > 1 ? 15 + s->ncams : 19] = "--skip-outlier-rejection";
    // mrcal-calibrate-cameras runs under Debian's Python (its shebang)
    model_note("solving %s from %d views (mrcal-calibrate-cameras)", lensmodel, nviews);
    char *log = g_strdup_printf("%s/mrcal-calibrate-cameras.log", mdir);
    char *model0 = g_strdup_printf("%s/camera-0.cameramodel", mdir);
    unlink(model0);
    int e = model_run_tool(cwd, argv_m, log, NULL, GEO_INSTALL_HINT);
    g_free(cwd);
    if (s->ncams > 1)
        for (int k = 0; k < s->ncams; k++) g_free(argv_m[15 + k]);
    if (e != 0 || access(model0, R_OK) != 0) {
        if (e > 0) model_warning("%s", model_last_error());   // the tail of its messages
        if (e >= 0)   // else it did not run: model_run_tool's message says why
            model_error_set(mdir, 0, "mrcal-calibrate-cameras failed (exit status %d) on %s with %s; see %s (a bad "
                            "seed? give --focal-px)", e, corners, lensmodel, log);
        g_free(log);
        g_free(model0);
        return false;
    }
    g_free(log);
    char *solpath = g_strdup_printf("%s/solution.json", mdir), dist[32];
    snprintf(dist, sizeof dist, "%g", o->distance_mm);
    model_note("residuals and projection uncertainty (mrcal)");
    e = model_run_script("calib_geometry_report.py", "solution", model0, solpath, dist, NULL);
    g_free(model0);
    if (e == 0) {
        json_error_t je;
        *sol = json_load_file(solpath, 0, &je);
        if (!*sol) model_error_set(solpath, je.line, "cannot read: %s", je.text);
    } else {
        model_error_set(solpath, 0, "scripts/calib_geometry_report.py solution failed (exit status %d)", e);
    }
    g_free(solpath);
    return *sol != NULL;
}

// A solve that failed with partial views in it (a ChArUco board seen in part,
// whose corners mrcal's outlier rejection can thin until a view's pose or a
// lens parameter is no longer held: "not positive definite", "factorization
// computation failed") is tried again: first with every corner (mrcal's
// --skip-outlier-rejection; the outliers' residuals then weigh in, and the
// command says so), then without the partial views (their lines
// left out of a copy of the corners file, each such view told why). false +
// the first failure's message when there are none or every solve fails.
static bool solve_again(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    char *first = g_strdup(model_last_error());
    int N0 = o->board.width_n * o->board.height_n, np0 = 0;
    for (guint i = 0; i < s->views.v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
        np0 += v->found && !v->why[0] && v->ncorners < N0;
    }
    if (np0 > 0) {
        model_warning("the solve failed (%s); solving again with every corner (mrcal's "
                      "outlier rejection off)", first);
        s->no_outlier_rejection = true;
        json_decref(s->sol);
        s->sol = NULL;
        if (calib_geometry_mrcal(o, s, s->lensmodel, s->solvecorners, s->mdir, s->nfound, &s->sol)) {
            g_free(first);
            return true;
        }
        s->no_outlier_rejection = false;
    }
    int N = o->board.width_n * o->board.height_n, npart = 0;
    GHashTable *drop = g_hash_table_new(g_str_hash, g_str_equal);
    for (guint i = 0; i < s->views.v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
        if (v->found && !v->why[0] && v->ncorners < N) g_hash_table_add(drop, v->name), npart++;
    }
    bool ok = false;
    char *txt = NULL, *path = NULL;
    if (npart > 0 && s->nfound - npart >= 3 && g_file_get_contents(s->solvecorners, &txt, NULL, NULL)) {
        GString *out = g_string_new("");
        char **lines = g_strsplit(txt, "\n", -1);
        for (int k = 0; lines[k]; k++) {
            if (!lines[k][0]) continue;
            char name[512] = "";
            if (lines[k][0] != '#' && sscanf(lines[k], "%511s", name) == 1 && g_hash_table_contains(drop, name))
                continue;
            g_string_append_printf(out, "%s\n", lines[k]);
        }
        g_strfreev(lines);
        path = g_strdup_printf("%s/corners-whole-views.vnl", s->outdir);
        model_warning("the solve failed (%s); solving again without the %d partial views",
                      first, npart);
        ok = g_file_set_contents(path, out->str, (gssize)out->len, NULL);
        g_string_free(out, TRUE);
        json_decref(s->sol);
        s->sol = NULL;
        ok = ok && calib_geometry_mrcal(o, s, s->lensmodel, path, s->mdir, s->nfound - npart, &s->sol);
        if (ok) {
            for (guint i = 0; i < s->views.v->len; i++) {
                calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
                if (g_hash_table_contains(drop, v->name))
                    snprintf(v->why, sizeof v->why, "left out of the solve: a partial view (%d of %d corners), and "
                             "the solve with the partial views failed", v->ncorners, N);
            }
            g_free(s->solvecorners);
            s->solvecorners = path;
            path = NULL;
        }
    }
    if (!ok) model_error_set(NULL, 0, "%s", first);
    g_free(txt);
    g_free(path);
    g_free(first);
    g_hash_table_destroy(drop);
    return ok;
}

bool calib_geometry_solve(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    g_free(s->solvecorners);
    s->solvecorners = NULL;
    if (s->ncams > 1 && o->board.kind != CALIB_BOARD_CHARUCO) {   // the corner order made to agree across the
        if (!align_corners(o, s, &s->solvecorners)) return false;    // cameras first (ChArUco's corners have ids)
    } else {
        s->solvecorners = g_strdup(s->cornpath);
    }
    if (!s->lensmodel) s->lensmodel = g_strdup(calib_geometry_is_auto(o->lensmodel) ? CALIB_GEOMETRY_LEAN_LENSMODEL
                                                                                  : o->lensmodel);
    g_free(s->soldir);
    s->soldir = g_strdup(s->mdir);
    json_decref(s->sol);
    s->sol = NULL;
    if (calib_geometry_mrcal(o, s, s->lensmodel, s->solvecorners, s->mdir, s->nfound, &s->sol)) return true;
    return solve_again(o, s);
}

bool calib_geometry_apply_solution(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *jimgs = json_object_get(s->sol, "images"), *intr = json_object_get(s->sol, "intrinsics");
    size_t k;
    json_t *im;
    json_array_foreach(jimgs, k, im) {
        const char *path = json_string_value(json_object_get(im, "path"));
        calib_geometry_view_t *v = s->ncams > 1 ? NULL : calib_geometry_view_find(&s->views, path);
        for (guint i = 0; i < s->views.v->len && s->ncams > 1 && path; i++) {   // names differ by directory only
            calib_geometry_view_t *w = g_ptr_array_index(s->views.v, i);
            size_t ln = strlen(path), lw = strlen(w->name);
            if (ln >= lw && !strcmp(path + ln - lw, w->name) && (ln == lw || path[ln - lw - 1] == '/')) v = w;
        }
        if (!v) continue;
        json_t *rt = json_object_get(im, "rt_cam_board");
        for (int c = 0; c < 6; c++) v->rt_cam_board[c] = json_real_value(json_array_get(rt, c));
        v->solved = true;
        json_t *rms = json_object_get(im, "rms_px");
        v->rms_px = json_is_number(rms) ? json_number_value(rms) : NAN;
        v->outliers = (int)json_integer_value(json_object_get(im, "outliers"));
    }
    double *ip = malloc((json_array_size(intr) + 1) * sizeof *ip);
    if (!ip) {
        model_error_set(s->mdir, 0, "out of memory");
        return false;
    }
    for (k = 0; k < json_array_size(intr); k++) ip[k] = json_real_value(json_array_get(intr, k));
    double zero[6] = { 0 };
    model_camera_free(s->cam);
    s->cam = model_camera_new(s->lensmodel, ip, s->W, s->H, zero);
    free(ip);
    if (!s->cam) return false;
    s->rms_px = json_real_value(json_object_get(s->sol, "rms_px"));
    model_note("RMS reprojection residual %.4f px, %d outliers", s->rms_px,
               (int)json_integer_value(json_object_get(s->sol, "outliers")));
    return true;
}
