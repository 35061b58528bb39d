// calib/geometry/output.c — the run's files: mrcal's .cameramodel (atomically),
// geometry.json's document, and with several cameras each camera's model and
// geometry.json's "cameras".
#include <errno.h>
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

static json_t *jarr(const double *x, int n)
{
    json_t *a = json_array();
    for (int i = 0; i < n; i++) json_array_append_new(a, json_real(x[i]));
    return a;
}

static bool write_cameramodel_ref(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                                  const double rt[6], const char *ref, double rms);

bool calib_geometry_write_cameramodel(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                              const double rt[6], bool rig, double rms)
{
    return write_cameramodel_ref(path, lensmodel, intr, W, H, rt,
                                 rig ? "the rig frame: origin on the fitted turntable axis at the table top, z up along "
                                       "the axis (counter-clockwise angles positive), x the board's grid direction at "
                                       "angle 0, tilt 0 closest to the image's +x"
                                     : "the camera itself (no turntable angles in the input: no rig frame)", rms);
}

// The model with the extrinsics' reference frame described by ref.
static bool write_cameramodel_ref(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                                  const double rt[6], const char *ref, double rms)
{
    char *tmp = g_strdup_printf("%s.part", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        model_error_set(path, 0, "cannot create: %s", strerror(errno));
        g_free(tmp);
        return false;
    }
    fprintf(f, "# refl calib geometry (refl %s): camera model from mrgingham corners and mrcal; RMS reprojection "
            "residual %.4f px.\n", REFL_VERSION, rms);
    fprintf(f, "# Units mm. extrinsics are rt_cam_ref (r in rad, t in mm) with ref = %s\n", ref);
    fprintf(f, "{\n    'lensmodel':  '%s',\n\n    # intrinsics are fx,fy,cx,cy,distortion0,distortion1,....\n"
            "    'intrinsics': [", lensmodel);
    size_t i;
    json_t *x;
    json_array_foreach(intr, i, x) fprintf(f, "%s%.17g,", i % 4 == 0 ? "\n        " : " ", json_real_value(x));
    fprintf(f, "\n    ],\n\n    # extrinsics are rt_fromref\n    'extrinsics': [");
    for (int k = 0; k < 6; k++) fprintf(f, " %.17g,", rt[k]);
    fprintf(f, " ],\n\n    'imagersize': [ %d, %d ],\n}\n", W, H);
    bool ok = !ferror(f);
    if (fclose(f) != 0) ok = false;
    if (ok && rename(tmp, path) != 0) ok = false;
    if (!ok) {
        model_error_set(path, 0, "cannot write: %s", strerror(errno));
        unlink(tmp);
    }
    g_free(tmp);
    return ok;
}

// The rig frame's 1-sigma from the axis fit: z (the axis direction), x (the
// tilt-0 board's turn about the axis), the origin across and along the axis,
// and what they make of the camera centre's position in the rig frame
// (sqrt(origin^2 + (distance x rotation)^2), rotation the two angles combined).
static json_t *rig_sigma_json(const calib_geometry_state_t *s)
{
    const calib_geometry_axis_t *ax = &s->axis;
    double inv[6], xs = ax->joint ? ax->rig_x_unc_deg : NAN, os = ax->joint ? ax->rig_origin_along_mm : NAN;
    geo_rt_invert(inv, s->rt_cam_rig);
    double d = norm3(&inv[3]), rot = hypot(ax->dir_unc_deg, isfinite(xs) ? xs : 0) * DEG;
    double o2 = ax->point_unc_mm * ax->point_unc_mm + (isfinite(os) ? os * os : 0);
    json_t *j = json_object();
    json_object_set_new(j, "z_direction_deg", json_real(ax->dir_unc_deg));
    json_object_set_new(j, "x_direction_deg", model_json_number(xs));
    json_object_set_new(j, "origin_across_axis_mm", json_real(ax->point_unc_mm));
    json_object_set_new(j, "origin_along_axis_mm", model_json_number(os));
    json_object_set_new(j, "camera_centre_mm", json_real(sqrt(o2 + d * d * rot * rot)));
    json_object_set_new(j, "note", json_string("1-sigma of the rig frame as the axis fit determines it (the "
                        "camera's intrinsics fixed); camera_centre_mm: sqrt(origin^2 + (distance x rotation)^2)"));
    return j;
}

// geometry.json: the axis (null without one).
static json_t *axis_json(const calib_geometry_state_t *s)
{
    const calib_geometry_axis_t *ax = &s->axis;
    if (!ax->ok) return json_null();
    json_t *aj = json_object();
    json_object_set_new(aj, "direction_cam", jarr(ax->a, 3));
    json_object_set_new(aj, "point_cam_mm", jarr(ax->c, 3));
    json_object_set_new(aj, "direction_uncertainty_deg", json_real(ax->dir_unc_deg));
    json_object_set_new(aj, "point_uncertainty_mm", json_real(ax->point_unc_mm));
    if (ax->joint) {
        json_object_set_new(aj, "method", json_string("fitted jointly with the board poses: each tilt group's board "
                            "one pose turned about the axis by the turntable's measured angles, fitted with the axis "
                            "to the observed corners (camera model fixed); the images' rt_cam_board are these poses"));
        json_object_set_new(aj, "uncertainty_note", json_string("1-sigma from the joint fit's covariance (corner "
                            "noise = mrcal's RMS residual / sqrt 2), scaled by chi^2/dof when above 1; the point: "
                            "RMS distance across the axis; the direction (in the camera frame) also carries the "
                            "principal point's 1-sigma from mrcal's solve (hypot(s_cx / fx, s_cy / fy)) in "
                            "quadrature"));
        json_object_set_new(aj, "joint_views", json_integer(ax->joint_views));
        json_object_set_new(aj, "direction_uncertainty_fit_deg", json_real(ax->dir_unc_fit_deg));
        json_object_set_new(aj, "direction_uncertainty_intrinsics_deg",
                            model_json_number(ax->dir_unc_intrinsics_deg));
        json_object_set_new(aj, "joint_rms_residual_px", json_real(ax->joint_rms_px));
        json_object_set_new(aj, "joint_chi2_per_dof", json_real(ax->joint_chi2));
    } else {
        json_object_set_new(aj, "method", json_string("closed form from the pairs of board poses (the joint fit "
                            "failed or was not run)"));
        json_object_set_new(aj, "uncertainty_note", json_string("approximate 1-sigma, from the scatter of the "
                            "pairwise estimates (direction) and of the point equations (point, across the axis)"));
    }
    json_object_set_new(aj, "off_axis_rms_deg", json_real(ax->off_axis_rms_deg));
    json_object_set_new(aj, "point_equation_rms_mm", json_real(ax->point_rms_mm));
    json_object_set_new(aj, "pairs", json_integer(ax->npairs));
    json_object_set_new(aj, "views", json_integer(ax->nviews));
    if (s->have_rig) {
        // in the rig frame the axis is +z through the origin, by construction
        json_object_set_new(aj, "direction_rig", json_pack("[fff]", 0.0, 0.0, 1.0));
        json_object_set_new(aj, "point_rig_mm", json_pack("[fff]", 0.0, 0.0, 0.0));
        json_object_set_new(aj, "rig_frame_sigma", rig_sigma_json(s));
    }
    json_object_set_new(aj, "fit", json_incref(ax->fit));
    return aj;
}

// geometry.json: the board (kind, corners, spacing; the detector and the least corners a view needs).
static json_t *board_json(const calib_geometry_opts_t *o)
{
    const calib_board_t *b = &o->board;
    int N = b->width_n * b->height_n, minc = o->min_corners > 0 ? o->min_corners : CALIB_GEOMETRY_MIN_CORNERS;
    json_t *j = json_pack("{s:s,s:i,s:i,s:f,s:f,s:f,s:s}", "kind", calib_board_kind_name(b->kind), "width_n",
                          b->width_n, "height_n", b->height_n, "spacing_mm", b->spacing_mm, "square_mm", b->spacing_mm,
                          "height_at_tilt0_mm", o->board_height_mm, "sample", o->sample);
    if (b->width_n == b->height_n) json_object_set_new(j, "gridn", json_integer(b->width_n));
    if (b->kind == CALIB_BOARD_CHARUCO) {
        json_object_set_new(j, "marker_mm", json_real(b->marker_mm));
        json_object_set_new(j, "dictionary", json_string(b->dict));
    }
    json_object_set_new(j, "detector", json_string(o->corners ? "corners file"
                        : calib_geometry_detector(o->detector, b) == CALIB_DETECTOR_MRGINGHAM ? "mrgingham" : "opencv"));
    if (!o->corners && calib_geometry_detector(o->detector, b) == CALIB_DETECTOR_OPENCV)
        json_object_set_new(j, "detectors_in_turn", b->kind == CALIB_BOARD_CHARUCO
                            ? json_pack("[s]", "opencv-charuco")
                            : json_pack("[sss]", "opencv-sb", "opencv-classic", "opencv-classic-normalised"));
    json_object_set_new(j, "min_corners", json_integer(minc > N ? N : minc < 4 ? 4 : minc));
    json_object_set_new(j, "frame", json_string("corner (i, j), i = 0..width_n-1, j = 0..height_n-1, at (i, j) "
                        "spacing_mm, z = 0 (mrcal's); corners.vnl lists corner (i, j) at j width_n + i"));
    return j;
}

// geometry.json: one view.
static json_t *view_json(const calib_geometry_state_t *s, const calib_geometry_view_t *v)
{
    json_t *im = json_object();
    json_object_set_new(im, "image", json_string(v->name));
    json_object_set_new(im, "source", json_string(v->source));
    if (s->ncams > 1) json_object_set_new(im, "camera", json_string(s->camnames[v->camera]));
    if (v->session) json_object_set_new(im, "session", json_string(v->session));
    if (isfinite(v->angle_deg)) json_object_set_new(im, "angle_deg", json_real(v->angle_deg));
    if (isfinite(v->tilt_deg)) {
        json_object_set_new(im, "tilt_deg", json_real(v->tilt_deg));
        json_object_set_new(im, "tilt_azimuth_deg", json_real(v->tilt_azimuth_deg));
    }
    json_object_set_new(im, "board_found", json_boolean(v->found));
    if (v->q) json_object_set_new(im, "corners_found", json_integer(v->ncorners));
    if (v->why[0]) json_object_set_new(im, "why", json_string(v->why));
    if (v->detector[0]) json_object_set_new(im, "detector", json_string(v->detector));
    if (v->attempts[0]) json_object_set_new(im, "detector_attempts", json_string(v->attempts));
    if (isfinite(v->rms_px)) {     // mrcal solved a pose for it
        json_object_set_new(im, "rms_residual_px", json_real(v->rms_px));
        json_object_set_new(im, "outliers", json_integer(v->outliers));
        json_object_set_new(im, "rt_cam_board", jarr(v->rt_cam_board, 6));
        json_object_set_new(im, "quarter_turns", json_integer(v->quarter_turns));
        if (s->have_rig && v->camera == 0) {
            double rt_rig_cam[6], rt_rig_board[6];
            geo_rt_invert(rt_rig_cam, s->rt_cam_rig);
            geo_rt_compose(rt_rig_board, rt_rig_cam, v->rt_cam_board);
            json_object_set_new(im, "rt_rig_board", jarr(rt_rig_board, 6));
        }
    }
    return im;
}

bool calib_geometry_json_check(const json_t *root, const char *path, int *version)
{
    return model_json_format_check(root, path, CALIB_GEOMETRY_JSON_FORMAT, CALIB_GEOMETRY_JSON_VERSION, version);
}

json_t *calib_geometry_json(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *sol = s->sol, *intr = json_object_get(sol, "intrinsics");
    json_t *out = json_object();
    model_json_set_format(out, CALIB_GEOMETRY_JSON_FORMAT, CALIB_GEOMETRY_JSON_VERSION);
    json_object_set_new(out, "units", json_string("lengths mm, angles deg (rotation vectors r in rad), pixels px with "
                                                  "(0, 0) the centre of the top-left pixel"));
    json_object_set_new(out, "camera_model", json_string(s->campath));
    model_camera_t *final = model_camera_load(s->campath);   // check it reads back
    if (!final) {
        json_decref(out);
        return NULL;
    }
    json_object_set_new(out, "camera_model_sha256", json_string(model_camera_sha256(final)));
    model_camera_free(final);
    json_object_set_new(out, "lensmodel", json_string(s->lensmodel));
    json_object_set_new(out, "intrinsics", json_incref(intr));
    json_object_set_new(out, "intrinsics_meaning", json_string("fx_px, fy_px, cx_px, cy_px, then the lens model's "
                                                               "distortion parameters (mrcal order)"));
    json_object_set_new(out, "imagersize_px", json_pack("[ii]", s->W, s->H));
    json_object_set_new(out, "rms_residual_px", json_real(s->rms_px));
    json_object_set_new(out, "views_used", json_integer(json_array_size(json_object_get(sol, "images"))));
    json_object_set_new(out, "views_total", json_integer(s->views.v->len));
    json_object_set_new(out, "points_used", json_incref(json_object_get(sol, "points")));
    json_object_set_new(out, "outliers", json_incref(json_object_get(sol, "outliers")));
    json_object_set_new(out, "projection_uncertainty", json_deep_copy(json_object_get(sol, "uncertainty")));
    json_object_set_new(out, "cross_validation", s->xv ? json_incref(s->xv) : json_null());
    json_object_set_new(out, "board", board_json(o));
    json_object_set_new(out, "rig_frame", json_string(s->have_rig
        ? "origin on the fitted turntable axis at the table top (board_height_mm below the board's corner plane at "
          "tilt 0); z up along the axis (counter-clockwise turntable angles positive seen from +z); x the board's "
          "grid direction at angle 0, tilt 0 closest to the image's +x, projected onto the table plane"
        : s->rigwhy));
    json_object_set_new(out, "rt_cam_rig", s->have_rig ? jarr(s->rt_cam_rig, 6) : json_null());
    if (s->have_rig) {
        double rt_rig_cam[6];
        geo_rt_invert(rt_rig_cam, s->rt_cam_rig);
        json_object_set_new(out, "camera_centre_rig_mm", jarr(&rt_rig_cam[3], 3));
    }
    json_object_set_new(out, "axis", axis_json(s));
    json_t *ims = json_array(), *missing = json_array();
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        json_array_append_new(ims, view_json(s, v));
        if (!v->found)
            json_array_append_new(missing, json_pack("{s:s,s:s,s:s}", "image", v->name, "source", v->source, "why",
                                                     v->why));
    }
    json_object_set_new(out, "images", ims);
    json_object_set_new(out, "images_without_board", missing);
    model_provenance_input(s->prov, "mrcal solution", s->campath);
    json_object_set_new(out, "provenance", json_incref(s->prov));
    return out;
}

// Several cameras: camera k's rt_cam_ref (the rig frame's, else camera 0's)
// from the joint solve's rt_camk_cam0.
static void camera_rt(const calib_geometry_state_t *s, json_t *cj, double rt[6])
{
    double rt_k0[6];
    json_t *e = json_object_get(cj, "rt_cam_cam0");
    for (int c = 0; c < 6; c++) rt_k0[c] = json_real_value(json_array_get(e, c));
    if (s->have_rig) geo_rt_compose(rt, rt_k0, s->rt_cam_rig);
    else memcpy(rt, rt_k0, sizeof rt_k0);
}

// Several cameras: DIR/NAME.cameramodel each, and geometry.json's "cameras".
bool geo_camera_outputs(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *cams = json_object_get(s->sol, "cameras"), *arr = json_array();
    bool ok = json_array_size(cams) == (size_t)s->ncams;
    if (!ok) model_error_set(s->mdir, 0, "the solution has %zu cameras, not %d", json_array_size(cams), s->ncams);
    for (int k = 0; k < s->ncams && ok; k++) {
        json_t *cj = json_array_get(cams, k), *c = json_object();
        double rt[6], inv[6];
        camera_rt(s, cj, rt);
        char *path = g_strdup_printf("%s/%s.cameramodel", s->outdir, s->camnames[k]);
        json_t *rms = json_object_get(cj, "rms_px");
        char ref[400];
        snprintf(ref, sizeof ref, "camera %s (the first camera; no rig frame: %s)", s->camnames[0], s->rigwhy);
        ok = s->have_rig ? calib_geometry_write_cameramodel(path, s->lensmodel, json_object_get(cj, "intrinsics"),
                                                            s->camw[k], s->camh[k], rt, true, json_number_value(rms))
                         : write_cameramodel_ref(path, s->lensmodel, json_object_get(cj, "intrinsics"), s->camw[k],
                                                 s->camh[k], rt, ref, json_number_value(rms));
        json_object_set_new(c, "name", json_string(s->camnames[k]));
        json_object_set_new(c, "camera_model", json_string(path));
        json_object_set_new(c, "intrinsics", json_incref(json_object_get(cj, "intrinsics")));
        json_object_set_new(c, "imagersize_px", json_pack("[ii]", s->camw[k], s->camh[k]));
        json_object_set_new(c, "rms_residual_px", json_incref(rms));
        json_object_set_new(c, "views_used", json_incref(json_object_get(cj, "observations")));
        json_object_set_new(c, "rt_cam_cam0", json_incref(json_object_get(cj, "rt_cam_cam0")));
        const char *keys[] = { "rt_cam_cam0_stdev", "rotation_stdev_deg", "translation_stdev_mm" };
        for (int i = 0; i < 3; i++)
            if (json_object_get(cj, keys[i])) json_object_set_new(c, keys[i], json_incref(json_object_get(cj, keys[i])));
        json_object_set_new(c, "rt_cam_rig", s->have_rig ? jarr(rt, 6) : json_null());
        if (s->have_rig) {
            geo_rt_invert(inv, rt);
            json_object_set_new(c, "camera_centre_rig_mm", jarr(&inv[3], 3));
        }
        json_object_set_new(c, "projection_uncertainty", json_incref(json_object_get(cj, "uncertainty")));
        json_array_append_new(arr, c);
        g_free(path);
    }
    json_object_set_new(s->out, "cameras_note", json_string("several cameras calibrated in one mrcal solve; "
                        "rt_cam_cam0: each camera's pose relative to the first (rt_camk_cam0, r rad, t mm) with its "
                        "1-sigma from the solve; rt_cam_rig = rt_cam_cam0 composed with the first camera's "
                        "rt_cam_rig (the rig frame from the first camera's views)"));
    json_object_set_new(s->out, "cameras", arr);
    return ok;
}
