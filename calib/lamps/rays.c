// calib/lamps/rays.c — stage 2 of the calibration (calib_lamps_find_highlights):
// per angle the sphere's image, per lamp its highlight in its frame and the
// ray toward the lamp; the rays again with the lamp's disk; the frames
// without a ray, as a list for the messages and the outputs.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

model_vec3_t lamps_centre_at(const double c0[3], double angle_deg)
{
    double th = angle_deg * M_PI / 180;
    return v3(cos(th) * c0[0] - sin(th) * c0[1], sin(th) * c0[0] + cos(th) * c0[1], c0[2]);
}

float *lamps_load_frame(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, int row)
{
    int w = 0, h = 0, W = model_camera_width(r->cam), H = model_camera_height(r->cam);
    float *img = rig_session_frame(r->session, row, &w, &h);
    if (img && (w != W || h != H)) {
        model_error_set(NULL, 0, "%s/%s: %dx%d pixels, the camera model %s has %dx%d", r->session_dir,
                        r->session->rows[row].file, w, h, o->camera, W, H);
        free(img);
        img = NULL;
    }
    return img;
}

// Lamp lp's highlight at angle a in its frame and the ray toward it: the
// direction-space model (pass 1: a point lamp), else the reflection at the
// sub-pixel position. false (message set) only when the frame cannot be read
// or out of memory.
static bool lamp_ray(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp, int a,
                     const calib_lamps_sphere_image_t *sph, const float *dark)
{
    int fr = lp->frame[a];
    calib_lamps_highlight_t *hl = &lp->hl[a];
    float *img = lamps_load_frame(o, r, fr);
    if (!img) return false;
    double fs = lamps_full_scale(r->session->rows[fr].pixel_format);
    bool mem = calib_lamps_find_highlight(img, dark, model_camera_width(r->cam), model_camera_height(r->cam), sph,
                                          o->min_snr, 0.02 * fs, 40, fs, hl);
    free(img);
    if (!mem) return false;
    if (!hl->found) return true;
    bool ok = false;
    if (o->method == CALIB_LAMPS_MODEL) {
        bool q = model_error_quiet_thread(true);
        ok = calib_lamps_fit_direction(r->cam, hl, r->centre_mm[a], o->sphere_radius_mm, 0, &lp->p_mm[a], &lp->d[a],
                                       NULL);
        model_error_quiet_thread(q);
    }
    if (!ok && o->method == CALIB_LAMPS_CENTROID) {
        hl->q[0] = hl->q_centroid[0];
        hl->q[1] = hl->q_centroid[1];
    }
    if (!ok && !calib_lamps_reflect(r->cam, hl->q, r->centre_mm[a], o->sphere_radius_mm, &lp->p_mm[a], &lp->d[a])) {
        hl->found = false;
        snprintf(hl->why, sizeof hl->why, "%s", model_last_error());
    } else {
        lp->has_ray[a] = lp->used[a] = true;
    }
    return true;
}

// Every lamp's highlight at angle a.
static bool angle_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r, int a)
{
    double ang = r->angle_deg[a];
    r->centre_mm[a] = lamps_centre_at(o->sphere_centre_mm, ang);
    model_progress("angle %d/%d (%.3f deg): finding highlights", a + 1, r->nangles, ang);
    calib_lamps_sphere_image_t *sph = calib_lamps_sphere_image(r->cam, r->centre_mm[a], o->sphere_radius_mm);
    if (!sph) {
        model_error_set(NULL, 0, "angle %.3f deg: %s", ang, model_last_error());
        return false;
    }
    float *dark = NULL;
    bool ok = false;
    if (r->dark_row[a] >= 0 && !(dark = lamps_load_frame(o, r, r->dark_row[a]))) goto done;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        if (lp->frame[a] < 0)
            snprintf(lp->hl[a].why, sizeof lp->hl[a].why, "no frame of this lamp at this angle in the session");
        else if (!lamp_ray(o, r, lp, a, sph, dark))
            goto done;
        if (lp->has_ray[a] && r->first_angle < 0) r->first_angle = a;
        lp->nmissing += !lp->has_ray[a];
    }
    ok = true;
done:
    free(dark);
    calib_lamps_sphere_image_free(sph);
    return ok;
}

bool calib_lamps_find_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    bool ok = true;
    for (int a = 0; ok && a < r->nangles; a++) ok = angle_highlights(o, r, a);
    model_progress_end();
    return ok;
}

const char *lamps_frame_file(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp, int a, int *step)
{
    int fr = lp->frame[a];
    *step = fr >= 0 ? r->session->rows[fr].step : -1;
    return fr >= 0 ? r->session->rows[fr].file : "(none)";
}

char *lamps_missing_text(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp)
{
    GString *g = g_string_new("");
    for (int a = 0; a < r->nangles; a++) {
        if (lp->has_ray[a]) continue;
        int step;
        const char *file = lamps_frame_file(r, lp, a, &step);
        g_string_append_printf(g, "    %s (step %d, %.3f deg): %s\n", file, step, r->angle_deg[a], lp->hl[a].why);
    }
    return g_string_free(g, FALSE);
}

void lamps_refit_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp,
                            const double x_mm[3])
{
    for (int a = 0; a < r->nangles; a++) {
        if (!lp->has_ray[a]) continue;
        model_vec3_t e = v3_sub(v3(x_mm[0], x_mm[1], x_mm[2]), lp->p_mm[a]);
        double dist = sqrt(v3_dot(e, e));
        double rho = lp->lamp_radius_mm > 0 && dist > lp->lamp_radius_mm ? asin(lp->lamp_radius_mm / dist) : 0;
        bool q = model_error_quiet_thread(true);
        calib_lamps_fit_direction(r->cam, &lp->hl[a], r->centre_mm[a], o->sphere_radius_mm, rho, &lp->p_mm[a],
                                  &lp->d[a], NULL);
        model_error_quiet_thread(q);
    }
}
