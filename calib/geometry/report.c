// calib/geometry/report.c — DIR/report.html: the plots of scripts/calib_geometry_report.py
// and the camera model, cross-validation, lens blur, cameras, axis and the
// views: who found the board in each, and why a view was refused.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/geometry/internal.h"
#include "calib/geometry/psf.h"
#include "model/model.h"
#include "model/base/report.h"

// The report's cross-validation section: each run's figures, the lens choice.
static void report_crossvalidation(FILE *f, const calib_geometry_state_t *s)
{
    json_t *x = s->xv;
    if (!x) return;
    model_html_heading(f, "Cross-validation and the lens model");
    model_html_para(f, "Method: %s. Criterion: %s.", json_string_value(json_object_get(x, "method")),
                    json_string_value(json_object_get(x, "criterion")));
    GPtrArray *rows = g_ptr_array_new_with_free_func(g_free);
    json_t *runs = json_object_get(x, "runs"), *r;
    size_t i;
    json_t *all = json_array();
    json_array_foreach(runs, i, r) json_array_append(all, r);
    if (json_object_get(x, "lean_vs_splined")) json_array_append(all, json_object_get(x, "lean_vs_splined"));
    json_array_foreach(all, i, r) {
        const char *what = json_object_get(r, "lensmodel") ? json_string_value(json_object_get(r, "lensmodel"))
                                                           : "lean against the splined fit of the same views";
        if (!json_is_true(json_object_get(r, "done")) && json_object_get(r, "lensmodel")) {
            g_ptr_array_add(rows, g_strdup_printf("%s|not done: %s||||", what,
                                                  json_string_value(json_object_get(r, "why"))));
            continue;
        }
        json_t *c;
        size_t k;
        json_array_foreach(json_object_get(r, "cameras"), k, c) {
            json_t *o = json_object_get(c, "observed");
            g_ptr_array_add(rows, g_strdup_printf("%s%s%s|%.4f / %.4f|%.4f / %.4f|%.2f|%s", what,
                            json_object_get(c, "camera") ? ", camera " : "",
                            json_object_get(c, "camera") ? json_string_value(json_object_get(c, "camera")) : "",
                            json_number_value(json_object_get(o, "diff_rms_px")),
                            json_number_value(json_object_get(o, "diff_worst_px")),
                            json_number_value(json_object_get(o, "predicted_rms_px")),
                            json_number_value(json_object_get(o, "predicted_worst_px")),
                            json_number_value(json_object_get(o, "ratio_rms")),
                            json_number_value(json_object_get(o, "ratio_rms")) <= CALIB_GEOMETRY_XV_MAX_RATIO
                                ? "passes" : "FAILS"));
        }
    }
    json_decref(all);
    model_html_table(f, "comparison|difference RMS / worst (px)|predicted s0 + s1 RMS / worst (px)|ratio|verdict",
                     (const char *const *)rows->pdata, (int)rows->len);
    char *png = g_strdup_printf("%s/crossvalidation.png", s->outdir);
    if (access(png, R_OK) == 0)
        model_html_figure(f, "crossvalidation.png", "the two halves' calibrations against each other (first camera): "
                          "|difference| / (s0 + s1) over the imager (top) and the projection difference in px "
                          "(bottom)");
    g_free(png);
    g_ptr_array_free(rows, TRUE);
    model_html_para(f, "Lens model: %s.",
                    json_string_value(json_object_get(json_object_get(x, "lens_choice"), "why")));
}

// The views: who found the board in each (the detector, its corners) and,
// for a view not used, why, with each detector's outcome.
static void report_views_table(FILE *f, const calib_geometry_state_t *s)
{
    model_html_heading(f, "Views: who found the board");
    GPtrArray *rows = g_ptr_array_new_with_free_func(g_free);
    int used = 0;
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        used += v->found;
        char rms[32] = "";
        if (isfinite(v->rms_px)) snprintf(rms, sizeof rms, "%.3f", v->rms_px);
        g_ptr_array_add(rows, g_strdup_printf("%s|%s|%s|%d|%s|%s%s%s", v->name, v->found ? "used" : "refused",
                                              v->detector[0] ? v->detector : "none", v->ncorners, rms, v->why,
                                              v->why[0] && v->attempts[0] && !strstr(v->why, v->attempts) ? "; " : "",
                                              strstr(v->why, v->attempts) ? "" : v->attempts));
    }
    model_html_para(f, "The board was used in %d of %u views; the detectors tried in turn and each one's outcome "
                    "(a view refused: why).", used, s->views.v->len);
    model_html_table(f, "image|view|found by|corners|RMS residual (px)|why / detectors' outcomes",
                     (const char *const *)rows->pdata, (int)rows->len);
    g_ptr_array_free(rows, TRUE);
}

// A figure of the plots script when it wrote it (it leaves out what it cannot draw, e.g. without mrcal).
static void report_figure_if(FILE *f, const char *outdir, const char *png, const char *caption)
{
    char *p = g_strdup_printf("%s/%s", outdir, png);
    if (access(p, R_OK) == 0) model_html_figure(f, png, caption);
    g_free(p);
}

bool calib_geometry_report(const calib_geometry_opts_t *o, const calib_geometry_state_t *s, const char *jpath)
{
    const calib_geometry_axis_t *ax = &s->axis;
    json_t *sol = s->sol, *intr = json_object_get(sol, "intrinsics");
    char *solpath = g_strdup_printf("%s/solution.json", s->soldir);
    char *hpath = g_strdup_printf("%s/report.html", s->outdir);
    model_note("plots");
    bool ok = model_run_script("calib_geometry_report.py", "plots", jpath, solpath, s->outdir, NULL) == 0;
    FILE *f = ok ? model_html_begin(hpath, "refl calib geometry", s->prov) : NULL;
    if (f) {
        int outliers = (int)json_integer_value(json_object_get(sol, "outliers"));
        model_html_heading(f, "Camera model");
        model_html_para(f, "%s, %dx%d px; %zu of %u views used; RMS reprojection residual %.4f px; %d outliers "
                        "of %d points.", s->lensmodel, s->W, s->H, json_array_size(json_object_get(sol, "images")),
                        s->views.v->len, s->rms_px, outliers,
                        (int)json_integer_value(json_object_get(sol, "points")) + outliers);
        const calib_board_t *bd = &o->board;
        char marker[96] = "";
        if (bd->kind == CALIB_BOARD_CHARUCO)
            snprintf(marker, sizeof marker, ", markers %g mm of %s", bd->marker_mm, bd->dict);
        model_html_para(f, "Board: %s of %d x %d inner corners %g mm apart%s; corners by %s.",
                        calib_board_kind_name(bd->kind), bd->width_n, bd->height_n, bd->spacing_mm, marker,
                        o->corners ? "the corners file" : calib_geometry_detector(o->detector, bd) ==
                        CALIB_DETECTOR_MRGINGHAM ? "mrgingham" : "OpenCV");
        model_html_para(f, "Intrinsics fx, fy, cx, cy: %.3f, %.3f, %.3f, %.3f px.",
                        json_real_value(json_array_get(intr, 0)), json_real_value(json_array_get(intr, 1)),
                        json_real_value(json_array_get(intr, 2)), json_real_value(json_array_get(intr, 3)));
        model_html_figure(f, "residuals_vectors.png", "Reprojection residuals over the imager");
        model_html_figure(f, "residuals_histogram.png", "Distribution of the residuals");
        model_html_figure(f, "residuals_per_image.png", "RMS residual per image");
        report_figure_if(f, s->outdir, "worst_views.png", "The three images with the largest RMS residual: observed "
                         "corners and their residuals over the image");
        report_figure_if(f, s->outdir, "distortion.png", "Lens distortion: how far the model moves each pixel from "
                         "the pinhole of the same fx, fy, cx, cy, with the valid-intrinsics region");
        json_t *u = json_object_get(sol, "uncertainty");
        if (json_object_get(u, "max_px")) {
            model_html_heading(f, "Projection uncertainty");
            model_html_para(f, "mrcal.projection_uncertainty (worst direction, 1 sigma) at %g mm: centre %.4f px, "
                            "median %.4f px, max %.4f px over the imager.", o->distance_mm,
                            json_real_value(json_object_get(u, "centre_px")),
                            json_real_value(json_object_get(u, "median_px")),
                            json_real_value(json_object_get(u, "max_px")));
            model_html_figure(f, "uncertainty.png", "Projection uncertainty (dots: observed corners)");
        }
        report_crossvalidation(f, s);
        calib_psf_report(f, s);
        json_t *cams = json_object_get(s->out, "cameras");
        if (json_array_size(cams) > 1) {
            model_html_heading(f, "Cameras (one joint solve)");
            size_t k;
            json_t *c;
            json_array_foreach(cams, k, c) {
                json_t *ci = json_object_get(c, "intrinsics"), *rel = json_object_get(c, "rt_cam_cam0");
                model_html_para(f, "%s: %s, %lld views, RMS %.4f px; fx, fy, cx, cy %.3f, %.3f, %.3f, %.3f px; pose "
                                "relative to %s rt %.6f %.6f %.6f rad, %.3f %.3f %.3f mm (1-sigma %.4f deg, %.3f mm).",
                                json_string_value(json_object_get(c, "name")),
                                json_string_value(json_object_get(c, "camera_model")),
                                json_integer_value(json_object_get(c, "views_used")),
                                json_number_value(json_object_get(c, "rms_residual_px")),
                                json_real_value(json_array_get(ci, 0)), json_real_value(json_array_get(ci, 1)),
                                json_real_value(json_array_get(ci, 2)), json_real_value(json_array_get(ci, 3)),
                                s->camnames[0], json_real_value(json_array_get(rel, 0)),
                                json_real_value(json_array_get(rel, 1)), json_real_value(json_array_get(rel, 2)),
                                json_real_value(json_array_get(rel, 3)), json_real_value(json_array_get(rel, 4)),
                                json_real_value(json_array_get(rel, 5)),
                                json_real_value(json_object_get(c, "rotation_stdev_deg")),
                                json_real_value(json_object_get(c, "translation_stdev_mm")));
            }
        }
        model_html_heading(f, "Turntable axis and rig frame");
        if (ax->ok) {
            model_html_para(f, "Axis direction (camera frame) %.6f %.6f %.6f, +- %.4f deg; point %.2f %.2f %.2f mm "
                            "+- %.3f mm across the axis (1 sigma, %s); %d pose pairs; off-axis rotation RMS of mrcal's "
                            "free poses %.4f deg.", ax->a[0], ax->a[1], ax->a[2], ax->dir_unc_deg, ax->c[0], ax->c[1],
                            ax->c[2], ax->point_unc_mm, ax->joint ? "fitted jointly with the board poses as turns "
                            "about it" : "closed form, approximate", ax->npairs, ax->off_axis_rms_deg);
            if (ax->joint)
                model_html_para(f, "Joint fit: %d views, corner RMS %.4f px (chi^2/dof %.2f). Rig frame 1 sigma: z "
                                "%.4f deg, x %.4f deg, origin %.3f mm across and %.3f mm along the axis.",
                                ax->joint_views, ax->joint_rms_px, ax->joint_chi2, ax->dir_unc_deg, ax->rig_x_unc_deg,
                                ax->point_unc_mm, ax->rig_origin_along_mm);
            model_html_figure(f, "axis_fit.png", "Board rotation about the fitted axis against the turntable angle");
        } else {
            model_html_para(f, "No axis: %s.", s->rigwhy);
        }
        model_html_para(f, "Rig frame: %s.", json_string_value(json_object_get(s->out, "rig_frame")));
        report_views_table(f, s);
        ok = model_html_end(f, hpath);
    } else {
        ok = false;
    }
    g_free(solpath);
    g_free(hpath);
    return ok;
}
