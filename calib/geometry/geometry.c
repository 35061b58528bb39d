// calib/geometry/geometry.c — the library of `refl calib geometry` (calib/geometry/geometry.h;
// the command is calib/cmd_geometry.c): the camera model (mrgingham corners,
// mrcal solve), the turntable axis from the board poses, and the camera's
// extrinsics in the rig frame.
//
// Flow: capture (one session per board tilt, all lamps on) or sessions /
// images / a corners file captured elsewhere → 8-bit copies of the frames in
// DIR/images (mrgingham reads 8-bit; frames are Mono12 in 16-bit PNG) →
// mrgingham --gridn N (a square chessboard) or OpenCV (calib/geometry/board_detect.h:
// any chessboard, ChArUco boards whole or in part) → DIR/corners.vnl (a corner
// a partial view does not show "nan nan -", as mrcal reads it) → mrcal-calibrate-cameras →
// DIR/mrcal/camera-0.cameramodel → scripts/calib_geometry_report.py solution
// (mrcal's board poses, residuals, projection uncertainty) → the axis fit and
// the rig frame here → DIR/camera.cameramodel, DIR/geometry.json,
// DIR/report.html.
//
// Here: calib_geometry_run, its stages in order, the axis stage's notes and
// the outputs stage. The stages live in views.c (the views and their 8-bit
// images), capture.c (--rig), corners.c, mrcal.c (the solve), diff.c
// (cross-validation and the lens model), axis.c (closed form), refine.c (the
// joint fit), frame.c (the rig frame), missing.c (why a view has no board),
// output.c (camera models, geometry.json), psf.c (the lens blur) and report.c.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/export.h"
#include "calib/geometry/internal.h"
#include "calib/geometry/psf.h"
#include "model/model.h"
#include "model/base/report.h"

// The camera frame itself is as uncertain as the principal point: a shift of
// (dcx, dcy) px turns every direction in it by about (dcy / fy, dcx / fx) rad.
// The axis direction's sigma (in the camera frame) gets that in quadrature
// (mrcal's 1-sigma of cx, cy from the solve; the fit's own kept apart).
static void axis_intrinsics_sigma(calib_geometry_state_t *s)
{
    calib_geometry_axis_t *ax = &s->axis;
    json_t *sd = json_object_get(s->sol, "intrinsics_core_stdev"), *in = json_object_get(s->sol, "intrinsics");
    ax->dir_unc_fit_deg = ax->dir_unc_deg;
    ax->dir_unc_intrinsics_deg = NAN;
    if (json_array_size(sd) != 4 || json_array_size(in) < 4) return;
    double ex = json_number_value(json_array_get(sd, 2)) / json_number_value(json_array_get(in, 0));
    double ey = json_number_value(json_array_get(sd, 3)) / json_number_value(json_array_get(in, 1));
    if (!isfinite(ex) || !isfinite(ey)) return;
    ax->dir_unc_intrinsics_deg = hypot(ex, ey) / DEG;
    ax->dir_unc_deg = hypot(ax->dir_unc_fit_deg, ax->dir_unc_intrinsics_deg);
}

// Stage 4: the axis, the rig frame and why views have no board. false +
// message only when out of memory (without an axis or a rig frame the run
// goes on, and says why).
static bool axis_and_rig_frame(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    calib_geometry_axis_t *ax = &s->axis;
    snprintf(s->rigwhy, sizeof s->rigwhy, "no turntable angles in the input (--images / --corners)");
    if (s->views.ngroups > 0) {
        model_note("fitting the turntable axis");
        model_error_clear();
        if (!calib_geometry_fit_axis(&s->views, &o->board, ax)) {
            if (*model_last_error()) return false;   // out of memory
            snprintf(s->rigwhy, sizeof s->rigwhy, "too few board poses at different angles of one tilt for the "
                     "axis (need 2 views 5..175 deg apart)");
            model_warning("no axis: %s", s->rigwhy);
        } else {
            model_note("the axis fitted with the board poses as turns about it (from the "
                       "closed form: direction +- %.4f deg)", ax->dir_unc_deg);
            if (!calib_geometry_refine_axis(&s->views, &o->board, s->cam, s->rms_px / sqrt(2), ax))
                model_warning("the joint axis fit failed (%s); the closed-form axis is kept",
                              model_last_error());
            else
                model_note("joint axis fit: %d views, corner RMS %.4f px (chi^2/dof %.2f)",
                           ax->joint_views, ax->joint_rms_px, ax->joint_chi2);
            axis_intrinsics_sigma(s);
            s->have_rig = calib_geometry_rig_frame(&s->views, o->board_height_mm, ax, s->rt_cam_rig, s->rigwhy,
                                                   sizeof s->rigwhy);
            if (!s->have_rig)
                model_warning("no rig frame: %s; the extrinsics are the camera's own frame",
                              s->rigwhy);
            model_note("axis direction (camera frame) %.6f %.6f %.6f +- %.4f deg, %d pairs, "
                       "off-axis rotation RMS %.4f deg", ax->a[0], ax->a[1], ax->a[2], ax->dir_unc_deg, ax->npairs,
                       ax->off_axis_rms_deg);
        }
    }
    if (!calib_geometry_explain_missing(&s->views, &o->board, ax->ok ? ax : NULL, s->cam, s->W, s->H)) return false;
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        bool same = !strcmp(v->name, v->source);   // the source named once
        if (!v->found)
            model_note("no board in %s%s%s%s: %s", v->name, same ? "" : " (",
                       same ? "" : v->source, same ? "" : ")", v->why);
    }
    return true;
}

// Stage 5: camera.cameramodel, geometry.json, the report.
static bool outputs(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    s->campath = g_strdup_printf("%s/camera.cameramodel", s->outdir);
    // each model written here gets mrcal's optimization_inputs (camera k's: the chosen solve's
    // camera-k.cameramodel) while keeping its extrinsics, so that mrcal's tools run on it (calib/geometry/export.c)
    char *m0 = g_strdup_printf("%s/camera-0.cameramodel", s->soldir);
    bool kept = calib_geometry_write_cameramodel(s->campath, s->lensmodel, json_object_get(s->sol, "intrinsics"), s->W,
                                                 s->H, s->rt_cam_rig, s->have_rig, s->rms_px) &&
                calib_export_keep_optimization_inputs(m0, s->campath);
    g_free(m0);
    if (!kept || !(s->out = calib_geometry_json(o, s))) return false;
    if (s->ncams > 1 && !geo_camera_outputs(o, s)) return false;
    if (!calib_psf_geometry(o, s)) return false;   // the lens's blur from the board's edges (calib/geometry/psf.c)
    for (int k = 0; k < s->ncams && s->ncams > 1 && kept; k++) {
        char *mk = g_strdup_printf("%s/camera-%d.cameramodel", s->soldir, k);
        char *pk = g_strdup_printf("%s/%s.cameramodel", s->outdir, s->camnames[k]);
        kept = calib_export_keep_optimization_inputs(mk, pk);
        g_free(mk);
        g_free(pk);
    }
    if (!kept) return false;
    char *jpath = g_strdup_printf("%s/geometry.json", s->outdir);
    bool ok = model_write_json(jpath, s->out) && calib_geometry_report(o, s, jpath);
    g_free(jpath);
    return ok;
}

calib_geometry_opts_t calib_geometry_defaults(void)
{
    return (calib_geometry_opts_t){ .lensmodel = "LENSMODEL_OPENCV8", .tilts = CALIB_GEOMETRY_DEFAULT_TILTS,
                                    .angles = CALIB_GEOMETRY_DEFAULT_ANGLES, .sample = "calib_board",
                                    .board = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = 10, .height_n = 10,
                                               .spacing_mm = 30, .marker_mm = 30 * CALIB_BOARD_DEFAULT_MARKER_RATIO,
                                               .dict = CALIB_BOARD_DEFAULT_DICT },
                                    .board_height_mm = 5, .exposure_us = 6000, .focal_px = NAN,
                                    .distance_mm = 900, .progress = 0 };
}

void calib_geometry_state_free(calib_geometry_state_t *s)
{
    calib_geometry_views_free(&s->views);
    json_decref(s->prov);
    free(s->outdir);
    g_free(s->imgdir);
    g_free(s->mdir);
    g_free(s->soldir);
    g_free(s->solvecorners);
    g_free(s->lensmodel);
    json_decref(s->xv);
    g_free(s->cornpath);
    g_strfreev(s->sessions);
    json_decref(s->sol);
    model_camera_free(s->cam);
    json_decref(s->axis.fit);
    g_free(s->campath);
    json_decref(s->out);
    memset(s, 0, sizeof *s);
}

void calib_geometry_result_free(calib_geometry_result_t *r)
{
    g_free(r->camera_model);
    g_free(r->outdir);
    memset(r, 0, sizeof *r);
}

bool calib_geometry_run(const calib_geometry_opts_t *o, calib_geometry_result_t *r)
{
    memset(r, 0, sizeof *r);
    calib_geometry_state_t s = { 0 };
    calib_geometry_views_init(&s.views);
    bool ok = false;
    s.prov = model_provenance(o->argc, o->argv);
    if (!model_mkdir_p(o->out)) goto done;
    s.outdir = realpath(o->out, NULL);
    s.imgdir = g_strdup_printf("%s/images", s.outdir);
    s.mdir = g_strdup_printf("%s/mrcal", s.outdir);
    if (!model_mkdir_p(s.imgdir) || !model_mkdir_p(s.mdir)) goto done;
    if (o->rig && (!model_provenance_input(s.prov, "rig", o->rig) || !calib_geometry_capture(o, &s, &r->usage)))
        goto done;
    if (!geo_collect_views(o, &s) || !calib_geometry_find_corners(o, &s) || !calib_geometry_solve(o, &s) ||
        !calib_geometry_apply_solution(o, &s) || !calib_geometry_validate_lens(o, &s))
        goto done;
    if (!axis_and_rig_frame(o, &s) || !outputs(o, &s)) goto done;
    r->camera_model = g_strdup(s.campath);
    r->outdir = g_strdup(s.outdir);
    r->rms_px = s.rms_px;
    r->have_rig = s.have_rig;
    ok = true;
done:
    calib_geometry_state_free(&s);
    return ok;
}
