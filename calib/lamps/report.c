// calib/lamps/report.c — stage 6 of the calibration (calib_lamps_write_report):
// report_data.json (rays, fits, one angle's detections), its plots
// (scripts/calib_lamps_report.py) and report.html.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/report.h"

// report_data.json's detections: at the first angle with a ray, the per-pixel
// maximum over the lamp frames (dark subtracted) around the sphere's image and
// the highlights found. *out NULL when there is nothing to show; false (message
// set) when out of memory.
static bool detections_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, json_t **out)
{
    const int a = r->first_angle, W = model_camera_width(r->cam);
    *out = NULL;
    if (a < 0) return true;
    const double ang = r->angle_deg[a];
    calib_lamps_sphere_image_t *sph = calib_lamps_sphere_image(r->cam, lamps_centre_at(o->sphere_centre_mm, ang),
                                                               o->sphere_radius_mm);
    if (!sph) return true;
    float *acc = calloc((size_t)sph->w * sph->h, sizeof *acc);
    if (!acc) {
        calib_lamps_sphere_image_free(sph);
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    float *dark = r->dark_row[a] >= 0 ? lamps_load_frame(o, r, r->dark_row[a]) : NULL;
    json_t *det = json_array(), *crop = json_array();
    for (int l = 0; l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        int fr = lp->frame[a], w = 0, h = 0;
        if (fr < 0) continue;
        float *img = rig_session_frame(r->session, fr, &w, &h);
        if (!img) continue;
        for (int y = 0; y < sph->h; y++)
            for (int x = 0; x < sph->w; x++) {
                size_t k = (size_t)(sph->y0 + y) * W + sph->x0 + x;
                float v = img[k] - (dark ? dark[k] : 0);
                if (v > acc[y * sph->w + x]) acc[y * sph->w + x] = v;
            }
        free(img);
        const calib_lamps_highlight_t *hl = &lp->hl[a];
        json_array_append_new(det, json_pack("{s:s,s:s,s:b,s:[ff],s:f}", "lamp", lp->name, "file",
                                             r->session->rows[fr].file, "found", hl->found, "q", hl->q[0], hl->q[1],
                                             "peak_dn", hl->peak_dn));
    }
    for (int i = 0; i < sph->w * sph->h; i++) json_array_append_new(crop, model_json_number(acc[i]));
    *out = json_pack("{s:f,s:i,s:i,s:i,s:i,s:o,s:o,s:[ff],s:f}", "angle_deg", ang, "x0", sph->x0, "y0",
                            sph->y0, "w", sph->w, "h", sph->h, "crop", crop, "highlights", det, "sphere_q",
                            sph->q_centre[0], sph->q_centre[1], "sphere_radius_px", sph->radius_px);
    free(acc);
    free(dark);
    calib_lamps_sphere_image_free(sph);
    return true;
}

// report_data.json for the plotting script: rays, fits, one angle's
// detections. NULL + message when out of memory.
static json_t *report_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r)
{
    json_t *rep = json_object(), *rl = json_array();
    model_json_set_format(rep, "refl-lamps-report-data", 1);
    for (int l = 0; l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
        json_t *j = json_object(), *rays = json_array();
        json_object_set_new(j, "name", json_string(lp->name));
        json_object_set_new(j, "position_mm", json_pack("[fff]", x[0], x[1], x[2]));
        json_object_set_new(j, "std_mm", json_pack("[fff]", sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8])));
        for (int a = 0; a < r->nangles; a++) {
            if (!lp->has_ray[a]) continue;
            const calib_lamps_highlight_t *hl = &lp->hl[a];
            const model_vec3_t p = lp->p_mm[a], d = lp->d[a];
            json_array_append_new(rays, json_pack("{s:[fff],s:[fff],s:b,s:f,s:f,s:s,s:[ff],s:[ff],s:f,s:b}", "p",
                                                  p.x, p.y, p.z, "d", d.x, d.y, d.z, "used", lp->used[a], "dist_mm",
                                                  lp->dist_mm[a], "angle_deg", r->angle_deg[a], "file",
                                                  r->session->rows[lp->frame[a]].file, "q", hl->q[0], hl->q[1],
                                                  "q_centroid", hl->q_centroid[0], hl->q_centroid[1], "peak_dn",
                                                  hl->peak_dn, "fit_used", hl->fit_used));
        }
        json_object_set_new(j, "rays", rays);
        json_array_append_new(rl, j);
    }
    json_object_set_new(rep, "lamps", rl);
    json_t *det;
    if (!detections_json(o, r, &det)) {
        json_decref(rep);
        return NULL;
    }
    if (det) json_object_set_new(rep, "detections", det);
    model_vec3_t Cw = model_camera_centre_world(r->cam);
    const double *c0 = o->sphere_centre_mm;
    json_object_set_new(rep, "camera_centre_mm", json_pack("[fff]", Cw.x, Cw.y, Cw.z));
    json_object_set_new(rep, "sphere_centre_angle0_mm", json_pack("[fff]", c0[0], c0[1], c0[2]));
    json_object_set_new(rep, "sphere_radius_mm", model_json_number(o->sphere_radius_mm));
    if (r->have_joint) {
        const double *g = r->joint.sphere, *gc = r->joint.sphere_cov;
        json_object_set_new(rep, "sphere_joint_fit", json_pack("{s:[fff],s:[ff],s:[ff],s:[fffffff]}", "offset_mm",
                                                               g[0], g[1], g[2], "shift_mm", g[3], g[4], "tilt_mrad",
                                                               g[5], g[6], "std", sqrt(gc[0]), sqrt(gc[8]),
                                                               sqrt(gc[16]), sqrt(gc[24]), sqrt(gc[32]),
                                                               sqrt(gc[40]), sqrt(gc[48])));
    }
    return rep;
}

// report.html's table: one row per lamp. false when out of memory.
static bool report_table(FILE *f, const calib_lamps_result_t *r)
{
    const char **rows = calloc((size_t)r->nlamps + 1, sizeof *rows);
    if (!rows) return false;
    for (int l = 0; l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
        rows[l] = g_strdup_printf("%s|%.2f|%.2f|%.2f|%.2f / %.2f / %.2f|%.2f|%d of %d|%d", lp->name, x[0], x[1],
                                  x[2], sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8]), lp->fit.rms_mm, lp->fit.n_used,
                                  r->nangles, lp->nmissing);
    }
    model_html_table(f, "lamp|x mm|y mm|z mm|std x / y / z mm|RMS ray distance mm|rays used|frames missing", rows,
                     r->nlamps);
    for (int l = 0; l < r->nlamps; l++) g_free((char *)rows[l]);
    free(rows);
    return true;
}

static bool report_html(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, const char *path)
{
    const double *c0 = o->sphere_centre_mm, *g = r->joint.sphere, *gc = r->joint.sphere_cov;
    FILE *f = model_html_begin(path, "refl calib lamps: lamp positions", r->provenance);
    if (!f) return false;
    model_html_heading(f, "Lamp positions");
    model_html_para(f, "Mirror sphere '%s': radius %g mm, centre (%g, %g, %g) mm at turntable angle 0 (rig frame); "
                    "%d angles. Each highlight's camera ray is reflected off the sphere into a ray toward the lamp; "
                    "the lamp is the least-squares point nearest its rays (outliers beyond 4 robust sigma dropped); "
                    "std from the ray residuals.", r->plan->sample, o->sphere_radius_mm, c0[0], c0[1], c0[2],
                    r->nangles);
    if (r->have_joint)
        model_html_para(f, "Joint fit of the lamps and the sphere's path over every highlight (the camera model's "
                        "extrinsics error moves the sphere relative to the camera; a tenth of a millimetre there is "
                        "millimetres at the lamps): centre at angle a = s0 + tilt x s0 + shift, s0 = Rz(a) (centre + "
                        "offset). Offset %.3f %.3f %.3f mm (std %.3f %.3f %.3f), shift %.3f %.3f mm (std %.3f %.3f), "
                        "tilt %.3f %.3f mrad (std %.3f %.3f); priors (std) offset %g mm, shift %g mm, tilt %g mrad. "
                        "Residuals are angles of the highlights' camera rays; the std of each lamp includes the "
                        "path's uncertainty.", g[0], g[1], g[2], sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]), g[3], g[4],
                        sqrt(gc[24]), sqrt(gc[32]), g[5], g[6], sqrt(gc[40]), sqrt(gc[48]), o->offset_prior_mm,
                        o->shift_prior_mm, o->tilt_prior_mrad);
    if (r->have_joint && r->have_typed) {
        const double *fm = r->found_mm, *t = r->typed_mm, *fc = r->found_cov_mm2;
        model_html_para(f, "The sphere's centre from its highlights across the angles: (%.3f, %.3f, %.3f) mm (std "
                        "%.3f %.3f %.3f), typed (%g, %g, %g) mm, %.2f mm apart; %d round%s of highlights (found again "
                        "at the moved centre while it moved by more than 0.2 mm).", fm[0], fm[1], fm[2], sqrt(fc[0]),
                        sqrt(fc[4]), sqrt(fc[8]), t[0], t[1], t[2],
                        sqrt(pow(fm[0] - t[0], 2) + pow(fm[1] - t[1], 2) + pow(fm[2] - t[2], 2)), r->rounds,
                        r->rounds == 1 ? "" : "s");
    }
    bool table = report_table(f, r);
    for (int l = 0; l < r->nlamps; l++) {
        if (!r->lamps[l].nmissing) continue;
        char *t = lamps_missing_text(r, &r->lamps[l]);
        model_html_para(f, "Lamp %s: no highlight in:\n%s", r->lamps[l].name, t);
        g_free(t);
    }
    model_html_figure(f, "lamps_triangulation.png", "Triangulation: the rays reflected off the sphere (one per "
                      "turntable angle; grey: left out as outliers) and the fitted lamp positions (x), top (x-y) "
                      "and side (x-z, y-z) views, mm, rig frame; ray residuals");
    model_html_figure(f, "lamps_detections.png", "Highlight detections at the first angle: the per-pixel maximum "
                      "of every lamp's frame minus dark around the sphere's predicted image (circle), the found "
                      "highlights marked");
    bool ok = model_html_end(f, path);
    if (ok && !table) model_error_set(path, 0, "out of memory");
    return ok && table;
}

bool calib_lamps_write_report(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (!lamps_provenance(o, r)) return false;
    json_t *rep = report_json(o, r);
    if (!rep) return false;
    char *path = g_strdup_printf("%s/report_data.json", o->out);
    char *png1 = g_strdup_printf("%s/lamps_triangulation.png", o->out);
    char *png2 = g_strdup_printf("%s/lamps_detections.png", o->out);
    char *html = g_strdup_printf("%s/report.html", o->out);
    bool ok = model_write_json(path, rep);
    if (ok) {
        model_note("plotting");
        ok = model_run_script("calib_lamps_report.py", path, png1, png2, NULL) == 0;
    }
    if (ok) ok = report_html(o, r, html);
    if (ok) model_note("wrote %s", html);
    json_decref(rep);
    g_free(path);
    g_free(png1);
    g_free(png2);
    g_free(html);
    return ok;
}
